"""Declare a node's parameters from its table (:mod:`tensegrity_stiffness.nodes.parameter_specs`)
and keep its settings in step with them: a change is validated as a whole before it is
accepted, and the settings are rebuilt and swapped as one object after it."""

from __future__ import annotations

import warnings
from collections.abc import Callable, Iterable, Mapping
from typing import Any

from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter

from tensegrity_stiffness.mechanics.unloaded import InitialScrewWarning
from tensegrity_stiffness.nodes.parameter_specs import STRICT_PARAMETERS, ParameterSpec
from tensegrity_stiffness.nodes.registry import refuse_unknown_parameters
from tensegrity_stiffness.ros.runtime.rclpy_internals import parameter_override_names

_ROS_TYPES = {
    'bool': Parameter.Type.BOOL, 'int': Parameter.Type.INTEGER,
    'double': Parameter.Type.DOUBLE, 'string': Parameter.Type.STRING,
    'double_array': Parameter.Type.DOUBLE_ARRAY, 'string_array': Parameter.Type.STRING_ARRAY,
}


def descriptor(spec: ParameterSpec) -> ParameterDescriptor:
    """The ROS descriptor of a table entry (description, read-only flag, range, choices)."""
    d = ParameterDescriptor(description=spec.description, read_only=spec.read_only,
                            additional_constraints=spec.constraints)
    if spec.range is not None and spec.type == 'double':
        d.floating_point_range = [FloatingPointRange(
            from_value=float(spec.range[0]), to_value=float(spec.range[1]), step=0.0)]
    elif spec.range is not None and spec.type == 'int':
        d.integer_range = [IntegerRange(from_value=int(spec.range[0]),
                                        to_value=int(spec.range[1]), step=1)]
    return d


def declare(node: Node, table: Iterable[ParameterSpec]) -> None:
    """Declare every parameter of ``table`` on ``node`` (a parameter file or overrides given at
    start-up take precedence over the defaults). An array without a default is declared typed,
    without a value."""
    for spec in table:
        default = spec.check(spec.default)
        value = default if default != [] else _ROS_TYPES[spec.type]
        node.declare_parameter(spec.name, value, descriptor(spec))


def declared_strictness(node: Node) -> bool:
    """Declare :data:`STRICT_PARAMETERS` on ``node`` (once) and return its value."""
    if not node.has_parameter(STRICT_PARAMETERS.name):
        node.declare_parameter(STRICT_PARAMETERS.name, STRICT_PARAMETERS.default,
                               descriptor(STRICT_PARAMETERS))
    return bool(node.get_parameter(STRICT_PARAMETERS.name).value)


def current_values(node: Node, table: Iterable[ParameterSpec]) -> dict[str, Any]:
    """``{name: value}`` of the node's parameters (a typed array without a value as ``[]``)."""
    values = {}
    for spec in table:
        try:
            value = node.get_parameter(spec.name).value
        except ParameterUninitializedException:
            value = None
        values[spec.name] = spec.check(value if value is not None else
                                       ([] if spec.type.endswith('_array') else value))
    return values


class ParameterBinding:
    """Declares ``table`` on ``node`` and refuses (ValueError: the node does not start) a
    misspelt parameter of the node's own sections in its parameter file or overrides, naming
    the nearest name (with ``strict_parameters:=false``: a warning, and the node runs);
    validates every parameter change of
    ``node`` as a whole with ``build`` (values -> settings, ValueError naming the field) and,
    once ROS has applied it, rebuilds the settings and hands them to ``apply``.
    ``on_rejected(reason)`` reports a rejected change."""

    def __init__(self, node: Node, table: Iterable[ParameterSpec],
                 build: Callable[[Mapping[str, Any]], Any],
                 apply: Callable[[Mapping[str, Any], set[str]], None],
                 on_rejected: Callable[[str], None]) -> None:
        self._node = node
        self._table = tuple(table)
        self._build = build
        self._apply = apply
        self._on_rejected = on_rejected
        declare(node, self._table)
        for line in refuse_unknown_parameters(parameter_override_names(node), self._table,
                                              declared_strictness(node)):
            node.get_logger().warning(line)
        node.add_on_set_parameters_callback(self._validate)
        node.add_post_set_parameters_callback(self._applied)

    def values(self, overrides: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """The current values, with ``overrides`` on top."""
        values = current_values(self._node, self._table)
        values.update(overrides or {})
        return values

    def build(self, values: Mapping[str, Any], *args: Any) -> Any:
        """The settings of ``values`` (``build(values, *args)``); a config's warnings (an
        ``initial_screw`` that is not an unloaded equilibrium) become log warnings."""
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter('always', InitialScrewWarning)
            settings = self._build(values, *args)
        for warning in caught:
            self._node.get_logger().warning(str(warning.message))
        return settings

    def _validate(self, parameters: list[Parameter]) -> SetParametersResult:
        try:
            with warnings.catch_warnings():  # logged once, when the change is applied
                warnings.simplefilter('ignore', InitialScrewWarning)
                self._build(self.values({p.name: p.value for p in parameters}))
        except Exception as exc:  # ValueError / TypeError name the field; anything else: a bug
            reason = str(exc) if isinstance(exc, (ValueError, TypeError)) else \
                f'internal error: {type(exc).__name__}: {exc}'
            self._on_rejected(reason)
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _applied(self, parameters: list[Parameter]) -> None:
        self._apply(self.values(), {p.name for p in parameters})


__all__ = ['ParameterBinding', 'current_values', 'declare', 'declared_strictness', 'descriptor']
