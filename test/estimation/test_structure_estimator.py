"""The structure estimator: measurement models against central differences and the structure's
own evaluation, statistics over seeded trials (NEES in the chi-square 95 % band), refusals,
gauges and outliers (tensegrity_stiffness.estimation.structure_estimator)."""

from __future__ import annotations

import dataclasses
import functools

import numpy as np
import pytest
from scipy.stats import chi2

from tensegrity_stiffness.estimation.structure_estimator import (
    StructureMeasurements,
    apply_increment,
    body_accelerations,
    estimate_structure_poses,
    length_scale,
    measurement_model,
    readings_of,
    specific_force_model,
    string_model,
)
from tensegrity_stiffness.geometry.screw import exp_so3, hat3, log_so3
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure
from tensegrity_stiffness.structures.templates import six_bar_document

STEP = 1e-6


@functools.cache
def example(name: str) -> tuple[Structure, np.ndarray, tuple[str, ...]]:
    """A shipped example at its equilibrium on the ground: structure, poses, contact nodes."""
    if name == 'six_bar':
        structure = Structure.from_dict(six_bar_document(ground=True))
    else:
        structure = Structure.from_yaml(f'config/examples/{name}.yaml')
    eq = solve_structure_equilibrium(structure)
    assert eq.success
    return structure, eq.poses, tuple(eq.contacts)


def gravity_direction(structure: Structure) -> np.ndarray:
    return structure.gravity / np.linalg.norm(structure.gravity)


def tangent_noise(rng: np.random.Generator, h: np.ndarray, std: float) -> np.ndarray:
    """The unit vector ``h`` turned by a random rotation of std ``std`` about each axis of its
    tangent plane (the IMU's noise model)."""
    helper = np.array([1.0, 0.0, 0.0]) if abs(h[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    t1 = np.cross(h, helper)
    t1 /= np.linalg.norm(t1)
    t2 = np.cross(h, t1)
    w = std * rng.standard_normal(2)
    return exp_so3(w[0] * t1 + w[1] * t2) @ h


def sensor_readings(structure: Structure, T: np.ndarray, contacts: tuple[str, ...],
                    rng: np.random.Generator, strings: bool = True, imus: bool = True,
                    **kwargs: object) -> StructureMeasurements:
    """The Rutgers/Yale set (every string's length, the encoders' rest lengths, an IMU per
    bar) with noise at the default stds, and the ground contact."""
    m = StructureMeasurements(**kwargs)  # type: ignore[arg-type]
    # the contacts at the truth's heights with noise (a sphere's sinking into the floor)
    x = structure.evaluate(T).node_positions
    ground = structure.ground
    m.contacts = {c: ground.normal @ x[c] - ground.height + m.contact_std * rng.standard_normal()
                  for c in contacts}
    lengths = structure.evaluate(T).lengths
    if strings:
        m.lengths = dict(zip(structure.string_names,
                             lengths + m.length_std * rng.standard_normal(lengths.size),
                             strict=True))
    if imus:
        g = gravity_direction(structure)
        m.imu_gravity = {b: tangent_noise(rng, T[i, :3, :3].T @ g, m.imu_std)
                         for i, b in enumerate(structure.body_names)}
    return m


def pose_error(estimate: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Stacked ``[dp; dw]`` (6N,) from ``truth`` to ``estimate`` (PoseWithCovariance)."""
    e = [np.concatenate([E[:3, 3] - T[:3, 3], log_so3(E[:3, :3] @ T[:3, :3].T)])
         for E, T in zip(estimate, truth, strict=True)]
    return np.concatenate(e)


def aligned_error(structure: Structure, estimate: object, truth: np.ndarray
                  ) -> tuple[np.ndarray, np.ndarray]:
    """The error ``[dp; dw]`` (6N,) of an estimate and its covariance (6N, 6N) after the turn
    about z and the translation along x, y that best align its nodes with the truth's (the
    plane motion, a gauge held at the start; the covariance turned with it)."""
    poses = estimate.poses  # type: ignore[attr-defined]
    xe, xt = structure.node_positions(poses), structure.node_positions(truth)
    ce, ct = xe[:, :2].mean(axis=0), xt[:, :2].mean(axis=0)
    a, b = xe[:, :2] - ce, xt[:, :2] - ct
    angle = np.arctan2(np.sum(a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]), np.sum(a * b))
    M = np.eye(4)
    M[:3, :3] = exp_so3([0.0, 0.0, angle])
    M[:2, 3] = ct - M[:2, :2] @ ce
    R = np.kron(np.eye(2 * structure.n_bodies), M[:3, :3])
    C = R @ estimate.covariance @ R.T  # type: ignore[attr-defined]
    return pose_error(M @ poses, truth), C


def determined_error(structure: Structure, e: np.ndarray, C: np.ndarray
                     ) -> tuple[np.ndarray, float, int]:
    """The error's part in the determined directions (the gauge, held at the start, removed),
    its NEES and its degrees of freedom, in the estimator's scaled metric."""
    lc = length_scale(structure)
    s = np.tile([lc, lc, lc, 1.0, 1.0, 1.0], structure.n_bodies)
    Cs = C / np.outer(s, s)
    w, V = np.linalg.eigh(Cs)
    keep = w > 1e-12 * w.max()
    es = V[:, keep].T @ (e / s)
    return s * (V[:, keep] @ es), float(es @ (es / w[keep])), int(keep.sum())


def perturbed(T: np.ndarray, rng: np.random.Generator, size: float = 0.01) -> np.ndarray:
    return apply_increment(T, size * rng.standard_normal(6 * T.shape[0]))


# ---------------------------------------------------------------------------------- models
@pytest.mark.parametrize('name', ['three_bar', 'six_bar'])
def test_string_model_is_the_structures_evaluation_and_its_derivative(name: str) -> None:
    structure, T0, _ = example(name)
    rng = np.random.default_rng(1)
    T = perturbed(T0, rng)
    rest = structure.rest_lengths * (1.0 + 0.01 * rng.standard_normal(structure.n_strings))
    lengths, tensions, dl, dphi = string_model(structure, T, rest)
    state = structure.evaluate(T, rest)
    np.testing.assert_allclose(lengths, state.lengths, rtol=0, atol=1e-14)
    np.testing.assert_allclose(tensions, state.tensions, rtol=0, atol=1e-12)
    num_l, num_phi = np.zeros_like(dl), np.zeros_like(dphi)
    for c in range(6 * structure.n_bodies):
        d = np.zeros(6 * structure.n_bodies)
        d[c] = STEP
        lp, pp, _, _ = string_model(structure, apply_increment(T, d), rest)
        lm, pm, _, _ = string_model(structure, apply_increment(T, -d), rest)
        num_l[:, c] = (lp - lm) / (2 * STEP)
        num_phi[:, c] = (pp - pm) / (2 * STEP)
    np.testing.assert_allclose(dl, num_l, rtol=0, atol=1e-8)
    np.testing.assert_allclose(dphi, num_phi, rtol=0, atol=1e-8 * np.abs(dphi).max())


def test_every_measurement_jacobian_matches_central_differences() -> None:
    structure, T0, contacts = example('three_bar')
    rng = np.random.default_rng(2)
    T = perturbed(T0, rng, 0.05)
    m = sensor_readings(structure, T0, contacts, rng)
    m.tensions = {s: 1.0 for s in structure.string_names[:4]}
    m.markers = {'bar0.a': np.zeros(3), 'bar2.b': np.zeros(3)}
    m.at_rest = True  # the wrench balances, with the contact forces as unknowns
    readings = readings_of(structure, m)
    rest = structure.rest_lengths
    forces = rng.standard_normal((3, 3))
    n6 = 6 * structure.n_bodies
    _, H, _, _ = measurement_model(structure, T, readings, rest, forces)
    assert H.shape[1] == n6 + 9
    numeric = np.zeros_like(H)
    for c in range(H.shape[1]):
        d = np.zeros(H.shape[1])
        d[c] = STEP
        hp = measurement_model(structure, apply_increment(T, d[:n6]), readings, rest,
                               forces + d[n6:].reshape(3, 3))[0]
        hm = measurement_model(structure, apply_increment(T, -d[:n6]), readings, rest,
                               forces - d[n6:].reshape(3, 3))[0]
        numeric[:, c] = (hp - hm) / (2 * STEP)
    np.testing.assert_allclose(H, numeric, rtol=0, atol=1e-8 * max(1.0, np.abs(H).max()))


def test_imu_marker_and_contact_predictions_are_the_geometry() -> None:
    structure, T, contacts = example('three_bar')
    m = StructureMeasurements(imu_gravity={'bar1': [0, 0, 1]}, markers={'bar2.b': [0, 0, 0]},
                              contacts=list(contacts))
    h, _, _, starts = measurement_model(structure, T, readings_of(structure, m),
                                        structure.rest_lengths)
    np.testing.assert_allclose(h[:3], T[1, :3, :3].T @ gravity_direction(structure), atol=1e-15)
    x = structure.evaluate(T).node_positions['bar2.b']
    np.testing.assert_allclose(h[3:6], x, atol=1e-15)
    np.testing.assert_allclose(h[6:], 0.0, atol=1e-9)  # the equilibrium's contacts
    assert starts == [0, 3, 6, 7, 8]


# ---------------------------------------------------------------------------------- statistics
# One static reading at the default stds (1 mm lengths, 5 mrad IMUs): measured RMS 3-bar
# 2.5 mm / 0.3 deg, 6-bar 5.4 mm / 0.5 deg (the 6-bar's 24 lengths see its shape less well per
# bar); the 5 mm is the rolling robot's (the recursive form averages readings).
@pytest.mark.parametrize('name, trials, position_rms',
                         [('three_bar', 200, 5e-3),
                          pytest.param('six_bar', 60, 6e-3, marks=pytest.mark.slow)])
def test_rutgers_sensor_set_pose_within_5_mm_2_deg_and_nees_in_the_band(
        name: str, trials: int, position_rms: float) -> None:
    """Every string's length, the encoders, an IMU per bar and the ground contact: every
    bar's pose within the RMS bound / 2 deg, NEES (the determined directions) in the 95 % band,
    the plane motion (x, y, the turn about the normal) a gauge held at the start."""
    structure, T, contacts = example(name)
    rng = np.random.default_rng(3)
    nees, dof, pos, ang, consistent = 0.0, 0, [], [], 0
    for _ in range(trials):
        m = sensor_readings(structure, T, contacts, rng)
        est = estimate_structure_poses(structure, m, start=perturbed(T, rng),
                                       hold_rigid_motion=True)
        assert est.success, est.message
        assert est.gauge == ('translation along x of the whole structure',
                             'translation along y of the whole structure',
                             'turn about z of the whole structure')
        e, value, k = determined_error(structure, *aligned_error(structure, est, T))
        nees += value
        dof += k
        pos.extend(np.linalg.norm(e.reshape(-1, 6)[:, :3], axis=1) ** 2)
        ang.extend(np.linalg.norm(e.reshape(-1, 6)[:, 3:], axis=1) ** 2)
        consistent += bool(est.consistent)
    print(name, np.sqrt(np.mean(pos)), np.degrees(np.sqrt(np.mean(ang))), nees / dof)
    assert chi2.ppf(0.025, dof) <= nees <= chi2.ppf(0.975, dof)
    assert np.sqrt(np.mean(pos)) < position_rms
    assert np.degrees(np.sqrt(np.mean(ang))) < 2.0
    assert consistent >= 0.95 * trials


def test_markers_determine_the_rigid_motion_and_bar_spins_are_a_gauge() -> None:
    structure, T, _ = example('three_bar')
    rng = np.random.default_rng(4)
    m = StructureMeasurements(markers={n: structure.evaluate(T).node_positions[n]
                                       + 1e-3 * rng.standard_normal(3)
                                       for n in structure.node_names})
    est = estimate_structure_poses(structure, m, start=perturbed(T, rng))
    assert est.success, est.message
    assert est.gauge == ('spin of bar0', 'spin of bar1', 'spin of bar2')
    for i in range(3):
        axis = est.poses[i, :3, 2]
        C = est.body_covariance(i)
        assert axis @ C[3:, 3:] @ axis < 1e-12 * np.trace(C)  # no variance along the spin
    assert est.redundancy == 18 - 15


# ---------------------------------------------------------------------------------- refusals
def test_the_plane_motion_without_markers_is_refused_by_name() -> None:
    structure, T, contacts = example('three_bar')
    m = sensor_readings(structure, T, contacts, np.random.default_rng(5))
    est = estimate_structure_poses(structure, m, start=T)
    assert not est.success
    assert ('translation along x, translation along y, turn about z of the whole structure'
            in est.message)
    assert 'add markers' in est.message
    assert np.isnan(est.poses).all() and np.isnan(est.covariance).all()


def test_lengths_alone_leave_the_rigid_motions() -> None:
    """Free of the ground, the 9 lengths leave the six rigid motions (and the spins); IMUs add
    the tilt and the spins, never the turn about gravity."""
    structure, T, _ = example('three_bar')
    m = sensor_readings(structure, T, (), np.random.default_rng(6), imus=False)
    est = estimate_structure_poses(structure, m, start=T)
    assert not est.success
    assert ('translation along x, translation along y, translation along z, turn about x, '
            'turn about y, turn about z of the whole structure') in est.message
    m = sensor_readings(structure, T, (), np.random.default_rng(6))
    m.markers = {'bar0.a': structure.evaluate(T).node_positions['bar0.a']}
    held = estimate_structure_poses(structure, m, start=T, hold_rigid_motion=True)
    assert held.success, held.message
    # the turn about the vertical through the marker: named by the rigid motions (about the
    # bodies' mean origin) it is made of
    assert held.gauge == ('translation along x of the whole structure',
                          'translation along y of the whole structure',
                          'turn about z of the whole structure')
    assert held.rank == 18 - 1


def test_too_few_lengths_leave_a_shape_undetermined() -> None:
    structure, T, contacts = example('three_bar')
    m = sensor_readings(structure, T, contacts, np.random.default_rng(7))
    m.lengths = dict(list(m.lengths.items())[:5])
    est = estimate_structure_poses(structure, m, start=T, hold_rigid_motion=True)
    assert not est.success
    assert 'a relative motion of' in est.message


def test_bad_readings_are_named() -> None:
    structure, _, _ = example('three_bar')
    with pytest.raises(ValueError, match='no string'):
        estimate_structure_poses(structure, StructureMeasurements(lengths={'nope': 0.1}))
    with pytest.raises(ValueError, match=r'lengths\[bottom_0\]'):
        estimate_structure_poses(structure, StructureMeasurements(lengths={'bottom_0': -1.0}))
    with pytest.raises(ValueError, match='imu_gravity'):
        estimate_structure_poses(structure, StructureMeasurements(imu_gravity={'bar0': [0, 0, 0]}))
    with pytest.raises(ValueError, match='no body'):
        estimate_structure_poses(structure, StructureMeasurements(imu_gravity={'bar9': [0, 0, 1]}))
    with pytest.raises(ValueError, match='length_std'):
        estimate_structure_poses(structure, StructureMeasurements(lengths={'bottom_0': 0.1},
                                                                  length_std=0.0))


# ---------------------------------------------------------------------------------- outliers
@pytest.mark.parametrize('name', ['three_bar', 'six_bar'])
def test_a_broken_length_sensor_is_named(name: str) -> None:
    """The lengths alone fix the shape (3-bar: 9 for 9, 6-bar: 24 for 24): a broken one is
    seen by the statics at rest (the encoders' rest lengths, the weight, the contacts)."""
    structure, T, contacts = example(name)
    rng = np.random.default_rng(8)
    for j in (0, structure.n_strings - 1):
        m = sensor_readings(structure, T, contacts, rng, at_rest=True)
        broken = structure.string_names[j]
        m.lengths = {**m.lengths, broken: m.lengths[broken] + 0.03}
        est = estimate_structure_poses(structure, m, start=T, hold_rigid_motion=True)
        assert est.success
        assert est.outliers == (f'length[{broken}]',), est.outlier_reasons
        assert est.consistent


@pytest.mark.parametrize('name', ['three_bar', 'six_bar'])
def test_a_flipped_imu_is_named(name: str) -> None:
    structure, T, contacts = example(name)
    rng = np.random.default_rng(9)
    m = sensor_readings(structure, T, contacts, rng)
    bar = structure.body_names[1]
    m.imu_gravity = {**m.imu_gravity, bar: -np.asarray(m.imu_gravity[bar])}
    est = estimate_structure_poses(structure, m, start=perturbed(T, rng),
                                   hold_rigid_motion=True)
    assert est.success
    assert est.outliers == (f'imu[{bar}]',), est.outlier_reasons
    assert est.consistent
    e, _, _ = determined_error(structure, *aligned_error(structure, est, T))
    assert np.abs(e.reshape(-1, 6)[:, :3]).max() < 0.015  # 3 std of the 6-bar's 5.4 mm


# ---------------------------------------------------------------------------------- the twin
TWIN_NOISE = {'lengths': 1e-3, 'accelerometer': 0.05, 'gyro': 0.01}
#: The contacts' std on the twin: about how far its contact spheres sink into the ground
#: (0.027 mm under the 3-bar, 0.054 mm under the 6-bar).
TWIN_CONTACT_STD = {3: 3e-5, 6: 6e-5}


@functools.cache
def settled_twin(name: str) -> object:
    """The MuJoCo twin of the example, settled on the ground from the library's equilibrium."""
    from tensegrity_stiffness.simulation.structure_twin import StructureSimulation

    structure, T, _ = example(name)
    sim = StructureSimulation(structure, poses=T)
    sim.settle(max_time=5.0)
    return sim


def twin_readings(sim: object, rng: np.random.Generator, at_rest: bool = True
                  ) -> StructureMeasurements:
    """The Rutgers/Yale set read from the twin with its seeded noise (SensorNoise)."""
    from tensegrity_stiffness.estimation.sensor_models import gravity_from_specific_force
    from tensegrity_stiffness.simulation.structure_twin import measure_structure
    from tensegrity_stiffness.simulation.twin import SensorNoise

    z = measure_structure(sim, SensorNoise(**TWIN_NOISE), rng)  # type: ignore[arg-type]
    structure = sim.structure  # type: ignore[attr-defined]
    return StructureMeasurements(
        lengths=dict(zip(structure.string_names, z.lengths, strict=True)),
        rest_lengths=z.encoders, length_std=TWIN_NOISE['lengths'],
        imu_gravity={b: gravity_from_specific_force(r.specific_force)
                     for b, r in zip(sim.imu_bodies, z.imus, strict=True)},  # type: ignore
        imu_std=TWIN_NOISE['accelerometer'] / 9.81,
        contacts=sim.contact_nodes(), contact_std=TWIN_CONTACT_STD[structure.n_bodies],  # type: ignore
        at_rest=at_rest)


@pytest.mark.slow
@pytest.mark.parametrize('at_rest', [False, True])
@pytest.mark.parametrize('name, trials', [('three_bar', 60), ('six_bar', 30)])
def test_on_the_twin_every_bar_within_5_mm_2_deg_and_nees_in_the_band(
        name: str, trials: int, at_rest: bool) -> None:
    """Data from MuJoCo (the structure twin settled on the ground), not our forward model:
    the Rutgers/Yale set (lengths, encoders, IMUs, contacts). With the statics at rest
    (``at_rest``) the default wrench std (0.02 N, 0.002 N m) is far above the twin's own
    mismatch (6e-4 N, 8e-5 N m): the NEES is below the band (conservative), checked against
    its upper end only."""
    sim = settled_twin(name)
    structure, _, _ = example(name)
    truth = sim.poses()  # type: ignore[attr-defined]
    rng = np.random.default_rng(10)
    nees, dof, pos, ang, alarms, chis = 0.0, 0, [], [], 0, []
    for _ in range(trials):
        est = estimate_structure_poses(structure, twin_readings(sim, rng, at_rest),
                                       start=perturbed(truth, rng), hold_rigid_motion=True)
        assert est.success, est.message
        alarms += bool(est.outliers)
        chis.append(est.chi2 / est.redundancy)
        e, value, k = determined_error(structure, *aligned_error(structure, est, truth))
        nees += value
        dof += k
        pos.extend(np.linalg.norm(e.reshape(-1, 6)[:, :3], axis=1) ** 2)
        ang.extend(np.linalg.norm(e.reshape(-1, 6)[:, 3:], axis=1) ** 2)
    print(name, np.sqrt(np.mean(pos)), np.degrees(np.sqrt(np.mean(ang))), nees / dof, alarms,
          np.mean(chis))
    assert (at_rest or chi2.ppf(0.025, dof) <= nees) and nees <= chi2.ppf(0.975, dof)
    assert alarms <= 0.05 * trials
    assert np.sqrt(np.mean(pos)) < 5e-3
    assert np.degrees(np.sqrt(np.mean(ang))) < 2.0


@pytest.mark.slow
@pytest.mark.parametrize('name', ['three_bar', 'six_bar'])
def test_on_the_twin_a_broken_length_and_a_flipped_imu_are_named(name: str) -> None:
    sim = settled_twin(name)
    structure, _, _ = example(name)
    truth = sim.poses()  # type: ignore[attr-defined]
    rng = np.random.default_rng(11)
    m = twin_readings(sim, rng)
    broken = structure.string_names[2]
    m.lengths = {**m.lengths, broken: m.lengths[broken] + 0.02}
    est = estimate_structure_poses(structure, m, start=truth, hold_rigid_motion=True)
    assert est.outliers == (f'length[{broken}]',), est.outlier_reasons
    m = twin_readings(sim, rng)
    bar = structure.bar_names[0]
    m.imu_gravity = {**m.imu_gravity, bar: -np.asarray(m.imu_gravity[bar])}
    est = estimate_structure_poses(structure, m, start=truth, hold_rigid_motion=True)
    assert est.outliers == (f'imu[{bar}]',), est.outlier_reasons
    assert est.consistent


# ---------------------------------------------------------------------------------- the filter
def test_filter_gyro_and_contact_velocity_jacobians_match_central_differences() -> None:
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter

    structure, T, contacts = example('three_bar')
    rng = np.random.default_rng(12)
    flt = StructureFilter(structure, perturbed(T, rng, 0.05))
    flt.V = rng.standard_normal((3, 6))
    m = StructureMeasurements(contacts=list(contacts))
    gyros = {'bar1': [0.1, 0.2, 0.3]}
    names, _, jac, _, _ = flt._rows(m, gyros)
    rows = [k for k, n in enumerate(names) if n.startswith(('gyro', 'contact_velocity'))]
    J = np.vstack([jac[k] for k in rows])
    T0, V0 = flt.T.copy(), flt.V.copy()
    numeric = np.zeros_like(J)
    for c in range(J.shape[1]):
        values = []
        for sign in (1.0, -1.0):
            d = np.zeros(J.shape[1])
            d[c] = sign * STEP
            flt.T = apply_increment(T0, d[:18])
            flt.V = V0 + d[18:].reshape(3, 6)
            _, r, _, _, _ = flt._rows(m, gyros)
            values.append(-np.concatenate([r[k] for k in rows]))  # h = z - r
        numeric[:, c] = (values[0] - values[1]) / (2 * STEP)
    np.testing.assert_allclose(J, numeric, rtol=0, atol=1e-7)


def filter_readings(sim: object, rng: np.random.Generator) -> tuple[StructureMeasurements,
                                                                   dict[str, np.ndarray]]:
    m = twin_readings(sim, rng, at_rest=False)
    m.contact_std = 1e-4
    m.imu_std = 0.1  # a roll's accelerations
    from tensegrity_stiffness.simulation.structure_twin import measure_structure
    from tensegrity_stiffness.simulation.twin import SensorNoise

    z = measure_structure(sim, SensorNoise(**TWIN_NOISE), rng)  # type: ignore[arg-type]
    gyros = {b: r.angular_velocity for b, r in zip(sim.imu_bodies, z.imus, strict=True)}  # type: ignore
    return m, gyros


@pytest.mark.slow
@pytest.mark.parametrize('name, string, bar', [('three_bar', 'top_1', 'bar2'),
                                               ('six_bar', 'x1b-y1a', 'z1')])
@pytest.mark.parametrize('fault', ['length', 'imu'])
def test_filter_names_a_broken_length_and_a_flipped_imu_within_0_1_s(
        fault: str, name: str, string: str, bar: str) -> None:
    """The settled 3-bar's and 6-bar's twins at 100 Hz: a length sensor 2 cm off, or an IMU
    turned upside down, from t = 0.3 s: named in the first update that has it, nothing else
    gated."""
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter

    sim = settled_twin(name)
    structure, _, _ = example(name)
    rng = np.random.default_rng(13)
    flt = StructureFilter(structure, sim.poses(), pose_std=(1e-3, 1e-2))  # type: ignore
    named_at = None
    expected = f'length[{string}]' if fault == 'length' else f'imu[{bar}]'
    for k in range(1, 41):
        m, gyros = filter_readings(sim, rng)
        t = 0.01 * k
        if t >= 0.3:
            if fault == 'length':
                m.lengths = {**m.lengths, string: m.lengths[string] + 0.02}
            else:
                m.imu_gravity = {**m.imu_gravity, bar: -np.asarray(m.imu_gravity[bar])}
        flt.predict(0.01)
        u = flt.update(m, gyros)
        if t < 0.3:
            assert u.outliers == (), u.outlier_reasons
        elif named_at is None and expected in u.outliers:
            named_at = t
            assert u.outliers == (expected,)
    # measured: named at 0.30 s, the first update with the fault, in all four cases
    assert named_at is not None and named_at - 0.3 <= 0.1 + 1e-9, named_at


def damped(structure: Structure, damping: float = 0.5) -> Structure:
    """The structure with the twin's string damping (StructureTwinOptions.string_damping) on
    every string whose config gives none: the robot's model of its strings."""
    strings = [s if s.damping > 0.0 else dataclasses.replace(s, damping=damping)
               for s in structure.strings]
    return Structure(structure.bodies, strings, structure.world_nodes, structure.gravity,
                     structure.ground, structure.force_law)


def dynamics_case(damping: float) -> tuple:
    """The dynamics models' Jacobian case: the 6-bar (string damping ``damping``) at perturbed
    poses and velocities, strings at 95 % of their rest lengths, bodies 0, 2 and 5, body 0 on its
    node ``x1.a`` and body 5 on ``z2.b``: ``(structure, T, V, rest, bodies, pivots)``."""
    structure, T0, _ = example('six_bar')
    structure = damped(structure, damping) if damping else structure
    rng = np.random.default_rng(15)
    T = perturbed(T0, rng)
    V = 0.1 * rng.standard_normal((6, 6))
    pivots = {0: structure.node_index('x1.a'), 5: structure.node_index('z2.b')}
    return structure, T, V, structure.rest_lengths * 0.95, [0, 2, 5], pivots


@pytest.mark.parametrize('damping', [0.0, 0.5])
def test_specific_force_model_jacobians_match_central_differences(damping: float) -> None:
    """The accelerometers' dynamics model, off the ground (Newton) and turning about a contact
    node (Euler about it): the velocity Jacobian exact, the pose Jacobian exact without damping;
    with damping it leaves out the damping's change with the pose (second order, 0.25 % of the
    largest entry here)."""
    structure, T, V, rest, bodies, pivots = dynamics_case(damping)
    model = functools.partial(specific_force_model, structure, rest=rest, bodies=bodies,
                              pivots=pivots)
    _, H_pose, H_vel = model(T, V)
    num_pose, num_vel = np.zeros_like(H_pose), np.zeros_like(H_vel)
    for c in range(36):
        d = np.zeros(36)
        d[c] = STEP
        plus, minus = apply_increment(T, d), apply_increment(T, -d)
        num_pose[:, c] = (model(plus, V)[0] - model(minus, V)[0]).ravel() / (2 * STEP)
        num_vel[:, c] = (model(T, V + d.reshape(6, 6))[0]
                         - model(T, V - d.reshape(6, 6))[0]).ravel() / (2 * STEP)
    scale = np.abs(H_pose).max()
    np.testing.assert_allclose(H_pose, num_pose, rtol=0, atol=(1e-8 if damping == 0 else 2e-3)
                               * scale)
    np.testing.assert_allclose(H_vel, num_vel, rtol=0, atol=1e-7 * max(1.0, np.abs(H_vel).max()))
    if damping == 0:
        assert not H_vel[3:6].any()  # off the ground, undamped: no velocity in Newton's law


@pytest.mark.parametrize('damping', [0.0, 0.5])
def test_body_accelerations_jacobians_match_central_differences(damping: float) -> None:
    """The dynamics' accelerations ``[a; alpha]`` (the prediction's and the accelerometers'),
    off the ground (Newton-Euler) and about a contact node (Euler): exact without damping; with
    damping the damping's change with the pose is left out but for its turn with the body
    (measured 4.8e-4 of the largest entry in ``a``, 1.6e-3 in ``alpha``; without that turn
    0.32 in ``alpha``: a bar's axial inertia is 1/1700 of its transverse one)."""
    structure, T, V, rest, bodies, pivots = dynamics_case(damping)
    model = functools.partial(body_accelerations, structure, rest=rest, bodies=bodies,
                              pivots=pivots)
    _, J_pose, J_vel = model(T, V)
    num_pose, num_vel = np.zeros_like(J_pose), np.zeros_like(J_vel)
    step = 1e-2  # in V: quadratic, so exact at any step, and alpha's rounding is 1/step's
    for c in range(36):
        d = np.zeros(36)
        d[c] = 1.0
        plus, minus = apply_increment(T, STEP * d), apply_increment(T, -STEP * d)
        num_pose[:, c] = (model(plus, V)[0] - model(minus, V)[0]).ravel() / (2 * STEP)
        num_vel[:, c] = (model(T, V + step * d.reshape(6, 6))[0]
                         - model(T, V - step * d.reshape(6, 6))[0]).ravel() / (2 * step)
    for rows in (np.r_[0:3, 6:9, 12:15], np.r_[3:6, 9:12, 15:18]):  # a, alpha
        scale = np.abs(J_pose[rows]).max()
        np.testing.assert_allclose(J_pose[rows], num_pose[rows], rtol=0,
                                   atol=(1e-7 if damping == 0 else 2e-3) * scale)
        np.testing.assert_allclose(J_vel[rows], num_vel[rows], rtol=0,
                                   atol=1e-6 * np.abs(J_vel[rows]).max())


@pytest.mark.parametrize('name', ['three_bar', 'six_bar'])
def test_filter_dynamics_step_jacobian_matches_central_differences(name: str) -> None:
    """The prediction's ``Phi = (I - h/2 A)^-1 (I + h/2 A)`` is the linearly implicit step's
    Jacobian in ``[dp; dw; dV]`` (a bar on a contact node, the others off the ground; the turn's
    ``hat(w)`` blocks included) but for ``A``'s own change, second order in ``h``: at h = 1e-5
    s measured 7.5e-6 (3-bar) and 2.9e-5 (6-bar) of ``Phi - I``'s largest entry (the 3-bar's
    7.6e-5 at 1e-4: it scales as ``h``), 7.1e-3 h and 7.9e-3 h in the poses' rows."""
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter

    structure, T0, contacts = example(name)
    rng = np.random.default_rng(18)
    T = perturbed(T0, rng)
    n = structure.n_bodies
    V = np.hstack([0.1 * rng.standard_normal((n, 3)), rng.standard_normal((n, 3))])
    rest = structure.rest_lengths * 0.98
    pivot = [structure.node_index(contacts[0])]
    flt = StructureFilter(structure, T)
    h = 1e-5

    def step(Ti: np.ndarray, Vi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        flt.T, flt.V = Ti, Vi.copy()
        dx, Phi = flt.implicit_step(h, rest, pivot)
        return apply_increment(Ti, dx[:6 * n]), Vi + dx[6 * n:].reshape(n, 6), Phi

    T1, _, Phi = step(T, V)
    numeric = np.zeros_like(Phi)
    for c in range(12 * n):
        d = np.zeros(12 * n)
        d[c] = STEP
        Tp, Vp, _ = step(apply_increment(T, d[:6 * n]), V + d[6 * n:].reshape(n, 6))
        Tm, Vm, _ = step(apply_increment(T, -d[:6 * n]), V - d[6 * n:].reshape(n, 6))
        numeric[:, c] = np.concatenate([pose_error(Tp, T1) - pose_error(Tm, T1),
                                        (Vp - Vm).ravel()]) / (2 * STEP)
    scale = np.abs(Phi - np.eye(12 * n)).max()
    np.testing.assert_allclose(Phi, numeric, rtol=0, atol=4e-5 * scale)
    # the poses' rows to 0.8 % of h (the turn's hat(w) blocks: 1.8 h and 6 h off with their
    # sign flipped)
    np.testing.assert_allclose(Phi[:6 * n], numeric[:6 * n], rtol=0, atol=0.02 * h)


def newton_euler(structure: Structure, T: np.ndarray, V: np.ndarray, rest: np.ndarray
                 ) -> list[tuple[np.ndarray, ...]]:
    """``(p', R', v', w')`` of every (free) body by Newton-Euler about its centre of mass: the
    strings' wrench (``Structure.evaluate_transforms``), their damping ``-L^T c L V`` and
    gravity."""
    W = structure.evaluate_transforms(T, rest).wrenches
    L = string_model(structure, T, rest)[2]
    Wd = -(L.T @ (structure.damping * (L @ V.reshape(-1)))).reshape(-1, 6)
    out = []
    for i, body in enumerate(structure.bodies):
        R, p, w = T[i, :3, :3], T[i, :3, 3], V[i, 3:]
        inertia = R @ body.inertia @ R.T
        moment = W[i, 3:] - np.cross(p, W[i, :3]) + Wd[i, 3:]
        out.append((V[i, :3], hat3(w) @ R, (W[i, :3] + Wd[i, :3]) / body.mass
                    + structure.gravity,
                    np.linalg.solve(inertia, moment - np.cross(w, inertia @ w))))
    return out


def runge_kutta(structure: Structure, T: np.ndarray, V: np.ndarray, rest: np.ndarray,
                dt: float, steps: int) -> tuple[np.ndarray, np.ndarray]:
    """:func:`newton_euler` integrated over ``dt`` by ``steps`` classical Runge-Kutta steps
    (explicit, fourth order; the rotations orthonormalised after each)."""
    h = dt / steps

    def moved(T: np.ndarray, V: np.ndarray, k: list, c: float) -> tuple[np.ndarray, np.ndarray]:
        T2, V2 = T.copy(), V.copy()
        for i, (dp, dR, dv, dw) in enumerate(k):
            T2[i, :3, 3] += c * dp
            T2[i, :3, :3] += c * dR
            V2[i] += c * np.concatenate([dv, dw])
        return T2, V2

    for _ in range(steps):
        k1 = newton_euler(structure, T, V, rest)
        k2 = newton_euler(structure, *moved(T, V, k1, h / 2), rest)
        k3 = newton_euler(structure, *moved(T, V, k2, h / 2), rest)
        k4 = newton_euler(structure, *moved(T, V, k3, h), rest)
        k = [[(a + 2 * b + 2 * c + d) / 6 for a, b, c, d in zip(*q, strict=True)]
             for q in zip(k1, k2, k3, k4, strict=True)]
        T, V = moved(T, V, k, h)
        u, _, vt = np.linalg.svd(T[:, :3, :3])
        T[:, :3, :3] = u @ vt
    return T, V


def test_filter_dynamics_step_is_newton_euler() -> None:
    """With no string slack and no contact (the 3-bar lifted 0.2 m off the ground, the twin's
    damping, 0.1 m/s and 1 rad/s random velocities), one prediction of 0.01 s equals
    Newton-Euler integrated by 200 Runge-Kutta steps (converged: 2.4e-10 m/s from 400), to second
    order in the sub-step: measured, at 1.25 ms (8 sub-steps), 2.1e-6 m / 1.1e-4 rad and 6.1e-4
    m/s / 0.011 rad/s of a change of 0.15 m/s / 3.6 rad/s, and 3.7-3.9 times that at 2.5 ms
    (at the default 10 ms, one step: 0.030 m/s / 0.61 rad/s, the string modes' phase)."""
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter

    structure, T0, _ = example('three_bar')
    structure = damped(structure)
    rng = np.random.default_rng(17)
    T = T0.copy()
    T[:, 2, 3] += 0.2
    V = np.hstack([0.1 * rng.standard_normal((3, 3)), rng.standard_normal((3, 3))])
    rest = structure.rest_lengths
    assert np.all(structure.evaluate_transforms(T, rest).tensions > 0.0)  # no slack
    T_ref, V_ref = runge_kutta(structure, T, V, rest, 0.01, 200)
    errors = []
    for substep in (2.5e-3, 1.25e-3):
        flt = StructureFilter(structure, T, max_substep=substep)
        flt.V = V.copy()
        flt.predict(0.01, rest_lengths=rest, contacts=())
        e = pose_error(flt.T, T_ref).reshape(-1, 6)
        errors.append(np.array([np.abs(e[:, :3]).max(), np.abs(e[:, 3:]).max(),
                                np.abs(flt.V - V_ref)[:, :3].max(),
                                np.abs(flt.V - V_ref)[:, 3:].max()]))
    assert np.all(errors[1] < [3e-6, 1.5e-4, 8e-4, 0.015]), errors[1]
    assert np.all((errors[0] / errors[1] > 3.4) & (errors[0] / errors[1] < 4.5))  # order 2


@functools.cache
def rolled_twin(name: str, seconds: float = 6.0) -> tuple[Structure, list[dict], tuple[str, ...]]:
    """The twin of the example rolled one face by the library's gait
    (simulation.structure_gait), motors at 0.1 m/s, its noise-free sensors and truth every
    0.01 s for at most ``seconds`` (from the start of the settle): the structure with the twin's
    string damping, the records, the IMU bodies."""
    from tensegrity_stiffness.simulation.structure_gait import DONE, RollGait, plan_roll_step
    from tensegrity_stiffness.simulation.structure_twin import StructureSimulation

    structure, T0, _ = example(name)
    sim = StructureSimulation(structure, poses=T0, rest_length_rate=0.1)
    sim.settle(max_time=3.0)
    gait = RollGait(plan_roll_step(structure, sim.poses(), (1.0, 0.0, 0.0)))
    sim.set_rest_lengths(gait.start(sim.time))
    every = round(0.01 / sim.model.opt.timestep)
    records = [{'poses': sim.poses(), 'velocities': sim.velocities()}]
    while gait.phase != DONE and sim.time < seconds:
        sim.step(every)
        contacts = sim.contact_nodes()
        command = gait.update(sim.time, contacts,
                              not sim.moving and float(np.abs(sim.data.qvel).max()) <= 1e-3)
        if command is not None:
            sim.set_rest_lengths(command)
        imus = sim.imus()
        records.append({'poses': sim.poses(), 'velocities': sim.velocities(),
                        'contacts': contacts, 'lengths': sim.string_lengths(),
                        'encoders': np.array(sim.rest_lengths), 'com': sim.centre_of_mass(),
                        'gyros': np.array([r.angular_velocity for r in imus]),
                        'specific_forces': np.array([r.specific_force for r in imus])})
    return damped(structure, sim.options.string_damping), records, tuple(sim.imu_bodies)


def track_roll(structure: Structure, records: list[dict], imu_bodies: tuple[str, ...],
               seed: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The filter through a recorded roll at 100 Hz with the twin's seeded sensor noise
    (SensorNoise: lengths 1 mm, accelerometers 0.05 m/s^2, gyros 0.01 rad/s): the errors
    (k, N, 6) ``[dp; dw]`` from the truth, the same after the plane motion is aligned (the
    part no sensor determines: followed from the contacts), the NEES (k,) and the gated
    readings."""
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter
    from tensegrity_stiffness.simulation.twin import SensorNoise

    noise = SensorNoise(**TWIN_NOISE)
    rng = np.random.default_rng(seed)
    flt = StructureFilter(structure, records[0]['poses'], pose_std=(1e-3, 1e-2),
                          accelerometer_std=TWIN_NOISE['accelerometer'])
    errors, aligned, nees, gated = [], [], [], 0
    for r in records[1:]:
        forces = noise.add(r['specific_forces'], 'accelerometer', rng)
        m = StructureMeasurements(
            lengths=dict(zip(structure.string_names, noise.add(r['lengths'], 'lengths', rng),
                             strict=True)),
            rest_lengths=r['encoders'], length_std=TWIN_NOISE['lengths'],
            contacts=r['contacts'], contact_std=1e-4)
        flt.predict(0.01)
        u = flt.update(m, dict(zip(imu_bodies, noise.add(r['gyros'], 'gyro', rng), strict=True)),
                       accelerometers=dict(zip(imu_bodies, forces, strict=True)))
        gated += len(u.outliers)
        e = pose_error(u.poses, r['poses'])
        errors.append(e.reshape(-1, 6))
        nees.append(e @ np.linalg.solve(u.covariance, e))
        aligned.append(aligned_error(structure, u, r['poses'])[0].reshape(-1, 6))
    return np.array(errors), np.array(aligned), np.array(nees), gated


def rms(errors: np.ndarray) -> tuple[float, float]:
    """Position (m) and angle (deg) RMS over the steps and bodies of errors (k, N, 6)."""
    return (float(np.sqrt(np.mean(np.sum(errors[..., :3] ** 2, axis=-1)))),
            float(np.degrees(np.sqrt(np.mean(np.sum(errors[..., 3:] ** 2, axis=-1))))))


#: The rolls tracked (structure, seconds of simulated time from the settle's start, bounds on
#: the position (m) and angle (deg) RMS, of the shape's position RMS (m)), from the measured
#: figures of the test's docstring.
ROLLS = [('six_bar', 6.0, 5.5e-3, 2.0, 1.0e-3), ('three_bar', 8.0, 7.5e-3, 2.0, 1.0e-3)]


@pytest.mark.slow
@pytest.mark.parametrize('name, seconds, position_rms, angle_rms, shape_rms', ROLLS)
def test_filter_on_the_twin_rolling(name: str, seconds: float, position_rms: float,
                                    angle_rms: float, shape_rms: float) -> None:
    """The twin rolled one face by the library's gait (``plan_roll_step`` plans the 3-bar's
    roll from its base triangle over an edge onto a side face as it does the 6-bar's), read at
    100 Hz: the 6-bar with 24 lengths, the 3-bar with the Rutgers/Yale set (9 lengths, the
    encoders, an IMU per bar), both with the IMUs' accelerometers and gyros and the contact
    nodes; 4 seeded noise trials. The prediction is the dynamics' (StructureFilter.drift, the
    default process noise DEFAULT_DYNAMICS_ACCELERATION_STD) and so are the accelerometers
    (specific_force_model: Newton's law off the ground, held here to the twin's own IMUs at its
    states to 4e-3 m/s^2; Euler's about a sticking contact node). Measured (4 seeds pooled,
    docs/structures.md): the 6-bar 5.0 mm / 0.87 deg RMS, its shape (the plane motion aligned)
    0.33 mm / 0.86 deg, NEES 0.35 per dof, 13 readings gated (of 7176 accelerometer readings:
    impacts); the 3-bar 6.3 mm / 1.09 deg, shape 0.53 mm / 1.09 deg, NEES 0.67, 142 gated (of
    5988, 2.4 %; at constant velocity: 6.6 mm / 1.18 deg, NEES 0.35, 12 gated, and 9.3 mm /
    1.78 deg, NEES 0.82, 36 gated).
    The rest of the position error is the plane motion, followed from the contacts as sticking
    while the twin's contacts slide (2 .. 7 mm while in contact: MuJoCo's soft friction), which
    no sensor of the set sees: the issue's 5 mm is missed there. NEES checked against the band's
    upper end (below it: conservative)."""
    structure, records, imu_bodies = rolled_twin(name, seconds)
    assert np.linalg.norm(records[-1]['com'][:2] - records[1]['com'][:2]) > 0.03  # it rolled
    for r in records[1:]:
        touching = {structure.node_bodies[structure.node_index(c)] for c in r['contacts']}
        off = [i for i in range(structure.n_bodies) if i not in touching]
        if off:
            f = specific_force_model(structure, r['poses'], r['velocities'], r['encoders'],
                                     off)[0]
            np.testing.assert_allclose(f, r['specific_forces'][off], rtol=0, atol=1e-2)
    errors, aligned, nees, dof, gated = [], [], 0.0, 0, 0
    for seed in range(4):
        e, a, n, g = track_roll(structure, records, imu_bodies, 100 + seed)
        errors.append(e)
        aligned.append(a)
        nees += float(n.sum())
        dof += n.size * 6 * structure.n_bodies
        gated += g
    pos, ang = rms(np.array(errors))
    shape_pos, shape_ang = rms(np.array(aligned))
    print(name, 'rolling', pos, ang, shape_pos, shape_ang, nees / dof, gated)
    assert gated <= 0.03 * 4 * (len(records) - 1) * structure.n_bodies  # impacts
    assert pos < position_rms
    assert ang < angle_rms
    assert shape_pos < shape_rms
    assert nees <= chi2.ppf(0.975, dof)


@pytest.mark.parametrize('prediction', ['constant_velocity', 'dynamics'])
def test_filter_prediction_is_the_constant_velocity_model(prediction: str) -> None:
    """predict at constant velocity (and on the dynamics before an update gave it the rest
    lengths and contacts): the poses moved by ``V dt``, the covariance ``F P F^T + Q`` (``F =
    [[I, dt I], [0, I]]``, ``Q`` the white accelerations'), computed by blocks."""
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter

    structure, T, _ = example('three_bar')
    rng = np.random.default_rng(16)
    flt = StructureFilter(structure, T, prediction=prediction,
                          acceleration_std=(2.0, 20.0))  # Q diagonal
    flt.V = rng.standard_normal((3, 6))
    X = rng.standard_normal((36, 36))
    flt.P = X @ X.T
    P0, V0, dt = flt.P.copy(), flt.V.copy(), 0.01
    flt.predict(dt)
    F = np.eye(36)
    F[:18, 18:] = dt * np.eye(18)
    q = np.diag(flt.q)
    Q = np.block([[q * dt ** 3 / 3, q * dt ** 2 / 2], [q * dt ** 2 / 2, q * dt]])
    np.testing.assert_allclose(flt.P, F @ P0 @ F.T + Q, rtol=0, atol=1e-13 * np.abs(P0).max())
    assert np.array_equal(flt.P, flt.P.T)
    np.testing.assert_allclose(flt.T, apply_increment(T, (V0 * dt).ravel()), rtol=0, atol=1e-15)


def test_filter_prediction_holds_the_last_updates_rest_lengths_and_contacts() -> None:
    """predict on the dynamics holds the last update's encoders and contact nodes (the same
    step as given explicitly); an unknown prediction or a sub-step <= 0 is refused by name."""
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter

    structure, T, contacts = example('three_bar')
    rest = structure.rest_lengths * 0.99
    m = StructureMeasurements(rest_lengths=rest, contacts=list(contacts))
    held, given, still = (StructureFilter(structure, T, acceleration_std=(1.0, 10.0),
                                          prediction=p)
                          for p in ('dynamics', 'dynamics', 'constant_velocity'))
    for flt in (held, given, still):
        flt.update(m)
    held.predict(0.01)
    given.predict(0.01, rest_lengths=rest, contacts=list(contacts))
    still.predict(0.01)
    np.testing.assert_array_equal(held.T, given.T)
    np.testing.assert_array_equal(held.P, given.P)
    assert np.abs(held.V - still.V).max() > 1e-3  # the shortened strings accelerate it
    with pytest.raises(ValueError, match='prediction'):
        StructureFilter(structure, T, prediction='euler')
    with pytest.raises(ValueError, match='max_substep'):
        StructureFilter(structure, T, max_substep=0.0)


@pytest.mark.parametrize('prediction', ['constant_velocity', 'dynamics'])
def test_filter_process_noise_about_a_bars_axis(prediction: str) -> None:
    """``acceleration_std = (linear, angular, about a bar's axis)``: from a zero covariance one
    prediction's is the white accelerations' ``Q``, a bar's angular block ``R diag(q_t, q_t,
    q_a) R^T`` (its axis the body's z), times ``dt`` in the velocities."""
    from tensegrity_stiffness.estimation.structure_estimator import StructureFilter

    structure, T, _ = example('three_bar')
    flt = StructureFilter(structure, perturbed(T, np.random.default_rng(19), 0.3),
                          acceleration_std=(1.0, 5.0, 15.0), prediction=prediction)
    flt.P[:] = 0.0
    dt = 0.01
    flt.predict(dt)
    for i in range(3):
        R = flt.T[i, :3, :3]
        w = slice(18 + 6 * i + 3, 18 + 6 * i + 6)
        np.testing.assert_allclose(flt.P[w, w], dt * R @ np.diag([25.0, 25.0, 225.0]) @ R.T,
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(flt.P[18 + 6 * i, 18 + 6 * i], dt, rtol=1e-12)
