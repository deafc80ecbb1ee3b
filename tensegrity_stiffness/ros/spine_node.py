"""``spine_node``: real-time per-joint and tip stiffness of a tensegrity spine over ROS 2.

A spine is a :class:`~tensegrity_stiffness.chain.JointChain` (conventions, frames and loads in
:mod:`tensegrity_stiffness.chain`; parameters in :mod:`tensegrity_stiffness.parameters`; topics,
services and QoS in README.md). Built from the parts of ``stiffness_node``: the parameter binding,
the reporter and guards, draining subscriptions, the worker process and the runner. Thin layer:
validate (:mod:`tensegrity_stiffness.spine_processing`), convert (:mod:`msg_tools`), call the
library, publish all of an input's outputs or none.

Concurrency as in ``stiffness_node``: ``~/screws`` and ``~/poses`` on the fast lane's thread
(``realtime.fast_lane``, else draining subscriptions on the executor), everything else on one
single-threaded executor; outputs are published under one lock; the equilibrium service is a
coroutine awaiting the worker process; all configuration is one immutable
:class:`SpineNodeSettings`, swapped as a whole and read once per callback.
"""

from __future__ import annotations

import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

import msg_tools
from tensegrity_stiffness.chain import solve_chain_equilibrium
from tensegrity_stiffness.parameters import (
    CHAIN_PARAMETERS,
    SpineNodeSettings,
    by_name,
    spine_node_parameters,
    spine_node_settings,
)
from tensegrity_stiffness.ros import runner, spine_services
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
from tensegrity_stiffness.spine_processing import (
    joint_health_in_chain,
    poses_input,
    rest_lengths_input,
    screws_input,
    spine_outputs,
)
from tensegrity_stiffness_interfaces.srv import SolveChainEquilibrium

NODE_NAME = 'spine_node'
#: Output topics in the order of :meth:`msg_tools.SpineOutputMessages.messages`.
OUTPUT_TOPICS = (
    (Float64MultiArray, '~/joint_wrenches'), (Float64MultiArray, '~/joint_stiffness'),
    (Float64MultiArray, '~/joint_cartesian_stiffness'), (PoseStamped, '~/tip_pose'),
    (WrenchStamped, '~/tip_wrench'), (Float64MultiArray, '~/tip_stiffness'),
    (Float64MultiArray, '~/tip_stiffness_base'))


def _declared_joint_count(node: Node) -> int:
    """``chain.n_joints`` as the parameter file or overrides set it: the parameter table depends
    on it (the ``joint_<i>`` overrides), so it is read before the table is declared."""
    spec = by_name(CHAIN_PARAMETERS)['chain.n_joints']
    value = node.declare_parameter(spec.name, spec.default).value
    node.undeclare_parameter(spec.name)  # declared again, with its descriptor, from the table
    return spec.check(value)


class SpineNode(Node):
    """Publishes per-joint wrenches, K, K_c and the tip pose, implied wrench and stiffness per
    input; solves the chain's equilibrium as a service."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.reporter = Reporter(self.get_logger())
        # Publication lock: the fast lane and the executor both publish; settings are swapped
        # (and re-published) under it too. Re-entrant: a swap re-publishes.
        self._output_lock = threading.RLock()
        n_joints = _declared_joint_count(self)
        self._binding = ParameterBinding(
            self, spine_node_parameters(n_joints), spine_node_settings, self._apply_parameters,
            lambda reason: self.reporter.warn('parameter change', reason))
        self._settings: SpineNodeSettings = spine_node_settings(self._binding.values())
        self._last = LastInput()
        self._last_solution: np.ndarray | None = None
        self._clock = self.get_clock()
        self._messages = msg_tools.SpineOutputMessages(n_joints)
        self._solver = SolverWorker('chain equilibrium worker')
        self._in_worker = WorkerCalls(self, self._solver)

        values = self._settings.values
        depth, reliability = values['qos.depth'], values['qos.input_reliability']
        out_qos = output_qos(depth)
        self._output_publishers = [create_output_publisher(self, t, topic, out_qos)
                                   for t, topic in OUTPUT_TOPICS]
        self._pub_markers = create_output_publisher(self, MarkerArray, '~/markers', out_qos)
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics', 10)

        qos = input_qos(depth, reliability)
        self._lane = FastLane(self, self.reporter.internal_error) \
            if values['realtime.fast_lane'] else None
        for msg_type, topic, callback in ((Float64MultiArray, '~/screws', self._on_screws),
                                          (PoseArray, '~/poses', self._on_poses)):
            if self._lane is not None:
                self._lane.create_subscription(msg_type, topic, callback, qos)
            else:
                create_draining_subscription(
                    self, msg_type, topic, callback, qos,
                    on_error=lambda exc, t=topic: self.reporter.internal_error(t, exc))
        self.create_subscription(Float64MultiArray, '~/rest_lengths', self._on_rest_lengths,
                                 LATCHED_QOS)
        self.create_service(SolveChainEquilibrium, '~/solve_equilibrium',
                            self._on_solve_equilibrium,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_timer(values['diagnostics.period'], self._publish_diagnostics)
        self._marker_timer = self.create_timer(
            self._settings.marker_period or 1.0, self._publish_markers)
        chain = self._settings.chain
        # Warm the worker up (imports, first solve) before the first request needs it.
        self._solver.submit(solve_chain_equilibrium, (chain, np.zeros(6)), {'time_budget': 1.0},
                            lambda _: None, lambda _: None, deadline_s=1.0 + SOLVER_GRACE_S)
        if self._lane is not None:
            self._lane.start()
        self.get_logger().info(
            f'ready: {n_joints} joints, frames {self._settings.base_frame} -> '
            f'{self._settings.tool_frame}, inputs {reliability} depth {depth}')

    def close(self) -> None:
        """End the fast lane and the worker process (called by the runner before the node is
        destroyed)."""
        if self._lane is not None:
            self._lane.stop()
        self._solver.close()

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, values: dict[str, Any], names: set[str]) -> None:
        """After a successful set: swap in the new settings, keeping topic rest lengths unless
        the change sets rest lengths itself, and re-publish the last configuration under them;
        no input is published in between (the output lock)."""
        with self._output_lock:
            try:
                old = self._settings
                settings = spine_node_settings(values, old.generation + 1)
                if old.rest_lengths is not None and not any(
                        n.endswith('.rest_lengths') for n in names) and [
                        r.shape[0] for r in old.rest_lengths] == settings.n_strings:
                    settings = replace(settings, rest_lengths=old.rest_lengths)
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
    @guarded('~/screws')
    def _on_screws(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            xi = screws_input(msg_tools.multiarray_to_array(
                msg, max_length=settings.max_array_length), settings.n_joints)
        except ValueError as exc:
            self.reporter.reject('~/screws', str(exc))
            return
        self._compute_and_publish(xi, None, '~/screws')

    @guarded('~/poses')
    def _on_poses(self, msg: PoseArray) -> None:
        settings = self._settings
        try:
            last = self._last.screws
            reference = last if last is not None else np.array(
                [model.initial_screw for model in settings.chain.joints])
            xi = poses_input(msg.header.frame_id, msg.poses, settings.base_frame, reference,
                             msg_tools.pose_to_transform)
        except ValueError as exc:
            self.reporter.reject('~/poses', str(exc))
            return
        stamp = msg.header.stamp
        self._compute_and_publish(xi, stamp if stamp.sec or stamp.nanosec else None, '~/poses')

    @guarded('~/rest_lengths')
    def _on_rest_lengths(self, msg: Float64MultiArray) -> None:
        with self._output_lock:  # the swap and its re-publish, with no input in between
            settings = self._settings
            try:
                rest = rest_lengths_input(msg_tools.multiarray_to_array(
                    msg, max_length=settings.max_array_length), settings.chain)
            except ValueError as exc:
                self.reporter.reject('~/rest_lengths', str(exc))
                return
            self._settings = replace(settings, rest_lengths=rest,
                                     generation=settings.generation + 1)
            self._republish_last()

    def _republish_last(self) -> None:
        if self._last.screws is not None:
            self._compute_and_publish(self._last.screws, self._last.stamp, 're-publish')

    # ------------------------------------------------------------------ outputs
    def _compute_and_publish(self, xi: np.ndarray, stamp: Any, source: str) -> None:
        """Build and check every output under the current settings, then publish them all (an
        input gets all of its outputs or none); topics nobody subscribes to are not filled (the
        outputs are volatile)."""
        with self._output_lock:
            settings = self._settings
            start = time.perf_counter()
            messages = self._messages
            try:
                outputs = spine_outputs(settings.chain, xi, settings.rest_lengths)
                if stamp is None:
                    stamp = self._clock.now().to_msg()
                wanted = tuple(p.get_subscription_count() > 0 for p in self._output_publishers)
                messages.fill(outputs, stamp, settings.base_frame, wanted)
                markers = None
                if settings.marker_period == 0.0:  # one per input; else _publish_markers
                    markers = msg_tools.spine_markers(settings.chain, outputs.state,
                                                      settings.base_frame, stamp)
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
        """At most ``markers.max_rate`` Hz, on the executor's thread (the whole spine's markers
        take milliseconds): the last configuration, once, if anyone listens."""
        settings = self._settings
        if settings.marker_period == 0.0 or self._pub_markers.get_subscription_count() == 0:
            return
        last = self._last.unmarked()
        if last is None:
            return
        outputs, stamp = last
        self._pub_markers.publish(msg_tools.spine_markers(
            settings.chain, outputs.state, settings.base_frame,
            stamp if stamp is not None else self._clock.now().to_msg()))

    # ------------------------------------------------------------------ services
    @guarded_service('~/solve_equilibrium')
    async def _on_solve_equilibrium(self, request: SolveChainEquilibrium.Request,
                                    response: SolveChainEquilibrium.Response
                                    ) -> SolveChainEquilibrium.Response:
        """Validated here, solved in the worker process within ``equilibrium.time_budget``."""
        settings = self._settings
        try:
            job = spine_services.chain_equilibrium_job(request, settings, self._last_solution)
        except ValueError as exc:
            self.reporter.reject('~/solve_equilibrium', str(exc))
            return spine_services.fail(response, f'invalid request: {exc}')
        try:
            result = await self._in_worker(solve_chain_equilibrium,
                                           (settings.chain, *job.args()), job.kwargs(),
                                           job.time_budget + SOLVER_GRACE_S)
        except ValueError as exc:  # a request the library refuses
            self.reporter.reject('~/solve_equilibrium', str(exc))
            return spine_services.fail(response, f'invalid request: {exc}')
        except (TimeoutError, WorkerDiedError) as exc:
            return answer_worker_failure(self.reporter, '~/solve_equilibrium', response, exc)
        if spine_services.fill_chain_equilibrium(response, result):
            self._last_solution = result.screws
        return response

    # ------------------------------------------------------------------ diagnostics
    @guarded('diagnostics')
    def _publish_diagnostics(self) -> None:
        settings = self._settings
        outputs = self._last.outputs
        values: list[tuple[str, Any]] = [
            ('joints', settings.n_joints),
            *self._last.statistics(),
            ('rejected inputs', dict(sorted(self.reporter.rejected.items())) or 0),
            ('parameter generation', settings.generation),
            ('equilibrium worker restarts', self._solver.restarts),
        ]
        name = self.get_name()
        statuses = []
        problems = []
        if outputs is not None:
            for i, model in enumerate(settings.chain.joints):
                health = joint_health_in_chain(outputs.state, i, model.string_names)
                if health.problems:
                    problems.append(f'joint {i + 1}: ' + ', '.join(health.problems))
                statuses.append(msg_tools.diagnostic_status(
                    f'{name}: joint {i + 1}', 'WARN' if health.problems else 'OK',
                    ', '.join(health.problems) or 'all strings taut, stable', health.values(),
                    hardware_id=settings.base_frame))
        message = ('no input yet' if outputs is None else
                   '; '.join(problems) or 'every joint: all strings taut, stable')
        statuses.insert(0, msg_tools.diagnostic_status(
            f'{name}: chain', 'WARN' if problems else 'OK', message, values,
            hardware_id=settings.base_frame))
        self._pub_diagnostics.publish(msg_tools.diagnostic_array(
            statuses, self.get_clock().now().to_msg()))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness spine_node``."""
    runner.run(SpineNode, args)


if __name__ == '__main__':
    main()
