"""Thin rclpy shells, one file per node. All logic lives in the core modules. The executables start
in :mod:`cone_perception.nodes.executables` (``--help`` without rclpy)."""
