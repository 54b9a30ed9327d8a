"""uav_tilt_sim."""
