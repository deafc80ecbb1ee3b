"""``stiffness_controller``: rest-length commands that hold a target pose with a target K_c, in
closed loop (issue 27), around :class:`tensegrity_stiffness.control.StiffnessController`.

Inputs (executor): ``~/target_pose`` (``PoseStamped`` in ``frames.link1``),
``~/target_stiffness`` (``Float64MultiArray``: 36 row-major, 6 for a diagonal, empty for none),
the state as ``estimator_node`` publishes it (``~/pose_estimate``,
``PoseWithCovarianceStamped``; ``~/wrench_estimate``, ``WrenchStamped``: one remap each) or a
known load on ``~/external_wrench``. A timer at ``control.rate`` runs one controller tick on the
latest state and publishes ``~/rest_lengths`` (latched, the format ``sim_node``,
``estimator_node`` and ``stiffness_node`` take: motor commands, ``true - offset``) and
``~/predicted_stiffness`` (36 row-major); ``/diagnostics`` once a second. A state older than
``control.max_state_age`` holds the last command and says so; a bad target or parameter is
refused with a throttled warning and the last command is kept.

Built from the shared parts (:mod:`.parameters` ParameterBinding, :mod:`.reporting`,
:mod:`.topics`, :mod:`.runner`); the parameter table is this module's
(:data:`CONTROLLER_PARAMETERS`, the joint and frame tables plus ``limits.*`` / ``control.*`` /
``joint.rest_length_offsets``) until it moves into :mod:`tensegrity_stiffness.parameters`.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, WrenchStamped
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

import msg_tools
from msg_tools import estimation as estimation_msgs
from tensegrity_stiffness.control import (
    ActuatorLimits,
    ControlCommand,
    ControlTarget,
    StiffnessController,
)
from tensegrity_stiffness.design import DEFAULT_TENSION_MAX, DEFAULT_TENSION_MIN
from tensegrity_stiffness.joint import JointModel
from tensegrity_stiffness.parameters import (
    COMMON_PARAMETERS,
    FRAME_PARAMETERS,
    JOINT_PARAMETERS,
    ParameterSpec,
    by_name,
    joint_from_values,
)
from tensegrity_stiffness.ros import runner
from tensegrity_stiffness.ros.parameters import ParameterBinding
from tensegrity_stiffness.ros.reporting import Reporter, guarded
from tensegrity_stiffness.ros.topics import LATCHED_QOS, create_output_publisher, input_qos
from tensegrity_stiffness.validation import require_frame

NODE_NAME = 'stiffness_controller'
#: Default rest-length range as fractions of the config's rest lengths (the issue's example).
DEFAULT_RANGE = (0.5, 1.2)
REST_LENGTHS_LABEL = 'rest lengths [m] (motor commands), string order of the config'
STIFFNESS_ROW_LABEL = 'wrench [fx fy fz mx my mz]'
STIFFNESS_COL_LABEL = 'twist [dx dy dz rx ry rz]'
#: Ticks over which /diagnostics reports the tick time and the latency (median, p99).
STATISTICS_WINDOW = 2000

CONTROL_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('joint.rest_length_offsets', 'double_array', None,
                  'calibrated rest-length offsets d, m, one per string (empty: zeros); the '
                  'true rest length is command + d'),
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
    JOINT_PARAMETERS + FRAME_PARAMETERS + CONTROL_PARAMETERS
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

    offsets = per_string('joint.rest_length_offsets', np.zeros(n))
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


class StiffnessControllerNode(Node):
    """Ticks :class:`StiffnessController` at ``control.rate`` on the latest state."""

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.reporter = Reporter(self.get_logger())
        self._binding = ParameterBinding(
            self, CONTROLLER_PARAMETERS, controller_settings, self._apply_parameters,
            lambda reason: self.reporter.warn('parameter change', reason))
        self._settings = controller_settings(self._binding.values())
        self._controller = self._new_controller(self._settings, None)
        self._pose: tuple[np.ndarray, float, int] | None = None
        self._tick_times: deque[float] = deque(maxlen=STATISTICS_WINDOW)
        self._latencies: deque[float] = deque(maxlen=STATISTICS_WINDOW)
        self._old_state_ticks = 0
        self._wrench: np.ndarray | None = None
        self._known_wrench: np.ndarray | None = None
        self._target_pose: np.ndarray | None = None
        self._target_stiffness: np.ndarray | None = None
        self._last: ControlCommand | None = None
        self._ticks = self._held = self._missed = 0
        self._tick_time = 0.0
        self._state_age = float('nan')
        self._hold_reason = 'no target yet'
        values = self._settings.values
        self._period = 1.0 / values['control.rate']
        self._last_tick = None
        self._pub_rest = create_output_publisher(self, Float64MultiArray, '~/rest_lengths',
                                                 LATCHED_QOS)
        self._pub_stiffness = create_output_publisher(self, Float64MultiArray,
                                                      '~/predicted_stiffness', 10)
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics',
                                                        10)
        qos = input_qos(values['qos.depth'], 'reliable')
        self.create_subscription(PoseStamped, '~/target_pose', self._on_target_pose, qos)
        self.create_subscription(Float64MultiArray, '~/target_stiffness',
                                 self._on_target_stiffness, qos)
        self.create_subscription(PoseWithCovarianceStamped, '~/pose_estimate',
                                 self._on_pose_estimate, qos)
        self.create_subscription(WrenchStamped, '~/wrench_estimate', self._on_wrench_estimate,
                                 qos)
        self.create_subscription(WrenchStamped, '~/external_wrench', self._on_external_wrench,
                                 qos)
        self._publish_rest(self._controller.rest_lengths)
        self.create_timer(self._period, self._tick)
        self.create_timer(values['diagnostics.period'], self._publish_diagnostics)
        self.get_logger().info(f'ready: {self._settings.model.n_strings} strings at '
                               f'{values["control.rate"]:g} Hz')

    def _new_controller(self, settings: ControllerSettings, rest: np.ndarray | None
                        ) -> StiffnessController:
        values = settings.values
        start = settings.model.rest_lengths - settings.offsets if rest is None else rest
        return StiffnessController(settings.model, settings.limits, start,
                                   integral_gain=values['control.integral_gain'],
                                   proportional_gain=values['control.proportional_gain'],
                                   rest_length_offsets=settings.offsets)

    def _apply_parameters(self, values: Mapping[str, Any], names: set[str]) -> None:
        """A validated change: a new controller from the last command (the integral restarts)."""
        try:
            settings = controller_settings(values)
            self._controller = self._new_controller(settings, self._controller.rest_lengths)
            self._settings = settings
        except Exception as exc:  # validated before: only a bug gets here
            self.reporter.internal_error('parameters', exc)
            return
        self.get_logger().info(f'parameters applied: {sorted(names)}')

    # ------------------------------------------------------------------ inputs
    @guarded('~/target_pose')
    def _on_target_pose(self, msg: PoseStamped) -> None:
        try:
            require_frame(msg.header.frame_id, self._settings.link1_frame, "link 1's frame")
            T = msg_tools.pose_to_transform(msg.pose)
            ControlTarget(pose=T)
        except ValueError as exc:
            self.reporter.reject('~/target_pose', str(exc))
            return
        self._target_pose = T

    @guarded('~/target_stiffness')
    def _on_target_stiffness(self, msg: Float64MultiArray) -> None:
        try:
            values = msg_tools.multiarray_to_array(
                msg, max_length=self._settings.values['limits.max_array_length'])
            K = stiffness_target(values)
        except ValueError as exc:
            self.reporter.reject('~/target_stiffness', str(exc))
            return
        self._target_stiffness = K

    @guarded('~/pose_estimate')
    def _on_pose_estimate(self, msg: PoseWithCovarianceStamped) -> None:
        try:
            require_frame(msg.header.frame_id, self._settings.link1_frame, "link 1's frame")
            T, _ = estimation_msgs.pose_with_covariance_to_arrays(msg.pose)
        except ValueError as exc:
            self.reporter.reject('~/pose_estimate', str(exc))
            return
        stamp = msg.header.stamp
        self._pose = (T, time.monotonic(), stamp.sec * 1_000_000_000 + stamp.nanosec)

    def _wrench_input(self, name: str, msg: WrenchStamped) -> np.ndarray | None:
        try:
            require_frame(msg.header.frame_id, self._settings.link1_frame, "link 1's frame")
            return estimation_msgs.wrench_stamped_to_array(msg)
        except ValueError as exc:
            self.reporter.reject(name, str(exc))
            return None

    @guarded('~/wrench_estimate')
    def _on_wrench_estimate(self, msg: WrenchStamped) -> None:
        W = self._wrench_input('~/wrench_estimate', msg)
        if W is not None:
            self._wrench = W

    @guarded('~/external_wrench')
    def _on_external_wrench(self, msg: WrenchStamped) -> None:
        W = self._wrench_input('~/external_wrench', msg)
        if W is not None:
            self._known_wrench = W

    # ------------------------------------------------------------------ the tick
    @guarded('tick')
    def _tick(self) -> None:
        now = time.monotonic()
        if self._last_tick is not None and now - self._last_tick > 1.5 * self._period:
            self._missed += int((now - self._last_tick) / self._period) - 1
        dt = self._period if self._last_tick is None else min(now - self._last_tick,
                                                                 10 * self._period)
        self._last_tick = now
        if self._target_pose is None:
            self._hold_reason = 'no target yet'
            return
        values = self._settings.values
        pose = None
        if self._pose is not None:
            self._state_age = now - self._pose[1]
            if self._state_age <= values['control.max_state_age']:
                pose = self._pose[0]
        if pose is None:
            self._held += 1
            self._hold_reason = (f'no pose estimate within control.max_state_age = '
                                 f'{values["control.max_state_age"]:g} s: last command held')
            return
        load = self._known_wrench
        if values['control.use_wrench_estimate'] and self._wrench is not None:
            load = self._wrench
        try:
            target = ControlTarget(pose=self._target_pose,
                                   cartesian_stiffness=self._target_stiffness)
            start = time.perf_counter()
            cmd = self._controller.update(dt, target, pose=pose, external_wrench=load)
            self._tick_time = time.perf_counter() - start
            self._tick_times.append(self._tick_time)
        except ValueError as exc:
            self.reporter.reject('tick', str(exc))
            return
        self._ticks += 1
        self._hold_reason = ''
        self._last = cmd
        if self._state_age > self._period:
            self._old_state_ticks += 1
        if cmd.feasible:
            self._publish_rest(cmd.rest_lengths)
            if self._pose[2]:  # the reading's stamp (the estimator passes the sensors' on)
                self._latencies.append(
                    1e-9 * (self.get_clock().now().nanoseconds - self._pose[2]))
            if self._pub_stiffness.get_subscription_count():
                self._pub_stiffness.publish(msg_tools.matrix_to_multiarray(
                    cmd.predicted_cartesian_stiffness, STIFFNESS_ROW_LABEL,
                    STIFFNESS_COL_LABEL))
        else:
            self.reporter.warn('target', cmd.message)

    def _publish_rest(self, rest: np.ndarray) -> None:
        self._pub_rest.publish(msg_tools.vector_to_multiarray(rest, REST_LENGTHS_LABEL))

    @guarded('/diagnostics')
    def _publish_diagnostics(self) -> None:
        cmd = self._last
        values: list[tuple[str, Any]] = [
            ('ticks', self._ticks), ('held ticks (stale state)', self._held),
            ('missed ticks', self._missed), ('tick time [ms]', 1e3 * self._tick_time),
            *_statistics('tick time', self._tick_times),
            *_statistics('latency from the reading', self._latencies),
            ('ticks on a state older than one period', self._old_state_ticks),
            ('age of the state used [s]', self._state_age),
            ('rejected inputs', dict(sorted(self.reporter.rejected.items())) or 0)]
        level, message = 'WARN', self._hold_reason or 'no command yet'
        if cmd is not None:
            margins = np.minimum(cmd.tensions - self._settings.limits.tension_min,
                                 self._settings.limits.tension_max - cmd.tensions)
            values += [('feasible', cmd.feasible),
                       ('stiffness target', 'none' if self._target_stiffness is None
                        else 'set'), ('stiffness error', cmd.stiffness_error),
                       ('saturated strings', int(cmd.saturated.sum())),
                       ('smallest tension margin [N]', float(np.min(margins))),
                       ('pose error [m, rad]', cmd.pose_error.tolist())]
            level = 'OK' if cmd.feasible and not self._hold_reason else 'WARN'
            message = self._hold_reason or cmd.message
        self._pub_diagnostics.publish(msg_tools.diagnostic_array(
            [msg_tools.diagnostic_status(f'{self.get_name()}: controller', level, message,
                                         values, hardware_id=self._settings.link1_frame)],
            self.get_clock().now().to_msg()))


def _statistics(name: str, seconds: deque[float]) -> list[tuple[str, Any]]:
    """``<name> median [ms]`` and ``p99`` of the window (empty: none)."""
    if not seconds:
        return []
    values = 1e3 * np.asarray(seconds)
    return [(f'{name} median [ms]', float(np.median(values))),
            (f'{name} p99 [ms]', float(np.percentile(values, 99)))]


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness stiffness_controller``."""
    runner.run(StiffnessControllerNode, args)


if __name__ == '__main__':
    main()
