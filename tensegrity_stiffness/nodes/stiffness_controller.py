"""``stiffness_controller``'s behaviour without ROS
(:mod:`tensegrity_stiffness.ros.stiffness_controller` converts, validates and publishes): its
parameter table (:data:`CONTROLLER_PARAMETERS`: the joint and frame tables,
``joint.rest_length_offsets``, ``limits.*`` and ``control.*``), its settings, the reading of a
stiffness target and the tick rule (:class:`ControllerTicks`: the state's age, the command held
on a stale state, the time step after missed ticks, the latency from a reading to its first
command), which runs :class:`tensegrity_stiffness.control.controller.StiffnessController`.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from tensegrity_stiffness.control.controller import (
    MIN_QP_ITERATIONS,
    ActuatorLimits,
    ControlCommand,
    ControlTarget,
    StiffnessController,
)
from tensegrity_stiffness.geometry.validation import per_string
from tensegrity_stiffness.mechanics.design import DEFAULT_TENSION_MAX, DEFAULT_TENSION_MIN
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name
from tensegrity_stiffness.nodes.shared_parameters import (
    COMMON_PARAMETERS,
    FRAME_PARAMETERS,
    JOINT_PARAMETERS,
    REST_LENGTH_OFFSET_PARAMETERS,
    joint_from_values,
    rest_length_offsets,
)

#: Default rest-length range as fractions of the config's rest lengths (the issue's example).
DEFAULT_RANGE = (0.5, 1.2)
#: Default tension range (``limits.tension_* = 0``) around the joint's design pretension (its
#: tensions at ``initial_screw`` with the config's rest lengths), as fractions of the smallest
#: and the largest of them, widened to :data:`DEFAULT_TENSION_MIN` / ``MAX`` (issue #39).
PRETENSION_RANGE = (0.5, 2.0)

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
    ParameterSpec('control.time_budget', 'double', 0.0,
                  "wall-clock budget of one tick's QP, s (0: half a period, 0.5 / control.rate); "
                  f"a tick whose QP is past it after its first {MIN_QP_ITERATIONS} iterations is "
                  "held ('time budget exhausted', the last command kept) and the next starts cold",
                  range=(0.0, 10.0)),
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

    def limit(name: str, default: np.ndarray) -> np.ndarray:
        """A per-string limit: one value for all or one per string; empty: ``default``."""
        return per_string(name, checked[name], n, repeat_one=True) if checked[name] else default

    if not checked['frames.link1'].strip():
        raise ValueError('frames.link1 must not be empty')
    offsets = rest_length_offsets(checked, n)
    t_min, t_max = default_tension_limits(model)
    limits = ActuatorLimits(
        limit('limits.rest_length_min', DEFAULT_RANGE[0] * model.rest_lengths),
        limit('limits.rest_length_max', DEFAULT_RANGE[1] * model.rest_lengths),
        checked['limits.max_rate'], checked['limits.tension_min'] or t_min,
        checked['limits.tension_max'] or t_max)
    start, warning = start_command(model, limits, offsets)
    settings = ControllerSettings(checked, model, limits, offsets, checked['frames.link1'],
                                  start, warning)
    try:
        new_controller(settings)  # gains and offsets valid
    except ValueError as exc:
        raise ValueError(f'joint.rest_length_offsets: at the start command: {exc}') from None
    return settings


#: The share of a period a tick's QP may take when ``control.time_budget`` is 0. The QP stops
#: only between iterations (after its first 20), and the tick's other work (the pose terms, the
#: command) needs the rest: with a whole period, bench_hostile's slowest accepted tick took
#: 2.18 ms at 500 Hz on a quiet machine, 1.09 periods.
QP_SHARE_OF_PERIOD = 0.5


def tick_time_budget(values: Mapping[str, Any]) -> float:
    """A tick's time budget (s): ``control.time_budget``, or :data:`QP_SHARE_OF_PERIOD` of a
    period when it is 0."""
    return values['control.time_budget'] or QP_SHARE_OF_PERIOD / values['control.rate']


def new_controller(settings: ControllerSettings, rest_lengths: np.ndarray | None = None
                   ) -> StiffnessController:
    """The controller of ``settings`` starting from the command ``rest_lengths`` (None: the
    settings' start command); ValueError when it cannot (offsets that make a true rest length
    <= 0)."""
    values = settings.values
    return StiffnessController(settings.model, settings.limits,
                               settings.start if rest_lengths is None else rest_lengths,
                               integral_gain=values['control.integral_gain'],
                               proportional_gain=values['control.proportional_gain'],
                               rest_length_offsets=settings.offsets,
                               time_budget=tick_time_budget(values))


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


#: A reading's stamp counts into the latency only within this window of the node's clock (s):
#: at most this far in the future (clock offsets between machines) and at most
#: ``STAMP_WINDOW[1]`` in the past. A stamp outside it (1 s after the epoch, a day ahead) is
#: counted (:attr:`ControllerTicks.stamps_out_of_window`), the reading used (its arrival is what
#: ages it).
STAMP_WINDOW = (0.01, 10.0)
#: Ticks over which the tick time and the latency are kept (median, p99 on /diagnostics).
STATISTICS_WINDOW = 2000
#: The time step of a tick is at most this many periods (a tick after a long pause, a stopped
#: clock, missed ticks: the integral does not jump).
MAX_STEP_PERIODS = 10


@dataclass(frozen=True)
class StateReading:
    """The latest pose estimate: ``transform`` (4, 4) of link 2 in link 1, its arrival
    ``received`` (monotonic s), the reading's stamp ``stamp_ns`` (0: unstamped) and its
    ``sequence`` number (one per state taken)."""

    transform: np.ndarray
    received: float
    stamp_ns: int
    sequence: int


@dataclass(frozen=True)
class TickOutcome:
    """What one tick gave: the ``command`` computed (None: held, or no target yet) or the
    controller's refusal (``error``: the ValueError's text)."""

    command: ControlCommand | None = None
    error: str = ''


class ControllerTicks:
    """The tick rule of ``stiffness_controller`` without ROS or threads: the latest state, load
    and targets (set by the node's inputs), and :meth:`tick` with the time passed in. A tick
    holds the last command (counted in :attr:`held`, the reason in :attr:`hold_reason`) while
    there is no target pose or no state younger than ``control.max_state_age``; its time step
    is the time since the last tick, at most :data:`MAX_STEP_PERIODS` periods (the first: one
    period). A tick whose QP runs past ``control.time_budget`` is held (counted in
    :attr:`out_of_time`, its command's message names the parameter). Not thread-safe: the
    node calls it under its lock."""

    def __init__(self, settings: ControllerSettings, controller: StiffnessController,
                 period: float) -> None:
        if not period > 0.0:
            raise ValueError(f'period must be > 0 s, got {period}')
        self.settings = settings
        self.controller = controller
        self.period = float(period)
        self.target_pose: np.ndarray | None = None
        self.target_stiffness: np.ndarray | None = None
        #: The load estimate (``~/wrench_estimate``) and the known load (``~/external_wrench``).
        self.wrench_estimate: np.ndarray | None = None
        self.known_wrench: np.ndarray | None = None
        self.state: StateReading | None = None
        self.last: ControlCommand | None = None
        self.ticks = 0  # commands computed
        self.held = 0  # ticks that held the last command on a stale (or no) state
        self.old_state_ticks = 0  # commands computed from a state older than one period
        self.stamps_out_of_window = 0
        self.out_of_time = 0  # ticks held at control.time_budget
        self.tick_time = 0.0
        self.state_age = float('nan')
        self.hold_reason = 'no target yet'
        self.tick_times: deque[float] = deque(maxlen=STATISTICS_WINDOW)
        self.latencies: deque[float] = deque(maxlen=STATISTICS_WINDOW)
        self._states = 0
        self._commanded_state = 0  # the sequence number of the last state a command came from
        self._last_tick: float | None = None
        # the ControlTarget of the targets set (pose, stiffness), validated once per set
        self._target: tuple[Any, Any, ControlTarget] | None = None

    def control_target(self) -> ControlTarget:
        """The :class:`ControlTarget` of :attr:`target_pose` and :attr:`target_stiffness`,
        built (and validated) once for each pair set, not every tick (the node sets new arrays
        per message and never changes one in place); ValueError as ``ControlTarget``'s."""
        cached = self._target
        pose, stiffness = self.target_pose, self.target_stiffness
        if cached is None or cached[0] is not pose or cached[1] is not stiffness:
            cached = self._target = (pose, stiffness,
                                     ControlTarget(pose=pose, cartesian_stiffness=stiffness))
        return cached[2]

    def reconfigure(self, settings: ControllerSettings, controller: StiffnessController
                    ) -> None:
        """A new parameter set and the controller built from it (the counters, the state and
        the targets are kept)."""
        self.settings, self.controller = settings, controller

    def take_state(self, transform: np.ndarray, received: float, stamp_ns: int,
                   wrench: np.ndarray | None = None) -> None:
        """The latest pose estimate (arrived at ``received``, monotonic s) and, when given, the
        load estimate: what the next tick uses."""
        self._states += 1
        self.state = StateReading(transform, received, stamp_ns, self._states)
        if wrench is not None:
            self.wrench_estimate = wrench

    def load(self) -> np.ndarray | None:
        """The load the controller feeds forward: the estimate with
        ``control.use_wrench_estimate`` (once one came), else the known load (None: none)."""
        if self.settings.values['control.use_wrench_estimate'] and \
                self.wrench_estimate is not None:
            return self.wrench_estimate
        return self.known_wrench

    def tick(self, now: float, clock_ns: int) -> TickOutcome:
        """One tick at ``now`` (monotonic s; ``clock_ns``: the node's clock in ns, for the
        latency of a stamped reading)."""
        dt = self.period if self._last_tick is None else min(
            now - self._last_tick, MAX_STEP_PERIODS * self.period)
        self._last_tick = now
        if self.target_pose is None:
            self.hold_reason = 'no target yet'
            return TickOutcome()
        max_age = self.settings.values['control.max_state_age']
        state = self.state
        if state is not None:
            self.state_age = now - state.received
        if state is None or self.state_age > max_age:
            self.held += 1
            self.hold_reason = (f'no pose estimate within control.max_state_age = '
                                f'{max_age:g} s: last command held')
            return TickOutcome()
        try:
            target = self.control_target()
            start = time.perf_counter()
            cmd = self.controller.update(dt, target, pose=state.transform,
                                         external_wrench=self.load())
            self.tick_time = time.perf_counter() - start
            self.tick_times.append(self.tick_time)
        except ValueError as exc:
            return TickOutcome(error=str(exc))
        self.ticks += 1
        if cmd.out_of_time:  # held; the log and /diagnostics name the parameter
            self.out_of_time += 1
            cmd = replace(cmd, message=f'{cmd.message} (control.time_budget = '
                          f'{self.controller.time_budget:g} s)')
        self.hold_reason = ''
        self.last = cmd
        if self.state_age > self.period:
            self.old_state_ticks += 1
        if cmd.feasible:
            # the latency of a reading: to the first command computed from it
            if state.stamp_ns and state.sequence != self._commanded_state:
                latency = 1e-9 * (clock_ns - state.stamp_ns)
                if -STAMP_WINDOW[0] <= latency <= STAMP_WINDOW[1]:
                    self.latencies.append(latency)
                else:
                    self.stamps_out_of_window += 1
            self._commanded_state = state.sequence
        return TickOutcome(cmd)
