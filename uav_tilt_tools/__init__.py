"""uav_tilt_tools."""
