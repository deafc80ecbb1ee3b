"""``stiffness_node``: real-time wrench and stiffness of a tensegrity joint over ROS 2.

Thin layer: validate, convert with :mod:`tensegrity_stiffness.ros.conversions`, call the library
(:mod:`tensegrity_stiffness.nodes.stiffness_node`), publish. Topics, services, parameters and
QoS are documented in docs/nodes.md; the conventions (frames, orderings, signs) in
:mod:`tensegrity_stiffness.mechanics.joint`; the parameters in
:mod:`tensegrity_stiffness.nodes.stiffness_node`.

Built on :class:`.StreamingNode` (:mod:`.node_base`: concurrency, the settings swap, the
publication under one lock); ``~/screw`` and ``~/pose`` are its streamed inputs, the equilibrium
and design services await the worker process (an equilibrium request is first tried on the
executor under a small budget), the planar services answer on the executor. All
the configuration a computation needs is one immutable :class:`JointNodeSettings`.
"""

from __future__ import annotations

from operator import attrgetter
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseStamped
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.mechanics.design import design_rest_lengths
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointState
from tensegrity_stiffness.nodes.health import joint_health
from tensegrity_stiffness.nodes.layouts import joint_output_layouts
from tensegrity_stiffness.nodes.messages import stamp_is_set
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.stiffness_node import (
    STIFFNESS_NODE_PARAMETERS,
    JointNodeSettings,
    JointOutputs,
    frequency_report,
    joint_node_settings,
    joint_outputs,
    pose_input,
    screw_input,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions.outputs import output_topics
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.node_base import Stream, StreamingNode
from tensegrity_stiffness.ros.runtime.reporting import guarded, guarded_service
from tensegrity_stiffness.ros.runtime.rest_length_topics import JointRestLengthTopic
from tensegrity_stiffness.ros.runtime.tf_broadcast import JointFrames
from tensegrity_stiffness.ros.runtime.topics import create_output_publisher, output_qos
from tensegrity_stiffness.ros.runtime.worker_calls import SOLVER_GRACE_S
from tensegrity_stiffness.ros.services import joint_services
from tensegrity_stiffness.srv import (
    DesignRestLengths,
    PlanarForwardKinematics,
    PlanarInverseKinematics,
    SolveEquilibrium,
)

NODE_NAME = 'stiffness_node'
#: Wall-clock bound of one rest-length design in the worker (it takes milliseconds).
DESIGN_DEADLINE_S = 5.0


class StiffnessNode(JointFrames, JointRestLengthTopic, StreamingNode):
    """Publishes wrench, K, K_c, tensions, interpretation, markers and diagnostics per input."""

    OUTPUT_TOPICS = output_topics(joint_output_layouts(()))
    EIGENVALUES_TOPIC = '~/stiffness_eigenvalues'
    WORKER_NAME = 'equilibrium worker'
    WORKER_FUNCTIONS = (solve_equilibrium, design_rest_lengths)
    _build_settings = staticmethod(joint_node_settings)
    _output_frame = attrgetter('link1_frame')
    _settings: JointNodeSettings

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._pub_frequencies = create_output_publisher(
            self, Float64MultiArray, '~/natural_frequencies',
            output_qos(self._settings.values['qos.depth'])) \
            if self._settings.dynamics is not None else None
        # Own reentrant group: each request is taken at once (a coroutine awaiting the worker
        # holds no queue), at most MAX_OUTSTANDING_REQUESTS in progress, the next refused with
        # a message; the default group (topics, planar services, timer) stays free.
        service_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST,
                                 depth=joint_services.SERVICE_QUEUE_DEPTH,
                                 reliability=ReliabilityPolicy.RELIABLE)
        self._outstanding = {
            name: joint_services.OutstandingRequests(name)
            for name in ('~/solve_equilibrium', '~/design_rest_lengths')}
        self.create_service(SolveEquilibrium, '~/solve_equilibrium', self._on_solve_equilibrium,
                            qos_profile=service_qos, callback_group=ReentrantCallbackGroup())
        self.create_service(DesignRestLengths, '~/design_rest_lengths',
                            self._on_design_rest_lengths, qos_profile=service_qos,
                            callback_group=ReentrantCallbackGroup())
        self.create_service(PlanarForwardKinematics, '~/planar_forward_kinematics',
                            self._on_planar_forward)
        self.create_service(PlanarInverseKinematics, '~/planar_inverse_kinematics',
                            self._on_planar_inverse)
        settings = self._settings
        model = settings.model
        self._start(solve_equilibrium, (model, np.zeros(6)),
                    f'{model.n_strings} strings, force law {model.force_law}, frames '
                    f'{settings.link1_frame} -> {settings.link2_frame}')

    # ------------------------------------------------------------------ declarations
    def _parameter_table(self) -> tuple[ParameterSpec, ...]:
        return STIFFNESS_NODE_PARAMETERS

    def _publish_extras(self, settings: JointNodeSettings, xi: np.ndarray,
                        outputs: JointOutputs) -> None:
        """``~/natural_frequencies`` with ``dynamics.enabled``: the modes of the joint held at
        ``xi`` by the load that balances it there (:meth:`JointDynamics.modes_at_pose`)."""
        publisher = self._pub_frequencies
        if settings.dynamics is None or publisher is None or \
                publisher.get_subscription_count() == 0:
            return
        try:
            modes, _ = settings.dynamics.modes_at_pose(xi, settings.model.rest_lengths)
        except (ValueError, np.linalg.LinAlgError) as exc:
            self.reporter.warn('~/natural_frequencies', str(exc))
            return
        values, label = frequency_report(modes)
        publisher.publish(conversions.vector_to_multiarray(values, label))

    def _cartesian_stiffness(self, outputs: JointOutputs) -> np.ndarray:
        return outputs.state.cartesian_stiffness

    def _streams(self) -> tuple[Stream, ...]:
        return ((Float64MultiArray, '~/screw', self._on_screw),
                (PoseStamped, '~/pose', self._on_pose))

    def _output_messages(self, settings: JointNodeSettings) -> conversions.JointOutputMessages:
        return conversions.JointOutputMessages(tuple(settings.model.string_names))

    def _outputs(self, settings: JointNodeSettings, xi: np.ndarray, wanted: tuple[bool, ...]
                 ) -> JointOutputs:
        return joint_outputs(settings.model, xi)

    def _markers(self, settings: JointNodeSettings, state: JointState, stamp: Any
                 ) -> MarkerArray:
        return conversions.joint_markers(settings.model, state, settings.link1_frame, stamp)

    # ------------------------------------------------------------------ inputs
    @guarded('~/screw')
    def _on_screw(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            xi = screw_input(conversions.multiarray_to_array(
                msg, expected_length=6, max_length=settings.max_array_length), settings.model)
        except ValueError as exc:
            self.reporter.reject('~/screw', str(exc))
            return
        self._compute_and_publish(xi, None, '~/screw')

    @guarded('~/pose')
    def _on_pose(self, msg: PoseStamped) -> None:
        settings = self._settings
        try:
            last = self._last.screws
            xi = pose_input(msg.header.frame_id, conversions.pose_message_to_transform(msg.pose),
                            settings.link1_frame,
                            last if last is not None else settings.model.initial_screw,
                            settings.model)
        except ValueError as exc:
            self.reporter.reject('~/pose', str(exc))
            return
        stamp = msg.header.stamp
        self._compute_and_publish(xi, stamp if stamp_is_set(stamp) else None,
                                  '~/pose')

    # ------------------------------------------------------------------ services
    @guarded_service('~/solve_equilibrium')
    async def _on_solve_equilibrium(self, request: SolveEquilibrium.Request,
                                    response: SolveEquilibrium.Response
                                    ) -> SolveEquilibrium.Response:
        """Validated here and tried here under a small budget
        (:meth:`.EquilibriumJob.quick_kwargs`); a request that try does not solve goes to the
        worker process, within ``equilibrium.time_budget``."""
        kind = '~/solve_equilibrium'
        outstanding = self._outstanding[kind]
        refusal = outstanding.enter()
        if refusal is not None:
            return joint_services.fail(response, refusal)
        try:
            settings = self._settings
            try:
                job = joint_services.equilibrium_job(request, settings, self._last_solution)
                result = solve_equilibrium(settings.model, job.external_wrench,
                                           **job.quick_kwargs())
            except ValueError as exc:  # the door's checks, or the solver's own refusal
                return self._invalid_request(kind, response, exc)
            if not result.success:
                result = await self._in_worker_or_fail(
                    kind, response, solve_equilibrium, (settings.model, job.external_wrench),
                    job.kwargs(), job.time_budget + SOLVER_GRACE_S)
            if result is not None and joint_services.fill_equilibrium(response, result):
                self._last_solution = result.screw
            return response
        finally:
            outstanding.leave()

    @guarded_service('~/design_rest_lengths')
    async def _on_design_rest_lengths(self, request: DesignRestLengths.Request,
                                      response: DesignRestLengths.Response
                                      ) -> DesignRestLengths.Response:
        """Validated here, designed in the worker process; the node's rest lengths stay."""
        kind = '~/design_rest_lengths'
        outstanding = self._outstanding[kind]
        refusal = outstanding.enter()
        if refusal is not None:
            return joint_services.fail(response, refusal)
        try:
            settings = self._settings
            last = self._last.screws
            try:
                kwargs = joint_services.design_kwargs(
                    request, settings,
                    last if last is not None else settings.model.initial_screw)
            except ValueError as exc:
                return self._invalid_request(kind, response, exc)
            # may_refuse: a request the library refuses (e.g. outside the chart)
            result = await self._in_worker_or_fail(kind, response, design_rest_lengths,
                                                   (settings.model,), kwargs,
                                                   DESIGN_DEADLINE_S, may_refuse=True)
            return response if result is None else joint_services.fill_design(response,
                                                                              result)
        finally:
            outstanding.leave()

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
    def _diagnostic_statuses(self, settings: JointNodeSettings, outputs: JointOutputs | None,
                             values: list[tuple[str, Any]]) -> list[Any]:
        level, message = 'OK', 'no input yet'
        if outputs is not None:
            health = joint_health(outputs.state, settings.model.string_names)
            values += health.values()
            level = 'WARN' if health.problems else 'OK'
            message = ', '.join(health.problems) or 'all strings taut, stable'
        return [conversions.diagnostic_status(
            f'{self.get_fully_qualified_name()}: joint', level, message, values,
            hardware_id=settings.link1_frame)]


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness stiffness_node``."""
    runner.run(StiffnessNode, args)


if __name__ == '__main__':
    main()
