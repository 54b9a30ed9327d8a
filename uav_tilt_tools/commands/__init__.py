"""The `uav-tilt` sub-commands: each builds its parser (``register``) and calls the library."""
