"""Dynamics in screw coordinates (tensegrity_stiffness.mechanics.dynamics), numpy-only checks.

Every closed form against the geometry it came from: the mass matrix against the kinetic energy
of link 2 from central differences of ``expm(hat(xi + t xi_dot))`` (scipy's exponential, not the
package's), the Coriolis terms against the Christoffel symbols of central differences of ``M``,
the generalized force against the energy, the linear model against central differences of the
accelerations, its static gain against re-solved equilibria. The twin (MuJoCo) checks are in
test_dynamics_twin.py.
"""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
from support import JOINT_CONFIG, SPINE_CONFIG

from tensegrity_stiffness.geometry.screw import hat, left_jacobian_se3, vee, vee3
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
from tensegrity_stiffness.mechanics.dynamics import (
    DEFAULT_LINK_MASS,
    DEFAULT_STRING_DAMPING,
    ChainDynamics,
    JointDynamics,
    LinkInertia,
    body_jacobian,
    body_jacobian_rate,
    chain_inertias_from_config,
    default_inertia_moments,
    format_modes,
    jacobian_derivatives,
    modes_from_config,
    modes_report,
    twin_link_inertias,
)
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel

#: The issue's tolerance of the mass matrix (relative).
MASS_TOLERANCE = 1e-6
#: Central-difference checks of derivatives (relative to the largest entry).
DERIVATIVE_TOLERANCE = 1e-6
#: Step of the central differences.
STEP = 1e-6
#: Static gain against re-solved equilibria (relative).
GAIN_TOLERANCE = 1e-6

MODEL = JointModel.from_yaml(JOINT_CONFIG)
XI0 = solve_equilibrium(MODEL, np.zeros(6)).screw
#: An inertia with everything non-trivial: centre of mass off the origin, full inertia matrix.
GENERAL = LinkInertia(0.02, (0.001, 0.002, -0.003),
                      [[3e-6, 1e-7, 0.0], [1e-7, 4e-6, 2e-7], [0.0, 2e-7, 5e-6]])
AXIS = np.array([1.0, 0.0, -1.0]) / math.sqrt(2.0)


def states() -> list[np.ndarray]:
    """>= 40 screws: near the equilibrium, random, |omega| from 1e-7 to pi - 1e-6."""
    rng = np.random.default_rng(0)
    out = [XI0 + np.r_[0.05 * rng.normal(size=3), 0.002 * rng.normal(size=3)]
           for _ in range(10)]
    out += [np.r_[rng.normal(size=3), 0.02 * rng.normal(size=3)] for _ in range(16)]
    for theta in (1e-7, 1e-5, 1e-3, 0.4999, 0.5, 0.5001, 1.0, 2.0):
        u = rng.normal(size=3)
        out.append(np.r_[theta * u / np.linalg.norm(u), 0.02 * rng.normal(size=3)])
    for axis in (AXIS, np.array([0.0, 0.0, 1.0]), rng.normal(size=3)):
        for theta in (math.pi - 1e-6, math.pi, math.pi + 1e-6):
            out.append(np.r_[theta * axis / np.linalg.norm(axis), 0.01, -0.02, 0.015])
    out.append(np.r_[0.0, 0.0, 0.0, 0.01, 0.02, 0.03])
    return out


STATES = states()


def kinetic_energy(inertia: LinkInertia, nodes: np.ndarray, xi: np.ndarray,
                   rate: np.ndarray, h: float = 1e-5) -> float:
    """1/2 m |c_dot|^2 + 1/2 w^T R I R^T w from central differences of scipy's expm."""
    T0 = scipy.linalg.expm(hat(xi))
    Td = (scipy.linalg.expm(hat(xi + h * rate)) - scipy.linalg.expm(hat(xi - h * rate))) / (2 * h)
    R, Rd = T0[:3, :3], Td[:3, :3]
    w = vee3(Rd @ R.T)
    c_dot = Rd @ inertia.com + Td[:3, 3]
    I_world = R @ inertia.inertia_matrix(nodes) @ R.T
    return 0.5 * inertia.mass * c_dot @ c_dot + 0.5 * w @ I_world @ w


# ---------------------------------------------------------------------------- mass matrix
def test_at_least_40_states_span_the_angles() -> None:
    theta = np.array([np.linalg.norm(x[:3]) for x in STATES])
    assert len(STATES) >= 40
    assert theta.min() <= 1e-7 * (1 + 1e-12)
    assert np.any(np.abs(theta - (math.pi - 1e-6)) < 1e-12)


@pytest.mark.parametrize('inertia', [GENERAL, LinkInertia()], ids=['general', 'twin_default'])
def test_mass_matrix_is_the_kinetic_energy(inertia: LinkInertia) -> None:
    dyn = JointDynamics(MODEL, inertia)
    rng = np.random.default_rng(1)
    nodes = MODEL.link2_nodes
    E = np.eye(6)
    for xi in STATES:
        M = dyn.mass_matrix(xi)
        # Every entry by polarization of the kinetic energy.
        ke = {i: kinetic_energy(inertia, nodes, xi, E[i]) for i in range(6)}
        ref = np.empty((6, 6))
        for i in range(6):
            ref[i, i] = 2.0 * ke[i]
            for k in range(i + 1, 6):
                ref[i, k] = ref[k, i] = kinetic_energy(inertia, nodes, xi, E[i] + E[k]) - \
                    ke[i] - ke[k]
        np.testing.assert_allclose(M, ref, rtol=0.0, atol=MASS_TOLERANCE * np.abs(ref).max())
        for _ in range(2):
            rate = np.r_[rng.normal(size=3), 0.05 * rng.normal(size=3)]
            np.testing.assert_allclose(0.5 * rate @ M @ rate,
                                       kinetic_energy(inertia, nodes, xi, rate),
                                       rtol=MASS_TOLERANCE)


def test_mass_matrix_symmetric_positive_definite() -> None:
    dyn = JointDynamics(MODEL, GENERAL)
    for xi in STATES:
        M = dyn.mass_matrix(xi)
        np.testing.assert_array_equal(M, M.T)
        assert np.linalg.eigvalsh(M)[0] > 0.0


def test_mass_matrix_at_zero_rotation_is_the_spatial_inertia() -> None:
    """At xi = 0 both Jacobians are the identity: M = G."""
    dyn = JointDynamics(MODEL, GENERAL)
    np.testing.assert_allclose(dyn.mass_matrix(np.zeros(6)), dyn.spatial_inertia, rtol=1e-15,
                               atol=1e-20)


# ---------------------------------------------------------------------------- kinematics
def test_body_jacobian_against_central_differences() -> None:
    rng = np.random.default_rng(2)
    for xi in STATES:
        rate = rng.normal(size=6)
        T = scipy.linalg.expm(hat(xi))
        Td = (scipy.linalg.expm(hat(xi + STEP * rate)) -
              scipy.linalg.expm(hat(xi - STEP * rate))) / (2 * STEP)
        ref = vee(np.linalg.solve(T, Td))
        np.testing.assert_allclose(body_jacobian(xi) @ rate, ref, rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * np.abs(ref).max())


def test_body_jacobian_rate_against_central_differences() -> None:
    rng = np.random.default_rng(3)
    h = 1e-5
    for xi in STATES:
        rate = rng.normal(size=6)
        ref = (body_jacobian(xi + h * rate) - body_jacobian(xi - h * rate)) @ rate / (2 * h)
        np.testing.assert_allclose(body_jacobian_rate(xi, rate), ref, rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * max(np.abs(ref).max(), 1.0))


def test_jacobian_derivatives_against_central_differences() -> None:
    for xi in STATES[::4]:
        dJl, dJb = jacobian_derivatives(xi)
        for i in range(6):
            e = np.eye(6)[i] * STEP
            ref_l = (left_jacobian_se3(xi + e) - left_jacobian_se3(xi - e)) / (2 * STEP)
            ref_b = (body_jacobian(xi + e) - body_jacobian(xi - e)) / (2 * STEP)
            np.testing.assert_allclose(dJl[i], ref_l, rtol=0.0, atol=DERIVATIVE_TOLERANCE)
            np.testing.assert_allclose(dJb[i], ref_b, rtol=0.0, atol=DERIVATIVE_TOLERANCE)


def test_string_length_jacobian_against_central_differences() -> None:
    dyn = JointDynamics(MODEL)
    for xi in STATES[:26]:
        L = dyn.string_length_jacobian(xi)
        ref = np.array([(MODEL.lengths(xi + STEP * e) - MODEL.lengths(xi - STEP * e)) /
                        (2 * STEP) for e in np.eye(6)]).T
        np.testing.assert_allclose(L, ref, rtol=0.0, atol=DERIVATIVE_TOLERANCE)


# ---------------------------------------------------------------------------- forces
def test_generalized_force_is_minus_the_energy_gradient() -> None:
    """Q = J_l^T Pi F = -dU/dxi (without load and damping); F alone is not (errata)."""
    dyn = JointDynamics(MODEL)
    for xi in STATES[:26]:
        Q = dyn.generalized_force(xi)
        grad = np.array([(MODEL.energy(xi + STEP * e) - MODEL.energy(xi - STEP * e)) /
                         (2 * STEP) for e in np.eye(6)])
        np.testing.assert_allclose(Q, -grad, rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * max(np.abs(grad).max(), 1e-3))


def test_damping_force_is_minus_c_dl_dt_along_each_string() -> None:
    """The damping's power is -sum c_j (dl_j/dt)^2, from central differences of the lengths."""
    c = np.linspace(0.1, 1.2, MODEL.n_strings)
    dyn = JointDynamics(MODEL, string_damping=c)
    rng = np.random.default_rng(4)
    for xi in STATES[:10]:
        rate = rng.normal(size=6)
        Qd = dyn.generalized_force(xi, rate) - dyn.generalized_force(xi)
        l_dot = (MODEL.lengths(xi + STEP * rate) - MODEL.lengths(xi - STEP * rate)) / (2 * STEP)
        np.testing.assert_allclose(Qd @ rate, -np.sum(c * l_dot ** 2), rtol=1e-7)


def test_coriolis_against_christoffel_symbols_of_central_differences() -> None:
    """b = dM/dt xi_dot - 1/2 d(xi_dot^T M xi_dot)/dxi, M differentiated numerically."""
    dyn = JointDynamics(MODEL, GENERAL)
    rng = np.random.default_rng(5)
    for xi in STATES:
        rate = np.r_[rng.normal(size=3), 0.05 * rng.normal(size=3)]
        dM = [(dyn.mass_matrix(xi + STEP * e) - dyn.mass_matrix(xi - STEP * e)) / (2 * STEP)
              for e in np.eye(6)]
        ref = sum(dM[i] * rate[i] for i in range(6)) @ rate - 0.5 * np.array(
            [rate @ dM[i] @ rate for i in range(6)])
        np.testing.assert_allclose(dyn.coriolis(xi, rate), ref, rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * np.abs(ref).max())


def test_energy_is_conserved_by_the_equations_without_damping() -> None:
    """d/dt (kinetic + potential) = W . twist = 0 (unloaded): M xi_ddot + b = Q conserves it."""
    dyn = JointDynamics(MODEL, GENERAL)
    rng = np.random.default_rng(6)
    for xi in STATES[:10]:
        rate = np.r_[rng.normal(size=3), 0.05 * rng.normal(size=3)]
        acc = dyn.acceleration(xi, rate)
        dM = sum((dyn.mass_matrix(xi + STEP * e) - dyn.mass_matrix(xi - STEP * e)) /
                 (2 * STEP) * rate[i] for i, e in enumerate(np.eye(6)))
        kinetic_rate = rate @ dyn.mass_matrix(xi) @ acc + 0.5 * rate @ dM @ rate
        potential_rate = (MODEL.energy(xi + STEP * rate) - MODEL.energy(xi - STEP * rate)) / \
            (2 * STEP)
        scale = abs(potential_rate) + abs(kinetic_rate) + 1e-9
        assert abs(kinetic_rate + potential_rate) <= DERIVATIVE_TOLERANCE * scale


# ---------------------------------------------------------------------------- linear model
LOADS = [np.zeros(6), np.array([0.3, -0.2, 0.1, 0.002, -0.001, 0.003])]


def numerical_linearization(dyn: JointDynamics, xi: np.ndarray, rest: np.ndarray,
                            W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = dyn.model.n_strings
    A = np.zeros((12, 12))
    A[:6, 6:] = np.eye(6)
    B = np.zeros((12, n + 6))
    zero = np.zeros(6)
    for i, e in enumerate(np.eye(6)):
        A[6:, i] = (dyn.acceleration(xi + STEP * e, zero, rest, W) -
                    dyn.acceleration(xi - STEP * e, zero, rest, W)) / (2 * STEP)
        A[6:, 6 + i] = (dyn.acceleration(xi, STEP * e, rest, W) -
                        dyn.acceleration(xi, -STEP * e, rest, W)) / (2 * STEP)
        B[6:, n + i] = (dyn.acceleration(xi, zero, rest, W + STEP * e) -
                        dyn.acceleration(xi, zero, rest, W - STEP * e)) / (2 * STEP)
    for j in range(n):
        d = np.zeros(n)
        d[j] = 1e-7
        B[6:, j] = (dyn.acceleration(xi, zero, rest + d, W) -
                    dyn.acceleration(xi, zero, rest - d, W)) / 2e-7
    return A, B


@pytest.mark.parametrize('damping', [0.0, 0.4])
@pytest.mark.parametrize('load', range(len(LOADS)))
def test_linearize_against_central_differences_at_equilibria(damping: float, load: int) -> None:
    dyn = JointDynamics(MODEL, GENERAL, damping)
    W = LOADS[load]
    xi = solve_equilibrium(MODEL, W).screw
    A, B = dyn.linearize(xi, external_wrench=W)
    An, Bn = numerical_linearization(dyn, xi, MODEL.rest_lengths, W)
    np.testing.assert_allclose(A, An, rtol=0.0, atol=DERIVATIVE_TOLERANCE * np.abs(An).max())
    for cols in (slice(0, 12), slice(12, 18)):
        np.testing.assert_allclose(B[:, cols], Bn[:, cols], rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * np.abs(Bn[:, cols]).max())


def test_linearize_off_equilibrium_and_near_pi() -> None:
    """Away from an equilibrium the derivatives of J_l and M enter (exact, tested here)."""
    dyn = JointDynamics(MODEL, GENERAL, 0.2)
    for xi in (XI0 + np.r_[0.04, -0.03, 0.02, 0.001, 0.002, -0.001],
               np.r_[(math.pi - 1e-6) * AXIS, 0.0166, 0.0, 0.0166], STATES[30]):
        A, B = dyn.linearize(xi)
        An, Bn = numerical_linearization(dyn, xi, MODEL.rest_lengths, np.zeros(6))
        np.testing.assert_allclose(A, An, rtol=0.0, atol=DERIVATIVE_TOLERANCE * np.abs(An).max())
        np.testing.assert_allclose(B, Bn, rtol=0.0, atol=DERIVATIVE_TOLERANCE * np.abs(Bn).max())


@pytest.mark.parametrize('load', range(len(LOADS)))
def test_static_gain_is_the_equilibrium_sensitivity(load: int) -> None:
    """-A21^-1 B (lower rows) = d xi_eq / d(l0, W) by central differences of solve_equilibrium."""
    dyn = JointDynamics(MODEL, GENERAL, 0.3)
    W = LOADS[load]
    xi = solve_equilibrium(MODEL, W).screw
    A, B = dyn.linearize(xi, external_wrench=W)
    gain = -np.linalg.solve(A[6:, :6], B[6:])
    n = MODEL.n_strings
    h = 1e-7
    for j in range(n + 6):
        rest_p, rest_m = MODEL.rest_lengths.copy(), MODEL.rest_lengths.copy()
        W_p, W_m = W.copy(), W.copy()
        if j < n:
            rest_p[j] += h
            rest_m[j] -= h
        else:
            W_p[j - n] += h
            W_m[j - n] -= h
        x_p = solve_equilibrium(MODEL, W_p, rest_p, xi, tolerance=1e-14).screw
        x_m = solve_equilibrium(MODEL, W_m, rest_m, xi, tolerance=1e-14).screw
        ref = (x_p - x_m) / (2 * h)
        np.testing.assert_allclose(gain[:, j], ref, rtol=0.0,
                                   atol=GAIN_TOLERANCE * np.abs(ref).max())


# ---------------------------------------------------------------------------- modes
def quadratic_residual(dyn: JointDynamics, xi: np.ndarray, lam: complex,
                       shape: np.ndarray) -> float:
    """|(lambda^2 M - lambda A22' - A21') v| / |lambda^2 M v| (the second-order eigenproblem)."""
    A, _ = dyn.linearize(xi)
    M = dyn.mass_matrix(xi)
    Kq, Dq = -M @ A[6:, :6], -M @ A[6:, 6:]
    r = (lam ** 2 * M + lam * Dq + Kq) @ shape
    return float(np.linalg.norm(r) / np.linalg.norm(lam ** 2 * M @ shape))


@pytest.mark.parametrize('damping', [0.0, 0.5])
def test_modes_solve_the_eigenproblem(damping: float) -> None:
    dyn = JointDynamics(MODEL, GENERAL, damping)
    modes = dyn.modes(XI0)
    assert modes.frequencies.shape == (6,) and modes.shapes.shape == (6, 6)
    assert np.all(np.diff(modes.frequencies) >= 0.0) and modes.stable
    np.testing.assert_allclose(modes.frequencies, np.abs(modes.eigenvalues) / (2 * math.pi),
                               rtol=1e-14)
    np.testing.assert_allclose(modes.damping_ratios,
                               -modes.eigenvalues.real / np.abs(modes.eigenvalues), rtol=1e-14)
    for k in range(6):
        assert quadratic_residual(dyn, XI0, modes.eigenvalues[k], modes.shapes[k]) < 1e-10
        np.testing.assert_allclose(modes.twists[k],
                                   (left_jacobian_se3(XI0)[[3, 4, 5, 0, 1, 2]] @
                                    modes.shapes[k]).real, atol=1e-15)
    if damping == 0.0:
        np.testing.assert_allclose(modes.damping_ratios, 0.0, atol=1e-9)
        A, _ = dyn.linearize(XI0)
        omega2 = np.sort(np.linalg.eigvals(-A[6:, :6]).real)
        np.testing.assert_allclose(modes.frequencies, np.sqrt(omega2) / (2 * math.pi),
                                   rtol=1e-10)
    else:
        assert np.all(modes.damping_ratios > 0.0)


#: Starting points from which the solver finds unstable unloaded equilibria of the default joint
#: (slack strings; found by a seeded search), and the stable default.
UNSTABLE_STARTS = [np.array([0.251, -0.264, 1.281, 0.003, -0.016, 0.011]),
                   np.array([2.608, 1.894, -1.407, -0.038, -0.019, 0.001]),
                   np.array([0.823, 2.085, -0.257, 0.041, -0.02, 0.011])]


@pytest.mark.parametrize('damping', [0.0, 0.3])
def test_modes_flag_unstable_equilibria(damping: float) -> None:
    """The modes' stability equals the library's (symmetric part of K_c) at unstable
    equilibria and at the stable default, damped or not."""
    dyn = JointDynamics(MODEL, GENERAL, damping)
    for start in [*UNSTABLE_STARTS, MODEL.initial_screw]:
        res = solve_equilibrium(MODEL, np.zeros(6), initial_screw=start)
        assert res.success
        modes = dyn.modes(res.screw)
        assert modes.stable == res.stable
        assert res.stable == (start is MODEL.initial_screw)


def test_frequency_response_at_zero_is_the_compliance() -> None:
    dyn = JointDynamics(MODEL, GENERAL, 0.3)
    W = LOADS[1]
    res = solve_equilibrium(MODEL, W)
    H = dyn.frequency_response(res.screw, [0.0, 10.0], external_wrench=W)
    Kc = MODEL.cartesian_stiffness(res.screw)
    np.testing.assert_allclose(H[0].real, np.linalg.inv(Kc), rtol=0.0,
                               atol=1e-8 * np.abs(np.linalg.inv(Kc)).max())
    np.testing.assert_allclose(H[0].imag, 0.0, atol=1e-12)
    assert not np.allclose(H[1], H[0])


def test_modes_report_is_plain_json() -> None:
    dyn = JointDynamics(MODEL, GENERAL, 0.3)
    report = modes_report(dyn.modes(XI0), [GENERAL], dyn.string_damping)
    text = json.dumps(report)
    back = json.loads(text)
    assert len(back['modes']) == 6 and back['stable'] is True
    assert back['modes'][0]['frequency_hz'] == pytest.approx(dyn.modes(XI0).frequencies[0])


# ---------------------------------------------------------------------------- inertia, config
def test_default_inertia_equals_the_twins_mjcf() -> None:
    """The twin's MJCF (joint and spine) carries exactly LinkInertia()'s default."""
    from tensegrity_stiffness.simulation.twin import DEFAULT_LINK_MASS as TWIN_MASS
    from tensegrity_stiffness.simulation.twin import chain_mjcf, joint_mjcf

    assert DEFAULT_LINK_MASS == TWIN_MASS
    inertial = re.findall(r'<inertial pos="([^"]*)" mass="([^"]*)" diaginertia="([^"]*)"',
                          joint_mjcf(MODEL))
    pos, mass, diag = inertial[0]
    li = LinkInertia()
    assert float(mass) == li.mass
    np.testing.assert_array_equal(np.fromstring(pos, sep=' '), li.com)
    np.testing.assert_array_equal(np.fromstring(diag, sep=' '),
                                  np.diag(li.inertia_matrix(MODEL.link2_nodes)))
    chain = JointChain.from_yaml(SPINE_CONFIG)
    heavy = JointChain(chain.joints, chain.link_offsets, chain.tool,
                       [0.02, 0.0, 0.03, 0.0, 0.05], np.tile([0.001, 0.01, -0.002], (5, 1)),
                       gravity=chain.gravity)
    for c in (chain, heavy):
        found = re.findall(r'<inertial pos="([^"]*)" mass="([^"]*)" diaginertia="([^"]*)"',
                           chain_mjcf(c))
        for (pos, mass, diag), li, model in zip(found, twin_link_inertias(c), c.joints,
                                                strict=True):
            assert float(mass) == li.mass
            np.testing.assert_array_equal(np.fromstring(pos, sep=' '), li.com)
            np.testing.assert_array_equal(np.fromstring(diag, sep=' '),
                                          np.diag(li.inertia_matrix(model.link2_nodes)))
    assert np.all(default_inertia_moments(np.zeros((2, 3)), 0.01) > 0.0)


def test_link_inertia_forms_and_config() -> None:
    full = LinkInertia(0.02, [0, 0, 0], [[2e-6, 0, 0], [0, 3e-6, 0], [0, 0, 4e-6]])
    moments = LinkInertia(0.02, (0, 0, 0), (2e-6, 3e-6, 4e-6))
    np.testing.assert_array_equal(full.inertia, moments.inertia)
    li = LinkInertia.from_config({'link2_mass': 0.03, 'link2_com': [0.0, 0.001, 0.0],
                                  'link2_inertia': [1e-6, 2e-6, 3e-6]})
    assert li.mass == 0.03 and li.com[1] == 0.001 and li.inertia[2, 2] == 3e-6
    empty = LinkInertia.from_config({'link2_inertia': [], 'link2_com': None})
    assert empty.inertia is None and empty.mass == DEFAULT_LINK_MASS and not np.any(empty.com)
    with pytest.raises(ValueError, match=r'joint\.link2_mass'):
        LinkInertia.from_config({'link2_mass': -1.0})
    with pytest.raises(ValueError, match=r'joint\.link2_inertia'):
        LinkInertia.from_config({'link2_inertia': [1.0, 2.0]})


def test_chain_inertias_from_config() -> None:
    import yaml

    document = yaml.safe_load(SPINE_CONFIG.read_text())
    params = document['/**']['ros__parameters']
    default = chain_inertias_from_config(document)
    assert [li.mass for li in default] == [DEFAULT_LINK_MASS] * 5
    assert all(li.inertia is None for li in default)
    params['chain']['link_masses'] = [0.02]
    params['chain']['link_coms'] = [0.0, 0.001, 0.0]
    params['chain']['link_inertias'] = [1e-6, 2e-6, 3e-6]
    custom = chain_inertias_from_config(document)
    assert [li.mass for li in custom] == [0.02] * 5
    assert all(li.com[1] == 0.001 and li.inertia[1, 1] == 2e-6 for li in custom)
    params['chain']['link_inertias'] = [1e-6] * 4
    with pytest.raises(ValueError, match=r'chain\.link_inertias'):
        chain_inertias_from_config(document)
    params['chain']['link_inertias'] = [1e-6, 2e-6, -3e-6]
    with pytest.raises(ValueError, match=r'chain\.link_inertias'):
        chain_inertias_from_config(document)


@pytest.mark.parametrize(('kwargs', 'match'), [
    ({'mass': 0.0}, 'mass'), ({'mass': math.nan}, 'mass'), ({'mass': True}, 'mass'),
    ({'mass': -1.0}, 'mass'), ({'com': (0.0, 1.0)}, 'com'), ({'com': (0.0, 0.0, math.nan)}, 'com'),
    ({'inertia': [[1.0, 0.5, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}, 'symmetric'),
    ({'inertia': [1.0, -1.0, 1.0]}, 'positive definite'),
    ({'inertia': [[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]}, 'positive definite'),
    ({'inertia': [1.0, 1.0]}, 'inertia')])
def test_link_inertia_rejects_bad_values(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        LinkInertia(**kwargs)


@pytest.mark.parametrize('given', [None, 0.0])
def test_an_unknown_dynamics_key_is_refused_with_the_nearest(given) -> None:
    """``dynamics.string_dampin: 0`` is not left out (the damping staying at its default):
    refused, as the joint's and chain's unknown keys are, even when the damping is given."""
    import yaml

    expected = r'dynamics\.string_dampin: unknown key \(did you mean dynamics\.string_damping\?\)'
    for path, cls in ((JOINT_CONFIG, JointDynamics), (SPINE_CONFIG, ChainDynamics)):
        document = yaml.safe_load(path.read_text())
        document['/**']['ros__parameters']['dynamics'] = {'string_dampin': 0.0, 'enabled': True}
        with pytest.raises(ValueError, match=expected):
            cls.from_config(document, given)


def test_bad_inputs_name_the_argument() -> None:
    dyn = JointDynamics(MODEL)
    with pytest.raises(ValueError, match='model'):
        JointDynamics('joint')  # type: ignore[arg-type]
    with pytest.raises(ValueError, match='inertia'):
        JointDynamics(MODEL, 0.01)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match='string_damping'):
        JointDynamics(MODEL, string_damping=-0.1)
    with pytest.raises(ValueError, match='string_damping'):
        JointDynamics(MODEL, string_damping=[0.1, 0.2])
    with pytest.raises(ValueError, match='xi'):
        dyn.mass_matrix(np.zeros(5))
    with pytest.raises(ValueError, match='xi'):
        dyn.mass_matrix([math.nan, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match='xi'):
        dyn.mass_matrix([7.0, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match='xi_dot'):
        dyn.acceleration(XI0, np.zeros(3))
    with pytest.raises(ValueError, match='external_wrench'):
        dyn.linearize(XI0, external_wrench=np.zeros(5))
    with pytest.raises(ValueError, match='rest_lengths'):
        dyn.modes(XI0, rest_lengths=np.ones(3))
    with pytest.raises(ValueError, match='frequencies_hz'):
        dyn.frequency_response(XI0, [-1.0])
    chain = JointChain.from_yaml(SPINE_CONFIG)
    with pytest.raises(ValueError, match='inertias'):
        ChainDynamics(chain, [LinkInertia()])
    with pytest.raises(ValueError, match='string_damping'):
        ChainDynamics(chain, string_damping=[0.1, 0.2])
    cd = ChainDynamics(chain)
    with pytest.raises(ValueError, match='screws'):
        cd.mass_matrix(np.zeros((4, 6)))
    with pytest.raises(ValueError, match='not an equilibrium'):
        cd.linearize(chain.unloaded_screws(), tip_wrench=[0.1, 0, 0, 0, 0, 0])


# ---------------------------------------------------------------------------- spines
CHAIN = JointChain.from_yaml(SPINE_CONFIG)
#: Weights under gravity, light enough to stand (twice these masses buckle the spine).
MASSES = np.array([0.01, 0.005, 0.015, 0.005, 0.01])
HEAVY = JointChain(CHAIN.joints, CHAIN.link_offsets, CHAIN.tool, MASSES,
                   np.tile([0.001, 0.01, -0.002], (5, 1)), gravity=CHAIN.gravity)


def chain_kinetic_energy(dyn: ChainDynamics, screws: np.ndarray, rates: np.ndarray,
                         h: float = 1e-5) -> float:
    """Sum over the links of 1/2 m |c_dot|^2 + 1/2 w^T I w from scipy's expm of each joint."""
    def poses(x: np.ndarray) -> list[np.ndarray]:
        out, current = [], np.eye(4)
        for i in range(dyn.n_joints):
            current = current @ scipy.linalg.expm(hat(x[i]))
            out.append(current)
            if i < dyn.n_joints - 1:
                current = current @ dyn.chain.link_offsets[i]
        return out

    L0, Lp, Lm = poses(screws), poses(screws + h * rates), poses(screws - h * rates)
    total = 0.0
    for i, li in enumerate(dyn.inertias):
        Ld = (Lp[i] - Lm[i]) / (2 * h)
        R, Rd = L0[i][:3, :3], Ld[:3, :3]
        w = vee3(Rd @ R.T)
        c_dot = Rd @ li.com + Ld[:3, 3]
        I_world = R @ li.inertia_matrix(dyn.chain.joints[i].link2_nodes) @ R.T
        total += 0.5 * li.mass * c_dot @ c_dot + 0.5 * w @ I_world @ w
    return total


def test_chain_mass_matrix_is_the_kinetic_energy() -> None:
    inertias = [GENERAL, LinkInertia(), GENERAL, LinkInertia(0.03, (0.0, 0.01, 0.0)), GENERAL]
    dyn = ChainDynamics(CHAIN, inertias)
    rng = np.random.default_rng(7)
    base = CHAIN.unloaded_screws()
    for k in range(8):
        screws = base + np.c_[0.1 * rng.normal(size=(5, 3)), 0.003 * rng.normal(size=(5, 3))]
        if k == 0:
            screws = base
        M = dyn.mass_matrix(screws)
        np.testing.assert_array_equal(M, M.T)
        assert np.linalg.eigvalsh(M)[0] > 0.0
        for _ in range(4):
            rates = np.c_[rng.normal(size=(5, 3)), 0.05 * rng.normal(size=(5, 3))]
            np.testing.assert_allclose(0.5 * rates.ravel() @ M @ rates.ravel(),
                                       chain_kinetic_energy(dyn, screws, rates),
                                       rtol=MASS_TOLERANCE)


def test_one_joint_chain_equals_the_joint() -> None:
    chain = JointChain([MODEL])
    cd = ChainDynamics(chain, [GENERAL], 0.3)
    jd = JointDynamics(MODEL, GENERAL, 0.3)
    rate = np.array([0.3, -0.2, 0.5, 0.01, 0.02, -0.01])
    np.testing.assert_allclose(cd.mass_matrix(XI0[None]), jd.mass_matrix(XI0), rtol=1e-13,
                               atol=1e-16)
    np.testing.assert_allclose(cd.acceleration(XI0[None], rate[None])[0],
                               jd.acceleration(XI0, rate), rtol=1e-10)
    np.testing.assert_allclose(cd.modes(XI0[None]).frequencies, jd.modes(XI0).frequencies,
                               rtol=1e-10)
    H = cd.tip_frequency_response(XI0[None], [0.0, 12.0])
    np.testing.assert_allclose(H, jd.frequency_response(XI0, [0.0, 12.0]), rtol=1e-9,
                               atol=1e-12)


def chain_equilibrium(chain: JointChain, W: np.ndarray, rest: list | None = None,
                      start: np.ndarray | None = None) -> np.ndarray:
    res = solve_chain_equilibrium(chain, W, rest_lengths=rest, initial_screws=start,
                                  tolerance=1e-14)
    assert res.residual < 1e-12, res.message
    return res.screws


@pytest.mark.parametrize('chain', [CHAIN, HEAVY], ids=['massless', 'weights'])
def test_chain_linearize_against_central_differences(chain: JointChain) -> None:
    dyn = ChainDynamics(chain, string_damping=0.2)
    W = np.array([0.05, 0.0, -0.03, 0.0, 0.001, 0.0])
    xi = chain_equilibrium(chain, W)
    A, B = dyn.linearize(xi, tip_wrench=W)
    zero = np.zeros((5, 6))
    n6 = 30
    for c in range(n6):
        e = np.zeros(n6)
        e[c] = STEP
        e = e.reshape(5, 6)
        col = (dyn.acceleration(xi + e, zero, tip_wrench=W) -
               dyn.acceleration(xi - e, zero, tip_wrench=W)).ravel() / (2 * STEP)
        np.testing.assert_allclose(A[n6:, c], col, rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * np.abs(A[n6:, :n6]).max())
        col = (dyn.acceleration(xi, e, tip_wrench=W) -
               dyn.acceleration(xi, -e, tip_wrench=W)).ravel() / (2 * STEP)
        np.testing.assert_allclose(A[n6:, n6 + c], col, rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * np.abs(A[n6:, n6:]).max())
    for c in range(6):
        e = np.eye(6)[c] * STEP
        col = (dyn.acceleration(xi, zero, tip_wrench=W + e) -
               dyn.acceleration(xi, zero, tip_wrench=W - e)).ravel() / (2 * STEP)
        np.testing.assert_allclose(B[n6:, -6 + c], col, rtol=0.0,
                                   atol=DERIVATIVE_TOLERANCE * np.abs(B[n6:, -6:]).max())


def test_chain_static_gain_is_the_equilibrium_sensitivity() -> None:
    dyn = ChainDynamics(HEAVY, string_damping=0.2)
    W = np.array([0.05, 0.0, -0.03, 0.0, 0.001, 0.0])
    xi = chain_equilibrium(HEAVY, W)
    A, B = dyn.linearize(xi, tip_wrench=W)
    gain = -np.linalg.solve(A[30:, :30], B[30:])
    h = 1e-7
    rest0 = [m.rest_lengths.copy() for m in HEAVY.joints]
    for joint, string in np.ndindex(5, 12):  # every rest length of every joint
        rp = [r.copy() for r in rest0]
        rm = [r.copy() for r in rest0]
        rp[joint][string] += h
        rm[joint][string] -= h
        ref = (chain_equilibrium(HEAVY, W, rp, xi) - chain_equilibrium(HEAVY, W, rm, xi)
               ).ravel() / (2 * h)
        np.testing.assert_allclose(gain[:, 12 * joint + string], ref, rtol=0.0,
                                   atol=GAIN_TOLERANCE * np.abs(ref).max())
    for c in range(6):
        e = np.eye(6)[c] * h
        ref = (chain_equilibrium(HEAVY, W + e, None, xi) -
               chain_equilibrium(HEAVY, W - e, None, xi)).ravel() / (2 * h)
        np.testing.assert_allclose(gain[:, 60 + c], ref, rtol=0.0,
                                   atol=GAIN_TOLERANCE * np.abs(ref).max())


def test_chain_tip_frequency_response_at_zero_is_the_tip_compliance() -> None:
    dyn = ChainDynamics(HEAVY, string_damping=0.2)
    W = np.array([0.05, 0.0, -0.03, 0.0, 0.001, 0.0])
    xi = chain_equilibrium(HEAVY, W)
    H = dyn.tip_frequency_response(xi, [0.0, 5.0], tip_wrench=W)
    C = np.linalg.inv(HEAVY.tip_stiffness(xi, W))
    np.testing.assert_allclose(H[0].real, C, rtol=0.0, atol=1e-8 * np.abs(C).max())
    modes = dyn.modes(xi, tip_wrench=W)
    assert modes.frequencies.shape == (30,) and modes.stable
    assert np.all(np.diff(modes.frequencies) >= 0.0)


def test_chain_modes_agree_with_the_chains_stability() -> None:
    """Twice the masses buckle the spine under gravity: the library's equilibrium says unstable
    and so do the modes (an eigenvalue with Re > 0)."""
    for scale in (1.0, 2.0):
        chain = JointChain(CHAIN.joints, CHAIN.link_offsets, CHAIN.tool, scale * MASSES,
                           HEAVY.link_coms, gravity=CHAIN.gravity)
        res = solve_chain_equilibrium(chain, np.zeros(6), tolerance=1e-14)
        modes = ChainDynamics(chain, string_damping=0.2).modes(res.screws)
        assert modes.stable == res.stable == (scale == 1.0)


def test_mode_figures_are_written(tmp_path: Path) -> None:
    pytest.importorskip('matplotlib')
    from tensegrity_stiffness.cli.dynamics_plots import plot_joint_modes, plot_spine_modes

    out = plot_joint_modes(MODEL, JointDynamics(MODEL, string_damping=0.5).modes(XI0),
                           tmp_path / 'joint.png', width=600, height=400)
    assert out.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    out = plot_spine_modes(CHAIN, ChainDynamics(CHAIN).modes(CHAIN.unloaded_screws()),
                           tmp_path / 'spine.png', count=2, width=600, height=400)
    assert out.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    with pytest.raises(ValueError, match='count'):
        plot_spine_modes(CHAIN, ChainDynamics(CHAIN).modes(CHAIN.unloaded_screws()),
                         tmp_path / 'x.png', count=0)
    with pytest.raises(ValueError, match='width'):
        plot_joint_modes(MODEL, JointDynamics(MODEL).modes(XI0), tmp_path / 'x.png', width=5)


def test_modes_from_config_and_table(tmp_path: Path) -> None:
    import yaml

    dyn, modes, report = modes_from_config()
    assert isinstance(dyn, JointDynamics)
    # The packaged config gives no string damping: the twin's (one value, issue #39).
    from tensegrity_stiffness.simulation.twin import DEFAULT_TENDON_DAMPING

    np.testing.assert_allclose(dyn.string_damping, DEFAULT_TENDON_DAMPING)
    np.testing.assert_allclose(modes.frequencies, JointDynamics(
        MODEL, string_damping=DEFAULT_STRING_DAMPING).modes(XI0).frequencies, rtol=1e-12)
    assert json.loads(json.dumps(report))['inertias'][0]['mass'] == DEFAULT_LINK_MASS
    table = format_modes(modes)
    assert table.count('\n') == 7 and 'stable: yes' in table
    document = yaml.safe_load(JOINT_CONFIG.read_text())
    document['/**']['ros__parameters']['joint']['link2_mass'] = 0.005
    document['/**']['ros__parameters']['dynamics'] = {'string_damping': 0.5}
    path = tmp_path / 'joint.yaml'
    path.write_text(yaml.safe_dump(document))
    _, light, report = modes_from_config(path)
    np.testing.assert_allclose(light.frequencies, JointDynamics(
        MODEL, LinkInertia(0.005), 0.5).modes(XI0).frequencies, rtol=1e-12)
    assert report['string_damping'] == [0.5] * 12
    chain_dyn, spine, report = modes_from_config(spine=True)
    assert isinstance(chain_dyn, ChainDynamics)
    assert spine.frequencies.shape == (30,) and 'joint 1' in format_modes(spine)


def test_modes_at_a_pose_are_those_of_its_balancing_load() -> None:
    dyn = JointDynamics(MODEL, GENERAL, 0.3)
    xi = XI0 + np.r_[0.04, -0.03, 0.02, 0.001, 0.002, -0.001]
    modes, W = dyn.modes_at_pose(xi)
    np.testing.assert_allclose(W, -MODEL.wrench(xi), rtol=1e-14)
    res = solve_equilibrium(MODEL, W, initial_screw=xi, tolerance=1e-14)
    np.testing.assert_allclose(res.screw, xi, atol=1e-12)
    np.testing.assert_allclose(modes.frequencies, dyn.modes(res.screw, external_wrench=W
                                                            ).frequencies, rtol=1e-9)


def test_halving_the_mass_raises_every_frequency_by_sqrt2() -> None:
    """The twin's default inertia scales with the mass, so M halves and f grows by sqrt(2)."""
    heavy = JointDynamics(MODEL, LinkInertia(0.01)).modes(XI0).frequencies
    light = JointDynamics(MODEL, LinkInertia(0.005)).modes(XI0).frequencies
    np.testing.assert_allclose(light, math.sqrt(2.0) * heavy, rtol=1e-12)


# ---------------------------------------------------------------------------- compiled kernel
#: The compiled linear model against the numpy path, relative to each block's largest entry
#: (both compute the same sums in another order: rounding, amplified by the 6x6 solve).
KERNEL_TOLERANCE = 1e-12
#: Mode shapes of the two paths (an eigenvector moves by rounding over the gap between
#: eigenvalues: 1e-13 on the default joint, whose frequencies come in near pairs).
SHAPE_TOLERANCE = 1e-9


def numpy_twin(dyn: JointDynamics) -> JointDynamics:
    """``dyn`` on the numpy path: the same model without the compiled kernel."""
    m = dyn.model
    model = JointModel(m.link1_nodes, m.connections, m.k, m.rest_lengths,
                       link2_nodes=m.link2_nodes, max_lengths=m.max_lengths,
                       force_law=m.force_law, initial_screw=m.initial_screw, use_kernel=False)
    return JointDynamics(model, dyn.inertia, dyn.string_damping)


def kernel_cases() -> list[tuple[JointDynamics, np.ndarray, np.ndarray, np.ndarray]]:
    """(dynamics, screw, rest lengths, load) at equilibria: the default joint under the test
    loads, damped, undamped and per string; random joints of both force laws (slack, taut and
    saturated strings) at random poses held by their balancing load."""
    from support.joint_compare import random_model

    rng = np.random.default_rng(7)
    cases = []
    for damping in (0.0, 0.4, rng.uniform(0.0, 1.0, MODEL.n_strings)):
        for W in LOADS:
            xi = solve_equilibrium(MODEL, W).screw
            cases.append((JointDynamics(MODEL, GENERAL, damping), xi, MODEL.rest_lengths, W))
    for law in ('hooke', 'paper'):
        k = 0
        while k < 6:
            model = random_model(rng, law)
            xi = np.r_[rng.normal(scale=0.4, size=3), rng.normal(scale=0.02, size=3)]
            lengths = model.evaluate(xi).lengths
            rest = lengths * rng.uniform(0.8, 1.03, lengths.size)  # slack, taut, saturated
            W = -model.evaluate(xi, rest).wrench
            dyn = JointDynamics(model, None if k % 2 else GENERAL, 0.3 * (k % 3))
            # Only joints without a mechanism (a zero eigenvalue, whose frequency rounding
            # decides): the smallest |eigenvalue| of A21 well above the largest's rounding.
            mu = np.abs(np.linalg.eigvals(numpy_twin(dyn).linearize(xi, rest, W)[0][6:, :6]))
            if mu.min() >= 1e-6 * mu.max():
                cases.append((dyn, xi, rest, W))
                k += 1
    return cases


@pytest.mark.skipif(not MODEL.uses_kernel, reason='the compiled kernel is not loaded')
def test_the_compiled_linear_model_equals_the_numpy_path(monkeypatch) -> None:
    """linearize and modes with the kernel (tsk_joint_linear_model) equal the numpy path's;
    every case goes through the kernel (counted), off an equilibrium the numpy path runs."""
    from tensegrity_stiffness.mechanics import kernel

    calls = []
    library = kernel.library()
    real = library.linear_model
    monkeypatch.setattr(library, 'linear_model', lambda *a: calls.append(1) or real(*a))
    saturated = 0
    for dyn, xi, rest, W in kernel_cases():
        dyn = JointDynamics(dyn.model.with_rest_lengths(dyn.model.rest_lengths), dyn.inertia,
                            dyn.string_damping)  # a kernel bound to the counting call
        ref = numpy_twin(dyn)
        assert not ref.model.uses_kernel
        saturated += int(dyn.model.evaluate(xi, rest).saturated.sum())
        before = len(calls)
        A, B = dyn.linearize(xi, rest, W)
        assert len(calls) == before + 1
        A0, B0 = ref.linearize(xi, rest, W)
        n = dyn.model.n_strings
        for new, old in ((A[6:, :6], A0[6:, :6]), (A[6:, 6:], A0[6:, 6:]), (B[6:, :n], B0[6:, :n]),
                         (B[6:, n:], B0[6:, n:])):
            np.testing.assert_allclose(new, old, rtol=0.0,
                                       atol=KERNEL_TOLERANCE * np.abs(old).max())
        np.testing.assert_array_equal(A[:6], A0[:6])
        np.testing.assert_array_equal(B[:6], B0[:6])
        modes, modes0 = dyn.modes(xi, rest, W), ref.modes(xi, rest, W)
        assert modes.stable == modes0.stable
        lam = np.abs(modes0.eigenvalues).max()
        np.testing.assert_allclose(modes.eigenvalues, modes0.eigenvalues, rtol=0.0,
                                   atol=KERNEL_TOLERANCE * lam)
        np.testing.assert_allclose(modes.frequencies, modes0.frequencies, rtol=0.0,
                                   atol=KERNEL_TOLERANCE * lam)
        np.testing.assert_allclose(modes.shapes, modes0.shapes, rtol=0.0, atol=SHAPE_TOLERANCE)
    assert saturated > 0  # the paper law's saturated branch of dF/dl0 was exercised
    # Off an equilibrium the kernel's blocks are not used (the derivatives of J and M are numpy's).
    dyn = JointDynamics(MODEL, GENERAL, 0.2)
    off = XI0 + np.r_[0.04, -0.03, 0.02, 0.001, 0.002, -0.001]
    for new, old in zip(dyn.linearize(off), numpy_twin(dyn).linearize(off), strict=True):
        np.testing.assert_allclose(new, old, rtol=0.0, atol=KERNEL_TOLERANCE * np.abs(old).max())


@pytest.mark.parametrize('damping', [0.0, 0.5, 40.0])
@pytest.mark.parametrize('load', range(len(LOADS)))
def test_modes_are_numpy_eig_of_the_linear_model(damping: float, load: int) -> None:
    """The modes (LAPACK's dgeev through scipy) are the eigen-decomposition np.linalg.eig gives
    of A: each eigenvalue one of numpy's, each shape numpy's eigenvector (top half, unit norm,
    largest component real); 40 N s/m makes modes overdamped (real eigenvalues, the pairs of
    the overdamped branch)."""
    dyn = JointDynamics(MODEL, GENERAL, damping)
    W = LOADS[load]
    xi = solve_equilibrium(MODEL, W).screw
    A, _ = dyn.linearize(xi, external_wrench=W)
    modes = dyn.modes(xi, external_wrench=W)
    lam, vec = np.linalg.eig(A)
    if damping == 40.0:
        overdamped = modes.eigenvalues.imag == 0.0
        assert overdamped.sum() >= 5 and np.all(modes.damping_ratios[overdamped] > 1.0)
    for k in range(6):
        j = int(np.argmin(np.abs(lam - modes.eigenvalues[k])))
        assert abs(lam[j] - modes.eigenvalues[k]) <= 1e-12 * np.abs(lam).max()
        v = vec[:6, j] / np.linalg.norm(vec[:6, j])
        big = v[np.argmax(np.abs(v))]
        np.testing.assert_allclose(modes.shapes[k], v * abs(big) / big, atol=SHAPE_TOLERANCE)
