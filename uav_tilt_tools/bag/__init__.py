"""Recordings: MCAP files in the ros2 profile, written by the recorder node or an in-process
flight, and read back for the report."""
