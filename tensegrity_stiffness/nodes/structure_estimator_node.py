"""The ROS-free half of ``structure_estimator_node`` (every body's pose of a structure with its
covariance, from what the robot measures; the rclpy node is
:mod:`tensegrity_stiffness.ros.structure_estimator_node`): its parameter table and settings, the
:class:`~tensegrity_stiffness.estimation.structure_estimator.StructureMeasurements` of the latest
readings, one estimate (``estimation.method``: ``static``, each reading set on its own with
:func:`~tensegrity_stiffness.estimation.structure_estimator.estimate_structure_poses`, or
``filter``, the recursive
:class:`~tensegrity_stiffness.estimation.structure_estimator.StructureFilter`), the outputs of it
(the structure node's at the estimated poses:
:func:`tensegrity_stiffness.nodes.structure_node.structure_outputs`), their names and layouts, and
the values of its ``/diagnostics`` and ``~/trust``.

Inputs as ``structure_sim_node`` publishes them (:data:`STRUCTURE_ESTIMATOR_INPUTS`, each
``Float64MultiArray`` in the structure's string or node order, NaN: not measured; one
``sensor_msgs/Imu`` per body with an IMU). The ground contacts are ``estimation.contacts`` by
name or, when none is listed, the nodes of free bodies within ``estimation.contact_distance``
of the ground at the last estimate (the filter: at its prediction).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.structure_estimator import (
    DEFAULT_ACCELERATION_STD,
    DEFAULT_CONTACT_STD,
    DEFAULT_CONTACT_VELOCITY_STD,
    DEFAULT_GYRO_STD,
    DEFAULT_IMU_STD,
    DEFAULT_LENGTH_STD,
    DEFAULT_MARKER_STD,
    DEFAULT_TENSION_STD,
    PREDICTIONS,
    StructureFilter,
    StructureMeasurements,
    estimate_structure_poses,
)
from tensegrity_stiffness.estimation.trust import CONSISTENCY_PROBABILITY
from tensegrity_stiffness.geometry.validation import require_all_finite
from tensegrity_stiffness.nodes.estimator_node import (
    ESTIMATION_METHODS,
    EstimatorInput,
    Reading,
    fresh_readings,
    gravity_reading,
    measured_array,
    trust_level,
)
from tensegrity_stiffness.nodes.estimator_node import (
    ESTIMATION_PARAMETERS as JOINT_ESTIMATION_PARAMETERS,
)
from tensegrity_stiffness.nodes.layouts import (
    FLOAT64_MULTIARRAY,
    OutputLayout,
    OutputRow,
    matrix_dims,
    table_arrays,
    table_layouts,
)
from tensegrity_stiffness.nodes.messages import MessageTypes, OutputMessages
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name
from tensegrity_stiffness.nodes.shared_parameters import rest_length_offsets
from tensegrity_stiffness.nodes.structure_node import (
    STRUCTURE_NODE_PARAMETERS,
    STRUCTURE_OUTPUT_TABLE,
    StructureNodeSettings,
    StructureOutputs,
    body_components,
    contact_nodes,
    structure_node_settings,
    structure_outputs,
)
from tensegrity_stiffness.structures.equilibrium import resting_poses
from tensegrity_stiffness.structures.structure import Structure

FloatArray = NDArray[np.float64]

NODE_NAME = 'structure_estimator_node'
#: The array inputs (topic ``~/<name>``), by the name ``estimation.trigger`` gives them; the
#: IMUs are ``~/imu/<body>`` (reading ``imu/<body>``), ``estimation.trigger: imu`` the last of
#: ``estimation.imu_bodies`` (the twin publishes them after the arrays of a step).
STRUCTURE_ESTIMATOR_INPUTS = ('measured_lengths', 'measured_tensions', 'measured_rest_lengths',
                              'measured_markers', 'measured_contacts')
TRIGGERS = (*STRUCTURE_ESTIMATOR_INPUTS, 'imu')
#: The component names of a body's pose covariance (PoseWithCovariance: position, then the
#: turn about the world's x, y, z).
POSE_COMPONENTS = ('x', 'y', 'z', 'rx', 'ry', 'rz')

#: The joint's estimator's parameters by name (the ones both estimators share).
JOINT_ESTIMATION = by_name(JOINT_ESTIMATION_PARAMETERS)

ESTIMATION_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('estimation.method', 'string', 'filter',
                  "'filter' (recursive on every body's pose and velocity: a rolling robot) or "
                  "'static' (each reading set on its own); docs/structures.md",
                  choices=ESTIMATION_METHODS),
    ParameterSpec('estimation.trigger', 'string', 'measured_lengths',
                  'the input whose messages trigger an estimate (with the latest of the others '
                  "no older than estimation.max_age); 'imu': the last IMU of "
                  'estimation.imu_bodies', choices=TRIGGERS),
    JOINT_ESTIMATION['estimation.max_age'],  # one home: the joint's estimator's
    JOINT_ESTIMATION['estimation.time_budget'],
    ParameterSpec('estimation.consistency_probability', 'double', CONSISTENCY_PROBABILITY,
                  'probability of the chi-square test of each estimate (and of the filter\'s '
                  'gate of each reading)', range=(1e-15, 0.5)),
    ParameterSpec('estimation.hold_rigid_motion', 'bool', True,
                  "'static': hold a rigid motion of the whole that the readings cannot see "
                  '(without markers: the motion along the ground) at the last estimate, named '
                  'in ~/trust (false: refuse the estimate)'),
    ParameterSpec('estimation.at_rest', 'bool', False,
                  "'static': the robot is still: every free body's wrench balance (strings at "
                  'the encoders\' rest lengths, weight, the contacts) is a reading too'),
    ParameterSpec('estimation.contacts', 'string_array', None,
                  'the nodes known to be on the ground (body.node; empty: those of a fresh '
                  '~/measured_contacts, else those within estimation.contact_distance of it at '
                  'the last estimate)'),
    ParameterSpec('estimation.contact_distance', 'double', 0.005,
                  'with neither estimation.contacts nor ~/measured_contacts: a node of a free '
                  'body at most this far above the ground at the last estimate is a contact '
                  '(0: no contacts), m', range=(0.0, 1.0)),
    ParameterSpec('estimation.imu_bodies', 'string_array', None,
                  'the bodies with an IMU on ~/imu/<body> (empty: every free bar, as the twin)',
                  read_only=True),
    ParameterSpec('sensors.length_std', 'double', DEFAULT_LENGTH_STD,
                  'string length sensors: std, m', range=(1e-12, 1e3)),
    ParameterSpec('sensors.tension_std', 'double', DEFAULT_TENSION_STD,
                  'load cells: std, N', range=(1e-12, 1e6)),
    ParameterSpec('sensors.imu_std', 'double', DEFAULT_IMU_STD,
                  "IMU: std of the gravity direction per axis, rad (a rolling robot's "
                  'accelerations belong in it)', range=(1e-9, 10.0)),
    ParameterSpec('sensors.gyro_std', 'double', DEFAULT_GYRO_STD,
                  "'filter': gyro std per axis, rad/s", range=(1e-9, 1e3)),
    ParameterSpec('sensors.imu_rest_tolerance', 'double', 1.0,
                  "'static': an IMU whose specific force differs from 9.81 m/s^2 by more than "
                  'this (m/s^2) is not at rest and is rejected', range=(0.0, 1e3)),
    ParameterSpec('sensors.marker_std', 'double', DEFAULT_MARKER_STD,
                  'marker positions: std per axis, m', range=(1e-12, 1e3)),
    ParameterSpec('sensors.contact_std', 'double', DEFAULT_CONTACT_STD,
                  "a contact node's height above the ground: std, m", range=(1e-12, 1.0)),
    ParameterSpec('filter.linear_acceleration', 'double', DEFAULT_ACCELERATION_STD[0],
                  "'filter': process noise, white acceleration of each body's origin, "
                  'm/s^2 sqrt(s)', range=(1e-9, 1e6)),
    ParameterSpec('filter.angular_acceleration', 'double', DEFAULT_ACCELERATION_STD[1],
                  "'filter': process noise, white angular acceleration of each body, "
                  'rad/s^2 sqrt(s)', range=(1e-9, 1e6)),
    ParameterSpec('filter.prediction', 'string', 'constant_velocity',
                  "'filter': 'constant_velocity' or 'dynamics' (the structure's, as "
                  "StructureFilter's default; measured with the accelerometers, which this node "
                  "reads as gravity directions: not yet across processes); docs/structures.md",
                  choices=PREDICTIONS),
    ParameterSpec('filter.contact_velocity_std', 'double', DEFAULT_CONTACT_VELOCITY_STD,
                  "'filter': std of a contact node's velocity (it sticks), m/s",
                  range=(1e-12, 1e3)),
    ParameterSpec('filter.max_gap', 'double', 0.2,
                  "'filter': an estimate more than this (s) after the last starts the filter "
                  'again from a static estimate (a prediction that long is not trusted)',
                  range=(1e-3, 3600.0)),
    ParameterSpec('filter.max_gated_share', 'double', 0.5,
                  "'filter': when more than this share of an update's readings is gated out, "
                  'the next estimate starts the filter again from a static estimate (lost)',
                  range=(0.0, 1.0)),
)

#: Every parameter of ``structure_estimator_node``: the structure node's (the structure, its
#: frames, the offsets, tf and the common ones), then the estimation's.
STRUCTURE_ESTIMATOR_PARAMETERS: tuple[ParameterSpec, ...] = (
    STRUCTURE_NODE_PARAMETERS + ESTIMATION_PARAMETERS)


@dataclass(frozen=True)
class StructureEstimatorSettings:
    """Everything one estimate needs, swapped as a whole: the structure node's settings
    (``node``: the structure, its rest lengths, frames, contact distance of the outputs) and the
    estimation's; ``values`` the checked parameters."""

    node: StructureNodeSettings
    method: str
    trigger: str
    max_age: float
    consistency_probability: float
    hold_rigid_motion: bool
    at_rest: bool
    contacts: tuple[str, ...]
    contact_distance: float
    imu_bodies: tuple[str, ...]
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def structure(self) -> Structure:
        return self.node.structure

    @property
    def world_frame(self) -> str:
        return self.node.world_frame

    @property
    def marker_period(self) -> float:
        return self.node.marker_period

    @property
    def max_array_length(self) -> int:
        return self.node.max_array_length

    @property
    def trigger_reading(self) -> str:
        """The reading whose arrival triggers an estimate."""
        return f'imu/{self.imu_bodies[-1]}' if self.trigger == 'imu' else self.trigger


def structure_estimator_settings(values: Mapping[str, Any], generation: int = 0
                                 ) -> StructureEstimatorSettings:
    """Validate a whole parameter set of ``structure_estimator_node``; ValueError names the bad
    field."""
    checked = {spec.name: spec.check(values[spec.name])
               for spec in STRUCTURE_ESTIMATOR_PARAMETERS}
    node = structure_node_settings(checked, generation)
    s = node.structure
    for name in checked['estimation.contacts']:
        try:
            node_index = s.node_index(name)
        except ValueError as exc:
            raise ValueError(f'estimation.contacts: {exc}') from None
        if s.node_bodies[node_index] < 0:
            raise ValueError(f'estimation.contacts: {name} is a world node, not on a body')
    if checked['estimation.contacts'] and s.ground is None:
        raise ValueError('estimation.contacts: the structure has no ground')
    imu_bodies = tuple(checked['estimation.imu_bodies']) or tuple(
        s.body_names[i] for i in s.bar_indices if not s.fixed[i])
    for name in imu_bodies:
        try:
            s.body_index(name)
        except ValueError as exc:
            raise ValueError(f'estimation.imu_bodies: {exc}') from None
    if checked['estimation.trigger'] == 'imu' and not imu_bodies:
        raise ValueError("estimation.trigger is 'imu' but no body has an IMU")
    if imu_bodies and (s.gravity is None or not np.any(s.gravity)):
        raise ValueError('estimation.imu_bodies: IMUs need the structure\'s gravity (set '
                         'estimation.imu_bodies to the bodies with an IMU)')
    return StructureEstimatorSettings(
        node=node, method=checked['estimation.method'], trigger=checked['estimation.trigger'],
        max_age=checked['estimation.max_age'],
        consistency_probability=checked['estimation.consistency_probability'],
        hold_rigid_motion=checked['estimation.hold_rigid_motion'],
        at_rest=checked['estimation.at_rest'], contacts=tuple(checked['estimation.contacts']),
        contact_distance=checked['estimation.contact_distance'], imu_bodies=imu_bodies,
        generation=generation, values=checked)


# ------------------------------------------------------------------------------ inputs
@dataclass(frozen=True)
class ImuSample:
    """One IMU message: ``specific_force`` (3,) m/s^2 and ``angular_velocity`` (3,) rad/s (None:
    no gyro), in the body's frame."""

    specific_force: FloatArray
    angular_velocity: FloatArray | None


def input_length(settings: StructureEstimatorSettings, name: str) -> int:
    """The number of values of the array input ``name``: one per string, or 3 per body node
    (``measured_markers``, the twin's node order)."""
    s = settings.structure
    body_nodes = int(np.count_nonzero(s.node_bodies >= 0))
    if name == 'measured_markers':
        return 3 * body_nodes
    if name == 'measured_contacts':
        return body_nodes
    return s.n_strings


def array_reading(settings: StructureEstimatorSettings, name: str, values: FloatArray
                  ) -> FloatArray:
    """A checked array input (:func:`measured_array`: the count, finite or NaN, one value at
    least); lengths and encoders positive; ValueError naming ``~/name``."""
    arr = measured_array(values, input_length(settings, name), f'~/{name}')
    if name in ('measured_lengths', 'measured_rest_lengths') and np.any(arr <= 0.0):
        raise ValueError(f'~/{name}: lengths must be > 0 (NaN: not measured)')
    if name == 'measured_contacts':
        if settings.structure.ground is None:
            raise ValueError('~/measured_contacts: the structure has no ground')
        if not np.all(np.isnan(arr) | (arr == 0.0) | (arr == 1.0)):
            raise ValueError('~/measured_contacts: values must be 1 (on the ground), 0 (off it) '
                             'or NaN (not known)')
    return arr


def imu_sample(settings: StructureEstimatorSettings, body: str, specific_force: FloatArray,
               angular_velocity: FloatArray | None) -> ImuSample:
    """A checked IMU reading of ``body``: the static estimator takes it only at rest
    (:func:`~tensegrity_stiffness.nodes.estimator_node.gravity_reading`); ValueError
    naming ``~/imu/<body>``."""
    try:
        if settings.method == 'static':
            gravity_reading(specific_force, settings.values['sensors.imu_rest_tolerance'])
        else:
            sm.gravity_from_specific_force(specific_force)
    except ValueError as exc:
        raise ValueError(f'~/imu/{body}: {exc}') from None
    return ImuSample(np.asarray(specific_force, dtype=np.float64), None
                     if angular_velocity is None else
                     np.asarray(angular_velocity, dtype=np.float64))


def estimate_contacts(settings: StructureEstimatorSettings, poses: FloatArray,
                      readings: Mapping[str, Reading]) -> tuple[str, ...]:
    """The ground contacts of an estimate: ``estimation.contacts``, or those of a fresh
    ``measured_contacts`` reading (its ones), or the nodes of free bodies within
    ``estimation.contact_distance`` of the ground at ``poses`` (N, 4, 4)."""
    if settings.contacts:
        return settings.contacts
    s = settings.structure
    if 'measured_contacts' in readings:
        names = [n for n, b in zip(s.node_names, s.node_bodies, strict=True) if b >= 0]
        on = readings['measured_contacts'].value == 1.0
        return tuple(n for n, c in zip(names, on, strict=True) if c)
    if s.ground is None or settings.contact_distance <= 0.0:
        return ()
    return tuple(s.node_names[j] for j in contact_nodes(s, poses, settings.contact_distance))


def estimate_rest_lengths(settings: StructureEstimatorSettings,
                          readings: Mapping[str, Reading]) -> FloatArray:
    """The rest lengths of an estimate: the fresh encoders plus ``joint.rest_length_offsets``
    where measured, the node's own (the config's or the commanded ones plus the offsets)
    elsewhere."""
    rest = settings.node.rest_lengths.copy()
    if 'measured_rest_lengths' in readings:
        s = settings.structure
        encoders = readings['measured_rest_lengths'].value
        measured = ~np.isnan(encoders)
        rest[measured] = (encoders + rest_length_offsets(settings.values, s.n_strings))[measured]
        rest = s.validate_rest_lengths(rest)
    return rest


def structure_measurements(settings: StructureEstimatorSettings,
                           readings: Mapping[str, Reading], rest: FloatArray,
                           contacts: Sequence[str]
                           ) -> tuple[StructureMeasurements, dict[str, FloatArray]]:
    """The :class:`StructureMeasurements` of the fresh ``readings`` with the sensors' stds,
    ``rest`` and ``contacts``, and the gyros (body -> (3,) rad/s)."""
    s, values = settings.structure, settings.values
    per_string = {}
    for name in ('measured_lengths', 'measured_tensions'):
        if name in readings:
            v = readings[name].value
            per_string[name] = {s.string_names[j]: float(v[j])
                                for j in np.flatnonzero(~np.isnan(v))}
    markers = None
    if 'measured_markers' in readings:
        names = [n for n, b in zip(s.node_names, s.node_bodies, strict=True) if b >= 0]
        x = readings['measured_markers'].value.reshape(-1, 3)
        markers = {n: x[k] for k, n in enumerate(names) if not np.any(np.isnan(x[k]))}
    imus = {body: readings[f'imu/{body}'].value for body in settings.imu_bodies
            if f'imu/{body}' in readings}
    gyros = {body: imu.angular_velocity for body, imu in imus.items()
             if imu.angular_velocity is not None}
    m = StructureMeasurements(
        lengths=per_string.get('measured_lengths'), tensions=per_string.get('measured_tensions'),
        rest_lengths=rest,
        imu_gravity={body: sm.gravity_from_specific_force(imu.specific_force)
                     for body, imu in imus.items()} or None,
        markers=markers or None, contacts=list(contacts) or None,
        at_rest=settings.at_rest and settings.method == 'static',
        length_std=values['sensors.length_std'], tension_std=values['sensors.tension_std'],
        imu_std=values['sensors.imu_std'], marker_std=values['sensors.marker_std'],
        contact_std=values['sensors.contact_std'])
    return m, gyros


def new_structure_filter(settings: StructureEstimatorSettings, poses: FloatArray
                         ) -> StructureFilter:
    """The filter of a parameter set, started at ``poses`` (the first static estimate)."""
    values = settings.values
    return StructureFilter(settings.structure, poses, acceleration_std=(
        values['filter.linear_acceleration'], values['filter.angular_acceleration']),
        gyro_std=values['sensors.gyro_std'],
        contact_velocity_std=values['filter.contact_velocity_std'],
        prediction=values['filter.prediction'],
        gate_probability=settings.consistency_probability)


@dataclass
class FilterTrack:
    """The filter of ``estimation.method: filter``, the time (s) of its last update (None
    before the first) and how often it was started again (``filter.max_gap``,
    ``filter.max_gated_share``)."""

    filter: StructureFilter | None = None
    time: float = 0.0
    restarts: int = 0


# ------------------------------------------------------------------------------ outputs
@dataclass(frozen=True)
class StructureEstimatorOutputs:
    """One estimate: ``poses`` (N, 4, 4) and ``covariance`` (6N, 6N, PoseWithCovariance per
    body, fixed bodies and the held directions zero); the trust: ``consistent`` (None: no
    redundancy), ``redundancy`` (static: measured minus determined degrees of freedom; filter:
    the degrees of freedom of the readings kept), ``chi2`` (static: of the fit; filter: the
    NIS), ``outliers`` / ``outlier_reasons``, ``gauge`` (the directions held); the ``contacts``
    used, the ``method``, the inputs ``used`` and every input's ``ages`` (s), ``structure``:
    the structure node's outputs at the estimate with the rest lengths used, and ``anchor``: the
    poses the next estimate starts from (the estimate's, or, while a rigid motion is held, the
    start that holds it)."""

    poses: FloatArray
    covariance: FloatArray
    consistent: bool | None
    redundancy: int
    chi2: float
    outliers: tuple[str, ...]
    outlier_reasons: tuple[str, ...]
    gauge: tuple[str, ...]
    contacts: tuple[str, ...]
    method: str
    used: tuple[str, ...]
    ages: Mapping[str, float]
    structure: StructureOutputs
    anchor: FloatArray | None = None

    @property
    def state(self) -> Any:
        """The structure's state at the estimate (markers, frames)."""
        return self.structure.state

    def body_covariance(self, i: int) -> FloatArray:
        """The (6, 6) covariance of body ``i``'s pose."""
        return self.covariance[6 * i:6 * i + 6, 6 * i:6 * i + 6]


def _static(settings: StructureEstimatorSettings, readings: Mapping[str, Reading],
            rest: FloatArray, start: FloatArray) -> Any:
    contacts = estimate_contacts(settings, start, readings)
    m, _ = structure_measurements(settings, readings, rest, contacts)
    est = estimate_structure_poses(settings.structure, m, start=start,
                                   hold_rigid_motion=settings.hold_rigid_motion,
                                   consistency_probability=settings.consistency_probability,
                                   time_budget=settings.values['estimation.time_budget'])
    if not est.success:
        raise ValueError(f'no estimate: {est.message}')
    return est, contacts


def estimate(settings: StructureEstimatorSettings, snapshot: EstimatorInput,
             track: FilterTrack | None = None) -> StructureEstimatorOutputs:
    """One estimate of the fresh readings of ``snapshot`` (``initial_screw``: the poses the
    static estimator starts from, the last estimate's ``anchor``; None: the structure's resting
    equilibrium, :func:`~tensegrity_stiffness.structures.equilibrium.resting_poses`, where
    the twin starts) under ``settings.method``; the filter
    (``track``) is started from the first static estimate and then predicted to
    ``snapshot.now`` and updated. ValueError (nothing is published) when no reading is fresh,
    a reading is bad, the readings cannot determine the poses (the message names what) or an
    output is not finite."""
    readings, ages = fresh_readings(snapshot, settings.max_age)
    if not readings:
        raise ValueError('no input within estimation.max_age')
    rest = estimate_rest_lengths(settings, readings)
    start = (resting_poses(settings.structure) if snapshot.initial_screw is None
             else snapshot.initial_screw)
    if settings.method == 'static' or track is None:
        est, contacts = _static(settings, readings, rest, start)
        poses, covariance = est.poses, est.covariance
        trust = (est.consistent, est.redundancy, est.chi2, est.outliers, est.outlier_reasons,
                 est.gauge)
        # A held rigid motion stays where the start has it: the next estimate starts from the
        # same poses, so that the readings' noise does not walk it (from the last estimate,
        # each estimate's leak along it would add up: a degree of yaw in seconds at 100 Hz).
        anchor = start if any('whole structure' in g for g in est.gauge) else poses
    else:
        gap = settings.values['filter.max_gap']
        if track.filter is not None and snapshot.now - track.time > gap:
            track.filter = None  # too long unobserved: the prediction is not to be trusted
            track.restarts += 1
        if track.filter is None:
            est, _ = _static(settings, readings, rest, start)
            track.filter = new_structure_filter(settings, est.poses)
        elif snapshot.now > track.time:
            track.filter.predict(snapshot.now - track.time)
        track.time = snapshot.now
        contacts = estimate_contacts(settings, track.filter.T, readings)
        m, gyros = structure_measurements(settings, readings, rest, contacts)
        update = track.filter.update(m, gyros)
        n_readings = (sum(len(r or {}) for r in (m.lengths, m.tensions, m.imu_gravity,
                                                  m.markers)) + 2 * len(contacts) + len(gyros))
        if len(update.outliers) > settings.values['filter.max_gated_share'] * n_readings:
            track.filter = None  # lost: most readings contradict it; the next starts again
            track.restarts += 1
        poses, covariance = update.poses, update.covariance
        anchor = poses
        trust = (update.consistent, update.dof, update.nis, update.outliers,
                 update.outlier_reasons, ())
    with np.errstate(all='ignore'):
        outputs = structure_outputs(replace(settings.node, rest_lengths=rest), poses)
    result = StructureEstimatorOutputs(
        poses, covariance, *trust, contacts=tuple(contacts), method=settings.method,
        used=tuple(name for name in sorted(readings)), ages=ages, structure=outputs,
        anchor=anchor)
    arrays = estimator_output_arrays(result)
    require_all_finite(STRUCTURE_ESTIMATOR_OUTPUT_NAMES[:len(arrays)], arrays)
    return result


def covariance_labels(body_names: Sequence[str]) -> tuple[str, str]:
    """Row and column labels of the (6N, 6N) ``~/pose_covariance``."""
    label = ('[dp; dw] of each body in the world (PoseWithCovariance: p -> p + dp, R -> '
             'exp(hat(dw)) R) [' + body_components(body_names, POSE_COMPONENTS) + ']')
    return 'rows: ' + label, 'cols: ' + label


def _covariance_layout(structure: Structure) -> OutputLayout:
    n6 = 6 * structure.n_bodies
    return OutputLayout(FLOAT64_MULTIARRAY, tuple(matrix_dims(
        n6, n6, *covariance_labels(structure.body_names))))


#: The estimator's array outputs (topic ``~/<name>``), published after ``~/poses`` and
#: ``~/trust``: one row each (name, layout of the structure, value of
#: :class:`StructureEstimatorOutputs`; :class:`~tensegrity_stiffness.nodes.layouts.OutputRow`):
#: the covariance (6N, 6N), then the structure node's outputs at the estimate
#: (:data:`~tensegrity_stiffness.nodes.structure_node.STRUCTURE_OUTPUT_TABLE`).
STRUCTURE_ESTIMATOR_OUTPUT_TABLE: tuple[OutputRow, ...] = (
    OutputRow('pose_covariance', _covariance_layout, 'covariance'),
    *(row.within('structure') for row in STRUCTURE_OUTPUT_TABLE),
)
#: The names of the arrays :func:`estimate` checks: the poses' transforms (``~/poses``), then
#: :data:`STRUCTURE_ESTIMATOR_OUTPUT_TABLE`'s.
STRUCTURE_ESTIMATOR_OUTPUT_NAMES = ('poses',
                                    *(row.name for row in STRUCTURE_ESTIMATOR_OUTPUT_TABLE))


def estimator_output_arrays(outputs: StructureEstimatorOutputs) -> tuple[FloatArray, ...]:
    """The published arrays in :data:`STRUCTURE_ESTIMATOR_OUTPUT_NAMES` order (the poses'
    transforms first; the contact forces only with a ground)."""
    return (outputs.poses, *table_arrays(STRUCTURE_ESTIMATOR_OUTPUT_TABLE, outputs))


def estimator_array_layouts(structure: Structure) -> dict[str, OutputLayout]:
    """The array outputs of ``structure`` by topic, in :data:`STRUCTURE_ESTIMATOR_OUTPUT_TABLE`
    order."""
    return table_layouts(STRUCTURE_ESTIMATOR_OUTPUT_TABLE, structure)


class StructureEstimatorArrayMessages(OutputMessages):
    """The estimator's array messages of ``structure`` (:func:`estimator_array_layouts`),
    refilled by :meth:`fill` (the finite check is :func:`estimate`'s)."""

    def __init__(self, structure: Structure, types: MessageTypes) -> None:
        super().__init__(estimator_array_layouts(structure), types)

    def fill(self, outputs: StructureEstimatorOutputs, stamp: Any, frame_id: str,
             wanted: Sequence[bool] | None = None) -> None:
        """Set the messages flagged in ``wanted`` (default all) from ``outputs``."""
        self.fill_arrays(table_arrays(STRUCTURE_ESTIMATOR_OUTPUT_TABLE, outputs), stamp,
                         frame_id, wanted)


# ------------------------------------------------------------------------------ trust
def trust_summary(outputs: StructureEstimatorOutputs) -> tuple[str, str]:
    """(level, message) of an estimate: WARN when it is inconsistent or left a reading out (the
    message names them), OK otherwise; without redundancy the message says so."""
    message = (f'{outputs.method} estimate from {", ".join(outputs.used)}; chi2 '
               f'{outputs.chi2:.3g}, redundancy {outputs.redundancy}')
    return trust_level(message, outputs.outliers, outputs.consistent)


def trust_values(outputs: StructureEstimatorOutputs) -> list[tuple[str, Any]]:
    """``(key, value)`` pairs of an estimate's trust (``~/trust`` and ``/diagnostics``)."""
    values: list[tuple[str, Any]] = [
        ('method', outputs.method),
        ('consistent', 'none (no redundancy)' if outputs.consistent is None
         else outputs.consistent),
        ('redundancy', outputs.redundancy), ('chi2', outputs.chi2),
        ('outliers', ', '.join(outputs.outliers) or 'none'),
        *((f'left out: {name}', reason) for name, reason in
          zip(outputs.outliers, outputs.outlier_reasons, strict=True)),
        ('gauge (held)', ', '.join(outputs.gauge) or 'none'),
        ('contacts', ', '.join(outputs.contacts) or 'none'),
        ('inputs used', ', '.join(outputs.used)),
    ]
    values += [(f'age of {name} [ms]', 1e3 * age) for name, age in sorted(outputs.ages.items())]
    return values


def pose_errors(estimate: FloatArray, truth: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Per body, the position error (m) and the angle (rad) between two sets of (N, 4, 4)
    poses: the live line's error of the estimate against the twin's truth."""
    dp = np.linalg.norm(estimate[:, :3, 3] - truth[:, :3, 3], axis=1)
    R = np.einsum('nji,njk->nik', truth[:, :3, :3], estimate[:, :3, :3])
    cos = np.clip((np.trace(R, axis1=1, axis2=2) - 1.0) / 2.0, -1.0, 1.0)
    return dp, np.arccos(cos)


def pose_rms(errors: FloatArray) -> float:
    """The root mean square of per-body errors."""
    return float(math.sqrt(np.mean(np.square(errors)))) if errors.size else math.nan
