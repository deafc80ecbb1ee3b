"""``stiffness_bridge``: the Cartesian stiffness of a joint or a spine's tip, in the form a
controller takes (crisp_controllers, fzi cartesian_controllers, ros2_controllers'
admittance_controller, Franka stacks); docs/controllers.md.

Thin layer: reads ``~/input_stiffness`` (a 6x6 ``Float64MultiArray`` as ``stiffness_node``'s
``~/cartesian_stiffness`` or ``spine_node``'s ``~/tip_stiffness``; remap it), conditions it with
the library (:mod:`tensegrity_stiffness.mechanics.controller_stiffness`: the controller's frame,
the nearest positive definite matrix, scale, clamps, low-pass) and delivers it, rate-limited: on
``~/output_stiffness`` in a layout (topic targets) or through the ``set_parameters`` service of
the controller node (parameter targets: asynchronous calls, only when a value moved beyond the
deadband; until the controller first answers, a call is sent again after
``target.first_contact_timeout``, doubled each time, instead of ``target.timeout``; refusals are
warned about with the controller's reason). ``/diagnostics`` says how far
the projection moved the matrix, whether the input was positive definite at all (an unstable
joint is never hidden), the clamps hit, the updates sent and refused and whether the target is
reachable.

Threads: the input is served on the fast lane (or the executor); the tick timer (rate-limited
outputs, retries, low-pass settling), the service responses and diagnostics on the executor. The
filter state and the delivery bookkeeping are shared under one lock.
"""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rcl_interfaces.srv import SetParameters
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.mechanics.controller_stiffness import (
    Conditioned,
    LowPass,
    diagonal,
    moved_beyond,
    to_layout,
)
from tensegrity_stiffness.nodes.stiffness_bridge import (
    BRIDGE_PARAMETERS,
    BridgeSettings,
    bridge_settings,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions.arrays import payload
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.declared_parameters import ParameterBinding
from tensegrity_stiffness.ros.runtime.draining_subscription import create_draining_subscription
from tensegrity_stiffness.ros.runtime.fast_lane import FastLane
from tensegrity_stiffness.ros.runtime.reporting import Reporter, guarded
from tensegrity_stiffness.ros.runtime.topics import create_output_publisher, input_qos, output_qos

NODE_NAME = 'stiffness_bridge'
INPUT_TOPIC = '~/input_stiffness'
OUTPUT_TOPIC = '~/output_stiffness'
#: Largest accepted input (a 6x6 matrix).
MAX_INPUT_LENGTH = 36
#: Seconds after the start at which a bridge that got no input and sees no publisher of its
#: input topic says so (once): a remap that went wrong (e.g. ``-r ~/input_stiffness:=...``
#: unquoted, which the shell turns into ``/root/input_stiffness:=...``) is otherwise silent.
NO_PUBLISHER_WARNING_S = 5.0


class StiffnessBridge(Node):
    """Conditions every ``~/input_stiffness`` and delivers it to the controller."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.reporter = Reporter(self.get_logger(), context=self.context)
        self._lock = threading.RLock()
        self._binding = ParameterBinding(
            self, BRIDGE_PARAMETERS, bridge_settings, self._apply_parameters,
            lambda reason: self.reporter.warn('parameter change', reason))
        settings = self._settings = bridge_settings(self._binding.values())
        values = settings.values
        self._filter = LowPass(settings.time_constant)
        self._clock = self.get_clock()

        # delivery bookkeeping (under the lock)
        self._pending = False
        self._last_emit = -float('inf')
        self._inputs = 0
        self._outputs = 0
        self._refused = 0
        self._lost = 0
        self._resends = 0  # calls given up on since the controller last answered
        self._first_contact_resends = 0  # of those, sent again before target.timeout
        self._skipped = 0  # parameter updates inside the deadband
        self._last_refusal = ''
        self._acknowledged: np.ndarray | None = None
        # the call waiting for its answer: (future, sent at, values, seconds it may wait)
        self._in_flight: tuple[Any, float, np.ndarray, float] | None = None
        self._reachable: bool | None = None
        self._last: Conditioned | None = None
        self._max_relative_projection = 0.0
        self._not_positive_definite = 0
        self._clamp_counts = {'translational': 0, 'rotational': 0, 'coupling_scaled': 0}
        self._dropped_off_diagonal = 0.0

        depth = values['qos.depth']
        self._publisher = None
        self._client = None
        if settings.kind == 'topic':
            self._publisher = create_output_publisher(self, Float64MultiArray, OUTPUT_TOPIC,
                                                      output_qos(depth))
            self._message = Float64MultiArray()
        else:
            self._client = self.create_client(SetParameters,
                                              f'{settings.target_node}/set_parameters')
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics', 10)

        qos = input_qos(depth, values['qos.input_reliability'])
        self._lane = FastLane(self, self.reporter.internal_error) \
            if values['realtime.fast_lane'] else None
        if self._lane is not None:
            self._lane.create_subscription(Float64MultiArray, INPUT_TOPIC, self._on_input, qos)
        else:
            create_draining_subscription(
                self, Float64MultiArray, INPUT_TOPIC, self._on_input, qos,
                on_error=lambda exc: self.reporter.internal_error(INPUT_TOPIC, exc))
        self._tick_timer = self.create_timer(settings.tick_period, self._tick)
        self.create_timer(values['diagnostics.period'], self._publish_diagnostics)
        self._input_check = self.create_timer(NO_PUBLISHER_WARNING_S, self._check_input)
        if self._lane is not None:
            self._lane.start()
        target = (f'{OUTPUT_TOPIC} ({settings.layout})' if settings.kind == 'topic' else
                  f'{settings.target_node}: {", ".join(settings.parameter_names)}')
        self.get_logger().info(
            f'ready: preset {settings.preset}, {settings.input_frame} -> '
            f'{settings.output_frame or "controller frame"}, target {target}, max rate '
            f'{settings.max_rate:g} Hz')

    def close(self) -> None:
        """End the fast lane (called by the runner before the node is destroyed)."""
        if self._lane is not None:
            self._lane.stop()

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, values: Any, names: set[str]) -> None:
        """After a successful set: swap the settings; the filter keeps its state."""
        with self._lock:
            try:
                old = self._settings
                settings = bridge_settings(values, old.generation + 1)
                self._filter.time_constant = settings.time_constant
                self._settings = settings
                if settings.tick_period != old.tick_period:
                    self._tick_timer.timer_period_ns = int(settings.tick_period * 1e9)
                    self._tick_timer.reset()
            except Exception as exc:  # validated before: only a bug gets here
                self.reporter.internal_error('parameters', exc)
                return
        self.get_logger().info(f'parameters applied: {sorted(names)}')

    # ------------------------------------------------------------------ input
    @guarded('input check')
    def _check_input(self) -> None:
        """Once, :data:`NO_PUBLISHER_WARNING_S` after the start: warn when no input came and
        nobody publishes the input topic."""
        self._input_check.cancel()
        topic = self.resolve_topic_name(INPUT_TOPIC)
        with self._lock:
            inputs = self._inputs
        if inputs == 0 and self.count_publishers(topic) == 0:
            self.get_logger().warning(
                f'{INPUT_TOPIC} ({topic}) has no publisher after {NO_PUBLISHER_WARNING_S:g} s: '
                f'check the remap (-r \'{INPUT_TOPIC}:=/<node>/cartesian_stiffness\', quoted: '
                'unquoted, the shell expands the ~)')

    @guarded(INPUT_TOPIC)
    def _on_input(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            K = conversions.multiarray_to_matrix(msg, expected_shape=(6, 6),
                                               max_length=MAX_INPUT_LENGTH)
            conditioned = settings.conditioner.apply(K)
        except ValueError as exc:
            self.reporter.reject(INPUT_TOPIC, str(exc))
            return
        now = time.monotonic()
        with self._lock:
            self._inputs += 1
            self._record(conditioned)
            self._filter.update(conditioned.matrix, now)
            self._pending = True
            if settings.max_rate == 0.0 or now - self._last_emit >= 1.0 / settings.max_rate:
                self._emit(settings, now)

    def _record(self, conditioned: Conditioned) -> None:
        self._last = conditioned
        self._max_relative_projection = max(self._max_relative_projection,
                                            conditioned.relative_projection)
        if not conditioned.input_positive_definite:
            self._not_positive_definite += 1
            self.reporter.warn(
                INPUT_TOPIC, f'not positive definite (min eigenvalue '
                f'{conditioned.input_min_eigenvalue:.3g} of its symmetric part): the joint is '
                f'unstable here; the output is its nearest positive definite matrix '
                f'({100 * conditioned.relative_projection:.3g} % moved)', label='projected')
        for name, hit in conditioned.clamps.items():
            self._clamp_counts[name] += int(hit)

    @guarded('tick')
    def _tick(self) -> None:
        """Rate-limited outputs held back, low-pass settling after the last input, retries of a
        target that was unreachable or busy, first-contact resends, lost calls."""
        settings = self._settings
        now = time.monotonic()
        with self._lock:
            if self._in_flight is not None and now - self._in_flight[1] > self._in_flight[3]:
                future, _, _, waited = self._in_flight
                self._in_flight = None
                self._resends += 1
                self._pending = True  # sent again (the controller may not have applied it)
                self._client.remove_pending_request(future)
                if waited < settings.timeout:
                    # not answered yet: the controller may not have matched the bridge's
                    # endpoints (target.first_contact_timeout)
                    self._first_contact_resends += 1
                else:
                    self._lost += 1
                    self._reachable = False
                    # a controller that is gone (or too slow to count as there): the
                    # documented warning of an unavailable target, with the reason
                    reason = ('gone' if not self._client.service_is_ready() else
                              f'gave no answer within target.timeout = {settings.timeout:g} s')
                    self._warn_unavailable(settings, f' ({reason})')
            if self._filter.target is None:
                return
            if not self._filter.settled():
                self._filter.update(None, now)
                self._pending = True
            if self._pending and (settings.max_rate == 0.0
                                  or now - self._last_emit >= 1.0 / settings.max_rate):
                self._emit(settings, now)

    # ------------------------------------------------------------------ delivery
    def _emit(self, settings: BridgeSettings, now: float) -> None:
        """Deliver the filter's output (under the lock)."""
        K = self._filter.value
        if settings.kind == 'topic':
            self._message.data = payload(to_layout(K, settings.layout))
            self._publisher.publish(self._message)
            self._outputs += 1
            self._pending = False
            self._last_emit = now
            return
        self._dropped_off_diagonal = _off_diagonal_share(K)
        values = diagonal(K)
        # against what the controller will hold: the values in flight, else the last accepted
        reference = self._in_flight[2] if self._in_flight is not None else self._acknowledged
        if not moved_beyond(values, reference, settings.deadband):
            self._pending = False
            self._skipped += 1
            return
        if self._in_flight is not None:
            return  # sent when the answer is in (a later tick)
        if not self._client.service_is_ready():
            self._reachable = False
            self._resends = 0  # the controller that comes (back) is a first contact
            self._warn_unavailable(settings, '')
            return
        request = SetParameters.Request(parameters=_parameter_messages(
            settings.parameter_names, values))
        future = self._client.call_async(request)
        self._in_flight = (future, now, values,
                           settings.call_timeout(self._reachable is True, self._resends))
        self._pending = False
        self._last_emit = now
        future.add_done_callback(self._on_answer)

    def _warn_unavailable(self, settings: BridgeSettings, reason: str) -> None:
        """``target: <node>/set_parameters is not available; retrying`` (throttled), with the
        ``reason`` of a lost call."""
        self.reporter.warn('target', f'{settings.target_node}/set_parameters is not available; '
                           f'retrying{reason}', label='unreachable')

    def _on_answer(self, future: Any) -> None:
        try:
            self._answered(future)
        except Exception as exc:  # the safety net: no callback may end the node
            self.reporter.internal_error('target answer', exc)

    def _answered(self, future: Any) -> None:
        settings = self._settings
        with self._lock:
            if self._in_flight is None or self._in_flight[0] is not future:
                return  # given up on (timeout)
            _, _, values, _ = self._in_flight
            self._in_flight = None
            if future.cancelled() or future.exception() is not None:
                self._lost += 1
                self._pending = True  # sent again on a later tick
                return
            self._reachable = True
            self._resends = 0
            results = future.result().results
            refused = [(name, r.reason) for name, r in zip(settings.parameter_names, results,
                                                          strict=False) if not r.successful]
            if len(results) != len(settings.parameter_names):
                refused.append(('(all)', f'{len(results)} results for '
                                f'{len(settings.parameter_names)} parameters'))
            if refused:
                self._refused += 1
                name, reason = refused[0]
                shown = ' '.join(f'{v:.6g}' for v in values)
                self._last_refusal = f'{name}: {reason}'
                self.reporter.warn('set_parameters', f'{settings.target_node} refused {name} '
                                   f'(values [{shown}]): {reason or "no reason given"}')
            else:
                self._outputs += 1
                self._acknowledged = values

    # ------------------------------------------------------------------ diagnostics
    @guarded('diagnostics')
    def _publish_diagnostics(self) -> None:
        settings = self._settings
        with self._lock:
            last = self._last
            level, problems = 'OK', []
            values: list[tuple[str, Any]] = [
                ('preset', settings.preset),
                ('input frame', settings.input_frame),
                ('output frame', settings.output_frame or '(output.pose in the input frame)'),
                ('output pose', list(settings.values['output.pose'])),
                ('inputs', self._inputs),
                ('rejected inputs', dict(sorted(self.reporter.rejected.items())) or 0),
                ('inputs not positive definite', self._not_positive_definite),
                ('max relative projection distance', self._max_relative_projection),
                ('clamps hit', dict(self._clamp_counts)),
            ]
            if last is not None:
                values[7:7] = [
                    ('input min eigenvalue (symmetric part, output frame)',
                     last.input_min_eigenvalue),
                    ('input positive definite', last.input_positive_definite),
                    ('input asymmetry |K - K^T| / |K|', last.asymmetry),
                    ('projection distance |P(K) - K|_F', last.projection_distance),
                    ('relative projection distance', last.relative_projection),
                ]
                if not last.input_positive_definite:
                    level = 'WARN'
                    problems.append(
                        f'input stiffness is not positive definite (min eigenvalue '
                        f'{last.input_min_eigenvalue:.3g}): the joint is unstable here, the '
                        f'output is its nearest positive definite matrix '
                        f'({100 * last.relative_projection:.3g} % moved)')
            if settings.kind == 'topic':
                values += [('target', f'topic {self._publisher.topic_name} '
                            f'({settings.layout})'), ('outputs published', self._outputs)]
            else:
                reachable = self._reachable
                values += [
                    ('target', f'{settings.target_node}: {" ".join(settings.parameter_names)}'),
                    ('target reachable', 'unknown' if reachable is None else reachable),
                    ('updates sent', self._outputs), ('updates refused', self._refused),
                    ('calls lost', self._lost),
                    ('first-contact resends', self._first_contact_resends),
                    ('updates inside the deadband', self._skipped),
                    ('last refusal', self._last_refusal or 'none'),
                    ('off-diagonal share dropped |K - diag K|_F / |K|_F',
                     self._dropped_off_diagonal),
                ]
                if reachable is False:
                    level = 'WARN'
                    problems.append(f'target {settings.target_node} not reachable')
                if self._refused:
                    level = 'WARN'
                    problems.append(f'{self._refused} updates refused')
            message = '; '.join(problems) or ('no input yet' if last is None else
                                              'positive definite input, delivered')
        status = conversions.diagnostic_status(
            f'{self.get_fully_qualified_name()}: controller stiffness', level, message, values,
            hardware_id=settings.input_frame)
        self._pub_diagnostics.publish(conversions.diagnostic_array(
            [status], self._clock.now().to_msg()))


def _off_diagonal_share(K: np.ndarray) -> float:
    norm = float(np.linalg.norm(K))
    return float(np.linalg.norm(K - np.diag(np.diag(K)))) / norm if norm > 0.0 else 0.0


def _parameter_messages(names: tuple[str, ...], values: np.ndarray) -> list[Any]:
    """Six double parameters, or one double array of the six values."""
    if len(names) == 1:
        return [Parameter(names[0], Parameter.Type.DOUBLE_ARRAY,
                          [float(v) for v in values]).to_parameter_msg()]
    return [Parameter(name, Parameter.Type.DOUBLE, float(v)).to_parameter_msg()
            for name, v in zip(names, values, strict=True)]


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness stiffness_bridge``."""
    runner.run(StiffnessBridge, args)


if __name__ == '__main__':
    main()
