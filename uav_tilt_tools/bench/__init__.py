"""`uav-tilt bench`: speed and accuracy measurements, one JSON object each."""
