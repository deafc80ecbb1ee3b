"""``stiffness_controller``: rest-length commands that hold a target pose with a target K_c, in
closed loop, around :class:`tensegrity_stiffness.control.controller.StiffnessController`.

Inputs: ``~/target_pose`` (``PoseStamped`` in ``frames.link1``), ``~/target_stiffness``
(``Float64MultiArray``: 36 row-major, 6 for a diagonal, empty for none) on the executor; the
state as ``estimator_node`` publishes it (``~/pose_estimate``, ``PoseWithCovarianceStamped``;
``~/wrench_estimate``, ``WrenchStamped``: one remap each) or a known load on
``~/external_wrench`` on the fast lane, newest only (a backlog is passed over and counted on
/diagnostics). A paced loop on a thread of its own (:mod:`.runtime.paced_loop`) runs one
controller tick at ``control.rate`` on the latest state and publishes ``~/rest_lengths``
(latched, the format ``sim_node``, ``estimator_node`` and ``stiffness_node`` take: motor
commands, ``true - offset``) and ``~/predicted_stiffness`` (36 row-major); ``/diagnostics`` once
a second (the rate asked for and achieved, missed ticks, the latency from a reading to the first
command computed from it, inputs skipped). A state older than ``control.max_state_age`` holds
the last command and says so; a bad target or parameter is refused with a throttled warning and
the last command is kept; so is a tick whose QP runs past ``control.time_budget`` (``tick held:
time budget exhausted ...``, counted on /diagnostics). In one process with the estimator
(``control_loop``) the state is handed over directly
(:meth:`StiffnessControllerNode.take_state`), not over topics.

Built from the shared parts (:mod:`.runtime.declared_parameters`, :mod:`.runtime.reporting`,
:mod:`.runtime.topics`, :mod:`.runtime.runner`); the parameter table, the settings and the tick
rule (:class:`~tensegrity_stiffness.nodes.stiffness_controller.ControllerTicks`) are
:mod:`tensegrity_stiffness.nodes.stiffness_controller`'s.
"""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Mapping
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, WrenchStamped
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.control.controller import ControlTarget
from tensegrity_stiffness.geometry.validation import require_all_finite, require_frame
from tensegrity_stiffness.mechanics.plausibility import (
    check_target_stiffness,
    check_translation,
    check_wrench,
)
from tensegrity_stiffness.nodes.layouts import (
    CONTROLLER_OUTPUT_TABLE,
    ESTIMATOR_POSE_OUTPUT,
    ESTIMATOR_WRENCH_OUTPUT,
    controller_output_layouts,
)
from tensegrity_stiffness.nodes.messages import multiarray
from tensegrity_stiffness.nodes.stiffness_controller import (
    CONTROLLER_PARAMETERS,
    STAMP_WINDOW,
    ControllerSettings,
    ControllerTicks,
    controller_settings,
    new_controller,
    stiffness_target,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions import estimation as estimation_msgs
from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES, output_topics
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.declared_parameters import ParameterBinding
from tensegrity_stiffness.ros.runtime.draining_subscription import SkippedCounts
from tensegrity_stiffness.ros.runtime.fast_lane import FastLane
from tensegrity_stiffness.ros.runtime.paced_loop import PacedLoop, RateCounter
from tensegrity_stiffness.ros.runtime.reporting import Reporter, guarded
from tensegrity_stiffness.ros.runtime.topics import LATCHED_QOS, create_output_publisher, input_qos

#: The state inputs carry estimator_node's output names (its pose and its load, named in
#: :mod:`tensegrity_stiffness.nodes.layouts`), so that one remap each wires them.
POSE_ESTIMATE = f'~/{ESTIMATOR_POSE_OUTPUT}'
WRENCH_ESTIMATE = f'~/{ESTIMATOR_WRENCH_OUTPUT}'

NODE_NAME = 'stiffness_controller'
#: The /diagnostics key of the readings whose stamp is outside :data:`STAMP_WINDOW`.
STAMPS_KEY = (f'stamps outside -{STAMP_WINDOW[1]:g} s .. +{STAMP_WINDOW[0]:g} s of the clock '
              '(left out of the latency)')


class StiffnessControllerNode(Node):
    """Ticks :class:`StiffnessController` at ``control.rate`` on the latest state.
    ``state_topics=False``: no state subscriptions; the state comes through :meth:`take_state`
    (the estimator in the same process)."""

    #: The /diagnostics key of the state inputs passed over for a newer one, per topic.
    SKIPPED_KEY = 'inputs skipped (a newer one was queued)'

    def __init__(self, node_name: str = NODE_NAME, *, state_topics: bool = True,
                 **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.reporter = Reporter(self.get_logger(), context=self.context)
        # The tick (its own thread) against parameter changes and targets (the executor).
        self._lock = threading.Lock()
        self._ticker: ControllerTicks | None = None
        self._binding = ParameterBinding(
            self, CONTROLLER_PARAMETERS, self._checked_settings, self._apply_parameters,
            lambda reason: self.reporter.warn('parameter change', reason))
        self._settings = self._binding.build(self._binding.values())
        if self._settings.start_warning:
            self.get_logger().warning(self._settings.start_warning)
        values = self._settings.values
        # the state, targets and counters of the ticks (the state replaced as a whole by the
        # state's thread)
        self._ticker = ControllerTicks(self._settings, new_controller(self._settings, None),
                                       1.0 / values['control.rate'])
        self._commands = RateCounter()
        self.skipped = SkippedCounts()
        # one publisher per row of the output table: the commands latched
        self._pub_rest, self._pub_stiffness = self._output_publishers = tuple(
            create_output_publisher(self, msg_type, topic, qos) for (msg_type, topic), qos in zip(
                output_topics(controller_output_layouts(self._settings.model.n_strings)),
                (LATCHED_QOS, 10), strict=True))
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics',
                                                        10)
        qos = input_qos(values['qos.depth'], 'reliable')
        self.create_subscription(PoseStamped, '~/target_pose', self._on_target_pose, qos)
        self.create_subscription(Float64MultiArray, '~/target_stiffness',
                                 self._on_target_stiffness, qos)
        self._lane = FastLane(self, self.reporter.internal_error)
        if state_topics:
            self._lane.create_subscription(PoseWithCovarianceStamped, POSE_ESTIMATE,
                                           self._on_pose_estimate, qos, self.skipped)
            self._lane.create_subscription(WrenchStamped, WRENCH_ESTIMATE,
                                           self._on_wrench_estimate, qos, self.skipped)
        self._lane.create_subscription(WrenchStamped, '~/external_wrench',
                                       self._on_external_wrench, qos, self.skipped)
        self._publish_output(0, self._ticker.controller)
        self.create_timer(values['diagnostics.period'], self._publish_diagnostics)
        self._loop = PacedLoop(values['control.rate'], self._tick,
                               lambda exc: self.reporter.internal_error('tick', exc),
                               name='controller ticks')
        self._lane.start()
        self._loop.start()
        self.get_logger().info(f'ready: {self._settings.model.n_strings} strings at '
                               f'{values["control.rate"]:g} Hz')

    def close(self) -> None:
        """End the ticks and the fast lane (called by the runner before the node is
        destroyed)."""
        self._loop.stop()
        self._lane.stop()

    def _checked_settings(self, values: Mapping[str, Any]) -> ControllerSettings:
        """The settings of a parameter set, refused (ValueError) when a controller of them
        cannot take over from the present command (new offsets that make a true rest length
        <= 0): a change applies whole or not at all."""
        settings = controller_settings(values)
        if self._ticker is not None:
            try:
                new_controller(settings, self._ticker.controller.rest_lengths)
            except ValueError as exc:
                raise ValueError(f'from the present command: {exc}') from None
        return settings

    def _apply_parameters(self, values: Mapping[str, Any], names: set[str]) -> None:
        """A validated change: a new controller from the last command (the integral restarts);
        a command outside a new rest-length range is moved in at the rate, with a warning."""
        try:
            settings = self._binding.build(values)
            with self._lock:
                present = self._ticker.controller.rest_lengths
                self._ticker.reconfigure(settings, new_controller(settings, present))
                self._settings = settings
        except Exception as exc:  # validated before: only a bug gets here
            self.reporter.internal_error('parameters', exc)
            return
        self.get_logger().info(f'parameters applied: {sorted(names)}')
        low, high, *_ = settings.limits.for_strings(settings.model.n_strings)
        outside = np.flatnonzero((present < low) | (present > high))
        if outside.size:
            self.get_logger().warning(
                'the present command is outside limits.rest_length_min/max for '
                f'{", ".join(settings.model.string_names[j] for j in outside)}: moved into the '
                'range at limits.max_rate')

    # ------------------------------------------------------------------ inputs
    @guarded('~/target_pose')
    def _on_target_pose(self, msg: PoseStamped) -> None:
        try:
            require_frame(msg.header.frame_id, self._settings.link1_frame, "link 1's frame")
            T = conversions.pose_message_to_transform(msg.pose)
            ControlTarget(pose=T)
            check_translation(self._settings.model, T[:3, 3], 'target_pose')
        except ValueError as exc:
            self.reporter.reject('~/target_pose', str(exc))
            return
        self._ticker.target_pose = T

    @guarded('~/target_stiffness')
    def _on_target_stiffness(self, msg: Float64MultiArray) -> None:
        try:
            values = conversions.multiarray_to_array(
                msg, max_length=self._settings.values['limits.max_array_length'])
            K = stiffness_target(values, tuple(d.size for d in msg.layout.dim))
            if K is not None:
                ticker = self._ticker
                load = ticker.known_wrench if ticker.wrench_estimate is None else \
                    ticker.wrench_estimate
                check_target_stiffness(self._settings.model, K, 'target_stiffness',
                                       length_scale=ticker.controller.length_scale, wrench=load)
        except ValueError as exc:
            self.reporter.reject('~/target_stiffness', str(exc))
            return
        self._ticker.target_stiffness = K

    def take_state(self, T: np.ndarray, stamp_ns: int, wrench: np.ndarray | None = None
                   ) -> None:
        """The latest pose estimate ``T`` (link 2 in link 1) of the reading stamped
        ``stamp_ns`` (0: unstamped) and, when given, the load estimate: what the next tick
        uses (the state topics' handlers, or the estimator in the same process). A pose out of
        the joint's reach is refused by name (counted as a rejected ``~/pose_estimate``)."""
        try:
            check_translation(self._settings.model, T[:3, 3], 'pose_estimate')
        except ValueError as exc:
            self.reporter.reject(POSE_ESTIMATE, str(exc))
            return
        self._ticker.take_state(T, time.monotonic(), stamp_ns, wrench)

    @guarded(POSE_ESTIMATE)
    def _on_pose_estimate(self, msg: PoseWithCovarianceStamped) -> None:
        try:
            require_frame(msg.header.frame_id, self._settings.link1_frame, "link 1's frame")
            T, _ = estimation_msgs.pose_with_covariance_to_arrays(msg.pose)
        except ValueError as exc:
            self.reporter.reject(POSE_ESTIMATE, str(exc))
            return
        stamp = msg.header.stamp
        self.take_state(T, stamp.sec * 1_000_000_000 + stamp.nanosec)

    def _wrench_input(self, name: str, msg: WrenchStamped) -> np.ndarray | None:
        try:
            require_frame(msg.header.frame_id, self._settings.link1_frame, "link 1's frame")
            W = estimation_msgs.wrench_stamped_to_array(msg)
            return check_wrench(self._settings.model, W, name.removeprefix('~/'))
        except ValueError as exc:
            self.reporter.reject(name, str(exc))
            return None

    @guarded(WRENCH_ESTIMATE)
    def _on_wrench_estimate(self, msg: WrenchStamped) -> None:
        W = self._wrench_input(WRENCH_ESTIMATE, msg)
        if W is not None:
            self._ticker.wrench_estimate = W

    @guarded('~/external_wrench')
    def _on_external_wrench(self, msg: WrenchStamped) -> None:
        W = self._wrench_input('~/external_wrench', msg)
        if W is not None:
            self._ticker.known_wrench = W

    # ------------------------------------------------------------------ the tick
    def _tick(self, due: int = 1) -> None:
        """One controller tick (the paced loop's thread; ``due`` periods since the last)."""
        with self._lock:
            self._tick_locked()

    def _tick_locked(self) -> None:
        outcome = self._ticker.tick(time.monotonic(), self.get_clock().now().nanoseconds)
        if outcome.error:
            self.reporter.reject('tick', outcome.error)
            return
        cmd = outcome.command
        if cmd is None:
            return
        if cmd.feasible:
            self._publish_output(0, cmd)
            self._commands.record()
            if self._pub_stiffness.get_subscription_count():
                self._publish_output(1, cmd)
        elif cmd.out_of_time:
            self.reporter.warn('tick', cmd.message, label='held')
        else:
            self.reporter.warn('target', cmd.message)

    def _publish_output(self, k: int, source: Any) -> None:
        """Publish output ``k`` of the output table (its row's value of ``source``: a command,
        or the controller's first one) in the row's layout; ValueError when not finite."""
        row = CONTROLLER_OUTPUT_TABLE[k]
        values = np.asarray(row.of(source), dtype=np.float64)
        require_all_finite((row.name,), (values,))
        self._output_publishers[k].publish(multiarray(row.layout(values.shape[0]).dims,
                                               values.ravel(), RCLPY_TYPES))

    @guarded('/diagnostics')
    def _publish_diagnostics(self) -> None:
        ticker = self._ticker
        cmd = ticker.last
        values: list[tuple[str, Any]] = [
            *self._loop.statistics(), ('command rate [Hz]', self._commands.rate()),
            ('commands computed', ticker.ticks), ('held ticks (stale state)', ticker.held),
            ('tick time [ms]', 1e3 * ticker.tick_time),
            *_statistics('tick time', ticker.tick_times),
            *_statistics('latency from the reading', ticker.latencies),
            (STAMPS_KEY, ticker.stamps_out_of_window),
            ('ticks on a state older than one period', ticker.old_state_ticks),
            ('ticks held at control.time_budget', ticker.out_of_time),
            ('tick time budget [ms]', 1e3 * ticker.controller.time_budget),
            ('age of the state used [s]', ticker.state_age),
            (self.SKIPPED_KEY, self.skipped.counts() or 0),
            ('rejected inputs', dict(sorted(self.reporter.rejected.items())) or 0)]
        level, message = 'WARN', ticker.hold_reason or 'no command yet'
        if cmd is not None:
            margins = np.minimum(cmd.tensions - self._settings.limits.tension_min,
                                 self._settings.limits.tension_max - cmd.tensions)
            values += [('feasible', cmd.feasible),
                       ('stiffness target', 'none' if ticker.target_stiffness is None
                        else 'set'), ('stiffness error', cmd.stiffness_error),
                       ('saturated strings', int(cmd.saturated.sum())),
                       ('smallest tension margin [N]', float(np.min(margins))),
                       ('pose error [m, rad]', cmd.pose_error.tolist())]
            level = 'OK' if cmd.feasible and not ticker.hold_reason else 'WARN'
            message = ticker.hold_reason or cmd.message
        name = f'{self.get_fully_qualified_name()}: controller'
        self._pub_diagnostics.publish(conversions.diagnostic_array(
            [conversions.diagnostic_status(name, level, message, values,
                                           hardware_id=self._settings.link1_frame)],
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
