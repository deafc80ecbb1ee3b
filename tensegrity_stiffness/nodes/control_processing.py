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
#: Default tension range (``limits.tension_* = 0``) around the joint's design pretension (its
#: tensions at ``initial_screw`` with the config's rest lengths), as fractions of the smallest
#: and the largest of them, widened to :data:`DEFAULT_TENSION_MIN` / ``MAX`` (issue #39).
PRETENSION_RANGE = (0.5, 2.0)
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
    ParameterSpec('limits.tension_min', 'double', 0.0,
                  'smallest string tension, N (> 0: taut; 0: from the joint, the smaller of '
                  f'{DEFAULT_TENSION_MIN:g} N and {PRETENSION_RANGE[0]:g} x its smallest '
                  'design tension)', range=(0.0, 1e6)),
    ParameterSpec('limits.tension_max', 'double', 0.0,
                  'largest string tension, N (0: from the joint, the larger of '
                  f'{DEFAULT_TENSION_MAX:g} N and {PRETENSION_RANGE[1]:g} x its largest design '
                  'tension)', range=(0.0, 1e6)),
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
    #: The first command (n,): the config's rest lengths less the offsets, moved into the
    #: rest-length range (:data:`start_warning` says which strings were moved).
    start: np.ndarray
    start_warning: str


def default_tension_limits(model: JointModel) -> tuple[float, float]:
    """``(tension_min, tension_max)`` N around the joint's design pretension (its tensions at
    ``initial_screw`` with the config's rest lengths): :data:`PRETENSION_RANGE` of the smallest
    and largest, widened to ``DEFAULT_TENSION_MIN`` / ``MAX`` (a slack design keeps those)."""
    t = model.evaluate(model.initial_screw).tensions
    taut = t[t > 0.0]
    if taut.size == 0:
        return DEFAULT_TENSION_MIN, DEFAULT_TENSION_MAX
    return (min(DEFAULT_TENSION_MIN, PRETENSION_RANGE[0] * float(taut.min())),
            max(DEFAULT_TENSION_MAX, PRETENSION_RANGE[1] * float(taut.max())))


def start_command(model: JointModel, limits: ActuatorLimits, offsets: np.ndarray
                  ) -> tuple[np.ndarray, str]:
    """The first command (n,) m: ``joint.rest_lengths - offsets`` moved into the rest-length
    range, and a warning naming the strings moved ('' when none)."""
    rest_min, rest_max, *_ = limits.for_strings(model.n_strings)
    wanted = model.rest_lengths - offsets
    start = np.clip(wanted, rest_min, rest_max)
    moved = np.flatnonzero(start != wanted)
    if not moved.size:
        return start, ''
    names = ', '.join(f'{model.string_names[j]} {wanted[j]:.4g} -> {start[j]:.4g} m'
                      for j in moved[:3]) + (', ...' if moved.size > 3 else '')
    return start, ('the start command (joint.rest_lengths - joint.rest_length_offsets) is '
                   f'outside limits.rest_length_min/max for {moved.size} strings, moved into '
                   f'the range: {names}')


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

    if not checked['frames.link1'].strip():
        raise ValueError('frames.link1 must not be empty')
    offsets = rest_length_offsets(checked, n)
    t_min, t_max = default_tension_limits(model)
    limits = ActuatorLimits(
        per_string('limits.rest_length_min', DEFAULT_RANGE[0] * model.rest_lengths),
        per_string('limits.rest_length_max', DEFAULT_RANGE[1] * model.rest_lengths),
        checked['limits.max_rate'], checked['limits.tension_min'] or t_min,
        checked['limits.tension_max'] or t_max)
    start, warning = start_command(model, limits, offsets)
    try:
        StiffnessController(model, limits, start,  # gains and offsets valid
                            integral_gain=checked['control.integral_gain'],
                            proportional_gain=checked['control.proportional_gain'],
                            rest_length_offsets=offsets)
    except ValueError as exc:
        raise ValueError(f'joint.rest_length_offsets: at the start command: {exc}') from None
    return ControllerSettings(checked, model, limits, offsets, checked['frames.link1'],
                              start, warning)


def stiffness_target(values: np.ndarray, layout: tuple[int, ...] = ()) -> np.ndarray | None:
    """K_c* of a ``~/target_stiffness`` payload: 36 row-major, 6 a diagonal, empty none;
    ``layout`` the sizes of the message's ``layout.dim`` (none, ``(36,)``, ``(6,)`` or
    ``(6, 6)``: a 3 x 12 layout of 36 values is refused by shape). Not judged here: see
    :func:`tensegrity_stiffness.mechanics.plausibility.check_target_stiffness`."""
    sizes = {(36,): 36, (6,): 6, (6, 6): 36, (0,): 0}
    if layout and sizes.get(tuple(layout)) != values.size:
        shape = ' x '.join(map(str, layout))
        raise ValueError(f'target_stiffness: layout {shape} of {values.size} values is '
                         'not a 6 x 6 matrix (36 row-major) or a diagonal of 6')
    if values.size == 0:
        return None
    if values.size == 6:
        return np.diag(values)
    if values.size == 36:
        return values.reshape(6, 6)
    raise ValueError(f'target_stiffness must have 36, 6 or 0 values, got {values.size}')
