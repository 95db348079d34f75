"""Parameters of a node from :data:`cone_perception.params.PARAMS`: declared with descriptors
(description, type, range, read-only unless dynamic), and changed at run time through one
on-set callback that validates every value and then applies it."""

from __future__ import annotations

from typing import Callable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..params import PARAMS, ParamSpec

_ROS_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
}


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The rclpy descriptor of ``spec`` (what ``ros2 param describe`` shows)."""
    d = ParameterDescriptor(
        name=spec.name,
        type=_ROS_TYPES[spec.type],
        description=spec.description,
        read_only=not spec.dynamic,
    )
    if spec.choices is not None:
        d.additional_constraints = "one of: " + ", ".join(spec.choices)
    if spec.type is float and spec.min is not None and spec.max is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.min), to_value=float(spec.max), step=0.0)]
    elif spec.type is int and spec.min is not None and spec.max is not None:
        d.integer_range = [IntegerRange(from_value=int(spec.min), to_value=int(spec.max), step=1)]
    return d


def declare(node: Node, name: str):
    """Declare the parameter ``name`` of :data:`PARAMS` on ``node``; returns its value (checked: a
    value from a parameter file out of range or of the wrong type stops the node with the reason)."""
    spec = PARAMS[name]
    value = node.declare_parameter(name, spec.default, descriptor(spec)).value
    why = spec.check(value)
    if why:
        from ..errors import ConfigError

        raise ConfigError(f"parameter {name}", None, why)
    return value


class RuntimeParameters:
    """One on-set-parameters callback per node: ``ros2 param set`` on a registered (dynamic) parameter
    is checked by :meth:`ParamSpec.check` and then handed to its ``apply`` function; a bad value is
    rejected with the reason and the node keeps the old one. Parameters not registered here are left
    to rclpy (read-only ones are refused by rclpy itself)."""

    def __init__(self, node: Node) -> None:
        self.node = node
        self._apply: dict[str, Callable[[object], None]] = {}
        node.add_on_set_parameters_callback(self._on_set)

    def register(self, name: str, apply: Callable[[object], None]) -> None:
        """Call ``apply(new_value)`` whenever ``name`` is set at run time (after it passed its check)."""
        if not PARAMS[name].dynamic:
            raise ValueError(f"parameter {name} is not dynamic")
        self._apply[name] = apply

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        mine = [p for p in params if p.name in self._apply]
        for p in mine:  # all checked before any is applied: a set of several is all or nothing
            why = PARAMS[p.name].check(p.value)
            if why:
                self.node.get_logger().warning(f"parameter change refused: {why}")
                return SetParametersResult(successful=False, reason=why)
        for p in mine:
            self._apply[p.name](p.value)
            self.node.get_logger().info(f"parameter {p.name} = {p.value!r}")
        return SetParametersResult(successful=True)
