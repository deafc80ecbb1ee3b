"""``estimator_node``: pose, load and stiffness of a tensegrity joint with their uncertainty,
estimated from what the robot measures (load cells, string lengths, an IMU, motion capture, a
force-torque sensor).

Thin layer: decode with :mod:`conversions.estimation`, keep the latest reading of each input,
estimate with :mod:`tensegrity_stiffness.nodes.estimator_node` (the library's filter or
:func:`~tensegrity_stiffness.estimation.joint_estimator.estimate_joint_state`, warm-started from
the last estimate) when a message of the trigger input (``estimation.trigger``) arrives, using
the latest of the others no older than ``estimation.max_age``; publish. Parameters in
:mod:`tensegrity_stiffness.nodes.estimator_node`, the method and conventions in
``docs/estimation.md``.

Built on :class:`.StreamingNode` (:mod:`.node_base`): the inputs are its streams (on the fast
lane, newest only: a reading queued behind a newer one is passed over and counted on
/diagnostics, ``inputs skipped``), an estimate is its "configuration" (all outputs or none,
under one lock, re-estimated when ``~/rest_lengths`` or a parameter changes), markers and
/diagnostics as the stiffness node's. Bad or stale input, or a set that cannot determine the
pose: a specific throttled warning, no publication, the state kept.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from operator import attrgetter
from typing import Any

import numpy as np
from geometry_msgs.msg import PoseWithCovarianceStamped, WrenchStamped
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.estimation.chain_filter import ChainFilter
from tensegrity_stiffness.estimation.joint_filter import JointFilter
from tensegrity_stiffness.geometry.validation import require_frame
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.nodes.estimator_node import (
    ESTIMATOR_NODE_PARAMETERS,
    EstimatorInput,
    EstimatorNodeSettings,
    EstimatorOutputs,
    Reading,
    check_reading,
    diagnostic_summary,
    diagnostic_values,
    estimator_node_settings,
    estimator_outputs,
    filter_outputs,
    imu_reading,
    measured_array,
    new_joint_filter,
)
from tensegrity_stiffness.nodes.layouts import ESTIMATOR_STD_OUTPUT, estimator_output_layouts
from tensegrity_stiffness.nodes.messages import stamp_is_set
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions import estimation as estimation_msgs
from tensegrity_stiffness.ros.conversions.outputs import output_topics
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.node_base import Stream, StreamingNode
from tensegrity_stiffness.ros.runtime.reporting import guarded
from tensegrity_stiffness.ros.runtime.rest_length_topics import JointRestLengthTopic
from tensegrity_stiffness.ros.runtime.tf_broadcast import JointFrames

NODE_NAME = 'estimator_node'


class EstimatorNode(JointFrames, JointRestLengthTopic, StreamingNode):
    """Publishes the pose (with covariance), load, screw, K, K_c, the tensions, the std of K_c
    and K and K_c stamped (``msg/StampedMatrix``) of every estimate
    (:data:`~tensegrity_stiffness.nodes.layouts.ESTIMATOR_OUTPUT_TABLE`); markers and
    diagnostics."""

    OUTPUT_TOPICS = output_topics(estimator_output_layouts(()))
    #: The output computed only while someone subscribes to it (most of an estimate's time).
    STIFFNESS_STD_OUTPUT = f'~/{ESTIMATOR_STD_OUTPUT}'
    SERVES_SOLVES = False  # no services: no worker process
    #: Sensor readings: only the newest of each input's queue is taken (the others are counted
    #: on /diagnostics), so that an estimate that takes longer than a reading's period passes
    #: over the backlog instead of turning it into latency.
    NEWEST_INPUT_ONLY = True
    #: The controller's rest-length commands (500 Hz) on the fast lane, in order: an executor
    #: wake-up for each cost more CPU than an estimate's processing (issue 37).
    REST_LENGTHS_ON_LANE = True
    #: Judges one reading on arrival (ValueError naming the input: the reading is dropped).
    _check_reading = staticmethod(check_reading)
    #: What the frame of ~/measured_pose and ~/measured_wrench is called in warnings.
    INPUT_FRAME_NAME = "link 1's frame"
    _build_settings = staticmethod(estimator_node_settings)
    _output_frame = attrgetter('link1_frame')
    _settings: EstimatorNodeSettings
    # The joint's rest lengths are kept and set as the stiffness node's (settings.model).

    def __init__(self, node_name: str = NODE_NAME, **kwargs: Any) -> None:
        self._readings: dict[str, Reading] = {}
        # estimation.method 'filter': the filter and its track (under the output lock; a new
        # one after every parameter change, kept through rest-length changes)
        self._track: JointFilter | ChainFilter | None = None
        self._estimates = 0
        self._consistent_estimates = 0
        super().__init__(node_name, **kwargs)
        self._start(*self._warm_up(self._settings))

    def _warm_up(self, settings: EstimatorNodeSettings) -> tuple[Any, tuple, str]:
        """The worker's first job and the ready line's summary (see ``StreamingNode._start``)."""
        model = settings.model
        return (solve_equilibrium, (model, np.zeros(6)),
                f'{model.n_strings} strings, {settings.method} estimator, load '
                f'{settings.load_mode}, trigger ~/{settings.trigger}, max age '
                f'{settings.max_age:g} s')

    def _options(self, settings: Any) -> EstimatorNodeSettings:
        """The estimator's settings (sensors, load mode, trigger, max age)."""
        return settings

    def _string_count(self, settings: Any) -> int:
        """Values of a measured-array input."""
        return settings.model.n_strings

    def _input_frames(self, settings: Any) -> tuple[str, str]:
        """(frame of the pose and the wrench inputs, frame of the IMU)."""
        return settings.link1_frame, settings.link2_frame

    # ------------------------------------------------------------------ declarations
    def _parameter_table(self) -> tuple[ParameterSpec, ...]:
        return ESTIMATOR_NODE_PARAMETERS

    def _streams(self) -> tuple[Stream, ...]:
        return ((Float64MultiArray, '~/measured_tensions', self._on_tensions),
                (Float64MultiArray, '~/measured_lengths', self._on_lengths),
                (PoseWithCovarianceStamped, '~/measured_pose', self._on_pose),
                (Imu, '~/imu', self._on_imu),
                (WrenchStamped, '~/measured_wrench', self._on_wrench))

    def _output_messages(self, settings: EstimatorNodeSettings
                         ) -> estimation_msgs.EstimatorOutputMessages:
        return estimation_msgs.EstimatorOutputMessages(tuple(settings.model.string_names))

    def stiffness_std_index(self) -> int:
        """Where :attr:`STIFFNESS_STD_OUTPUT` is among ``OUTPUT_TOPICS``."""
        return [topic for _, topic in self.OUTPUT_TOPICS].index(self.STIFFNESS_STD_OUTPUT)

    def _wanted_outputs(self, settings: Any) -> tuple[bool, ...]:
        """As every node's (a subscriber), and the std of the stiffness
        (:attr:`STIFFNESS_STD_OUTPUT`) only with ``estimation.stiffness_std``."""
        wanted = super()._wanted_outputs(settings)
        if self._options(settings).stiffness_std:
            return wanted
        k = self.stiffness_std_index()
        return (*wanted[:k], False, *wanted[k + 1:])

    def _outputs(self, settings: EstimatorNodeSettings, snapshot: EstimatorInput,
                 wanted: tuple[bool, ...]) -> EstimatorOutputs:
        # the std of K_c (most of an estimate's time) only when it is wanted
        std = wanted[self.stiffness_std_index()]
        if settings.method == 'filter':
            if self._track is None:
                self._track = new_joint_filter(settings)
            outputs = filter_outputs(settings, snapshot, self._track, std)
        else:
            outputs = estimator_outputs(settings, snapshot, std)
        self._count(outputs)
        return outputs

    def _count(self, outputs: Any) -> None:
        """An estimate for /diagnostics' ``estimates`` and ``consistent share``."""
        self._estimates += 1
        self._consistent_estimates += outputs.estimate.consistent is not False

    def _apply_parameters(self, values: Any, names: set[str]) -> None:
        """As every streaming node's; the filter starts a new track under the new settings."""
        with self._output_lock:
            self._track = None
            super()._apply_parameters(values, names)

    def _republish_last(self) -> None:
        """The static estimator estimates the last readings again under new settings or rest
        lengths; the filter does not (stepping it again on the same readings would count them
        twice): its next reading is predicted with the rest lengths in force."""
        if self._options(self._settings).method == 'static':
            super()._republish_last()

    def _markers(self, settings: EstimatorNodeSettings, state: Any, stamp: Any) -> MarkerArray:
        return conversions.joint_markers(settings.model, state, settings.link1_frame, stamp)

    # ------------------------------------------------------------------ inputs
    def _store(self, name: str, value: Any, stamp: Any) -> None:
        """Keep the reading; when ``name`` is the trigger, estimate from the latest readings
        (warm-started from the last estimate) and publish, stamped with the trigger's header
        stamp or, for an input without a header (the measured arrays), the time it arrived: the
        controller's latency from a reading to its command starts there."""
        try:
            self._check_reading(self._settings, name, value)
        except ValueError as exc:
            self.reporter.reject(f'~/{name}', str(exc))
            return
        now = time.monotonic()
        arrived = None if stamp is not None and stamp_is_set(stamp) else self._clock.now()
        self._readings[name] = Reading(value, now)
        if name != self._options(self._settings).trigger:
            return
        last = self._last.outputs
        snapshot = EstimatorInput(dict(self._readings), now,
                                  None if last is None else last.screw)
        self._compute_and_publish(snapshot, stamp if arrived is None else arrived.to_msg(),
                                  f'~/{name}')

    def _measured(self, name: str, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            values = measured_array(
                estimation_msgs.measured_values(msg, settings.max_array_length),
                self._string_count(settings), f'~/{name}')
        except ValueError as exc:
            self.reporter.reject(f'~/{name}', str(exc))
            return
        self._store(name, values, None)

    @guarded('~/measured_tensions')
    def _on_tensions(self, msg: Float64MultiArray) -> None:
        self._measured('measured_tensions', msg)

    @guarded('~/measured_lengths')
    def _on_lengths(self, msg: Float64MultiArray) -> None:
        self._measured('measured_lengths', msg)

    def _store_framed(self, name: str, msg: Any, expected: str, what: str,
                      decode: Callable[[Any], Any]) -> None:
        """Keep ``decode(msg)`` as input ``name`` with the header's stamp when the header's
        frame is ``expected`` (or empty, ``what`` names it) and it decodes; otherwise a
        throttled warning naming the problem."""
        try:
            require_frame(msg.header.frame_id, expected, what)
            value = decode(msg)
        except ValueError as exc:
            self.reporter.reject(f'~/{name}', str(exc))
            return
        self._store(name, value, msg.header.stamp)

    @guarded('~/measured_pose')
    def _on_pose(self, msg: PoseWithCovarianceStamped) -> None:
        self._store_framed('measured_pose', msg, self._input_frames(self._settings)[0],
                           self.INPUT_FRAME_NAME,
                           lambda m: estimation_msgs.pose_with_covariance_to_arrays(m.pose))

    @guarded('~/imu')
    def _on_imu(self, msg: Imu) -> None:
        settings = self._settings
        self._store_framed('imu', msg, self._input_frames(settings)[1], "link 2's frame",
                           lambda m: imu_reading(settings, *estimation_msgs.imu_motion(m)))

    @guarded('~/measured_wrench')
    def _on_wrench(self, msg: WrenchStamped) -> None:
        self._store_framed('measured_wrench', msg, self._input_frames(self._settings)[0],
                           self.INPUT_FRAME_NAME, estimation_msgs.wrench_stamped_to_array)

    # ------------------------------------------------------------------ diagnostics
    def _diagnostic_statuses(self, settings: Any, outputs: Any,
                             values: list[tuple[str, Any]]) -> list[Any]:
        options = self._options(settings)
        level, message = 'WARN', 'no estimate yet'
        if outputs is not None:
            values += diagnostic_values(outputs)
            level, message = diagnostic_summary(outputs)
        share = (self._consistent_estimates / self._estimates if self._estimates
                 else float('nan'))
        values += [('method', options.method), ('estimates', self._estimates),
                   ('consistent share', share),
                   ('load', options.load_mode), ('trigger', f'~/{options.trigger}'),
                   ('max age [s]', options.max_age),
                   ('consistency probability', options.consistency_probability)]
        return [conversions.diagnostic_status(
            f'{self.get_fully_qualified_name()}: estimator', level, message, values,
            hardware_id=self._output_frame(settings))]


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness estimator_node``."""
    runner.run(EstimatorNode, args)


if __name__ == '__main__':
    main()
