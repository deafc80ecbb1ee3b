"""The MuJoCo twin (tensegrity_stiffness.simulation.twin) against the library.

MuJoCo computes every force here (tendon lengths, its spring law, its integrator); the library
is the reference: the string wrench at seeded configurations (slack strings included), settled
equilibria of the joint under loads and of the spine under a tip load and weights, the twin
falling away where the library says unstable, K_c from small twists, rest lengths moving the
equilibrium, the IMU against finite differences of MuJoCo's own velocities.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness import cli, config
from tensegrity_stiffness.geometry.screw import log_se3, log_so3
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.simulation.twin import (
    MIN_REST_LENGTH_FRACTION,
    REST_LENGTH_MARGIN,
    ChainSimulation,
    JointSimulation,
    SensorNoise,
    SimulationOptions,
    chain_mjcf,
    joint_mjcf,
    measure,
)

mujoco = pytest.importorskip('mujoco')

REPO = REPO
JOINT_CONFIG = REPO / 'config' / 'default_joint.yaml'
SPINE_CONFIG = REPO / 'config' / 'default_spine.yaml'
#: The issue's tolerances.
WRENCH_TOLERANCE = 1e-10      # relative
POSITION_TOLERANCE = 1e-8     # m
ROTATION_TOLERANCE = 1e-7     # rad
KC_TOLERANCE = 1e-6           # relative
GRAVITY = np.array([0.0, -9.81, 0.0])


@pytest.fixture(scope='module')
def model() -> JointModel:
    return JointModel.from_yaml(JOINT_CONFIG)


@pytest.fixture(scope='module')
def chain() -> JointChain:
    return JointChain.from_yaml(SPINE_CONFIG)


def drawn_model(model: JointModel, rng: np.random.Generator) -> JointModel:
    """A model with "true" per-string stiffness and rest lengths drawn around the nominal."""
    k = model.k * rng.uniform(0.8, 1.2, model.n_strings)
    rest = model.rest_lengths * rng.uniform(0.97, 1.03, model.n_strings)
    return JointModel(model.link1_nodes, model.connections, k, rest,
                      max_lengths=rest + model.max_stretch, node_names=model.node_names,
                      string_names=model.string_names, initial_screw=model.initial_screw)


def pose_errors(T: np.ndarray, T_ref: np.ndarray) -> tuple[float, float]:
    """(|position difference| m, rotation angle between the two, rad)."""
    dR = T[:3, :3].T @ T_ref[:3, :3]
    return (float(np.linalg.norm(T[:3, 3] - T_ref[:3, 3])),
            float(np.linalg.norm(log_so3(dR))))


def wrench_from_qfrc(sim: JointSimulation) -> np.ndarray:
    """MuJoCo's own generalised spring force on link 2 ([f world; torque in the body about its
    origin]) as the library's wrench in {1} about its origin."""
    d = sim.mj_data
    q = d.qfrc_spring[:6]
    T = sim.pose()
    f, m = q[:3], T[:3, :3] @ q[3:]
    return np.concatenate([f, m + np.cross(T[:3, 3], f)])


def test_mjcf_has_the_models_strings(model: JointModel) -> None:
    root = ET.fromstring(joint_mjcf(model))
    tendons = root.find('tendon').findall('spatial')
    assert [t.get('name') for t in tendons] == model.string_names
    for t, k, l0, lmax in zip(tendons, model.k, model.rest_lengths, model.max_lengths,
                              strict=True):
        assert float(t.get('stiffness')) == k
        assert [float(v) for v in t.get('springlength').split()] == [0.0, l0]
        assert float(t.get('range').split()[1]) == lmax
    ignore = ET.fromstring(joint_mjcf(model, max_length='ignore'))
    assert all(t.get('range') is None for t in ignore.find('tendon').findall('spatial'))
    spine = ET.fromstring(chain_mjcf(JointChain.from_yaml(SPINE_CONFIG)))
    names = [t.get('name') for t in spine.find('tendon').findall('spatial')]
    assert len(names) == 60 and names[0] == 'j1_cross_AA' and names[-1] == 'j5_straight_DC'
    bodies = [b.get('name') for b in spine.find('worldbody').findall('body')]
    assert bodies == [f'link_{i}' for i in range(1, 6)]
    # Both load in MuJoCo as they are written.
    mujoco.MjModel.from_xml_string(joint_mjcf(model))


def test_bad_options_and_models_are_named(model: JointModel) -> None:
    with pytest.raises(ValueError, match='max_length'):
        SimulationOptions(max_length='clip')
    with pytest.raises(ValueError, match='timestep'):
        JointSimulation(model, timestep=0.0)
    with pytest.raises(ValueError, match='integrator'):
        joint_mjcf(model, integrator='RK4')
    with pytest.raises(ValueError, match='unknown simulation options'):
        JointSimulation(model, dampign=1.0)
    paper = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                       force_law='paper')
    with pytest.raises(ValueError, match='force_law'):
        JointSimulation(paper)
    # the exported model too (it wrote the paper's joint as Hooke springs without a word)
    with pytest.raises(ValueError, match="force_law: the twin simulates Hooke's law only"):
        joint_mjcf(paper)
    with pytest.raises(ValueError, match="joint 1 force_law"):
        chain_mjcf(JointChain([paper]))
    sim = JointSimulation(model)
    with pytest.raises(ValueError, match='rest_lengths'):
        sim.set_rest_lengths(model.rest_lengths[:5])
    with pytest.raises(ValueError, match='rest_lengths'):
        sim.set_rest_lengths(-model.rest_lengths)
    with pytest.raises(ValueError, match='wrench'):
        sim.apply_wrench([0.0, math.nan, 0, 0, 0, 0])
    with pytest.raises(ValueError, match='wrench'):
        sim.apply_wrench([1.0, 2.0])


#: The issue's hostile rest lengths and wrenches: each refused, naming the value.
HOSTILE_REST_LENGTHS = (1e308, 1e6, 5e-324)
HOSTILE_WRENCHES = ([1e308, 0, 0, 0, 0, 0], [0, 0, math.inf, 0, 0, 0], [0, 0, 0, 0, 0, -1e6],
                    [1e3, 0, 0, 0, 0, 0], [0, 0, 0, math.nan, 0, 0])


def test_twin_refuses_impossible_rest_lengths_and_wrenches_and_keeps_its_state(
        model: JointModel, chain: JointChain) -> None:
    """Rest lengths outside the physical range (above MIN_REST_LENGTH_FRACTION of the configured
    one, at most 1 + REST_LENGTH_MARGIN times the maximum length) and non-finite or absurd
    wrenches: a ValueError naming the value, and the twin keeps its rest lengths, load and
    motion; a configured range replaces the physical one."""
    W = np.array([0.04, -0.05, 0.02, 0.0, 5e-4, 0.0])
    sim = JointSimulation(model)
    sim.apply_wrench(W)
    sim.step(50)  # moving
    low, high = sim.rest_length_bounds
    np.testing.assert_allclose(low, MIN_REST_LENGTH_FRACTION * model.rest_lengths)
    np.testing.assert_allclose(high, (1.0 + REST_LENGTH_MARGIN) * model.max_lengths)
    qpos, qvel = sim.mj_data.qpos.copy(), sim.mj_data.qvel.copy()
    for value in HOSTILE_REST_LENGTHS:
        rest = model.rest_lengths.copy()
        rest[5] = value
        message = re.escape(f'straight_AC = {value:.6g} m is outside')
        with pytest.raises(ValueError, match=message):
            sim.set_rest_lengths(rest)
    for wrench in HOSTILE_WRENCHES:
        with pytest.raises(ValueError, match=r'wrench must be finite|exceeds max_'):
            sim.apply_wrench(wrench)
    np.testing.assert_array_equal(sim.rest_lengths, model.rest_lengths)
    np.testing.assert_array_equal(sim.external_wrench, W)
    np.testing.assert_array_equal(sim.mj_data.qpos, qpos)
    np.testing.assert_array_equal(sim.mj_data.qvel, qvel)
    assert sim.settle(max_time=10.0)
    res = solve_equilibrium(model, W)
    dp, dr = pose_errors(sim.pose(), res.state.transform)
    assert dp <= POSITION_TOLERANCE and dr <= ROTATION_TOLERANCE
    # the edges of the range are taken; a configured range and bound replace the defaults
    sim.set_rest_lengths(high)
    sim.set_rest_lengths(low * (1.0 + 1e-12))
    narrow = JointSimulation(model, rest_length_range=(0.03, 0.04), max_force=1.0)
    with pytest.raises(ValueError, match=r'range \[0.03, 0.04\]'):
        narrow.set_rest_lengths(np.full(12, 0.041))
    with pytest.raises(ValueError, match='exceeds max_force = 1 N'):
        narrow.apply_wrench([2.0, 0, 0, 0, 0, 0])
    narrow.set_rest_lengths(np.full(12, 0.035))
    with pytest.raises(ValueError, match='rest_length_range'):
        SimulationOptions(rest_length_range=(0.04, 0.03))
    spine = ChainSimulation(chain)
    rest = [m.rest_lengths.copy() for m in chain.joints]
    rest[2][0] = 1e6
    with pytest.raises(ValueError, match='j3_cross_AA = 1e\\+06 m is outside'):
        spine.set_rest_lengths(rest)
    np.testing.assert_array_equal(spine.rest_lengths[2], chain.joints[2].rest_lengths)


def test_string_wrench_equals_the_library_at_200_configurations(model: JointModel) -> None:
    """Seeded configurations around the unloaded equilibrium (some far enough for slack
    strings), on the default model, one with its own link-2 nodes and three with drawn k and
    rest lengths: MuJoCo's tendon lengths, tensions and string wrench equal the library's
    (1e-10 relative), and so does the wrench taken from MuJoCo's own generalised spring
    forces."""
    rng = np.random.default_rng(21)
    other_link2 = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                             link2_nodes=model.link2_nodes * 1.1, max_lengths=model.max_lengths,
                             initial_screw=model.initial_screw)  # its own link-2 node set
    models = [model, other_link2] + [drawn_model(model, rng) for _ in range(3)]
    sims = [JointSimulation(m, max_length='ignore') for m in models]
    slack_total = 0
    checked = 0
    while checked < 200:
        index = checked % len(models)
        m, sim = models[index], sims[index]
        scale = rng.choice([0.2, 1.0, 3.0])
        xi = m.initial_screw + scale * np.concatenate([rng.normal(0, 0.05, 3),
                                                       rng.normal(0, 0.002, 3)])
        state = m.evaluate(xi)
        if np.any(state.saturated) or np.all(state.slack):
            continue  # past lmax the library saturates (MuJoCo cannot), all slack: no wrench
        sim.set_screw(xi)
        scale_F = max(np.abs(state.wrench).max(), 1e-3)
        np.testing.assert_allclose(sim.string_lengths(), state.lengths, rtol=0, atol=1e-15)
        np.testing.assert_allclose(sim.tensions(), state.tensions, rtol=0,
                                   atol=WRENCH_TOLERANCE * max(state.tensions.max(), 1e-3))
        assert np.abs(sim.string_wrench() - state.wrench).max() <= WRENCH_TOLERANCE * scale_F
        assert np.abs(wrench_from_qfrc(sim) - state.wrench).max() <= WRENCH_TOLERANCE * scale_F
        np.testing.assert_allclose(sim.screw(), xi, rtol=0, atol=1e-12)
        slack_total += int(np.count_nonzero(state.slack))
        checked += 1
    assert slack_total >= 50  # slack strings are part of the check


def test_settled_equilibria_equal_solve_equilibrium_under_50_loads(model: JointModel) -> None:
    """50 seeded loads (every fifth on a model with drawn k and rest lengths): from the
    unloaded equilibrium the twin settles (net force and moment below 1e-10, at rest; about
    0.7 s simulated) within 1e-8 m and 1e-7 rad of the library's solution."""
    rng = np.random.default_rng(50)
    sim = JointSimulation(model)
    true_model = drawn_model(model, rng)
    true_sim = JointSimulation(true_model)
    for trial in range(50):
        m, s = (true_model, true_sim) if trial % 5 == 4 else (model, sim)
        W = np.concatenate([rng.uniform(-0.08, 0.08, 3), rng.uniform(-1.5e-3, 1.5e-3, 3)])
        res = solve_equilibrium(m, W)
        assert res.success and res.stable, res.message
        s.set_screw(m.initial_screw)  # from the unloaded equilibrium, the whole way
        s.apply_wrench(W)
        assert s.settle(tolerance=1e-10, max_time=10.0), (trial, s.net_force())
        dp, dr = pose_errors(s.pose(), res.state.transform)
        assert dp <= POSITION_TOLERANCE and dr <= ROTATION_TOLERANCE, (trial, dp, dr)


def test_cartesian_stiffness_from_small_twists_equals_the_library(model: JointModel) -> None:
    rng = np.random.default_rng(6)
    for m in (model, drawn_model(model, rng)):
        sim = JointSimulation(m)
        for W in (np.zeros(6), np.array([0.05, -0.03, 0.02, 5e-4, 0.0, -8e-4])):
            res = solve_equilibrium(m, W)
            sim.set_screw(res.screw)
            K_twin = sim.cartesian_stiffness(step=1e-6)
            K_lib = res.cartesian_stiffness
            assert np.abs(K_twin - K_lib).max() <= KC_TOLERANCE * np.abs(K_lib).max()
            np.testing.assert_allclose(sim.screw(), res.screw, atol=1e-14)  # state restored


def test_rest_lengths_move_the_equilibrium_as_the_library_predicts(model: JointModel) -> None:
    sim = JointSimulation(model)
    W = np.array([0.0, -0.05, 0.02, 0.0, 0.0, 0.0])
    sim.apply_wrench(W)
    rest = model.rest_lengths * np.linspace(0.97, 1.03, model.n_strings)
    res = solve_equilibrium(model, W, rest_lengths=rest)
    sim.set_rest_lengths(rest)
    np.testing.assert_array_equal(sim.rest_lengths, rest)
    assert sim.settle(max_time=10.0)
    dp, dr = pose_errors(sim.pose(), res.state.transform)
    assert dp <= POSITION_TOLERANCE and dr <= ROTATION_TOLERANCE


def test_rest_lengths_follow_a_rate_limit(model: JointModel) -> None:
    sim = JointSimulation(model, rest_length_rate=0.01)  # 10 mm/s
    target = model.rest_lengths + 0.002
    sim.set_rest_lengths(target)
    sim.step(100)  # 0.1 s: 1 mm of the 2 mm
    np.testing.assert_allclose(sim.rest_lengths, model.rest_lengths + 0.001, atol=1e-12)
    assert not sim.settle(max_time=0.05)  # still moving
    sim.step(150)
    np.testing.assert_allclose(sim.rest_lengths, target, atol=1e-15)
    np.testing.assert_allclose(sim.mj_model.tendon_lengthspring[:, 1], target, atol=1e-15)
    np.testing.assert_allclose(sim.mj_model.tendon_range[:, 1], target + model.max_stretch,
                               atol=1e-15)
    sim.set_rest_lengths(model.rest_lengths, rate=math.inf)  # at once
    np.testing.assert_array_equal(sim.rest_lengths, model.rest_lengths)


def test_max_length_limit_stops_the_string_ignore_does_not(model: JointModel) -> None:
    pull = np.array([0.0, -15.0, 0.0, 0.0, 0.0, 0.0])  # far beyond what lmax allows
    lengths = {}
    for mode in ('limit', 'ignore'):
        sim = JointSimulation(model, max_length=mode)
        sim.apply_wrench(pull)
        sim.step(1500)
        lengths[mode] = sim.string_lengths()
        if mode == 'limit':
            over = lengths[mode] - model.max_lengths
            assert over.max() < 1e-3  # a soft stop: passed by less than a millimetre
            # the stop's force is part of the tension: the strings hold the 3 N pull
            assert np.linalg.norm(sim.string_wrench()[:3] + pull[:3]) < 0.05
    assert np.max(lengths['ignore'] - model.max_lengths) > 5e-3


def test_imu_against_mujocos_own_velocities(model: JointModel) -> None:
    """At rest: no rotation, specific force -g in {2}. Moving (Euler, no damping, where
    v(t + dt) = v(t) + dt a(t) exactly): the specific force equals the velocity difference,
    and the angular velocity the rotation of one step."""
    sim = JointSimulation(model)
    imu = sim.imu()
    R = sim.pose()[:3, :3]
    np.testing.assert_allclose(imu.angular_velocity, 0.0, atol=1e-15)
    np.testing.assert_allclose(imu.specific_force, -R.T @ GRAVITY, atol=1e-9)
    free = JointSimulation(model, integrator='Euler', tendon_damping=0.0, joint_damping=0.0)
    free.set_screw(model.initial_screw + np.array([0.1, 0.0, -0.05, 0.003, 0.0, 0.001]))
    free.step(20)
    dt = free.options.timestep
    for _ in range(5):
        imu, T0 = free.imu(), free.pose()
        v0 = free.mj_data.qvel[:3].copy()
        free.step()
        T1 = free.pose()
        v1 = free.mj_data.qvel[:3].copy()
        expected = T0[:3, :3].T @ ((v1 - v0) / dt - GRAVITY)
        np.testing.assert_allclose(imu.specific_force, expected, rtol=1e-9, atol=1e-9)
        omega = log_so3(T0[:3, :3].T @ T1[:3, :3]) / dt  # the step's rotation, body frame
        omega_next = free.imu().angular_velocity
        np.testing.assert_allclose(omega, omega_next, rtol=1e-9, atol=1e-9)


def test_noise_is_seeded_and_has_its_standard_deviations(model: JointModel) -> None:
    sim = JointSimulation(model)
    noise = SensorNoise(lengths=1e-4, tensions=0.01, gyro=0.002, accelerometer=0.05)
    a = measure(sim, noise, np.random.default_rng(3))
    b = measure(sim, noise, np.random.default_rng(3))
    np.testing.assert_array_equal(a.lengths, b.lengths)
    np.testing.assert_array_equal(a.imu.specific_force, b.imu.specific_force)
    rng = np.random.default_rng(4)
    draws = np.array([measure(sim, noise, rng).lengths - sim.string_lengths()
                      for _ in range(2000)])
    assert abs(draws.std() / 1e-4 - 1.0) < 0.03
    exact = measure(sim, SensorNoise(), rng)
    np.testing.assert_array_equal(exact.tensions, sim.tensions())
    with pytest.raises(ValueError, match='gyro'):
        SensorNoise(gyro=-1.0)


def test_spine_string_wrenches_and_tip_load_equilibrium(chain: JointChain) -> None:
    """The spine's per-joint string wrenches equal the library's at a perturbed configuration;
    under a tip load it settles from its unloaded equilibrium where solve_chain_equilibrium
    says."""
    rng = np.random.default_rng(5)
    sim = ChainSimulation(chain, max_length='ignore')
    x = chain.unloaded_screws() + np.concatenate([rng.normal(0, 0.03, (5, 3)),
                                                  rng.normal(0, 0.001, (5, 3))], axis=1)
    sim.set_screws(x)
    state = chain.evaluate(x)
    assert np.abs(sim.joint_wrenches() - state.wrenches).max() <= \
        WRENCH_TOLERANCE * np.abs(state.wrenches).max()
    np.testing.assert_allclose(sim.string_lengths(), state.lengths, atol=1e-15)
    np.testing.assert_allclose(sim.link_poses(), state.link_transforms, atol=1e-15)
    np.testing.assert_allclose(sim.screws(), x, atol=1e-12)
    np.testing.assert_allclose(sim.joint_transforms(), state.transforms, atol=1e-14)
    W = np.array([0.04, 0.0, -0.02, 0.0, 5e-4, 0.0])
    res = solve_chain_equilibrium(chain, W)
    assert res.success and res.stable
    load = ChainSimulation(chain)
    load.apply_wrench(W)
    assert load.settle(max_time=30.0), load.net_forces()
    for T, T_ref in zip(load.link_poses(), chain.link_transforms(res.screws), strict=True):
        dp, dr = pose_errors(T, T_ref)
        assert dp <= POSITION_TOLERANCE and dr <= ROTATION_TOLERANCE


def weighted_chain(mass: float) -> JointChain:
    document = config.parameters(config.load_yaml(SPINE_CONFIG))
    document = {**document, 'chain': {**document['chain'], 'link_masses': [mass],
                                      'link_coms': [0.0, 0.01, 0.0]}}
    return JointChain.from_dict(document)


def test_spine_with_weights_settles_where_the_library_says() -> None:
    chain = weighted_chain(0.004)
    res = solve_chain_equilibrium(chain, np.zeros(6))
    assert res.success and res.stable, res.message
    sim = ChainSimulation(chain)
    np.testing.assert_array_equal(sim.gravity, GRAVITY)
    assert sim.mj_model.body_gravcomp[1:].tolist() == [0.0] * 5  # weights act
    rng = np.random.default_rng(8)
    sim.set_screws(res.screws + rng.normal(0, 1e-5, res.screws.shape))
    assert sim.settle(max_time=30.0), sim.net_forces()
    for T, T_ref in zip(sim.link_poses(), chain.link_transforms(res.screws), strict=True):
        dp, dr = pose_errors(T, T_ref)
        assert dp <= POSITION_TOLERANCE and dr <= ROTATION_TOLERANCE


def test_spine_falls_away_where_the_library_says_unstable() -> None:
    """20 g per vertebra under gravity: the library's equilibrium is unstable; the twin,
    started 1e-6 from it, falls away (the same start at the stable 4 g spine stays)."""
    rng = np.random.default_rng(9)
    departures = {}
    for mass in (0.02, 0.004):
        chain = weighted_chain(mass)
        res = solve_chain_equilibrium(chain, np.zeros(6))
        assert res.success
        assert res.stable == (mass < 0.01), res.message
        sim = ChainSimulation(chain)
        sim.set_screws(res.screws + rng.normal(0, 1e-6, res.screws.shape))
        departure = 0.0
        while sim.time < 8.0 and departure < 0.05:
            sim.step(250)
            departure = np.abs(sim.screws() - res.screws).max()
        departures[mass] = departure
    assert departures[0.02] >= 0.05      # fell away (0.05 rad within 8 s)
    assert departures[0.004] < 1e-5      # stayed for the 8 s


def test_export_mjcf_command(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    out = tmp_path / 'joint.xml'
    assert cli.main(['export-mjcf', '--out', str(out)]) == 0
    m = mujoco.MjModel.from_xml_string(out.read_text())
    assert m.ntendon == 12 and m.nbody == 2 and np.all(m.tendon_limited)
    assert cli.main(['export-mjcf', '--spine', '--max-length', 'ignore']) == 0
    spine = mujoco.MjModel.from_xml_string(capsys.readouterr().out)
    assert spine.ntendon == 60 and spine.nbody == 6 and not np.any(spine.tendon_limited)
    assert cli.main(['export-mjcf', '--config', str(tmp_path / 'missing.yaml')]) == 2
    assert 'missing.yaml' in capsys.readouterr().err


@pytest.mark.slow
def test_spine_tip_stiffness_under_load_from_small_loads(chain: JointChain) -> None:
    """The spine settled under a tip wrench; each tip-load component nudged both ways and
    settled again: the tip twists give the compliance, whose inverse equals the library's exact
    tip stiffness under load (load transport included) to 1e-5 relative (2.4e-7 measured)."""
    W = np.array([0.03, 0.0, -0.02, 0.0, 0.0, 0.0])
    sim = ChainSimulation(chain)
    sim.apply_wrench(W)
    assert sim.settle()
    x0, T0 = sim.screws(), sim.tip_pose()
    h = np.array([1e-3] * 3 + [2e-5] * 3)  # N, N m
    C = np.empty((6, 6))
    for j in range(6):
        twists = []
        for sign in (1.0, -1.0):
            sim.set_screws(x0)
            sim.apply_wrench(W + sign * h[j] * np.eye(6)[j])
            assert sim.settle(max_time=30.0)
            xi = log_se3(sim.tip_pose() @ np.linalg.inv(T0))  # [w; v]
            twists.append(np.concatenate([xi[3:], xi[:3]]))    # [dv; dw]
        C[:, j] = (twists[0] - twists[1]) / (2.0 * h[j])
    K_lib = chain.tip_stiffness(x0, tip_wrench=W)
    assert np.abs(np.linalg.inv(C) - K_lib).max() <= 1e-5 * np.abs(K_lib).max()


def test_export_mjcf_takes_link2_inertia_from_the_config(tmp_path) -> None:
    """The twin and the dynamics read the same ``joint.link2_*`` keys."""
    import yaml

    from tensegrity_stiffness.mechanics.dynamics import LinkInertia
    from tensegrity_stiffness.simulation.twin import export_mjcf

    document = config.load_yaml(config.packaged_config_path())
    joint = config.parameters(document)['joint']
    joint.update(link2_mass=0.02, link2_com=[0.0, 0.001, 0.0], link2_inertia=[1e-6, 2e-6, 3e-6])
    path = tmp_path / 'joint.yaml'
    path.write_text(yaml.safe_dump(document))
    xml = export_mjcf(path)
    inertia = LinkInertia.from_config(joint)
    assert inertia.mass == 0.02
    assert 'mass="0.02"' in xml and 'pos="0.0 0.001 0.0"' in xml
    assert 'diaginertia="1e-06 2e-06 3e-06"' in xml
