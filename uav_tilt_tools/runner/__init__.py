"""One mission in-process: the plant and controller cores stepped together, no ROS."""
