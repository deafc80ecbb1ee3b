"""Dynamics in screw coordinates against the MuJoCo twin (tensegrity_stiffness.simulation.twin).

MuJoCo computes the reference here with its own dynamics (free joints, tendon springs and
dampers, its composite-rigid-body mass matrix and bias forces): the library's accelerations
against MuJoCo's ``qacc`` of the same state, the library's modes against the eigenvalues of the
twin linearised by central differences of ``qacc`` in MuJoCo's own coordinates (``qpos``
perturbed by ``mj_integratePos``, ``qvel`` directly) at the library's equilibria, and the free
response of the twin after a small push along a mode, its spectral peak at the predicted
frequency. The state is set through the twin's public ``mj_model`` / ``mj_data`` and MuJoCo's
API: a free joint's ``qpos`` is ``[p; quat wxyz]`` of {2} in {1}, its ``qvel`` ``[p_dot (world);
omega (body)]``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest
from scipy.optimize import linear_sum_assignment
from support import JOINT_CONFIG, SPINE_CONFIG

from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
from tensegrity_stiffness.mechanics.dynamics import (
    ChainDynamics,
    JointDynamics,
    LinkInertia,
    body_jacobian,
    body_jacobian_rate,
)
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.simulation.twin import ChainSimulation, JointSimulation

mujoco = pytest.importorskip('mujoco')

#: The issue's tolerances: accelerations (relative to the largest), frequencies (relative),
#: damping ratios (absolute).
ACCELERATION_TOLERANCE = 1e-6
FREQUENCY_TOLERANCE = 1e-4
DAMPING_TOLERANCE = 1e-3
#: Spectral peak of the free response against the predicted frequency (relative): the
#: record is 400 periods of the joint's slowest mode or more, the peak parabolically refined.
PEAK_TOLERANCE = 2e-3
#: Central-difference step of the twin's linearisation (m, rad, m/s, rad/s).
TWIN_STEP = 1e-6
#: An equilibrium of the library is the twin's: MuJoCo's accelerations there (m/s^2, rad/s^2).
REST_ACCELERATION = 1e-7

MODEL = JointModel.from_yaml(JOINT_CONFIG)
CHAIN = JointChain.from_yaml(SPINE_CONFIG)
GENERAL = LinkInertia(0.02, (0.001, 0.002, -0.003),
                      [[3e-6, 1e-7, 0.0], [1e-7, 4e-6, 2e-7], [0.0, 2e-7, 5e-6]])


# ---------------------------------------------------------------------------- MuJoCo helpers
def free_state(T: np.ndarray, V: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """qpos (7,) and qvel (6,) of a free joint at pose T with body twist V = [w; v]."""
    R = T[:3, :3]
    x, y, z, w = rotation_to_quaternion(R)
    return np.r_[T[:3, 3], w, x, y, z], np.r_[R @ V[3:], V[:3]]


def free_acceleration(T: np.ndarray, V: np.ndarray, Vd: np.ndarray) -> np.ndarray:
    """qacc (6,) of a free joint from the body twist and its rate: [R (v_dot + w x v); w_dot]."""
    return np.r_[T[:3, :3] @ (Vd[3:] + np.cross(V[:3], V[3:])), Vd[:3]]


def apply_load(m: object, d: object, body: int, dof: int, W: np.ndarray) -> None:
    """The library's wrench (on the body, base frame about the base origin) as the free joint's
    generalised force at the current pose: [f; R^T (m - p x f)] (MuJoCo's kinematics first)."""
    mujoco.mj_kinematics(m, d)
    p, R = d.xpos[body], d.xmat[body].reshape(3, 3)
    d.qfrc_applied[:] = 0.0
    d.qfrc_applied[dof:dof + 3] = W[:3]
    d.qfrc_applied[dof + 3:dof + 6] = R.T @ (W[3:] - np.cross(p, W[:3]))


def forward(sim: JointSimulation | ChainSimulation, qpos: np.ndarray, qvel: np.ndarray,
            W: np.ndarray, body: int, dof: int) -> np.ndarray:
    m, d = sim.mj_model, sim.mj_data
    d.qpos[:] = qpos
    d.qvel[:] = qvel
    apply_load(m, d, body, dof, W)
    mujoco.mj_forward(m, d)
    assert d.nefc == 0  # no tendon length limit is active: MuJoCo's and the library's laws agree
    return d.qacc.copy()


def twin_eigenvalues(sim: JointSimulation | ChainSimulation, qpos: np.ndarray, W: np.ndarray,
                     body: int, dof: int) -> np.ndarray:
    """Eigenvalues of the twin linearised at rest at qpos, by central differences of MuJoCo's
    qacc: positions in MuJoCo's tangent coordinates (mj_integratePos), velocities its qvel."""
    m = sim.mj_model
    nv = m.nv
    A = np.zeros((2 * nv, 2 * nv))
    A[:nv, nv:] = np.eye(nv)
    zero = np.zeros(nv)
    for i in range(nv):
        cols = []
        for sign in (1.0, -1.0):
            dq = np.zeros(nv)
            dq[i] = sign * TWIN_STEP
            q = qpos.copy()
            mujoco.mj_integratePos(m, q, dq, 1.0)
            cols.append(forward(sim, q, zero, W, body, dof))
        A[nv:, i] = (cols[0] - cols[1]) / (2 * TWIN_STEP)
        cols = []
        for sign in (1.0, -1.0):
            v = zero.copy()
            v[i] = sign * TWIN_STEP
            cols.append(forward(sim, qpos, v, W, body, dof))
        A[nv:, nv + i] = (cols[0] - cols[1]) / (2 * TWIN_STEP)
    return np.linalg.eigvals(A)


def frequencies_and_damping(eigenvalues: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """One eigenvalue of each conjugate pair (all underdamped here), ascending in |lambda|."""
    upper = eigenvalues[eigenvalues.imag > 0.0]
    assert 2 * upper.size == eigenvalues.size, 'every mode of these cases is underdamped'
    upper = upper[np.argsort(np.abs(upper))]
    return np.abs(upper) / (2 * math.pi), -upper.real / np.abs(upper)


def spectral_peak(signal: np.ndarray, dt: float, near: float) -> float:
    """Frequency (Hz) of the largest peak of the Hann-windowed spectrum within 20 % of ``near``,
    refined by a parabola through the log magnitudes."""
    x = (signal - signal.mean(axis=0)) * np.hanning(signal.shape[0])[:, None]
    power = np.sum(np.abs(np.fft.rfft(x, axis=0)) ** 2, axis=1)
    f = np.fft.rfftfreq(signal.shape[0], dt)
    window = np.flatnonzero(np.abs(f - near) <= 0.2 * near)
    k = int(window[np.argmax(power[window])])
    a, b, c = np.log(power[k - 1:k + 2])
    return float(f[k] + 0.5 * (a - c) / (a - 2 * b + c) * (f[1] - f[0]))


# ---------------------------------------------------------------------------- the joint
def joint_twin(damping: float, inertia: LinkInertia | None = None, **options: object
               ) -> tuple[JointSimulation, int, int]:
    """The twin (joint damping off: the library models the strings' damping only) and link 2's
    body and first dof; with ``inertia``, the twin's link 2 has it (``SimulationOptions.link2``:
    centre of mass and full inertia)."""
    sim = JointSimulation(MODEL, joint_damping=0.0, tendon_damping=damping, link2=inertia,
                          **options)
    body = mujoco.mj_name2id(sim.mj_model, mujoco.mjtObj.mjOBJ_BODY, 'link2')
    return sim, body, 0


def joint_qpos(xi: np.ndarray, rate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return free_state(exp_se3(xi), body_jacobian(xi) @ rate)


@pytest.mark.parametrize('inertia', [None, GENERAL], ids=['twin_default', 'general'])
def test_joint_acceleration_is_mujocos(inertia: LinkInertia | None) -> None:
    damping = 0.3
    sim, body, dof = joint_twin(damping, inertia)
    dyn = JointDynamics(MODEL, inertia, damping)
    rng = np.random.default_rng(10)
    xi0 = MODEL.initial_screw
    for k in range(24):
        xi = xi0 + np.r_[0.05 * rng.normal(size=3), 0.002 * rng.normal(size=3)]
        rate = np.r_[3.0 * rng.normal(size=3), 0.05 * rng.normal(size=3)]
        W = np.zeros(6) if k % 3 == 0 else np.r_[0.3 * rng.normal(size=3),
                                                  0.003 * rng.normal(size=3)]
        acc = dyn.acceleration(xi, rate, external_wrench=W)
        Jb = body_jacobian(xi)
        expected = free_acceleration(exp_se3(xi), Jb @ rate,
                                     Jb @ acc + body_jacobian_rate(xi, rate))
        qacc = forward(sim, *joint_qpos(xi, rate), W, body, dof)
        np.testing.assert_allclose(expected, qacc, rtol=0.0,
                                   atol=ACCELERATION_TOLERANCE * np.abs(qacc).max())


JOINT_CASES = [  # (external wrench, rest-length scale per string or None)
    (np.zeros(6), None),
    (np.array([0.3, 0.0, 0.0, 0.0, 0.0, 0.0]), None),
    (np.array([0.0, -0.4, 0.1, 0.0, 0.0, 0.0]), None),
    (np.array([0.1, 0.2, -0.1, 0.004, -0.002, 0.003]), None),
    (np.zeros(6), 0.97),
    (np.array([0.0, 0.2, 0.0, 0.002, 0.0, 0.0]), 'random'),
]


def joint_case(index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    W, scale = JOINT_CASES[index]
    rest = MODEL.rest_lengths.copy()
    if scale == 'random':
        rest *= np.random.default_rng(11).uniform(0.96, 1.02, rest.size)
    elif scale is not None:
        rest *= scale
    res = solve_equilibrium(MODEL, W, rest, tolerance=1e-13)
    assert res.success and res.stable
    return res.screw, rest, W


@pytest.mark.parametrize('damping', [0.0, 0.3])
@pytest.mark.parametrize('case', range(len(JOINT_CASES)))
def test_joint_modes_are_the_linearised_twins(case: int, damping: float) -> None:
    xi, rest, W = joint_case(case)
    sim, body, dof = joint_twin(damping)
    sim.set_rest_lengths(rest)
    qpos, _ = joint_qpos(xi, np.zeros(6))
    assert np.abs(forward(sim, qpos, np.zeros(6), W, body, dof)).max() < REST_ACCELERATION
    f_twin, zeta_twin = frequencies_and_damping(twin_eigenvalues(sim, qpos, W, body, dof))
    modes = JointDynamics(MODEL, None, damping).modes(xi, rest, W)
    assert modes.stable
    np.testing.assert_allclose(modes.frequencies, f_twin, rtol=FREQUENCY_TOLERANCE)
    np.testing.assert_allclose(modes.damping_ratios, zeta_twin, rtol=0.0, atol=DAMPING_TOLERANCE)
    if damping == 0.0:
        np.testing.assert_allclose(modes.damping_ratios, 0.0, atol=DAMPING_TOLERANCE)


def test_joint_modes_with_a_general_inertia_are_the_linearised_twins() -> None:
    xi, rest, W = joint_case(3)
    sim, body, dof = joint_twin(0.3, GENERAL)
    qpos, _ = joint_qpos(xi, np.zeros(6))
    f_twin, zeta_twin = frequencies_and_damping(twin_eigenvalues(sim, qpos, W, body, dof))
    modes = JointDynamics(MODEL, GENERAL, 0.3).modes(xi, rest, W)
    np.testing.assert_allclose(modes.frequencies, f_twin, rtol=FREQUENCY_TOLERANCE)
    np.testing.assert_allclose(modes.damping_ratios, zeta_twin, rtol=0.0, atol=DAMPING_TOLERANCE)


def check_ringing(sim: Any, qvel: np.ndarray, steps: int, dt: float, frequency: float,
                  k: int) -> None:
    """The twin ``sim`` started with the velocities ``qvel`` and run ``steps`` steps of ``dt``:
    its velocity spectrum peaks at mode ``k``'s ``frequency`` (Hz, within PEAK_TOLERANCE)."""
    sim.mj_data.qvel[:] = qvel
    mujoco.mj_forward(sim.mj_model, sim.mj_data)
    record = np.empty((steps, qvel.size))
    for s in range(steps):
        sim.step()
        record[s] = sim.mj_data.qvel
    peak = spectral_peak(record, dt, frequency)
    assert abs(peak - frequency) <= PEAK_TOLERANCE * frequency, (k, peak, frequency)


@pytest.mark.slow
def test_joint_free_response_rings_at_the_predicted_frequencies() -> None:
    """The twin pushed along each mode (a velocity of 1e-3 times the mode shape), undamped,
    8 s at 10 kHz: its velocity spectrum peaks at that mode's frequency."""
    dt, duration = 1e-4, 8.0
    sim, _, _ = joint_twin(0.0, None, timestep=dt, integrator='Euler')
    dyn = JointDynamics(MODEL)
    xi = MODEL.initial_screw
    modes = dyn.modes(xi)
    steps = round(duration / dt)
    for k in range(6):
        sim.set_screw(xi)
        rate = 1e-3 * modes.shapes[k].real / np.abs(modes.shapes[k].real).max()
        _, qvel = joint_qpos(xi, rate)
        check_ringing(sim, qvel, steps, dt, modes.frequencies[k], k)


# ---------------------------------------------------------------------------- the spine
#: Light weights under gravity (the spine stands; twice these buckle it: test_dynamics.py).
MASSES = np.array([0.01, 0.005, 0.015, 0.005, 0.01])
HEAVY = JointChain(CHAIN.joints, CHAIN.link_offsets, CHAIN.tool, MASSES,
                   np.tile([0.001, 0.01, -0.002], (5, 1)), gravity=CHAIN.gravity)


def chain_twin(chain: JointChain, damping: float, **options: object
               ) -> tuple[ChainSimulation, int, int]:
    sim = ChainSimulation(chain, joint_damping=0.0, tendon_damping=damping, **options)
    n = chain.n_joints
    body = mujoco.mj_name2id(sim.mj_model, mujoco.mjtObj.mjOBJ_BODY, f'link_{n}')
    return sim, body, 6 * (n - 1)


def chain_qpos(dyn: ChainDynamics, screws: np.ndarray, rates: np.ndarray
               ) -> tuple[np.ndarray, np.ndarray]:
    L = dyn.chain.link_transforms(screws)
    V, _ = dyn.body_velocities(screws, rates)
    parts = [free_state(L[i], V[i]) for i in range(dyn.n_joints)]
    return np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts])


@pytest.mark.parametrize('chain', [CHAIN, HEAVY], ids=['massless', 'weights'])
def test_chain_acceleration_is_mujocos(chain: JointChain) -> None:
    damping = 0.2
    sim, body, dof = chain_twin(chain, damping)
    dyn = ChainDynamics(chain, None, damping)
    rng = np.random.default_rng(12)
    base = chain.unloaded_screws()
    for k in range(10):
        xi = base + np.c_[0.03 * rng.normal(size=(5, 3)), 0.001 * rng.normal(size=(5, 3))]
        rate = np.c_[2.0 * rng.normal(size=(5, 3)), 0.03 * rng.normal(size=(5, 3))]
        W = np.zeros(6) if k % 2 == 0 else np.r_[0.05 * rng.normal(size=3),
                                                  0.001 * rng.normal(size=3)]
        acc = dyn.acceleration(xi, rate, tip_wrench=W)
        L = chain.link_transforms(xi)
        V, Vd = dyn.body_velocities(xi, rate, acc)
        expected = np.concatenate([free_acceleration(L[i], V[i], Vd[i]) for i in range(5)])
        qacc = forward(sim, *chain_qpos(dyn, xi, rate), W, body, dof)
        np.testing.assert_allclose(expected, qacc, rtol=0.0,
                                   atol=ACCELERATION_TOLERANCE * np.abs(qacc).max())


CHAIN_CASES = [  # (chain, tip wrench)
    (CHAIN, np.zeros(6)),
    (CHAIN, np.array([0.05, 0.0, -0.03, 0.0, 0.001, 0.0])),
    (CHAIN, np.array([0.0, -0.2, 0.0, 0.0, 0.0, 0.002])),
    (HEAVY, np.zeros(6)),
    (HEAVY, np.array([0.03, 0.0, 0.02, 0.0, 0.0, 0.0])),
]


@pytest.mark.parametrize('damping', [0.0, 0.1])
@pytest.mark.parametrize('case', range(len(CHAIN_CASES)))
def test_chain_modes_are_the_linearised_twins(case: int, damping: float) -> None:
    chain, W = CHAIN_CASES[case]
    res = solve_chain_equilibrium(chain, W, tolerance=1e-13)
    assert res.success and res.stable
    sim, body, dof = chain_twin(chain, damping)
    dyn = ChainDynamics(chain, None, damping)
    qpos, _ = chain_qpos(dyn, res.screws, np.zeros((5, 6)))
    assert np.abs(forward(sim, qpos, np.zeros(30), W, body, dof)).max() < REST_ACCELERATION
    f_twin, zeta_twin = frequencies_and_damping(twin_eigenvalues(sim, qpos, W, body, dof))
    modes = dyn.modes(res.screws, tip_wrench=W)
    assert modes.stable
    np.testing.assert_allclose(modes.frequencies, f_twin, rtol=FREQUENCY_TOLERANCE)
    np.testing.assert_allclose(modes.damping_ratios, zeta_twin, rtol=0.0, atol=DAMPING_TOLERANCE)


@pytest.mark.slow
def test_chain_free_response_rings_at_the_predicted_frequencies() -> None:
    """The spine twin pushed along a few of its modes (slowest, a middle and a fast one),
    undamped: the velocity spectrum peaks at each mode's frequency."""
    dyn = ChainDynamics(CHAIN)
    xi = CHAIN.unloaded_screws()
    modes = dyn.modes(xi)
    # The slowest mode (1.5 Hz) for 200 periods at 1 ms (its frequency found to 4e-6 of the
    # bound 2e-3: Euler's error at 1 ms is (2 pi f dt)^2 ~ 1e-4 of it for 1.5 Hz, and the spine's
    # fastest mode is far inside the step's stability); the others 8 s at 0.2 ms.
    twins = {dt: chain_twin(CHAIN, 0.0, timestep=dt, integrator='Euler')[0]
             for dt in (1e-3, 2e-4)}
    for k in (0, 2, 8, 16):
        dt = 1e-3 if k == 0 else 2e-4
        sim = twins[dt]
        duration = 200.0 / modes.frequencies[0] if k == 0 else 8.0
        steps = round(duration / dt)
        sim.set_screws(xi)
        shape = modes.shapes[k].real.reshape(5, 6)
        _, qvel = chain_qpos(dyn, xi, 1e-3 * shape / np.abs(shape).max())
        check_ringing(sim, qvel, steps, dt, modes.frequencies[k], k)


@pytest.mark.parametrize('damping', [0.0, 0.3])
def test_joint_unstable_equilibrium_is_unstable_in_the_twin(damping: float) -> None:
    """At an unstable equilibrium (slack strings) every eigenvalue of the library's linear
    model is the linearised twin's, including the one with Re > 0."""
    start = np.array([2.608, 1.894, -1.407, -0.038, -0.019, 0.001])
    res = solve_equilibrium(MODEL, np.zeros(6), initial_screw=start, tolerance=1e-13)
    assert res.success and not res.stable
    sim, body, dof = joint_twin(damping)
    qpos, _ = joint_qpos(res.screw, np.zeros(6))
    twin = twin_eigenvalues(sim, qpos, np.zeros(6), body, dof)
    dyn = JointDynamics(MODEL, None, damping)
    A, _ = dyn.linearize(res.screw)
    library = np.linalg.eigvals(A)
    # Pair each eigenvalue with its nearest (an assignment: sorting complex numbers is fragile).
    rows, cols = linear_sum_assignment(np.abs(library[:, None] - twin[None, :]))
    np.testing.assert_allclose(library[rows], twin[cols], rtol=0.0,
                               atol=FREQUENCY_TOLERANCE * np.abs(twin).max())
    assert twin.real.max() > 0.0 and not dyn.modes(res.screw).stable
