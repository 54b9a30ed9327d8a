"""uav_tilt_control."""
