"""``stiffness_node``: real-time wrench and stiffness of a tensegrity joint over ROS 2.

Thin layer: validate, convert with :mod:`msg_tools`, call the library
(:mod:`tensegrity_stiffness.processing`), publish. Topics, services, parameters and QoS are
documented in README.md; the conventions (frames, orderings, signs) in
:mod:`tensegrity_stiffness.joint`; the parameters in :mod:`tensegrity_stiffness.parameters`.

Concurrency: ``~/screw`` and ``~/pose`` are served in order on a thread of their own
(:mod:`.fast_lane`: rclpy's executor costs more per message than the computation itself; with
``realtime.fast_lane: false`` the executor serves them, draining the queue behind each message).
A single-threaded executor runs everything else. The equilibrium and design services are
coroutines: they validate the request, hand the work to the worker process
(:class:`.SolverWorker`) and await it, so the topics keep being served meanwhile. All the
configuration a computation needs is one immutable :class:`JointNodeSettings`, swapped as a whole
when parameters or rest lengths change and read once per input; outputs are built and published
under one lock, so no output mixes two sets and the two threads never interleave a publication.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

import msg_tools
from tensegrity_stiffness.design import design_rest_lengths
from tensegrity_stiffness.equilibrium import solve_equilibrium
from tensegrity_stiffness.health import joint_health
from tensegrity_stiffness.parameters import (
    STIFFNESS_NODE_PARAMETERS,
    joint_node_settings,
)
from tensegrity_stiffness.processing import joint_outputs, pose_input, screw_input
from tensegrity_stiffness.ros import joint_services, runner
from tensegrity_stiffness.ros.draining_subscription import create_draining_subscription
from tensegrity_stiffness.ros.fast_lane import FastLane
from tensegrity_stiffness.ros.last_input import LastInput
from tensegrity_stiffness.ros.parameters import ParameterBinding
from tensegrity_stiffness.ros.reporting import Reporter, guarded, guarded_service
from tensegrity_stiffness.ros.solver_worker import SolverWorker, WorkerDiedError
from tensegrity_stiffness.ros.topics import (
    LATCHED_QOS,
    create_output_publisher,
    input_qos,
    output_qos,
)
from tensegrity_stiffness.ros.worker_calls import (
    SOLVER_GRACE_S,
    WorkerCalls,
    answer_worker_failure,
)
from tensegrity_stiffness_interfaces.srv import (
    DesignRestLengths,
    PlanarForwardKinematics,
    PlanarInverseKinematics,
    SolveEquilibrium,
)

NODE_NAME = 'stiffness_node'
#: Wall-clock bound of one rest-length design in the worker (it takes milliseconds).
DESIGN_DEADLINE_S = 5.0


class StiffnessNode(Node):
    """Publishes wrench, K, K_c, tensions, interpretation, markers and diagnostics per input."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.reporter = Reporter(self.get_logger())
        # Publication lock: the fast lane and the executor both publish; settings are swapped
        # (and re-published) under it too. Re-entrant: a swap re-publishes.
        self._output_lock = threading.RLock()
        self._binding = ParameterBinding(
            self, STIFFNESS_NODE_PARAMETERS, joint_node_settings, self._apply_parameters,
            lambda reason: self.reporter.warn('parameter change', reason))
        self._settings = joint_node_settings(self._binding.values())
        self._last = LastInput()
        self._last_solution: np.ndarray | None = None
        self._clock = self.get_clock()
        self._messages = msg_tools.JointOutputMessages(tuple(self._settings.model.string_names))
        self._solver = SolverWorker('equilibrium worker')
        self._in_worker = WorkerCalls(self, self._solver)

        values = self._settings.values
        depth, reliability = values['qos.depth'], values['qos.input_reliability']
        out_qos = output_qos(depth)
        self._output_publishers = [
            create_output_publisher(self, t, topic, out_qos) for t, topic in (
                (WrenchStamped, '~/wrench'), (Float64MultiArray, '~/stiffness'),
                (Float64MultiArray, '~/cartesian_stiffness'),
                (Float64MultiArray, '~/string_tensions'),
                (Float64MultiArray, '~/stiffness_interpretation'))]
        self._pub_markers = create_output_publisher(self, MarkerArray, '~/markers', out_qos)
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics', 10)

        qos = input_qos(depth, reliability)
        self._lane = FastLane(self, self.reporter.internal_error) \
            if values['realtime.fast_lane'] else None
        for msg_type, topic, callback in ((Float64MultiArray, '~/screw', self._on_screw),
                                          (PoseStamped, '~/pose', self._on_pose)):
            if self._lane is not None:
                self._lane.create_subscription(msg_type, topic, callback, qos)
            else:
                create_draining_subscription(
                    self, msg_type, topic, callback, qos,
                    on_error=lambda exc, t=topic: self.reporter.internal_error(t, exc))
        self.create_subscription(Float64MultiArray, '~/rest_lengths', self._on_rest_lengths,
                                 LATCHED_QOS)
        # Own group: the coroutine holds its group while it awaits the worker; the default group
        # (topics, planar services, timer) stays free.
        self.create_service(SolveEquilibrium, '~/solve_equilibrium', self._on_solve_equilibrium,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(DesignRestLengths, '~/design_rest_lengths',
                            self._on_design_rest_lengths,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(PlanarForwardKinematics, '~/planar_forward_kinematics',
                            self._on_planar_forward)
        self.create_service(PlanarInverseKinematics, '~/planar_inverse_kinematics',
                            self._on_planar_inverse)
        self.create_timer(values['diagnostics.period'], self._publish_diagnostics)
        self._marker_timer = self.create_timer(
            self._settings.marker_period or 1.0, self._publish_markers)
        model = self._settings.model
        # Warm the worker up (imports, first solve) before the first request needs it.
        self._solver.submit(solve_equilibrium, (model, np.zeros(6)), {'time_budget': 1.0},
                            lambda _: None, lambda _: None, deadline_s=1.0 + SOLVER_GRACE_S)
        if self._lane is not None:
            self._lane.start()
        self.get_logger().info(
            f'ready: {model.n_strings} strings, force law {model.force_law}, frames '
            f'{self._settings.link1_frame} -> {self._settings.link2_frame}, inputs '
            f'{reliability} depth {depth}')

    def close(self) -> None:
        """End the fast lane and the worker process (called by the runner before the node is
        destroyed)."""
        if self._lane is not None:
            self._lane.stop()
        self._solver.close()

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, values: dict[str, Any], names: set[str]) -> None:
        """After a successful set: swap in the new settings, keeping topic rest lengths unless
        the change sets joint.rest_lengths itself, and re-publish the last configuration under
        them; no input is published in between (the output lock)."""
        with self._output_lock:
            try:
                old = self._settings
                settings = joint_node_settings(values, old.generation + 1)
                rest = old.model.rest_lengths
                if 'joint.rest_lengths' not in names and rest.shape == (
                        settings.model.n_strings,):
                    settings = replace(settings, model=settings.model.with_rest_lengths(rest))
                self._settings = settings
                if 'markers.max_rate' in names:
                    self._marker_timer.timer_period_ns = int(
                        1e9 * (settings.marker_period or 1.0))
                    self._marker_timer.reset()
            except Exception as exc:  # validated before: only a bug gets here; the old set stays
                self.reporter.internal_error('parameters', exc)
                return
            self.get_logger().info(f'parameters applied: {sorted(names)}')
            try:  # an exception here would reach the parameter service, and the executor
                self._republish_last()
            except Exception as exc:  # the safety net: no callback may end the node
                self.reporter.internal_error('re-publish', exc)

    # ------------------------------------------------------------------ inputs
    @guarded('~/screw')
    def _on_screw(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            xi = screw_input(msg_tools.multiarray_to_array(
                msg, expected_length=6, max_length=settings.max_array_length))
        except ValueError as exc:
            self.reporter.reject('~/screw', str(exc))
            return
        self._compute_and_publish(xi, None, '~/screw')

    @guarded('~/pose')
    def _on_pose(self, msg: PoseStamped) -> None:
        settings = self._settings
        try:
            last = self._last.screws
            xi = pose_input(msg.header.frame_id, msg_tools.pose_to_transform(msg.pose),
                            settings.link1_frame,
                            last if last is not None else settings.model.initial_screw)
        except ValueError as exc:
            self.reporter.reject('~/pose', str(exc))
            return
        stamp = msg.header.stamp
        self._compute_and_publish(xi, stamp if stamp.sec or stamp.nanosec else None,
                                  '~/pose')

    @guarded('~/rest_lengths')
    def _on_rest_lengths(self, msg: Float64MultiArray) -> None:
        with self._output_lock:  # the swap and its re-publish, with no input in between
            settings = self._settings
            try:
                rest = msg_tools.multiarray_to_array(msg, expected_length=settings.model.n_strings,
                                                     max_length=settings.max_array_length)
                model = settings.model.with_rest_lengths(rest)
            except ValueError as exc:
                self.reporter.reject('~/rest_lengths', str(exc))
                return
            self._settings = replace(settings, model=model, generation=settings.generation + 1)
            self._republish_last()

    def _republish_last(self) -> None:
        if self._last.screws is not None:
            self._compute_and_publish(self._last.screws, self._last.stamp, 're-publish')

    # ------------------------------------------------------------------ outputs
    def _compute_and_publish(self, xi: np.ndarray, stamp: Any, source: str) -> None:
        """Build and check every output under the current settings, then publish them all (an
        input gets all of its outputs or none); topics nobody subscribes to are not filled (a
        publication there reaches no one: the outputs are volatile)."""
        with self._output_lock:
            settings = self._settings
            start = time.perf_counter()
            messages = self._messages
            try:
                outputs = joint_outputs(settings.model, xi)
                if stamp is None:
                    stamp = self._clock.now().to_msg()
                if messages.string_names != tuple(settings.model.string_names):
                    messages = self._messages = msg_tools.JointOutputMessages(
                        tuple(settings.model.string_names))
                wanted = tuple(p.get_subscription_count() > 0 for p in self._output_publishers)
                messages.fill(outputs, stamp, settings.link1_frame, wanted)
                markers = None
                if settings.marker_period == 0.0:  # one per input; else _publish_markers
                    markers = msg_tools.joint_markers(settings.model, outputs.state,
                                                      settings.link1_frame, stamp)
            except ValueError as exc:
                self.reporter.reject(source, str(exc))
                return
            for publisher, msg, publish in zip(self._output_publishers, messages.messages(),
                                               wanted, strict=True):
                if publish:
                    publisher.publish(msg)
            if markers is not None:
                self._pub_markers.publish(markers)
            self._last.record(xi, stamp, outputs, start)

    @guarded('~/markers')
    def _publish_markers(self) -> None:
        """At most ``markers.max_rate`` Hz, on the executor's thread (a MarkerArray costs as much
        as all other outputs together): the last configuration, once, if anyone listens."""
        settings = self._settings
        if settings.marker_period == 0.0 or self._pub_markers.get_subscription_count() == 0:
            return
        last = self._last.unmarked()
        if last is None:
            return
        outputs, stamp = last
        self._pub_markers.publish(msg_tools.joint_markers(
            settings.model, outputs.state, settings.link1_frame,
            stamp if stamp is not None else self._clock.now().to_msg()))

    # ------------------------------------------------------------------ services
    @guarded_service('~/solve_equilibrium')
    async def _on_solve_equilibrium(self, request: SolveEquilibrium.Request,
                                    response: SolveEquilibrium.Response
                                    ) -> SolveEquilibrium.Response:
        """Validated here, solved in the worker process within ``equilibrium.time_budget``."""
        settings = self._settings
        try:
            job = joint_services.equilibrium_job(request, settings, self._last_solution)
        except ValueError as exc:
            self.reporter.reject('~/solve_equilibrium', str(exc))
            return joint_services.fail(response, f'invalid request: {exc}')
        try:
            result = await self._in_worker(solve_equilibrium,
                                           (settings.model, job.external_wrench), job.kwargs(),
                                           job.time_budget + SOLVER_GRACE_S)
        except (TimeoutError, WorkerDiedError) as exc:
            return answer_worker_failure(self.reporter, '~/solve_equilibrium', response, exc)
        if joint_services.fill_equilibrium(response, result):
            self._last_solution = result.screw
        return response

    @guarded_service('~/design_rest_lengths')
    async def _on_design_rest_lengths(self, request: DesignRestLengths.Request,
                                      response: DesignRestLengths.Response
                                      ) -> DesignRestLengths.Response:
        """Validated here, designed in the worker process; the node's rest lengths stay."""
        settings = self._settings
        last = self._last.screws
        try:
            kwargs = joint_services.design_kwargs(
                request, settings, last if last is not None else settings.model.initial_screw)
        except ValueError as exc:
            self.reporter.reject('~/design_rest_lengths', str(exc))
            return joint_services.fail(response, f'invalid request: {exc}')
        try:
            result = await self._in_worker(design_rest_lengths, (settings.model,), kwargs,
                                           DESIGN_DEADLINE_S)
        except ValueError as exc:  # a request the library refuses (e.g. outside the chart)
            self.reporter.reject('~/design_rest_lengths', str(exc))
            return joint_services.fail(response, f'invalid request: {exc}')
        except (TimeoutError, WorkerDiedError) as exc:
            return answer_worker_failure(self.reporter, '~/design_rest_lengths', response, exc)
        return joint_services.fill_design(response, result)

    @guarded_service('~/planar_forward_kinematics')
    def _on_planar_forward(self, request: PlanarForwardKinematics.Request,
                           response: PlanarForwardKinematics.Response
                           ) -> PlanarForwardKinematics.Response:
        return joint_services.planar_forward(self._settings.planar, request, response)

    @guarded_service('~/planar_inverse_kinematics')
    def _on_planar_inverse(self, request: PlanarInverseKinematics.Request,
                           response: PlanarInverseKinematics.Response
                           ) -> PlanarInverseKinematics.Response:
        return joint_services.planar_inverse(self._settings.planar, request, response)

    # ------------------------------------------------------------------ diagnostics
    @guarded('diagnostics')
    def _publish_diagnostics(self) -> None:
        settings = self._settings
        outputs = self._last.outputs
        values: list[tuple[str, Any]] = [
            *self._last.statistics(),
            ('rejected inputs', dict(sorted(self.reporter.rejected.items())) or 0),
            ('parameter generation', settings.generation),
            ('equilibrium worker restarts', self._solver.restarts),
        ]
        level, message = 'OK', 'no input yet'
        if outputs is not None:
            health = joint_health(outputs.state, settings.model.string_names)
            values += health.values()
            level = 'WARN' if health.problems else 'OK'
            message = ', '.join(health.problems) or 'all strings taut, stable'
        status = msg_tools.diagnostic_status(f'{self.get_name()}: joint', level, message,
                                             values, hardware_id=settings.link1_frame)
        self._pub_diagnostics.publish(msg_tools.diagnostic_array(
            [status], self.get_clock().now().to_msg()))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness stiffness_node``."""
    runner.run(StiffnessNode, args)


if __name__ == '__main__':
    main()
