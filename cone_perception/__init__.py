"""cone_perception: camera cone perception for a Formula Student driverless car.

The runtime, ROS-free: adapter, crop, detector/, model/, geometry/, attitude/, mapping, tracking/,
pipeline, on the vocabulary (classes, errors, records). The ROS 2 nodes live in
:mod:`cone_perception.nodes`. The tools around them: data/, evaluation/, calibrate/, synth/, train/,
replay/, bench/, and the command line (:mod:`cone_perception.cli`). docs/architecture.md draws it.
"""

__version__ = "0.1.0"
