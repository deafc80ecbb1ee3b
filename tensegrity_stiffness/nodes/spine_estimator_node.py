"""``spine_estimator_node``'s parameters without ROS
(:mod:`tensegrity_stiffness.ros.spine_estimator_node` runs the chain estimators with them): its
table (:func:`spine_estimator_node_parameters`: the spine's and the estimator's) and its settings
(:func:`spine_estimator_node_settings`). What it does with one input is
:mod:`.estimation_processing`'s. No ROS import.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

from tensegrity_stiffness.estimation.joint_filter import DEFAULT_CHAIN_PROCESS_NOISE
from tensegrity_stiffness.nodes.estimator_node import (
    ESTIMATION_PARAMETERS,
    ESTIMATOR_NODE_PARAMETERS,
    EstimatorNodeSettings,
    estimator_node_settings,
)
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name, defaults
from tensegrity_stiffness.nodes.shared_parameters import COMMON_PARAMETERS, JOINT_PARAMETERS
from tensegrity_stiffness.nodes.spine_node import (
    SpineNodeSettings,
    spine_node_parameters,
    spine_node_settings,
)

#: Inputs of ``spine_estimator_node`` (no IMU on a spine yet): per-string arrays of every joint,
#: joint-major; ``measured_pose`` is the tool frame in the base; ``measured_wrench`` the tip load.
SPINE_ESTIMATOR_INPUTS = ('measured_tensions', 'measured_lengths', 'measured_pose',
                          'measured_wrench')


#: The filter's process noise of a spine (``ChainFilter``'s defaults,
#: :data:`~tensegrity_stiffness.estimation.joint_filter.DEFAULT_CHAIN_PROCESS_NOISE`).
SPINE_PROCESS_NOISE_PARAMETERS = tuple(
    replace(spec, default=getattr(DEFAULT_CHAIN_PROCESS_NOISE, spec.name[len('filter.'):]))
    for spec in ESTIMATION_PARAMETERS if spec.name.startswith('filter.'))


def spine_estimator_node_parameters(n_joints: int = 5) -> tuple[ParameterSpec, ...]:
    """Every parameter of ``spine_estimator_node``: the spine's (as ``spine_node``: the links'
    inertias and the strings' damping are the filter's dynamics) and the estimator's
    (``estimation.*``, ``filter.*`` with the spine's defaults, ``sensors.*``; the IMU's are not
    used)."""
    spine_noise = by_name(SPINE_PROCESS_NOISE_PARAMETERS)
    return spine_node_parameters(n_joints) + tuple(
        spine_noise.get(spec.name, spec) for spec in ESTIMATION_PARAMETERS)


@dataclass(frozen=True)
class SpineEstimatorNodeSettings(SpineNodeSettings):
    """Everything one estimate of ``spine_estimator_node`` needs, swapped as a whole: the spine's
    settings (``chain``, frames, topic-set ``rest_lengths``: :class:`SpineNodeSettings`) and
    the estimator's (``estimator``: the sensors' stds, load mode, trigger, max age)."""

    estimator: EstimatorNodeSettings = field(kw_only=True)

    @property
    def stiffness_std(self) -> bool:
        """``estimation.stiffness_std`` (as :attr:`EstimatorNodeSettings.stiffness_std`)."""
        return self.estimator.stiffness_std


def spine_estimator_node_settings(values: Mapping[str, Any], generation: int = 0
                                  ) -> SpineEstimatorNodeSettings:
    """Validate a whole parameter set of ``spine_estimator_node``; ValueError names the bad
    field (an ``estimation.trigger`` the spine has no input for among them)."""
    spine = spine_node_settings(values, generation)
    if values['estimation.trigger'] not in SPINE_ESTIMATOR_INPUTS:
        raise ValueError(f'estimation.trigger must be one of {" | ".join(SPINE_ESTIMATOR_INPUTS)}'
                         f' for a spine, got {values["estimation.trigger"]!r}')
    joint_values = {name: values[name] for name in (spec.name for spec in JOINT_PARAMETERS)}
    estimator = estimator_node_settings({
        **defaults(ESTIMATOR_NODE_PARAMETERS), **joint_values,
        **{spec.name: values[spec.name] for spec in ESTIMATION_PARAMETERS + COMMON_PARAMETERS}})
    inherited = {f.name: getattr(spine, f.name) for f in fields(SpineNodeSettings)}
    inherited['values'] = spine.values | {
        spec.name: estimator.values[spec.name] for spec in ESTIMATION_PARAMETERS}
    return SpineEstimatorNodeSettings(**inherited, estimator=estimator)
