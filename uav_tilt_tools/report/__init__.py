"""`uav-tilt report`: summary.json and plots of a recorded run."""
