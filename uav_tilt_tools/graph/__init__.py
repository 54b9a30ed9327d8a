"""Tools on the running ROS graph: topics, the mission watcher, the Foxglove bridge and the
hover client of the plant's tests."""
