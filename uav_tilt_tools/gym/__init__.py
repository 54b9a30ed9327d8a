"""The Gymnasium environment of the touch on a wall (extra ``uav_tilt[gym]``)."""
