"""``spine_estimator_node``: every joint's screw, the tip load, the tip pose and the exact tip
stiffness of a spine with their uncertainty, estimated from per-joint load cells or string
lengths, a motion-capture tip pose or a force-torque reading of the tip load.

:class:`.EstimatorNode` on a :class:`~tensegrity_stiffness.mechanics.chain.JointChain`: the same
inputs and triggering (``~/measured_tensions`` / ``~/measured_lengths`` hold every joint's
strings, joint-major, NaN = not measured; ``~/measured_pose`` is the tool frame in the base;
``~/measured_wrench`` the tip load in the base; no IMU), the library's
:class:`~tensegrity_stiffness.estimation.chain_filter.ChainFilter` (``estimation.method:
filter``, the default: on the spine's dynamics) or
:func:`~tensegrity_stiffness.estimation.chain_estimator.estimate_chain_state` (``static``: the
equilibria exact, the tip load shared by every joint, warm-started from the last estimate).
The spine's parameters and ``~/rest_lengths`` are ``spine_node``'s; the estimator's are
``estimator_node``'s.
"""

from __future__ import annotations

from operator import attrgetter
from typing import Any

import numpy as np
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.mechanics.chain import solve_chain_equilibrium
from tensegrity_stiffness.nodes.estimator_node import EstimatorInput, EstimatorNodeSettings
from tensegrity_stiffness.nodes.layouts import (
    SPINE_ESTIMATOR_STD_OUTPUT,
    spine_estimator_output_layouts,
)
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.spine_estimator_node import (
    SpineEstimatorNodeSettings,
    SpineEstimatorOutputs,
    check_spine_reading,
    new_chain_filter,
    spine_estimator_node_parameters,
    spine_estimator_node_settings,
    spine_estimator_outputs,
    spine_filter_outputs,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.conversions import estimation as estimation_msgs
from tensegrity_stiffness.ros.conversions.outputs import output_topics
from tensegrity_stiffness.ros.estimator_node import EstimatorNode
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.node_base import Stream
from tensegrity_stiffness.ros.runtime.rest_length_topics import SpineRestLengthTopic
from tensegrity_stiffness.ros.runtime.tf_broadcast import SpineFrames
from tensegrity_stiffness.ros.spine_node import declared_joint_count

NODE_NAME = 'spine_estimator_node'


class SpineEstimatorNode(SpineFrames, SpineRestLengthTopic, EstimatorNode):
    """Publishes the screws, the tip pose (with covariance), the tip load, the tip stiffness
    with its std and the tip stiffness stamped (``msg/StampedMatrix``) per estimate
    (:data:`~tensegrity_stiffness.nodes.layouts.SPINE_ESTIMATOR_OUTPUT_TABLE`); markers and
    diagnostics."""

    OUTPUT_TOPICS = output_topics(spine_estimator_output_layouts(1))
    STIFFNESS_STD_OUTPUT = f'~/{SPINE_ESTIMATOR_STD_OUTPUT}'
    INPUT_FRAME_NAME = 'the base frame'
    _build_settings = staticmethod(spine_estimator_node_settings)
    _check_reading = staticmethod(check_spine_reading)
    _output_frame = attrgetter('base_frame')
    _settings: SpineEstimatorNodeSettings
    # The spine's rest lengths are kept and set as spine_node's (settings.rest_lengths).

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)

    def _warm_up(self, settings: SpineEstimatorNodeSettings) -> tuple[Any, tuple, str]:
        options = settings.estimator
        return (solve_chain_equilibrium, (settings.chain, np.zeros(6)),
                f'{settings.n_joints} joints, {options.method} estimator, load '
                f'{options.load_mode}, trigger ~/{options.trigger}, max age '
                f'{options.max_age:g} s')

    def _options(self, settings: SpineEstimatorNodeSettings) -> EstimatorNodeSettings:
        return settings.estimator

    def _string_count(self, settings: SpineEstimatorNodeSettings) -> int:
        return sum(settings.n_strings)

    def _input_frames(self, settings: SpineEstimatorNodeSettings) -> tuple[str, str]:
        return settings.base_frame, ''

    # ------------------------------------------------------------------ declarations
    def _parameter_table(self) -> tuple[ParameterSpec, ...]:
        return spine_estimator_node_parameters(declared_joint_count(self))

    def _streams(self) -> tuple[Stream, ...]:
        return tuple(stream for stream in super()._streams() if stream[1] != '~/imu')

    def _output_messages(self, settings: SpineEstimatorNodeSettings
                         ) -> estimation_msgs.SpineEstimatorOutputMessages:
        return estimation_msgs.SpineEstimatorOutputMessages(settings.n_joints)

    def _outputs(self, settings: SpineEstimatorNodeSettings, snapshot: EstimatorInput,
                 wanted: tuple[bool, ...]) -> SpineEstimatorOutputs:
        # the std of the tip stiffness only when it is wanted (EstimatorNode._wanted_outputs)
        std = wanted[self.stiffness_std_index()]
        if settings.estimator.method == 'filter':
            if self._track is None:
                self._track = new_chain_filter(settings)
            outputs = spine_filter_outputs(settings, snapshot, self._track, std)
        else:
            outputs = spine_estimator_outputs(settings, snapshot, std)
        self._count(outputs)
        return outputs

    def _markers(self, settings: SpineEstimatorNodeSettings, state: Any, stamp: Any
                 ) -> MarkerArray:
        return conversions.spine_markers(settings.chain, state, settings.base_frame, stamp)


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness spine_estimator_node``."""
    runner.run(SpineEstimatorNode, args)


if __name__ == '__main__':
    main()
