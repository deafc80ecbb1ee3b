"""``structure_node``: real-time wrenches and stiffness of a structure of rigid bodies and strings
over ROS 2 (the 3-bar and 6-bar robots; docs/structures.md, "The node").

Thin layer: validate (:mod:`tensegrity_stiffness.nodes.structure_node`: parameters, settings,
inputs, outputs, health), convert (:mod:`tensegrity_stiffness.ros.conversions`), call the library
(:meth:`Structure.evaluate_transforms`, the compiled kernel when built), publish all of an
input's outputs or none. Built on :class:`.StreamingNode` as ``stiffness_node`` and
``spine_node`` are: ``~/poses`` (PoseArray) and ``~/pose_values`` (7N values) are its streamed
inputs; the equilibrium and the analysis report are computed in the worker process.
"""

from __future__ import annotations

import json
from operator import attrgetter
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseArray
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.cli.common import jsonable
from tensegrity_stiffness.mechanics.templates import pose_vector
from tensegrity_stiffness.nodes import structure_node as processing
from tensegrity_stiffness.nodes.messages import stamp_is_set
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.structure_node import (
    NODE_NAME,
    STRUCTURE_NODE_PARAMETERS,
    StructureNodeSettings,
    StructureOutputs,
    structure_node_settings,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions.outputs import output_topics
from tensegrity_stiffness.ros.conversions.structure_outputs import (
    StructureOutputMessages,
    structure_markers,
)
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.node_base import Stream, StreamingNode
from tensegrity_stiffness.ros.runtime.reporting import guarded, guarded_service
from tensegrity_stiffness.ros.runtime.worker_calls import SOLVER_GRACE_S
from tensegrity_stiffness.srv import SolveStructureEquilibrium, StructureReport
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import StructureState

#: The index of ``~/contact_forces`` among the outputs (with a ground).
CONTACTS = processing.STRUCTURE_OUTPUTS.index('contact_forces')
#: Seconds a report (the equilibrium, the modes, the prestressed equilibrium and the analysis:
#: some 50 ms for the 6-bar) may take in the worker.
REPORT_BUDGET_S = 10.0


class StructureNode(StreamingNode):
    """Publishes the bodies' wrenches, the stiffness, tensions, bar and contact forces per set
    of poses; solves the equilibrium and reports the analysis as services."""

    WORKER_NAME = 'structure equilibrium worker'
    WORKER_FUNCTIONS = (solve_structure_equilibrium, processing.structure_report)
    _build_settings = staticmethod(structure_node_settings)
    _output_frame = attrgetter('world_frame')
    _settings: StructureNodeSettings

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.create_service(SolveStructureEquilibrium, '~/solve_equilibrium',
                            self._on_solve_equilibrium,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(StructureReport, '~/report', self._on_report,
                            callback_group=MutuallyExclusiveCallbackGroup())
        s = self._settings.structure
        ground = ', ground' if s.ground is not None else ''
        self._start(solve_structure_equilibrium, (s,),
                    f'{s.n_bodies} bodies, {s.n_strings} strings{ground} in '
                    f'{self._settings.world_frame}')

    # ------------------------------------------------------------------ declarations
    @property
    def OUTPUT_TOPICS(self) -> tuple[tuple[Any, str], ...]:
        """The outputs of this node's structure (``~/contact_forces`` only with a ground)."""
        return output_topics(processing.structure_output_layouts(self._settings.structure))

    def _parameter_table(self) -> tuple[ParameterSpec, ...]:
        return STRUCTURE_NODE_PARAMETERS

    def _streams(self) -> tuple[Stream, ...]:
        return ((PoseArray, '~/poses', self._on_poses),
                (Float64MultiArray, '~/pose_values', self._on_pose_values))

    def _output_messages(self, settings: StructureNodeSettings) -> StructureOutputMessages:
        return StructureOutputMessages(settings.structure)

    def _outputs(self, settings: StructureNodeSettings, T: np.ndarray, wanted: tuple[bool, ...]
                 ) -> StructureOutputs:
        """The outputs; the contact forces only while ``~/contact_forces`` has a subscriber."""
        return processing.structure_outputs(settings, T, contacts=len(wanted) > CONTACTS
                                            and wanted[CONTACTS])

    def _markers(self, settings: StructureNodeSettings, state: StructureState, stamp: Any
                 ) -> MarkerArray:
        return structure_markers(settings.structure,
                                 processing.outputs_of_state(settings, state),
                                 settings.world_frame, stamp)

    def _frame_transforms(self, settings: StructureNodeSettings, state: StructureState
                          ) -> tuple[Any, ...]:
        return processing.body_frame_transforms(settings, state)

    def _keep_topic_rest_lengths(self, old: StructureNodeSettings,
                                 settings: StructureNodeSettings, names: set[str]
                                 ) -> StructureNodeSettings:
        if old.commanded_rest_lengths is None:
            return settings
        try:  # the commands again, with the (possibly new) offsets
            return processing.with_commanded_rest_lengths(settings, old.commanded_rest_lengths)
        except ValueError as exc:
            self.reporter.warn('parameter change', f'the commanded rest lengths no longer '
                               f'apply ({exc}): the config\'s are used')
            return settings

    def _with_rest_lengths(self, settings: StructureNodeSettings, msg: Float64MultiArray
                           ) -> StructureNodeSettings:
        return processing.with_commanded_rest_lengths(settings, conversions.multiarray_to_array(
            msg, max_length=settings.max_array_length))

    # ------------------------------------------------------------------ inputs
    @guarded('~/poses')
    def _on_poses(self, msg: PoseArray) -> None:
        settings = self._settings
        try:
            T = processing.poses_input(msg.header.frame_id, msg.poses, settings.world_frame,
                                       settings.n_bodies, conversions.pose_message_to_transform)
        except ValueError as exc:
            self.reporter.reject('~/poses', str(exc))
            return
        stamp = msg.header.stamp
        self._compute_and_publish(T, stamp if stamp_is_set(stamp) else None, '~/poses')

    @guarded('~/pose_values')
    def _on_pose_values(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            T = processing.pose_values_input(conversions.multiarray_to_array(
                msg, max_length=settings.max_array_length), settings.structure)
        except ValueError as exc:
            self.reporter.reject('~/pose_values', str(exc))
            return
        self._compute_and_publish(T, None, '~/pose_values')

    # ------------------------------------------------------------------ services
    @guarded_service('~/solve_equilibrium')
    async def _on_solve_equilibrium(self, request: SolveStructureEquilibrium.Request,
                                    response: SolveStructureEquilibrium.Response
                                    ) -> SolveStructureEquilibrium.Response:
        """Validated here, solved in the worker process within ``equilibrium.time_budget``."""
        kind = '~/solve_equilibrium'
        settings = self._settings
        try:
            job = processing.equilibrium_job(
                settings, request.loads, request.start, request.rest_lengths,
                request.without_gravity, request.without_ground, self._last.screws)
        except ValueError as exc:
            return self._invalid_request(kind, response, exc)
        result = await self._in_worker_or_fail(
            kind, response, solve_structure_equilibrium, job.args(), job.kwargs(),
            job.time_budget + SOLVER_GRACE_S, may_refuse=True)
        if result is None:
            return response
        response.success = bool(result.success)
        response.message = result.message
        response.poses = [v for T in result.poses for v in pose_vector(T)]
        if result.state is not None:
            response.tensions = result.state.tensions.tolist()
            response.bar_forces = result.state.bar_forces.tolist()
        response.contact_nodes = list(result.contacts)
        response.contact_forces = [float(v) for f in result.contacts.values() for v in f]
        response.sliding = list(result.sliding)
        response.stable = bool(result.stable)
        response.stability_margin = float(result.stability_margin)
        if result.tangent_stiffness is not None:
            response.tangent_stiffness = result.tangent_stiffness.ravel().tolist()
        response.residual = float(result.residual)
        response.iterations = int(result.iterations)
        return response

    @guarded_service('~/report')
    async def _on_report(self, request: StructureReport.Request,
                         response: StructureReport.Response) -> StructureReport.Response:
        """:func:`~tensegrity_stiffness.structures.report.check_structure` in the worker."""
        kind = '~/report'
        settings = self._settings
        try:
            rest = processing.request_rest_lengths(request.rest_lengths, settings)
        except ValueError as exc:
            return self._invalid_request(kind, response, exc)
        report = await self._in_worker_or_fail(
            kind, response, processing.structure_report, (settings.structure, rest), {},
            REPORT_BUDGET_S + SOLVER_GRACE_S, may_refuse=True)
        if report is None:
            return response
        response.success = True
        response.message = 'sound' if report['sound'] else '; '.join(report['problems'])
        response.sound = bool(report['sound'])
        response.problems = [str(p) for p in report['problems']]
        response.notes = [str(n) for n in report['notes']]
        response.report_json = json.dumps(jsonable(report), allow_nan=False)
        return response

    # ------------------------------------------------------------------ diagnostics
    def _diagnostic_statuses(self, settings: StructureNodeSettings,
                             outputs: StructureOutputs | None,
                             values: list[tuple[str, Any]]) -> list[Any]:
        name = self.get_fully_qualified_name()
        s = settings.structure
        values = [('bodies', s.n_bodies), ('strings', s.n_strings), *values]
        if outputs is None:
            return [conversions.diagnostic_status(f'{name}: structure', 'OK', 'no input yet',
                                                  values, hardware_id=settings.world_frame)]
        health = processing.structure_health(settings, outputs)
        problems = health.problems
        return [conversions.diagnostic_status(
            f'{name}: structure', 'WARN' if problems else 'OK',
            '; '.join(problems) or 'all strings taut, stable', [*values, *health.values()],
            hardware_id=settings.world_frame)]


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness structure_node``."""
    runner.run(StructureNode, args)


if __name__ == '__main__':
    main()
