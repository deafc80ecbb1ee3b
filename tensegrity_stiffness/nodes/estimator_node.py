"""``estimator_node``'s parameters without ROS (:mod:`tensegrity_stiffness.ros.estimator_node`
runs the estimators with them): its table (:data:`ESTIMATOR_NODE_PARAMETERS`: the shared joint,
frame and common sections, ``estimation.*``, ``filter.*`` and ``sensors.*``) and its settings
(:func:`estimator_node_settings`). What it does with one input is
:mod:`.estimation_processing`'s. No ROS import.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from tensegrity_stiffness.estimation.estimators import CONSISTENCY_PROBABILITY
from tensegrity_stiffness.estimation.joint_filter import DEFAULT_PROCESS_NOISE, ProcessNoise
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.shared_parameters import (
    COMMON_PARAMETERS,
    FRAME_PARAMETERS,
    JOINT_DYNAMICS_PARAMETERS,
    JOINT_PARAMETERS,
    LINK2_PARAMETERS,
    REST_LENGTH_OFFSET_PARAMETERS,
    TF_PARAMETERS,
    joint_from_values,
    marker_period,
)

#: What ``estimator_node`` assumes about the external load (``estimation.external_wrench``).
LOAD_MODES = ('unknown', 'zero', 'measured')
#: Inputs of ``estimator_node`` by the name ``estimation.trigger`` gives them (topic ``~/<name>``).
ESTIMATOR_INPUTS = ('measured_tensions', 'measured_lengths', 'measured_pose', 'imu',
                    'measured_wrench')

#: What ``estimation.method`` selects: the recursive filter on the joint's dynamics
#: (:class:`~tensegrity_stiffness.estimation.joint_filter.JointFilter`) or the quasi-static
#: estimate of each reading set
#: (:func:`~tensegrity_stiffness.estimation.joint_estimator.estimate_joint_state`).
ESTIMATION_METHODS = ('filter', 'static')
#: The filter's process noise densities, by parameter (``filter.<field>``: the fields of
#: :class:`~tensegrity_stiffness.estimation.joint_filter.ProcessNoise`, whose defaults are the
#: one home).
PROCESS_NOISE_UNITS = {'angular_acceleration': 'rad/s^2 sqrt(s)',
                       'linear_acceleration': 'm/s^2 sqrt(s)', 'force_rate': 'N/s sqrt(s)',
                       'moment_rate': 'N m/s sqrt(s)'}

ESTIMATION_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('estimation.method', 'string', 'filter',
                  "'filter' (recursive, on the joint's dynamics: a moving joint) or 'static' "
                  '(each reading set on its own, the joint at rest); docs/estimation.md',
                  choices=ESTIMATION_METHODS),
    *(ParameterSpec(f'filter.{name}', 'double', getattr(DEFAULT_PROCESS_NOISE, name),
                    f'process noise of the filter: {name.replace("_", " ")} density, {unit}',
                    range=(0.0, 1e9)) for name, unit in PROCESS_NOISE_UNITS.items()),
    ParameterSpec('estimation.external_wrench', 'string', 'unknown',
                  "the load on link 2: 'unknown' (estimated, W = -F), 'zero' (unloaded, to "
                  "sensors.force_std / moment_std) or 'measured' (~/measured_wrench)",
                  choices=LOAD_MODES),
    ParameterSpec('estimation.trigger', 'string', 'measured_tensions',
                  'the input whose messages trigger an estimate (with the latest of the others '
                  'no older than estimation.max_age)', choices=ESTIMATOR_INPUTS),
    ParameterSpec('estimation.max_age', 'double', 0.05,
                  'inputs older than this (s, by arrival) are left out of an estimate',
                  range=(0.0, 3600.0)),
    ParameterSpec('estimation.consistency_probability', 'double', CONSISTENCY_PROBABILITY,
                  'probability of the chi-square test of each estimate (consistent: False when '
                  'its chi2 exceeds the 1 - p quantile; contradicted readings are then left out '
                  'while redundancy remains)', range=(1e-15, 0.5)),
    ParameterSpec('estimation.stiffness_std', 'bool', True,
                  'publish the first-order std of the stiffness (~/cartesian_stiffness_std; the '
                  "spine's ~/tip_stiffness_base_std), computed only while it has a subscriber"),
    ParameterSpec('sensors.tension_std', 'double', 0.005, 'load cells: tension std, N',
                  range=(1e-12, 1e6)),
    ParameterSpec('sensors.length_std', 'double', 1e-4, 'string length sensors: std, m',
                  range=(1e-12, 1e3)),
    ParameterSpec('sensors.gravity_std', 'double', 0.01,
                  'IMU: std of each component of the measured gravity direction (unit vector)',
                  range=(1e-9, 1.0)),
    ParameterSpec('sensors.gravity_base', 'double_array', [0.0, -1.0, 0.0],
                  'direction of gravity in {1} (3 values; normalised)'),
    ParameterSpec('sensors.imu_rest_tolerance', 'double', 1.0,
                  "estimation.method 'static': an ~/imu reading whose specific force differs "
                  'from 9.81 m/s^2 by more than this (m/s^2) is not at rest and is rejected',
                  range=(0.0, 1e3)),
    ParameterSpec('sensors.accelerometer_std', 'double', 0.0981,
                  "estimation.method 'filter': accelerometer std of each component, m/s^2 "
                  '(modelled with the link\'s acceleration)', range=(1e-9, 1e3)),
    ParameterSpec('sensors.gyro_std', 'double', 0.01,
                  "estimation.method 'filter': gyro std of each component, rad/s (an ~/imu "
                  'whose angular_velocity_covariance[0] is -1 has no gyro)',
                  range=(1e-9, 1e3)),
    ParameterSpec('sensors.pose_position_std', 'double', 1e-4,
                  'motion capture position std, m, used when ~/measured_pose carries no '
                  'covariance (all zeros)', range=(1e-12, 1e3)),
    ParameterSpec('sensors.pose_angle_std', 'double', 0.0017453292519943296,
                  'motion capture angle std, rad, used when ~/measured_pose carries no '
                  'covariance', range=(1e-12, 10.0)),
    ParameterSpec('sensors.force_std', 'double', 0.01,
                  'force-torque sensor force std, N (also the tolerance of a zero load)',
                  range=(1e-12, 1e6)),
    ParameterSpec('sensors.moment_std', 'double', 0.0005,
                  'force-torque sensor moment std, N m (also the tolerance of a zero load)',
                  range=(1e-12, 1e6)),
)

#: Every parameter of ``estimator_node``, in declaration order (link 2's inertia and the
#: strings' damping: the filter's dynamics).
ESTIMATOR_NODE_PARAMETERS: tuple[ParameterSpec, ...] = (
    JOINT_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + FRAME_PARAMETERS + TF_PARAMETERS
    + ESTIMATION_PARAMETERS + COMMON_PARAMETERS + LINK2_PARAMETERS
    + (JOINT_DYNAMICS_PARAMETERS[-1],))


@dataclass(frozen=True)
class EstimatorNodeSettings:
    """Everything one estimate of ``estimator_node`` needs, swapped as a whole (never mutated):
    built from a complete set of parameter values by :func:`estimator_node_settings`."""

    model: JointModel
    link1_frame: str
    link2_frame: str
    load_mode: str
    trigger: str
    method: str
    process_noise: ProcessNoise
    accelerometer_std: float
    gyro_std: float
    max_age: float
    stiffness_std: bool
    consistency_probability: float
    tension_std: float
    length_std: float
    gravity_std: float
    gravity_base: tuple[float, float, float]
    imu_rest_tolerance: float
    pose_position_std: float
    pose_angle_std: float
    force_std: float
    moment_std: float
    max_array_length: int
    marker_period: float
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)


def estimator_node_settings(values: Mapping[str, Any], generation: int = 0
                            ) -> EstimatorNodeSettings:
    """Validate a whole parameter set of ``estimator_node`` and build its settings; ValueError
    names the bad field. Every parameter of the table must be in ``values``."""
    checked = {spec.name: spec.check(values[spec.name]) for spec in ESTIMATOR_NODE_PARAMETERS}
    for name in ('frames.link1', 'frames.link2'):
        if not checked[name].strip():
            raise ValueError(f'{name} must not be empty')
    base = checked['sensors.gravity_base']
    if len(base) != 3 or not all(math.isfinite(v) for v in base) or math.hypot(*base) < 1e-9:
        raise ValueError(f'sensors.gravity_base must be 3 finite values, not all zero, got '
                         f'{base}')
    return EstimatorNodeSettings(
        model=joint_from_values(checked), link1_frame=checked['frames.link1'],
        link2_frame=checked['frames.link2'],
        load_mode=checked['estimation.external_wrench'], trigger=checked['estimation.trigger'],
        method=checked['estimation.method'],
        process_noise=ProcessNoise(**{name: checked[f'filter.{name}']
                                      for name in PROCESS_NOISE_UNITS}),
        accelerometer_std=checked['sensors.accelerometer_std'],
        gyro_std=checked['sensors.gyro_std'], max_age=checked['estimation.max_age'],
        stiffness_std=checked['estimation.stiffness_std'],
        consistency_probability=checked['estimation.consistency_probability'],
        tension_std=checked['sensors.tension_std'], length_std=checked['sensors.length_std'],
        gravity_std=checked['sensors.gravity_std'],
        gravity_base=(float(base[0]), float(base[1]), float(base[2])),
        imu_rest_tolerance=checked['sensors.imu_rest_tolerance'],
        pose_position_std=checked['sensors.pose_position_std'],
        pose_angle_std=checked['sensors.pose_angle_std'],
        force_std=checked['sensors.force_std'], moment_std=checked['sensors.moment_std'],
        max_array_length=checked['limits.max_array_length'],
        marker_period=marker_period(checked['markers.max_rate']),
        generation=generation, values=checked)

