"""``structure_estimator_node``: every body's pose of a structure (the 3-bar, the 6-bar) with its
covariance, from string lengths, load cells, motor encoders, one IMU per bar and optional
markers, over ROS 2 (docs/structures.md, "The estimator node").

Thin layer: decode, keep the newest reading of each input, estimate with
:mod:`tensegrity_stiffness.nodes.structure_estimator_node` (the static estimator or the filter,
``estimation.method``) when a message of ``estimation.trigger`` arrives, publish. Built on
:class:`.StreamingNode` as ``estimator_node``: the inputs are its streams on the fast lane,
newest only (a reading queued behind a newer one is passed over and counted on /diagnostics), an
estimate is its "configuration" (all outputs or none, under one lock), markers, ``/tf`` (a frame
per body) and /diagnostics as the structure node's. Bad input or a set that cannot determine the
poses: a specific throttled warning, no publication, the state kept.
"""

from __future__ import annotations

import time
from dataclasses import replace
from functools import partial
from operator import attrgetter
from typing import Any

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.geometry.validation import require_frame
from tensegrity_stiffness.nodes import structure_node
from tensegrity_stiffness.nodes.estimator_node import EstimatorInput, Reading
from tensegrity_stiffness.nodes.messages import stamp_is_set
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.structure_estimator_node import (
    NODE_NAME,
    STRUCTURE_ESTIMATOR_INPUTS,
    STRUCTURE_ESTIMATOR_PARAMETERS,
    FilterTrack,
    StructureEstimatorArrayMessages,
    StructureEstimatorOutputs,
    StructureEstimatorSettings,
    array_reading,
    estimate,
    estimator_array_layouts,
    imu_sample,
    structure_estimator_settings,
    trust_summary,
    trust_values,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions import estimation as estimation_msgs
from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES, output_topics
from tensegrity_stiffness.ros.conversions.structure_outputs import structure_markers
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.node_base import Stream, StreamingNode
from tensegrity_stiffness.ros.runtime.reporting import guarded
from tensegrity_stiffness.structures.equilibrium import resting_poses
from tensegrity_stiffness.structures.structure import Structure


class StructureEstimatorMessages:
    """The per-estimate messages: ``~/poses`` (PoseArray in the world frame, body order),
    ``~/trust`` (a DiagnosticArray of one status: consistent, redundancy, chi2, outliers, the
    held gauge, the contacts), then the arrays (``~/pose_covariance`` and the structure node's
    outputs at the estimate)."""

    def __init__(self, structure: Structure, status_name: str) -> None:
        self.poses = PoseArray()
        self.trust = DiagnosticArray()
        self.status_name = status_name
        self.arrays = StructureEstimatorArrayMessages(structure, RCLPY_TYPES)

    def messages(self) -> tuple[Any, ...]:
        return (self.poses, self.trust, *self.arrays.messages())

    def fill(self, outputs: StructureEstimatorOutputs, stamp: Any, frame_id: str,
             wanted: tuple[bool, ...] | None = None) -> None:
        """Set the messages flagged in ``wanted`` (default all); ValueError (none is set) when
        a pose is not a rigid transform."""
        wanted = wanted or (True,) * len(self.messages())
        if wanted[0]:
            poses = [conversions.transform_to_pose(T) for T in outputs.poses]
            self.poses.header.stamp, self.poses.header.frame_id = stamp, frame_id
            self.poses.poses = poses
        if wanted[1]:
            level, message = trust_summary(outputs)
            self.trust = conversions.diagnostic_array(
                [conversions.diagnostic_status(self.status_name, level, message,
                                               trust_values(outputs), hardware_id=frame_id)],
                stamp, frame_id)
        self.arrays.fill(outputs, stamp, frame_id, wanted[2:])


class StructureEstimatorNode(StreamingNode):
    """Publishes every body's pose with its covariance, the trust and the structure node's
    outputs of every estimate; markers, frames and diagnostics."""

    SERVES_SOLVES = False  # no services: no worker process
    #: Sensor readings: only the newest of each input's queue is taken (as estimator_node's).
    NEWEST_INPUT_ONLY = True
    _build_settings = staticmethod(structure_estimator_settings)
    _output_frame = attrgetter('world_frame')
    _settings: StructureEstimatorSettings

    def __init__(self, **kwargs: Any) -> None:
        self._readings: dict[str, Reading] = {}
        self._track = FilterTrack()  # 'filter': a new one after every parameter change
        self._estimates = 0
        self._consistent_estimates = 0
        super().__init__(NODE_NAME, **kwargs)
        settings = self._settings
        s = settings.structure
        self._start_poses = resting_poses(s)  # the first estimate's start
        self._start(resting_poses, (s,),
                    f'{s.n_bodies} bodies, {s.n_strings} strings, {settings.method} estimator, '
                    f'IMUs on {" ".join(settings.imu_bodies) or "none"}, trigger '
                    f'~/{settings.trigger_reading}, max age {settings.max_age:g} s')

    # ------------------------------------------------------------------ declarations
    @property
    def OUTPUT_TOPICS(self) -> tuple[tuple[Any, str], ...]:
        """``~/poses``, ``~/trust``, then the arrays (``~/contact_forces`` only with a ground)."""
        return ((PoseArray, '~/poses'), (DiagnosticArray, '~/trust'),
                *output_topics(estimator_array_layouts(self._settings.structure)))

    def _parameter_table(self) -> tuple[ParameterSpec, ...]:
        return STRUCTURE_ESTIMATOR_PARAMETERS

    def _streams(self) -> tuple[Stream, ...]:
        on_array = guarded('~/measured arrays')(StructureEstimatorNode._on_array)
        on_imu = guarded('~/imu')(StructureEstimatorNode._on_imu)
        return (*((Float64MultiArray, f'~/{name}', partial(on_array, self, name))
                  for name in STRUCTURE_ESTIMATOR_INPUTS),
                *((Imu, f'~/imu/{body}', partial(on_imu, self, body))
                  for body in self._settings.imu_bodies))

    def _output_messages(self, settings: StructureEstimatorSettings
                         ) -> StructureEstimatorMessages:
        return StructureEstimatorMessages(settings.structure,
                                          f'{self.get_fully_qualified_name()}: estimate')

    def _outputs(self, settings: StructureEstimatorSettings, snapshot: EstimatorInput,
                 wanted: tuple[bool, ...]) -> StructureEstimatorOutputs:
        outputs = estimate(settings, snapshot,
                           self._track if settings.method == 'filter' else None)
        self._estimates += 1
        self._consistent_estimates += outputs.consistent is not False
        return outputs

    def _apply_parameters(self, values: Any, names: set[str]) -> None:
        """As every streaming node's; the filter starts a new track under the new settings."""
        with self._output_lock:
            self._track = FilterTrack()
            super()._apply_parameters(values, names)

    def _republish_last(self) -> None:
        """The static estimator estimates the last readings again under new settings or rest
        lengths; the filter does not (it would count them twice)."""
        if self._settings.method == 'static':
            super()._republish_last()

    def _markers(self, settings: StructureEstimatorSettings, state: Any, stamp: Any
                 ) -> MarkerArray:
        return structure_markers(settings.structure,
                                 structure_node.outputs_of_state(settings.node, state),
                                 settings.world_frame, stamp)

    def _frame_transforms(self, settings: StructureEstimatorSettings, state: Any
                          ) -> tuple[Any, ...]:
        return structure_node.body_frame_transforms(settings.node, state)

    def _keep_topic_rest_lengths(self, old: StructureEstimatorSettings,
                                 settings: StructureEstimatorSettings, names: set[str]
                                 ) -> StructureEstimatorSettings:
        commanded = old.node.commanded_rest_lengths
        if commanded is None:
            return settings
        try:  # the commands again, with the (possibly new) offsets
            return replace(settings, node=structure_node.with_commanded_rest_lengths(
                settings.node, commanded))
        except ValueError as exc:
            self.reporter.warn('parameter change', f'the commanded rest lengths no longer '
                               f'apply ({exc}): the config\'s are used')
            return settings

    def _with_rest_lengths(self, settings: StructureEstimatorSettings, msg: Float64MultiArray
                           ) -> StructureEstimatorSettings:
        return replace(settings, node=structure_node.with_commanded_rest_lengths(
            settings.node, conversions.multiarray_to_array(
                msg, max_length=settings.max_array_length)))

    # ------------------------------------------------------------------ inputs
    def _store(self, name: str, value: Any, stamp: Any) -> None:
        """Keep the reading; when it is the trigger, estimate from the newest readings (started
        at the last estimate's anchor) and publish, stamped with the trigger's header stamp or,
        for an array (no header), the time it arrived."""
        now = time.monotonic()
        self._readings[name] = Reading(value, now)
        settings = self._settings
        if name != settings.trigger_reading:
            return
        last = self._last.outputs
        snapshot = EstimatorInput(dict(self._readings), now,
                                  self._start_poses if last is None else last.anchor)
        if stamp is None or not stamp_is_set(stamp):
            stamp = self._clock.now().to_msg()
        # A refused estimate is counted and warned about as 'estimate', apart from the inputs'
        # own rejections (each kind throttled on its own).
        self._compute_and_publish(snapshot, stamp, 'estimate')

    def _on_array(self, name: str, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            values = array_reading(settings, name, estimation_msgs.measured_values(
                msg, settings.max_array_length))
        except ValueError as exc:
            self.reporter.reject(f'~/{name}', str(exc))
            return
        self._store(name, values, None)

    def _on_imu(self, body: str, msg: Imu) -> None:
        settings = self._settings
        kind = f'~/imu/{body}'
        try:
            require_frame(msg.header.frame_id, body, f"{body}'s frame")
            value = imu_sample(settings, body, *estimation_msgs.imu_motion(msg))
        except ValueError as exc:
            self.reporter.reject(kind, str(exc))
            return
        self._store(f'imu/{body}', value, msg.header.stamp)

    # ------------------------------------------------------------------ diagnostics
    def _diagnostic_statuses(self, settings: StructureEstimatorSettings,
                             outputs: StructureEstimatorOutputs | None,
                             values: list[tuple[str, Any]]) -> list[Any]:
        level, message = 'WARN', 'no estimate yet'
        if outputs is not None:
            values += trust_values(outputs)
            level, message = trust_summary(outputs)
        share = (self._consistent_estimates / self._estimates if self._estimates
                 else float('nan'))
        values += [('estimates', self._estimates), ('consistent share', share),
                   ('filter restarts', self._track.restarts),
                   ('trigger', f'~/{settings.trigger_reading}'),
                   ('max age [s]', settings.max_age)]
        name = f'{self.get_fully_qualified_name()}: structure estimator'
        return [conversions.diagnostic_status(name, level, message, values,
                                              hardware_id=settings.world_frame)]


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness structure_estimator_node``."""
    runner.run(StructureEstimatorNode, args)


if __name__ == '__main__':
    main()
