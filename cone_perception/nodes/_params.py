"""Parameters of a node from its table in :mod:`cone_perception.params` (:func:`~cone_perception.params.node_params`):
declared with descriptors (description, type, range, read-only unless dynamic), and changed at run time
through one on-set callback that validates every value and then applies it. No node declares a
parameter any other way (tested)."""

from __future__ import annotations

from typing import Callable

from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType, SetParametersResult
from rclpy.exceptions import InvalidParameterTypeException
from rclpy.node import Node
from rclpy.parameter import Parameter

from ..errors import ConfigError
from ..params import COMMON_PARAMS, NODES, PARAMS, ParamSpec, node_params

_ROS_TYPES = {
    bool: ParameterType.PARAMETER_BOOL,
    int: ParameterType.PARAMETER_INTEGER,
    float: ParameterType.PARAMETER_DOUBLE,
    str: ParameterType.PARAMETER_STRING,
    tuple: ParameterType.PARAMETER_DOUBLE_ARRAY,
}


_ROS_TYPE_WORDS = {bool: "bool", int: "integer", float: "double", str: "string", tuple: "double array"}


def specs_of(kind: str) -> dict[str, ParamSpec]:
    """The parameter table of the node executable ``kind`` (every parameter by name for another node)."""
    if kind in NODES:
        return node_params(kind)
    return {**PARAMS, **{p.name: p for p in COMMON_PARAMS}}


def _spec(node: Node, name: str) -> ParamSpec:
    table = getattr(node, "param_specs", None) or specs_of(node.get_name())
    return table[name]


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """The rclpy descriptor of ``spec`` (what ``ros2 param describe`` shows)."""
    d = ParameterDescriptor(
        name=spec.name,
        type=_ROS_TYPES[spec.type],
        description=spec.description,
        read_only=not spec.dynamic,
    )
    if spec.choices is not None:
        d.additional_constraints = "one of: " + ", ".join(c or '""' for c in spec.choices)
    elif spec.range_text():
        d.additional_constraints = spec.range_text()
    if spec.type is float and spec.min is not None and spec.max is not None:
        d.floating_point_range = [FloatingPointRange(from_value=float(spec.min), to_value=float(spec.max), step=0.0)]
    elif spec.type is int and spec.min is not None and spec.max is not None:
        d.integer_range = [IntegerRange(from_value=int(spec.min), to_value=int(spec.max), step=1)]
    return d


def declare(node: Node, name: str):
    """Declare the parameter ``name`` of the node's table on ``node``; returns its value (checked: a value
    from a parameter file out of range or of the wrong type stops the node with the reason). An array
    comes back as a list."""
    spec = _spec(node, name)
    try:
        value = node.declare_parameter(name, spec.ros_default, descriptor(spec)).value
    except InvalidParameterTypeException as e:  # e.g. -p far_rows:=off, which ROS reads as a boolean
        hint = (": a word ROS reads as a boolean (on, off, yes, no, true, false) is not a string; write another or "
                "quote it (name:=\"'off'\")") if spec.type is str else ""
        got = str(e.args[0]).split("' to ", 1)[-1].split(", expecting", 1)[0] if e.args else "another type"
        raise ConfigError(f"parameter {name}", None, f"must be a {_ROS_TYPE_WORDS[spec.type]}, got {got}{hint}") from None
    why = spec.check(value)
    if why:
        raise ConfigError(f"parameter {name}", None, why)
    return list(value) if isinstance(spec.default, tuple) else value


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
        if not _spec(self.node, name).dynamic:
            raise ValueError(f"parameter {name} is not dynamic")
        self._apply[name] = apply

    def _on_set(self, params: list[Parameter]) -> SetParametersResult:
        mine = [p for p in params if p.name in self._apply]
        for p in mine:  # all checked before any is applied: a set of several is all or nothing
            why = _spec(self.node, p.name).check(p.value)
            if why:
                self.node.get_logger().warning(f"parameter change refused: {why}")
                return SetParametersResult(successful=False, reason=why)
        for p in mine:
            self._apply[p.name](p.value)
            self.node.get_logger().info(f"parameter {p.name} = {p.value!r}")
        return SetParametersResult(successful=True)
