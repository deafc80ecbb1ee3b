"""The parameter machinery of the package's nodes: one :class:`ParameterSpec` per parameter
(name, type, default, range, read-only flag, description), the table helpers (:func:`by_name`,
:func:`defaults`, :func:`flatten`), the ``strict_parameters`` switch and :class:`NodeTable`, a
node's table as ``docs/parameters.md`` shows it. The tables themselves are the nodes' (one
module per node, :mod:`.shared_parameters` for the sections several nodes share); the registry
and the unknown-parameter rules that need every node's table are :mod:`.registry`'s. No ROS
import.

Types are ROS parameter types by name: ``bool``, ``int``, ``double``, ``string``,
``double_array``, ``string_array``. A ``default`` of ``None`` on an array means "empty" (an
optional array left out, e.g. ``joint.link2_nodes``: link 2 uses link 1's nodes).
"""

from __future__ import annotations

import math
import re
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

TYPES = ('bool', 'int', 'double', 'string', 'double_array', 'string_array')
RELIABILITIES = ('reliable', 'best_effort')


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter: ``name`` (dotted), ROS ``type`` name, ``default``, ``description``,
    ``read_only`` (fixed once the node runs), numeric ``range`` (inclusive) and string
    ``choices``."""

    name: str
    type: str
    default: Any
    description: str
    read_only: bool = False
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f'{self.name}: unknown type {self.type!r}')

    @property
    def constraints(self) -> str:
        """Human-readable constraints (the descriptor's ``additional_constraints``)."""
        return ' | '.join(self.choices)

    def check(self, value: Any) -> Any:
        """``value`` converted to this parameter's Python type; ValueError naming the parameter
        when it has another type, lies outside ``range`` or is not one of ``choices``."""
        kind = self.type
        if kind in ('double_array', 'string_array'):
            if value is None:
                return []
            if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
                raise ValueError(f'{self.name} must be a list ({kind}), got {value!r}')
            value = list(value)
            if kind == 'double_array':
                if not all(_is_number(v) for v in value):
                    raise ValueError(f'{self.name} must be a list of numbers')
                return [float(v) for v in value]
            if not all(isinstance(v, str) for v in value):
                raise ValueError(f'{self.name} must be a list of strings')
            return value
        if kind == 'bool':
            if not isinstance(value, bool):
                raise ValueError(f'{self.name} must be true or false, got {value!r}')
            return value
        if kind == 'string':
            if not isinstance(value, str):
                raise ValueError(f'{self.name} must be a string, got {value!r}')
            if self.choices and value not in self.choices:
                raise ValueError(f'{self.name} must be one of {self.constraints}, got {value!r}')
            return value
        if kind == 'int':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f'{self.name} must be an integer, got {value!r}')
        elif not _is_number(value):
            raise ValueError(f'{self.name} must be a number, got {value!r}')
        else:
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(f'{self.name} must be finite, got {value}')
        if self.range is not None and not self.range[0] <= value <= self.range[1]:
            raise ValueError(f'{self.name} = {value:g} is outside [{self.range[0]:g}, '
                             f'{self.range[1]:g}]')
        return value


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def by_name(table: Iterable[ParameterSpec]) -> dict[str, ParameterSpec]:
    """The table as a mapping from parameter name to spec."""
    return {spec.name: spec for spec in table}


def defaults(table: Iterable[ParameterSpec]) -> dict[str, Any]:
    """``{name: default}`` of a table (arrays without a default as empty lists)."""
    return {spec.name: spec.check(spec.default) for spec in table}


def flatten(section: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Dotted names of a nested parameter mapping (``{'qos': {'depth': 1}}`` ->
    ``{'qos.depth': 1}``), as ROS names the parameters of a parameter file."""
    out: dict[str, Any] = {}
    for key, value in section.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = value
    return out



#: A spine's per-joint override section ``joint_<i>`` (any i) as one section.
OVERRIDE_SECTION = re.compile(r'^joint_\d+(?=\.)')


def generic_name(name: str) -> str:
    """``name`` with a spine's per-joint section ``joint_<i>`` written ``joint_<i>`` (one name
    for every joint's override)."""
    return OVERRIDE_SECTION.sub('joint_<i>', name)


#: Every node's switch between refusing and warning about an unknown parameter of its own
#: sections (declared by every node beside its table: ``ros/runtime/declared_parameters.py``).
STRICT_PARAMETERS = ParameterSpec(
    'strict_parameters', 'bool', True,
    "an unknown parameter in one of the node's own sections (joint.stifness) makes the node "
    "refuse to start, naming the nearest name; false (a file shared with other packages' nodes "
    'that use the same section names): warn and run', read_only=True)



@dataclass(frozen=True)
class NodeTable:
    """One node's parameter table as ``docs/parameters.md`` shows it: the ``node`` (executable)
    name, its ``parameters`` in declaration order, the packaged ``config`` file that agrees with
    their defaults (empty: none), a one-line ``summary`` and the docs ``page`` of its topics and
    services (the node's ``--help`` names them)."""

    node: str
    parameters: tuple[ParameterSpec, ...]
    config: str = ''
    summary: str = ''
    page: str = ''


