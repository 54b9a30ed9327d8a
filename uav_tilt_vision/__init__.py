"""uav_tilt_vision."""
