"""``spine_estimator_node``'s parameters without ROS
(:mod:`tensegrity_stiffness.ros.spine_estimator_node` runs the chain estimators with them): its
table (:func:`spine_estimator_node_parameters`: the spine's and the estimator's) and its settings
(:func:`spine_estimator_node_settings`); and what it does with one input: the chain filter or
the static chain estimator on the readings :mod:`.estimator_node` keeps (its readings, their
freshness and the shared diagnostics), each judged on arrival (:func:`check_spine_reading`).
No ROS import.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.estimation.chain_estimator import ChainEstimate, estimate_chain_state
from tensegrity_stiffness.estimation.chain_filter import ChainFilter
from tensegrity_stiffness.estimation.joint_filter import DEFAULT_CHAIN_PROCESS_NOISE
from tensegrity_stiffness.estimation.measurements import Measurements
from tensegrity_stiffness.mechanics.chain import ChainState
from tensegrity_stiffness.mechanics.inertia import chain_link_inertias
from tensegrity_stiffness.mechanics.plausibility import (
    check_chain_translation,
    check_chain_wrench,
)
from tensegrity_stiffness.nodes.estimator_node import (
    ESTIMATION_PARAMETERS,
    ESTIMATOR_NODE_PARAMETERS,
    EstimatorInput,
    EstimatorNodeSettings,
    Reading,
    dropped_reading,
    estimator_node_settings,
    load_measurement,
    pose_reading,
    require_finite_outputs,
    require_success,
    usable_readings,
)
from tensegrity_stiffness.nodes.layouts import (
    SPINE_ESTIMATOR_OUTPUT_TABLE,
    SPINE_ESTIMATOR_STD_OUTPUT,
    flat_table_arrays,
    table_array_names,
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


FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class SpineEstimatorOutputs:
    """One spine estimate
    (:class:`~tensegrity_stiffness.estimation.chain_estimator.ChainEstimate`), the inputs used,
    every input's age (s) and whether the std of the tip stiffness was computed (else it is NaN
    and not published)."""

    estimate: ChainEstimate
    used: tuple[str, ...]
    ages: Mapping[str, float] = field(default_factory=dict)
    stiffness_std: bool = True

    @property
    def state(self) -> ChainState:
        return self.estimate.state

    @property
    def screw(self) -> tuple[FloatArray, FloatArray]:
        """The warm start of the next estimate: (screws, tip wrench)."""
        return self.estimate.screws, self.estimate.tip_wrench


#: Names of the spine's published arrays, in :func:`spine_output_arrays` order: the topics,
#: and the tip pose's covariance after the tip pose (those of
#: :data:`~tensegrity_stiffness.nodes.layouts.SPINE_ESTIMATOR_OUTPUT_TABLE`).
SPINE_OUTPUT_NAMES = table_array_names(SPINE_ESTIMATOR_OUTPUT_TABLE)


def spine_output_arrays(outputs: SpineEstimatorOutputs) -> tuple[FloatArray, ...]:
    """The published arrays in :data:`SPINE_OUTPUT_NAMES` order (the values of
    :data:`~tensegrity_stiffness.nodes.layouts.SPINE_ESTIMATOR_OUTPUT_TABLE`)."""
    return flat_table_arrays(SPINE_ESTIMATOR_OUTPUT_TABLE, outputs)


def spine_joint_measurements(settings: SpineEstimatorNodeSettings,
                             readings: Mapping[str, Reading]) -> list[Measurements | None]:
    """Each joint's :class:`Measurements` of the fresh per-string arrays (joint-major; None for
    a joint with nothing measured)."""
    options = settings.estimator
    bounds = np.cumsum([0, *settings.n_strings])
    joints: list[Measurements | None] = []
    for i in range(settings.n_joints):
        part = slice(bounds[i], bounds[i + 1])
        kw: dict[str, Any] = {}
        for name, key, std in (('measured_tensions', 'tensions', options.tension_std),
                               ('measured_lengths', 'lengths', options.length_std)):
            if name in readings:
                values = readings[name].value[part]
                if not np.all(np.isnan(values)):
                    kw.update({key: values, f'{key[:-1]}_std': std})
        joints.append(Measurements(**kw) if kw else None)
    return joints


def check_spine_reading(settings: SpineEstimatorNodeSettings, name: str, value: Any) -> None:
    """ValueError naming ``~/name`` when one reading of the spine cannot be used on its own,
    judged on arrival as :func:`~tensegrity_stiffness.nodes.estimator_node.check_reading`
    judges a joint's (issue #42: a bad reading spoils only itself, not every estimate until it
    ages out): each joint's part of a per-string array validated as that joint's estimator
    validates it (the error names the joint), a tip pose's covariance likewise and its
    translation within the spine's reach
    (:func:`~tensegrity_stiffness.mechanics.plausibility.check_chain_translation`), a tip load
    within what the weakest joint can carry (``check_chain_wrench``)."""
    try:
        if name == 'measured_wrench':
            check_chain_wrench(settings.chain, value, 'measured_wrench')
        elif name == 'measured_pose':
            transform, covariance = pose_reading(settings.estimator, {name: Reading(value, 0.0)})
            Measurements(pose=transform, pose_covariance=covariance).prepared(
                settings.n_strings[0])
            check_chain_translation(settings.chain, np.asarray(transform)[:3, 3],
                                    'measured_pose')
        else:
            for i, joint in enumerate(spine_joint_measurements(settings,
                                                               {name: Reading(value, 0.0)})):
                if joint is None:
                    continue
                try:
                    joint.prepared(settings.n_strings[i])
                except ValueError as exc:
                    raise ValueError(f'joint {i + 1}: {exc}') from None
    except ValueError as exc:
        raise dropped_reading(name, exc) from None


def new_chain_filter(settings: SpineEstimatorNodeSettings) -> ChainFilter:
    """The spine's filter of a parameter set (as :func:`new_joint_filter`): the links'
    inertias (``chain.link_inertias``), ``dynamics.string_damping``, ``filter.*``, a tip load
    that is a state unless ``estimation.external_wrench`` is 'zero'."""
    values, options = settings.values, settings.estimator
    return ChainFilter(settings.chain, chain_link_inertias(settings.chain,
                                                           values['chain.link_inertias']),
                       options.process_noise,
                       load='known' if options.load_mode == 'zero' else 'unknown',
                       string_damping=values['dynamics.string_damping'],
                       consistency_probability=options.consistency_probability,
                       stiffness_std=options.stiffness_std,
                       restart_time_budget=options.values['estimation.time_budget'])


def _spine_readings(settings: SpineEstimatorNodeSettings, snapshot: EstimatorInput
                    ) -> tuple[dict[str, Reading], dict[str, float], Any, Any, Any, Any]:
    """The fresh readings and their ages, the tip pose and its covariance, the tip load and
    its covariance of ``snapshot`` (each None when absent); ValueError when none is fresh."""
    options = settings.estimator
    readings, ages = usable_readings(snapshot, options.max_age)
    tip_pose, tip_cov = pose_reading(options, readings)
    load, load_covariance = load_measurement(options, readings)
    return readings, ages, tip_pose, tip_cov, load, load_covariance


def spine_filter_outputs(settings: SpineEstimatorNodeSettings, snapshot: EstimatorInput,
                         chain_filter: ChainFilter, stiffness_std: bool | None = None
                         ) -> SpineEstimatorOutputs:
    """``chain_filter`` stepped to ``snapshot.now`` (s) with the rest lengths in force and
    updated with the fresh readings (as :func:`spine_estimator_outputs`); ValueError as
    there."""
    options = settings.estimator
    stiffness_std = options.stiffness_std if stiffness_std is None else stiffness_std
    readings, ages, tip_pose, tip_cov, load, load_covariance = _spine_readings(settings, snapshot)
    chain_filter.stiffness_std = stiffness_std
    est = chain_filter.step(snapshot.now, spine_joint_measurements(settings, readings),
                            settings.current_rest_lengths(), tip_pose, tip_cov,
                            None if options.load_mode == 'zero' else load,
                            None if options.load_mode == 'zero' else load_covariance)
    return _checked_spine_outputs(est, snapshot, readings, ages, options.max_age,
                                  stiffness_std)


def _checked_spine_outputs(est: ChainEstimate, snapshot: EstimatorInput,
                           readings: Mapping[str, Reading], ages: Mapping[str, float],
                           max_age: float, stiffness_std: bool) -> SpineEstimatorOutputs:
    """The outputs of a successful spine estimate with finite values; ValueError otherwise."""
    require_success(est, snapshot, readings, max_age)
    outputs = SpineEstimatorOutputs(
        est, tuple(name for name in SPINE_ESTIMATOR_INPUTS if name in readings), ages,
        stiffness_std)
    require_finite_outputs(SPINE_OUTPUT_NAMES, spine_output_arrays(outputs),
                           None if stiffness_std else SPINE_ESTIMATOR_STD_OUTPUT)
    return outputs


def spine_estimator_outputs(settings: SpineEstimatorNodeSettings, snapshot: EstimatorInput,
                            stiffness_std: bool | None = None) -> SpineEstimatorOutputs:
    """The static spine estimate of the fresh readings of ``snapshot`` (per-string arrays of
    every joint, joint-major; ``measured_pose`` the tool frame in the base;
    ``measured_wrench`` the tip load), with the std of the tip stiffness when
    ``stiffness_std`` (None: the settings'); ValueError (nothing is published) as
    :func:`estimator_outputs`."""
    options = settings.estimator
    stiffness_std = options.stiffness_std if stiffness_std is None else stiffness_std
    readings, ages, tip_pose, tip_cov, load, load_covariance = _spine_readings(settings, snapshot)
    initial_screws = initial_wrench = None
    if snapshot.initial_screw is not None:
        initial_screws, initial_wrench = snapshot.initial_screw
    est = estimate_chain_state(
        settings.chain, spine_joint_measurements(settings, readings), tip_pose, tip_cov, load,
        load_covariance, rest_lengths=settings.current_rest_lengths(),
        initial_screws=initial_screws, initial_tip_wrench=initial_wrench,
        stiffness_std=stiffness_std, consistency_probability=options.consistency_probability,
        time_budget=options.values['estimation.time_budget'])
    return _checked_spine_outputs(est, snapshot, readings, ages, options.max_age,
                                  stiffness_std)
