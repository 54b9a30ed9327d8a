"""The detector's offline side: the data set generator, training, evaluation metrics,
pruning and quantization, profiling, and the ``uav-tilt vision`` command.

The only part of uav_tilt_vision that imports the simulator (the data set is rendered by
it); the runtime the vision node runs imports nothing from here.
"""
