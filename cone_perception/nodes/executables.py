"""The node executables (``setup.py``'s console scripts, ``ros2 run cone_perception <node>``).

:func:`launch` answers ``-h`` /
``--help`` from the parameter schema (:func:`cone_perception.params.help_text`) before the node's
module is imported, so asking for help loads no rclpy, sets no DDS environment and creates no DDS
participant. ROS's own arguments (``--ros-args ... [--]``) pass through untouched; a ``-h`` among
them is ROS's, not ours.
"""

from __future__ import annotations

import importlib
import sys

from ..params import help_text  # ROS-free


def user_args(argv: list[str]) -> list[str]:
    """The arguments of ``argv`` (without the program name) outside every ``--ros-args ... [--]`` section."""
    out, in_ros = [], False
    for a in argv:
        if a == "--ros-args":
            in_ros = True
        elif in_ros and a == "--":
            in_ros = False
        elif not in_ros:
            out.append(a)
    return out


def wants_help(argv: list[str]) -> bool:
    """Whether ``argv`` (without the program name) asks for help: ``-h`` or ``--help`` outside ``--ros-args``."""
    return any(a in ("-h", "--help") for a in user_args(argv))


def launch(node: str, argv: list[str] | None = None) -> int:
    """``main()`` of the node executable ``node``: its help, or the node (imported only then)."""
    argv = list(sys.argv if argv is None else argv)
    if wants_help(argv[1:]):
        sys.stdout.write(help_text(node))
        return 0
    return importlib.import_module(f"cone_perception.nodes.{node}").main(argv)


def driver_adapter() -> int:
    return launch("driver_adapter")


def detection() -> int:
    return launch("detection")


def mapping() -> int:
    return launch("mapping")


def pipeline() -> int:
    return launch("pipeline")


def cone_tracker() -> int:
    return launch("cone_tracker")
