"""cone_perception: camera cone perception for a Formula Student driverless car.

Core modules (ROS-free): classes, errors, crop, adapter, camera, geometry, calib,
records. ROS 2 nodes live in :mod:`cone_perception.nodes`; the command line in
:mod:`cone_perception.cli`.
"""

__version__ = "0.1.0"
