"""``stiffness_controller``'s behaviour without ROS: its parameter table
(:data:`CONTROLLER_PARAMETERS`: the joint and frame tables, ``joint.rest_length_offsets``,
``limits.*`` and ``control.*``), its settings and the reading of a stiffness target. The node
(:mod:`tensegrity_stiffness.ros.stiffness_controller`) runs
:class:`tensegrity_stiffness.control.StiffnessController` with them."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from tensegrity_stiffness.control.controller import ActuatorLimits, StiffnessController
from tensegrity_stiffness.mechanics.design import DEFAULT_TENSION_MAX, DEFAULT_TENSION_MIN
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.parameters import (
    COMMON_PARAMETERS,
    FRAME_PARAMETERS,
    JOINT_PARAMETERS,
    REST_LENGTH_OFFSET_PARAMETERS,
    ParameterSpec,
    by_name,
    joint_from_values,
    rest_length_offsets,
)

#: Default rest-length range as fractions of the config's rest lengths (the issue's example).
DEFAULT_RANGE = (0.5, 1.2)
REST_LENGTHS_LABEL = 'rest lengths [m] (motor commands), string order of the config'

CONTROL_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('limits.rest_length_min', 'double_array', None,
                  'smallest motor command, m: one value or one per string (empty: '
                  f'{DEFAULT_RANGE[0]} x joint.rest_lengths)'),
    ParameterSpec('limits.rest_length_max', 'double_array', None,
                  'largest motor command, m: one value or one per string (empty: '
                  f'{DEFAULT_RANGE[1]} x joint.rest_lengths)'),
    ParameterSpec('limits.max_rate', 'double', 0.05, 'largest motor speed, m/s',
                  range=(1e-9, 1e3)),
    ParameterSpec('limits.tension_min', 'double', DEFAULT_TENSION_MIN,
                  'smallest string tension, N (> 0: taut)', range=(1e-9, 1e6)),
    ParameterSpec('limits.tension_max', 'double', DEFAULT_TENSION_MAX,
                  'largest string tension, N', range=(1e-9, 1e6)),
    ParameterSpec('control.rate', 'double', 500.0, 'controller ticks per second, Hz',
                  read_only=True, range=(1.0, 10_000.0)),
    ParameterSpec('control.max_state_age', 'double', 0.05,
                  'a pose estimate older than this (s, by arrival) holds the last command',
                  range=(0.0, 3600.0)),
    ParameterSpec('control.integral_gain', 'double', 8.0,
                  'integral gain on the pose error, 1/s (docs/control.md)', range=(0.0, 1e4)),
    ParameterSpec('control.proportional_gain', 'double', 0.0,
                  'share of the pose error added to the design pose, [0, 1)',
                  range=(0.0, 0.999)),
    ParameterSpec('control.use_wrench_estimate', 'bool', False,
                  'feed ~/wrench_estimate forward as the load (false: ~/external_wrench, or '
                  "none: the integral takes the load). Only for an estimator that measures the "
                  "load: with estimation.external_wrench 'unknown' the estimate is -F of the "
                  'commanded rest lengths, which during a transient feeds the command back '
                  'into itself'),
)

#: Every parameter of ``stiffness_controller``, in declaration order.
CONTROLLER_PARAMETERS: tuple[ParameterSpec, ...] = (
    JOINT_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + FRAME_PARAMETERS + CONTROL_PARAMETERS
    + tuple(s for s in COMMON_PARAMETERS if s.name in ('qos.depth', 'limits.max_array_length',
                                                       'diagnostics.period')))


@dataclass(frozen=True)
class ControllerSettings:
    """One whole parameter set, validated (swapped as a whole)."""

    values: Mapping[str, Any]
    model: JointModel
    limits: ActuatorLimits
    offsets: np.ndarray
    link1_frame: str


def controller_settings(values: Mapping[str, Any]) -> ControllerSettings:
    """The settings of a parameter set; ValueError names the bad field."""
    specs = by_name(CONTROLLER_PARAMETERS)
    checked = {name: specs[name].check(v) for name, v in values.items() if name in specs}
    model = joint_from_values(checked)
    n = model.n_strings

    def per_string(name: str, default: np.ndarray) -> np.ndarray:
        raw = checked[name]
        if not raw:
            return default
        if len(raw) not in (1, n):
            raise ValueError(f'{name} must have 1 or {n} values, got {len(raw)}')
        return np.broadcast_to(np.asarray(raw, float), (n,)).copy()

    offsets = rest_length_offsets(checked, n)
    limits = ActuatorLimits(
        per_string('limits.rest_length_min', DEFAULT_RANGE[0] * model.rest_lengths),
        per_string('limits.rest_length_max', DEFAULT_RANGE[1] * model.rest_lengths),
        checked['limits.max_rate'], checked['limits.tension_min'], checked['limits.tension_max'])
    StiffnessController(model, limits, model.rest_lengths - offsets,  # gains and offsets valid
                        integral_gain=checked['control.integral_gain'],
                        proportional_gain=checked['control.proportional_gain'],
                        rest_length_offsets=offsets)
    return ControllerSettings(checked, model, limits, offsets, checked['frames.link1'])


def stiffness_target(values: np.ndarray) -> np.ndarray | None:
    """K_c* of a ``~/target_stiffness`` payload: 36 row-major, 6 a diagonal, empty none."""
    if values.size == 0:
        return None
    if values.size == 6:
        return np.diag(values)
    if values.size == 36:
        return values.reshape(6, 6)
    raise ValueError(f'target_stiffness must have 36, 6 or 0 values, got {values.size}')
