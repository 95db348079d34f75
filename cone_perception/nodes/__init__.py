"""Thin rclpy shells, one file per node. All logic lives in the core modules."""
