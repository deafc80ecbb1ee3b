"""``estimator_node``'s parameters without ROS (:mod:`tensegrity_stiffness.ros.estimator_node`
runs the estimators with them): its table (:data:`ESTIMATOR_NODE_PARAMETERS`: the shared joint,
frame and common sections, ``estimation.*``, ``filter.*`` and ``sensors.*``) and its settings
(:func:`estimator_node_settings`); and what it does with its inputs: the latest reading of each
sensor, the choice of those fresh enough for an estimate, the
:class:`~tensegrity_stiffness.estimation.measurements.Measurements` they make with the node's
settings, and the outputs of one estimate: of the recursive filter (``estimation.method:
filter``, :class:`~tensegrity_stiffness.estimation.joint_filter.JointFilter`, one
:func:`new_joint_filter` per parameter set, stepped by :func:`filter_outputs`) or of the static
estimator (``static``, :func:`estimator_outputs`). Decoding a message into numbers is
:mod:`tensegrity_stiffness.ros.conversions.estimation`'s part; this module takes the numbers
(and the time each arrived, ``time.monotonic`` seconds). No ROS import.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.joint_estimator import JointEstimate, estimate_joint_state
from tensegrity_stiffness.estimation.joint_filter import (
    DEFAULT_GRAVITY,
    DEFAULT_PROCESS_NOISE,
    JointFilter,
    ProcessNoise,
)
from tensegrity_stiffness.estimation.measurements import Measurements
from tensegrity_stiffness.estimation.trust import CONSISTENCY_PROBABILITY
from tensegrity_stiffness.geometry.validation import require_all_finite
from tensegrity_stiffness.mechanics.joint import JointModel, JointState
from tensegrity_stiffness.mechanics.plausibility import check_translation, check_wrench
from tensegrity_stiffness.nodes.layouts import (
    ESTIMATOR_OUTPUT_TABLE,
    ESTIMATOR_STD_OUTPUT,
    flat_table_arrays,
    table_array_names,
)
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
    link2_inertia_from_values,
    marker_period,
)

if TYPE_CHECKING:
    from tensegrity_stiffness.estimation.chain_estimator import ChainEstimate
    from tensegrity_stiffness.nodes.spine_estimator_node import SpineEstimatorOutputs

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
                       'moment_rate': 'N m/s sqrt(s)', 'rest_rate': 'm/s', 'hold_fraction': '1'}
#: What the process noise's fields that are not densities say (the accelerations' rule,
#: ProcessNoise's docstring).
_PROCESS_NOISE_RULE = {
    'rest_rate': 'process noise of the filter: the RMS rate of the rest lengths at which the '
                 'acceleration densities are filter.angular_acceleration / linear_acceleration '
                 '(their variance scales with (rate / rest_rate)^2); 0: constant densities, m/s',
    'hold_fraction': 'process noise of the filter: the part of the acceleration variance '
                     'densities kept while the rest lengths hold'}

ESTIMATION_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('estimation.method', 'string', 'filter',
                  "'filter' (recursive, on the joint's dynamics: a moving joint) or 'static' "
                  '(each reading set on its own, the joint at rest); docs/estimation.md',
                  choices=ESTIMATION_METHODS),
    *(ParameterSpec(f'filter.{name}', 'double', getattr(DEFAULT_PROCESS_NOISE, name),
                    _PROCESS_NOISE_RULE.get(name, f'process noise of the filter: '
                                            f'{name.replace("_", " ")} density, {unit}'),
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
    # Its own budget, not equilibrium.time_budget's 0.05 s: a structure's cold fit takes up to
    # 30 iterations of about 2 ms, so a node starved of CPU would fail ordinary estimates.
    ParameterSpec('estimation.time_budget', 'double', 0.5,
                  "wall-clock budget of one 'static' estimate (its fits and refits), s: past "
                  "its first iterations, which it never cuts short, the estimate fails with "
                  "'time budget exhausted'", range=(1e-4, 10.0)),
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



FloatArray = NDArray[np.float64]

#: Standard gravity (m/s^2): an accelerometer at rest reads this much specific force.
STANDARD_GRAVITY = 9.80665


@dataclass(frozen=True)
class Reading:
    """One decoded input: ``value`` (see :data:`READING_FORMATS`) and when it arrived
    (``time.monotonic`` s)."""

    value: Any
    received: float


#: The value of each input's :class:`Reading`.
READING_FORMATS = {
    'measured_tensions': '(n,) N, NaN where not measured',
    'measured_lengths': '(n,) m, NaN where not measured',
    'measured_pose': '((4, 4) transform of {2} in {1}, (6, 6) covariance or None)',
    'imu': "(3,) unit direction of gravity in {2} ('static'), an ImuReading ('filter')",
    'measured_wrench': '(6,) [N; N m] on link 2 in {1} about its origin',
}


@dataclass(frozen=True)
class EstimatorInput:
    """What one estimate starts from: the latest reading of each input (absent ones left out),
    the time the estimate was triggered and the warm start (the last estimate's screw)."""

    readings: Mapping[str, Reading]
    now: float
    initial_screw: FloatArray | None = None


def measured_array(values: FloatArray, n: int, name: str, require_any: bool = True
                   ) -> FloatArray:
    """A per-string reading: ``n`` values, finite or NaN (not measured), at least one measured
    when ``require_any``; ValueError naming ``name`` otherwise. The one check of measured
    arrays, for the estimators' topics and the calibration's recordings."""
    arr = np.asarray(values, dtype=np.float64)
    if arr.shape != (n,):
        raise ValueError(f'{name}: expected {n} values (one per string, NaN = not measured), '
                         f'got {arr.size}')
    if np.any(np.isinf(arr)):
        raise ValueError(f'{name}: values must be finite or NaN (not measured), got inf')
    if require_any and np.all(np.isnan(arr)):
        raise ValueError(f'{name}: every value is NaN (nothing measured)')
    return arr


def gravity_reading(specific_force: FloatArray, tolerance: float) -> FloatArray:
    """The direction of gravity in link 2 from an accelerometer's specific force at rest;
    ValueError when its magnitude differs from :data:`STANDARD_GRAVITY` by more than
    ``tolerance`` (m/s^2): the link is accelerating."""
    a = np.asarray(specific_force, dtype=np.float64)
    norm = float(np.linalg.norm(a))
    if not abs(norm - STANDARD_GRAVITY) <= tolerance:
        raise ValueError(f'specific force of {norm:.3f} m/s^2 is not {STANDARD_GRAVITY} within '
                         f'{tolerance} m/s^2: the link is not at rest')
    return sm.gravity_from_specific_force(a)


@dataclass(frozen=True)
class ImuReading:
    """An IMU's raw reading for the filter: ``specific_force`` (3,) m/s^2 and, with a gyro,
    ``angular_velocity`` (3,) rad/s (else None), both in link 2's frame."""

    specific_force: FloatArray
    angular_velocity: FloatArray | None


def imu_reading(settings: EstimatorNodeSettings, specific_force: FloatArray,
                angular_velocity: FloatArray | None) -> FloatArray | ImuReading:
    """The value of an ``~/imu`` :class:`Reading` under ``settings.method``: the raw reading for
    the filter (its accelerometer is modelled with the link's acceleration), the direction of
    gravity for the static estimator (ValueError when the link is not at rest:
    :func:`gravity_reading`)."""
    if settings.method == 'filter':
        return ImuReading(np.asarray(specific_force, dtype=np.float64), None
                          if angular_velocity is None else
                          np.asarray(angular_velocity, dtype=np.float64))
    return gravity_reading(specific_force, settings.imu_rest_tolerance)


def fresh_readings(snapshot: EstimatorInput, max_age: float
                   ) -> tuple[dict[str, Reading], dict[str, float]]:
    """(readings no older than ``max_age``, the age of every reading in s)."""
    ages = {name: snapshot.now - r.received for name, r in snapshot.readings.items()}
    return {name: r for name, r in snapshot.readings.items() if ages[name] <= max_age}, ages


def usable_readings(snapshot: EstimatorInput, max_age: float
                     ) -> tuple[dict[str, Reading], dict[str, float]]:
    """:func:`fresh_readings`; ValueError when none is fresh."""
    readings, ages = fresh_readings(snapshot, max_age)
    if not readings:
        raise ValueError('no input within estimation.max_age')
    return readings, ages


def require_success(est: JointEstimate | ChainEstimate, snapshot: EstimatorInput,
                     readings: Mapping[str, Reading], max_age: float) -> None:
    """ValueError with the estimate's message (and the inputs left out as stale) when it
    failed."""
    if est.success:
        return
    stale = sorted(set(snapshot.readings) - set(readings))
    left_out = f' (left out as older than {max_age:g} s: {", ".join(stale)})' if stale else ''
    raise ValueError(f'no estimate: {est.message}{left_out}')


def pose_reading(settings: EstimatorNodeSettings, readings: Mapping[str, Reading]
                 ) -> tuple[FloatArray | None, FloatArray | None]:
    """(transform, covariance) of the fresh ``measured_pose`` (None, None when absent); a
    message without a covariance gets the settings' pose stds."""
    if 'measured_pose' not in readings:
        return None, None
    transform, covariance = readings['measured_pose'].value
    if covariance is None:
        covariance = np.diag([settings.pose_position_std ** 2] * 3
                             + [settings.pose_angle_std ** 2] * 3)
    return transform, covariance


def measurements(settings: EstimatorNodeSettings, readings: Mapping[str, Reading]
                 ) -> Measurements:
    """The :class:`Measurements` of the fresh ``readings`` under ``settings`` (the sensors'
    stds, the direction of gravity, the load mode); ValueError when the load is 'measured' and
    no fresh ``measured_wrench`` is there."""
    W, covariance = load_measurement(settings, readings)
    return Measurements(**sensor_measurements(settings, readings), external_wrench=W,
                        wrench_covariance=covariance)


def dropped_reading(name: str, exc: ValueError) -> ValueError:
    """The error of a reading on ``~/name`` judged unusable on arrival (:func:`check_reading`,
    a spine's ``check_spine_reading``): the input named, the reading dropped."""
    return ValueError(f'~/{name}: {exc} (this reading dropped, the others kept)')


def check_reading(settings: EstimatorNodeSettings, name: str, value: Any) -> None:
    """ValueError naming ``~/name`` when one reading cannot be used on its own (issue #42: a bad
    reading spoils only itself, it is dropped at arrival instead of failing every estimate
    until it ages out): validated as the estimator validates it (lengths > 0, a symmetric
    positive definite pose covariance, ...) and, for a pose, within the joint's reach
    (:func:`~tensegrity_stiffness.mechanics.plausibility.check_translation`), for a wrench
    within its strings' capacity (``check_wrench``). A spine's readings:
    :func:`~tensegrity_stiffness.nodes.spine_estimator_node.check_spine_reading`."""
    model = settings.model
    try:
        if name == 'measured_wrench':
            check_wrench(model, value, 'measured_wrench')
            return
        kw = sensor_measurements(settings, {name: Reading(value, 0.0)})
        Measurements(**kw).prepared(model.n_strings)
        if name == 'measured_pose':
            check_translation(model, np.asarray(value[0])[:3, 3], 'measured_pose')
    except ValueError as exc:
        raise dropped_reading(name, exc) from None


def sensor_measurements(settings: EstimatorNodeSettings, readings: Mapping[str, Reading]
                        ) -> dict[str, Any]:
    """The keyword arguments of :class:`Measurements` of the sensors among ``readings`` (the
    load apart: :func:`load_measurement`)."""
    kw: dict[str, Any] = {}
    if 'measured_tensions' in readings:
        kw.update(tensions=readings['measured_tensions'].value, tension_std=settings.tension_std)
    if 'measured_lengths' in readings:
        kw.update(lengths=readings['measured_lengths'].value, length_std=settings.length_std)
    transform, covariance = pose_reading(settings, readings)
    if transform is not None:
        kw.update(pose=transform, pose_covariance=covariance)
    if 'imu' in readings:
        imu = readings['imu'].value
        if isinstance(imu, ImuReading):
            kw.update(specific_force=imu.specific_force,
                      specific_force_std=settings.accelerometer_std)
            if imu.angular_velocity is not None:
                kw.update(angular_velocity=imu.angular_velocity,
                          angular_velocity_std=settings.gyro_std)
        else:
            kw.update(gravity=imu, gravity_std=settings.gravity_std,
                      gravity_base=settings.gravity_base)
    return kw


def load_measurement(settings: EstimatorNodeSettings, readings: Mapping[str, Reading]
                     ) -> tuple[FloatArray | None, FloatArray | None]:
    """(wrench, covariance) of the load under ``estimation.external_wrench``: (None, None) when
    unknown, zero or the fresh ``measured_wrench`` with the force-torque stds; ValueError when
    'measured' and none is fresh."""
    if settings.load_mode == 'unknown':
        return None, None
    covariance = np.diag([settings.force_std ** 2] * 3 + [settings.moment_std ** 2] * 3)
    if settings.load_mode == 'zero':
        return np.zeros(6), covariance
    if 'measured_wrench' not in readings:
        raise ValueError("estimation.external_wrench is 'measured' but no ~/measured_wrench "
                         'arrived within estimation.max_age')
    return readings['measured_wrench'].value, covariance


@dataclass(frozen=True)
class EstimatorOutputs:
    """One estimate and what the node publishes of it: ``estimate`` (:class:`JointEstimate`),
    ``state`` (the joint at the estimate, for the markers), the inputs used, every input's
    age (s) and whether the std of K_c was computed (else it is NaN and not published)."""

    estimate: JointEstimate
    used: tuple[str, ...]
    ages: Mapping[str, float] = field(default_factory=dict)
    stiffness_std: bool = True

    @property
    def state(self) -> JointState:
        return self.estimate.state

    @property
    def screw(self) -> FloatArray:
        return self.estimate.screw


#: Names of the published arrays, in :func:`output_arrays` order: the topics, and the pose's
#: covariance after the pose (those of
#: :data:`~tensegrity_stiffness.nodes.layouts.ESTIMATOR_OUTPUT_TABLE`).
OUTPUT_NAMES = table_array_names(ESTIMATOR_OUTPUT_TABLE)


def output_arrays(outputs: EstimatorOutputs) -> tuple[FloatArray, ...]:
    """The published arrays in :data:`OUTPUT_NAMES` order (the values of
    :data:`~tensegrity_stiffness.nodes.layouts.ESTIMATOR_OUTPUT_TABLE`)."""
    return flat_table_arrays(ESTIMATOR_OUTPUT_TABLE, outputs)


def require_finite_outputs(names: Sequence[str], arrays: Sequence[FloatArray],
                           std_output: str | None) -> None:
    """ValueError naming the first of ``arrays`` (named by ``names``) that is not finite,
    leaving out the one named ``std_output`` (a std not computed: NaN; None: none left out)."""
    if std_output is None or std_output not in names:
        require_all_finite(names, arrays)
        return
    kept = [i for i, name in enumerate(names) if name != std_output]
    require_all_finite([names[i] for i in kept], [arrays[i] for i in kept])


def estimator_outputs(settings: EstimatorNodeSettings, snapshot: EstimatorInput,
                      stiffness_std: bool | None = None) -> EstimatorOutputs:
    """The static estimate of the fresh readings of ``snapshot``, with the std of K_c when
    ``stiffness_std`` (None: ``settings.stiffness_std``; else NaN); ValueError (nothing is
    published) when the inputs are bad, the set cannot determine the pose (the message names
    what is missing), the estimate does not converge or runs past ``estimation.time_budget``
    ('time budget exhausted ...') or an output is not finite."""
    if stiffness_std is None:
        stiffness_std = settings.stiffness_std
    readings, ages = usable_readings(snapshot, settings.max_age)
    est = estimate_joint_state(settings.model, measurements(settings, readings),
                               initial_screw=snapshot.initial_screw,
                               stiffness_std=stiffness_std,
                               consistency_probability=settings.consistency_probability,
                               time_budget=settings.values['estimation.time_budget'])
    return _checked_outputs(est, snapshot, readings, ages, settings.max_age, stiffness_std)


def new_joint_filter(settings: EstimatorNodeSettings) -> JointFilter:
    """The filter of a parameter set (a new one, without a track, after every parameter
    change): link 2's inertia (``joint.link2_*``), ``dynamics.string_damping``, ``filter.*``
    (the process noise), a load that is a state unless ``estimation.external_wrench`` is
    'zero' (then known: zero; 'measured' updates the state with ``~/measured_wrench``), the
    accelerometer's gravity along ``sensors.gravity_base``."""
    values = settings.values
    direction = np.asarray(settings.gravity_base, dtype=np.float64)
    gravity = float(np.linalg.norm(DEFAULT_GRAVITY)) * direction / np.linalg.norm(direction)
    return JointFilter(settings.model, link2_inertia_from_values(values),
                       settings.process_noise,
                       load='known' if settings.load_mode == 'zero' else 'unknown',
                       string_damping=values['dynamics.string_damping'], gravity=gravity,
                       consistency_probability=settings.consistency_probability,
                       stiffness_std=settings.stiffness_std,
                       restart_time_budget=values['estimation.time_budget'])


def filter_outputs(settings: EstimatorNodeSettings, snapshot: EstimatorInput,
                   joint_filter: JointFilter, stiffness_std: bool | None = None
                   ) -> EstimatorOutputs:
    """``joint_filter`` stepped to ``snapshot.now`` (s) with the rest lengths in force
    (``settings.model``'s) and updated with the fresh readings of ``snapshot``; the std of K_c
    as :func:`estimator_outputs`; ValueError (nothing is published) as there."""
    if stiffness_std is None:
        stiffness_std = settings.stiffness_std
    readings, ages = usable_readings(snapshot, settings.max_age)
    joint_filter.stiffness_std = stiffness_std
    est = joint_filter.step(snapshot.now, measurements(settings, readings),
                            settings.model.rest_lengths)
    return _checked_outputs(est, snapshot, readings, ages, settings.max_age, stiffness_std)


def _checked_outputs(est: JointEstimate, snapshot: EstimatorInput,
                     readings: Mapping[str, Reading], ages: Mapping[str, float],
                     max_age: float, stiffness_std: bool) -> EstimatorOutputs:
    """The outputs of a successful estimate with finite values; ValueError otherwise."""
    require_success(est, snapshot, readings, max_age)
    outputs = EstimatorOutputs(est, tuple(name for name in ESTIMATOR_INPUTS if name in readings),
                               ages, stiffness_std)
    require_finite_outputs(OUTPUT_NAMES, output_arrays(outputs),
                           None if stiffness_std else ESTIMATOR_STD_OUTPUT)
    return outputs


def diagnostic_values(outputs: EstimatorOutputs | SpineEstimatorOutputs
                      ) -> list[tuple[str, Any]]:
    """``(key, value)`` pairs of the last estimate (a joint's or a spine's) for /diagnostics."""
    est = outputs.estimate
    ratio = est.chi2 / est.dof if est.dof > 0 else math.nan
    values: list[tuple[str, Any]] = [
        ('chi2', est.chi2), ('dof', est.dof), ('chi2/dof', ratio),
        ('observable', est.observable), ('rank', est.rank),
        ('condition number', est.condition_number), ('iterations', est.iterations),
        ('inputs used', ', '.join(outputs.used)),
    ]
    values += [(f'age of {name} [ms]', 1e3 * age) for name, age in sorted(outputs.ages.items())]
    values += [('consistent', 'none (no redundancy)' if est.consistent is None
                else est.consistent),
               ('redundancy', est.redundancy),
               ('outliers', ', '.join(est.outliers) or 'none'),
               *((f'left out: {reason.partition(": ")[0]}', reason.partition(': ')[2])
                 for reason in est.outlier_reasons),
               ('cold restart', est.restarted)]
    return values


def diagnostic_summary(outputs: EstimatorOutputs | SpineEstimatorOutputs
                       ) -> tuple[str, str]:
    """(level, message) of the last estimate for /diagnostics: WARN when it is inconsistent
    or left a reading out (the message names them), OK otherwise; without redundancy the
    message says that the readings cannot check themselves."""
    est = outputs.estimate
    message = (f'estimating from {", ".join(outputs.used)}; chi2/dof {est.chi2:.3g}/{est.dof}, '
               f'rank {est.rank}')
    return trust_level(message, est.outliers, est.consistent)


def trust_level(message: str, outliers: Sequence[str], consistent: bool | None
                ) -> tuple[str, str]:
    """(level, message) of an estimate's trust, for every estimator node: WARN when it left
    ``outliers`` out (named) or is not ``consistent``, OK otherwise; ``consistent`` None (no
    redundancy) is said in the message."""
    level = 'OK'
    if outliers:
        level = 'WARN'
        message += f'; left out {", ".join(outliers)}'
    if consistent is False:
        level = 'WARN'
        message += '; inconsistent: the readings contradict each other'
    elif consistent is None:
        message += '; no redundancy: the readings cannot check themselves'
    return level, message


# ---------------------------------------------------------------------------------- spines
