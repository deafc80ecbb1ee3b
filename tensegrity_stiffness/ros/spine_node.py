"""``spine_node``: real-time per-joint and tip stiffness of a tensegrity spine over ROS 2.

A spine is a :class:`~tensegrity_stiffness.mechanics.chain.JointChain` (conventions, frames and
loads in
:mod:`tensegrity_stiffness.mechanics.chain`; parameters in
:mod:`tensegrity_stiffness.nodes.spine_node`; topics,
services and QoS in docs/nodes.md). Thin layer: validate
(:mod:`tensegrity_stiffness.nodes.spine_node`), convert
(:mod:`tensegrity_stiffness.ros.conversions`), call the library,
publish all of an input's outputs or none.

Built on :class:`.StreamingNode` as ``stiffness_node`` is (:mod:`.node_base`: concurrency, the
settings swap, the publication under one lock): ``~/screws`` and ``~/poses`` are its streamed
inputs, the equilibrium service awaits the worker process; all configuration is one immutable
:class:`SpineNodeSettings`.
"""

from __future__ import annotations

from operator import attrgetter
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.mechanics.chain import ChainState, solve_chain_equilibrium
from tensegrity_stiffness.nodes.layouts import NATURAL_FREQUENCIES_LABEL, spine_output_layouts
from tensegrity_stiffness.nodes.messages import stamp_is_set
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name
from tensegrity_stiffness.nodes.shared_parameters import CHAIN_PARAMETERS
from tensegrity_stiffness.nodes.spine_node import (
    SpineNodeSettings,
    SpineOutputs,
    joint_health_in_chain,
    poses_input,
    screws_input,
    spine_node_parameters,
    spine_node_settings,
    spine_outputs,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions.outputs import output_topics
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.node_base import Stream, StreamingNode
from tensegrity_stiffness.ros.runtime.reporting import guarded, guarded_service
from tensegrity_stiffness.ros.runtime.rest_length_topics import SpineRestLengthTopic
from tensegrity_stiffness.ros.runtime.tf_broadcast import SpineFrames
from tensegrity_stiffness.ros.runtime.topics import create_output_publisher, output_qos
from tensegrity_stiffness.ros.runtime.worker_calls import SOLVER_GRACE_S
from tensegrity_stiffness.ros.services import spine_services
from tensegrity_stiffness.srv import SolveChainEquilibrium

NODE_NAME = 'spine_node'
#: Output topics in the order of :meth:`conversions.SpineOutputMessages.messages`.
OUTPUT_TOPICS = output_topics(spine_output_layouts(1))


def declared_joint_count(node: Node) -> int:
    """``chain.n_joints`` as the parameter file or overrides set it: the parameter table depends
    on it (the ``joint_<i>`` overrides), so it is read before the table is declared."""
    spec = by_name(CHAIN_PARAMETERS)['chain.n_joints']
    value = node.declare_parameter(spec.name, spec.default).value
    node.undeclare_parameter(spec.name)  # declared again, with its descriptor, from the table
    return spec.check(value)


class SpineNode(SpineFrames, SpineRestLengthTopic, StreamingNode):
    """Publishes per-joint wrenches, K, K_c and the tip pose, implied wrench and stiffness per
    input; solves the chain's equilibrium as a service."""

    OUTPUT_TOPICS = OUTPUT_TOPICS
    EIGENVALUES_TOPIC = '~/tip_stiffness_eigenvalues'
    WORKER_NAME = 'chain equilibrium worker'
    WORKER_FUNCTIONS = (solve_chain_equilibrium,)
    _build_settings = staticmethod(spine_node_settings)
    _output_frame = attrgetter('base_frame')
    _settings: SpineNodeSettings

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._pub_frequencies = create_output_publisher(
            self, Float64MultiArray, '~/natural_frequencies',
            output_qos(self._settings.values['qos.depth'])) \
            if self._settings.dynamics is not None else None
        self.create_service(SolveChainEquilibrium, '~/solve_equilibrium',
                            self._on_solve_equilibrium,
                            callback_group=MutuallyExclusiveCallbackGroup())
        settings = self._settings
        self._start(solve_chain_equilibrium, (settings.chain, np.zeros(6)),
                    f'{settings.n_joints} joints, frames {settings.base_frame} -> '
                    f'{settings.tool_frame}')

    # ------------------------------------------------------------------ declarations
    def _parameter_table(self) -> tuple[ParameterSpec, ...]:
        return spine_node_parameters(declared_joint_count(self))

    def _cartesian_stiffness(self, outputs: SpineOutputs) -> np.ndarray:
        return outputs.tip_stiffness_tool

    def _streams(self) -> tuple[Stream, ...]:
        return ((Float64MultiArray, '~/screws', self._on_screws),
                (PoseArray, '~/poses', self._on_poses))

    def _output_messages(self, settings: SpineNodeSettings) -> conversions.SpineOutputMessages:
        return conversions.SpineOutputMessages(settings.n_joints, settings.tool_frame)

    def _publish_extras(self, settings: SpineNodeSettings, xi: np.ndarray,
                        outputs: SpineOutputs) -> None:
        """``~/natural_frequencies`` (6N) with ``dynamics.enabled``, for an input that is an
        equilibrium of its implied tip wrench (:meth:`ChainDynamics.modes`); off equilibrium
        nothing (a spine's linear model there is not implemented)."""
        publisher = self._pub_frequencies
        if settings.dynamics is None or publisher is None or \
                publisher.get_subscription_count() == 0:
            return
        try:
            modes = settings.dynamics.modes(xi, settings.current_rest_lengths(),
                                            outputs.tip_wrench)
        except (ValueError, np.linalg.LinAlgError):
            return
        publisher.publish(conversions.vector_to_multiarray(modes.frequencies,
                                                           NATURAL_FREQUENCIES_LABEL))

    def _outputs(self, settings: SpineNodeSettings, xi: np.ndarray, wanted: tuple[bool, ...]
                 ) -> SpineOutputs:
        return spine_outputs(settings.chain, xi, settings.rest_lengths)

    def _markers(self, settings: SpineNodeSettings, state: ChainState, stamp: Any
                 ) -> MarkerArray:
        return conversions.spine_markers(settings.chain, state, settings.base_frame, stamp)

    # ------------------------------------------------------------------ inputs
    @guarded('~/screws')
    def _on_screws(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            xi = screws_input(conversions.multiarray_to_array(
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
                             conversions.pose_message_to_transform)
        except ValueError as exc:
            self.reporter.reject('~/poses', str(exc))
            return
        stamp = msg.header.stamp
        self._compute_and_publish(xi, stamp if stamp_is_set(stamp) else None, '~/poses')

    # ------------------------------------------------------------------ services
    @guarded_service('~/solve_equilibrium')
    async def _on_solve_equilibrium(self, request: SolveChainEquilibrium.Request,
                                    response: SolveChainEquilibrium.Response
                                    ) -> SolveChainEquilibrium.Response:
        """Validated here, solved in the worker process within ``equilibrium.time_budget``."""
        kind = '~/solve_equilibrium'
        settings = self._settings
        try:
            job = spine_services.chain_equilibrium_job(request, settings, self._last_solution)
        except ValueError as exc:
            return self._invalid_request(kind, response, exc)
        result = await self._in_worker_or_fail(
            kind, response, solve_chain_equilibrium, (settings.chain, *job.args()),
            job.kwargs(), job.time_budget + SOLVER_GRACE_S, may_refuse=True)
        if result is not None and spine_services.fill_chain_equilibrium(response, result):
            self._last_solution = result.screws
        return response

    # ------------------------------------------------------------------ diagnostics
    def _diagnostic_statuses(self, settings: SpineNodeSettings, outputs: SpineOutputs | None,
                             values: list[tuple[str, Any]]) -> list[Any]:
        name = self.get_fully_qualified_name()
        statuses = []
        problems = []
        if outputs is not None:
            for i, model in enumerate(settings.chain.joints):
                health = joint_health_in_chain(outputs.state, i, model.string_names)
                if health.problems:
                    problems.append(f'joint {i + 1}: ' + ', '.join(health.problems))
                statuses.append(conversions.diagnostic_status(
                    f'{name}: joint {i + 1}', 'WARN' if health.problems else 'OK',
                    ', '.join(health.problems) or 'all strings taut, stable', health.values(),
                    hardware_id=settings.base_frame))
        message = ('no input yet' if outputs is None else
                   '; '.join(problems) or 'every joint: all strings taut, stable')
        statuses.insert(0, conversions.diagnostic_status(
            f'{name}: chain', 'WARN' if problems else 'OK', message,
            [('joints', settings.n_joints), *values], hardware_id=settings.base_frame))
        return statuses


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness spine_node``."""
    runner.run(SpineNode, args)


if __name__ == '__main__':
    main()
