"""Planar mechanism: geometry, energy, forward kinematics, Jacobian and stiffness (Ji, Li & Lin).

Printed equations that are wrong (``docs/errata.md``, second paper) are kept here as ``_printed_*``
helpers; each has a test showing the printed form fails and the corrected form passes.
"""

import itertools
import math

import numpy as np
import pytest

from tensegrity_stiffness.mechanics.planar import (
    NODE_NAMES,
    SPRINGS,
    PlanarForwardResult,
    PlanarMechanism,
)

SQRT3 = math.sqrt(3.0)
#: Central-difference steps (first and second derivatives).
H1 = 1e-6
H2 = 1e-4
#: Relative tolerance of the Jacobian against central differences (issue: 1e-7).
JACOBIAN_RTOL = 1e-7
#: Agreement of closed forms that should be identical up to rounding.
EXACT_RTOL = 1e-12


@pytest.fixture
def mech() -> PlanarMechanism:
    """Parameters of Figs. 2-3 and 7-8."""
    return PlanarMechanism(L=1.0, K1=200.0, K2=100.0)


def random_states(n: int, seed: int, L3_max: float = 2.0) -> tuple[np.ndarray, ...]:
    """Random (L3, theta1, theta2) over the default ranges (theta2 over a full turn)."""
    rng = np.random.default_rng(seed)
    return (rng.uniform(0.0, L3_max, n), rng.uniform(0.0, math.pi, n),
            rng.uniform(-math.pi, math.pi, n))


def _eq4_energy(m: PlanarMechanism, L3, t1, t2):
    """Eq. (4) transcribed term by term from the paper."""
    L, K1, K2 = m.L, m.K1, m.K2
    c1, s1 = np.cos(t1), np.sin(t1)
    return ((K1 + K2) / 2 * (5 * L ** 2 + L3 ** 2 + 2 * SQRT3 * L * L3 * s1)
            + (K1 - K2) * L * L3 * c1
            + ((2 * K1 - K2) * L ** 2 + (K1 / 2 + K2) * L * L3 * c1
               + SQRT3 / 2 * K1 * L * L3 * s1) * np.cos(t2)
            + ((K1 / 2 + K2) * L * L3 * s1 - SQRT3 / 2 * K1 * L * L3 * c1
               + SQRT3 * K2 * L ** 2) * np.sin(t2))


# ---------------------------------------------------------------------- geometry and energy
def test_node_positions_eq1(mech):
    p = mech.node_positions(1.3, 0.4, 2.1)
    L = mech.L
    np.testing.assert_allclose(p[0], [0.0, 0.0])
    np.testing.assert_allclose(p[1], [-L, -SQRT3 * L])
    np.testing.assert_allclose(p[2], [L, -SQRT3 * L])
    np.testing.assert_allclose(p[3], [1.3 * math.cos(0.4), 1.3 * math.sin(0.4)])
    # both triangles equilateral: base side 2L, mobile side L
    d = lambda i, j: np.linalg.norm(p[i] - p[j])  # noqa: E731
    np.testing.assert_allclose([d(0, 1), d(0, 2), d(1, 2)], [2 * L] * 3, rtol=1e-14)
    np.testing.assert_allclose([d(3, 4), d(3, 5), d(4, 5)], [L] * 3, rtol=1e-14)
    assert NODE_NAMES.index('D3') == 5


def test_spring_assignment_is_the_only_one_matching_eq4(mech):
    """Derive the springs: of all 81 (Ci-Dj, Ck-Dl) pairs only (C2-D2, C3-D3) gives eq. (4)."""
    L3, t1, t2 = random_states(50, seed=1)
    p = mech.node_positions(L3, t1, t2)
    target = _eq4_energy(mech, L3, t1, t2)
    matches = []
    for (a, b), (c, d) in itertools.product(itertools.product(range(3), range(3, 6)), repeat=2):
        u = (0.5 * mech.K1 * np.sum((p[:, b] - p[:, a]) ** 2, axis=-1)
             + 0.5 * mech.K2 * np.sum((p[:, d] - p[:, c]) ** 2, axis=-1))
        if np.allclose(u, target, rtol=1e-12, atol=0.0):
            matches.append(((NODE_NAMES[a], NODE_NAMES[b]), (NODE_NAMES[c], NODE_NAMES[d])))
    assert matches == [SPRINGS]


@pytest.mark.parametrize('K1, K2', [(200.0, 100.0), (100.0, 10.0), (0.3, 7.0)])
def test_geometric_energy_equals_eq4(K1, K2):
    m = PlanarMechanism(L=0.7, K1=K1, K2=K2)
    L3, t1, t2 = random_states(1000, seed=2, L3_max=1.4)
    geo = m.geometric_energy(L3, t1, t2)
    np.testing.assert_allclose(m.energy(L3, t1, t2), geo, rtol=EXACT_RTOL, atol=0.0)
    np.testing.assert_allclose(_eq4_energy(m, L3, t1, t2), geo, rtol=EXACT_RTOL, atol=0.0)


def test_torque_eq41_and_stiffness_eq42_against_central_differences(mech):
    L3, t1, t2 = random_states(200, seed=3)
    U = mech.geometric_energy  # independent of the closed form
    dU = (U(L3, t1, t2 + H1) - U(L3, t1, t2 - H1)) / (2 * H1)
    d2U = (U(L3, t1, t2 + H2) - 2 * U(L3, t1, t2) + U(L3, t1, t2 - H2)) / H2 ** 2
    scale = mech.stiffness_closed_form(L3, t1)  # amplitude of tau and K
    np.testing.assert_allclose(mech.torque(L3, t1, t2) / scale, dU / scale, atol=1e-8)
    np.testing.assert_allclose(mech.stiffness(L3, t1, t2) / scale, d2U / scale, atol=1e-6)


def test_eq43_and_eq45_hold(mech):
    """Eq. (43) d^j U = -d^(j+2) U (j >= 1) and eq. (45) d2K = d4U = -d2U."""
    L3, t1, t2 = random_states(100, seed=4)
    K = mech.stiffness
    tau = mech.torque(L3, t1, t2)
    d3U = (K(L3, t1, t2 + H1) - K(L3, t1, t2 - H1)) / (2 * H1)
    scale = mech.stiffness_closed_form(L3, t1)
    np.testing.assert_allclose(tau / scale, -d3U / scale, atol=1e-8)  # j = 1
    d2K = (K(L3, t1, t2 + H2) - 2 * K(L3, t1, t2) + K(L3, t1, t2 - H2)) / H2 ** 2
    np.testing.assert_allclose(d2K / scale, -K(L3, t1, t2) / scale, atol=1e-6)  # eq. (45)


def test_eq44_printed_sign_is_wrong(mech):
    """Eq. (44) prints dK/dtheta2 = -d3U/dtheta2^3; it is +d3U/dtheta2^3 = -dU/dtheta2."""
    L3, t1, t2 = random_states(100, seed=5)
    K = mech.stiffness
    dK = (K(L3, t1, t2 + H1) - K(L3, t1, t2 - H1)) / (2 * H1)
    tau = mech.torque(L3, t1, t2)
    d3U = -tau  # eq. (43), checked above
    scale = mech.stiffness_closed_form(L3, t1)
    np.testing.assert_allclose(dK / scale, d3U / scale, atol=1e-8)  # corrected: +d3U = -dU
    printed = -d3U
    assert np.max(np.abs(dK - printed) / scale) > 0.1


# ---------------------------------------------------------------------- forward kinematics
def test_forward_returns_stable_equilibrium(mech):
    L3, t1, _ = random_states(200, seed=6)
    grid = np.linspace(-math.pi, math.pi, 20001)
    for a, b in zip(L3[:20], t1[:20], strict=True):
        r = mech.forward(a, b)
        assert isinstance(r, PlanarForwardResult)
        assert r.stable and r.stiffness > 0.0
        assert abs(mech.torque(a, b, r.theta2)) < 1e-10 * r.stiffness
        # energy minimum over a full turn, the unstable root the maximum
        U = mech.energy(a, b, grid)
        assert r.energy <= U.min() + 1e-9 * abs(U).max()
        assert r.energy_unstable >= U.max() - 1e-9 * abs(U).max()
        assert r.stiffness_unstable == -r.stiffness
        np.testing.assert_allclose(mech.stiffness(a, b, r.theta2_unstable), -r.stiffness,
                                   rtol=1e-12)
        # eqs. (2)-(3)
        np.testing.assert_allclose([r.x, r.y], [a * math.cos(b) + math.cos(r.theta2),
                                                a * math.sin(b) + math.sin(r.theta2)], atol=1e-14)
        assert mech.theta2_min <= r.theta2 < mech.theta2_min + 2 * math.pi
        assert r.theta2_in_range == (r.theta2 <= mech.theta2_max)
        assert r.actuator_in_range


def test_paper_root_in_0_pi_is_stable_only_where_eta1_negative(mech):
    """Errata (docs/errata.md): the root of eq. (5) in [0, pi] is the energy minimum only where
    eta1 < 0."""
    L3, t1, _ = random_states(2000, seed=7)
    e1, e2 = mech.eta(L3, t1)
    paper_root = np.mod(np.arctan2(e1, e2), math.pi)  # arctan of eq. (5) in [0, pi)
    K_paper = mech.stiffness(L3, t1, paper_root)
    np.testing.assert_array_equal(K_paper > 0, e1 < 0)
    assert np.mean(e1 < 0) < 0.1  # a small part of the workspace for K1 = 200, K2 = 100
    g = mech.forward_grid(L3, t1)
    np.testing.assert_array_equal(g.theta2_in_range, e1 <= 0)


def test_eta_eq6_eq7_and_equilibrium_angles(mech):
    L3, t1, _ = random_states(100, seed=8)
    L, K1, K2 = mech.L, mech.K1, mech.K2
    e1 = (K1 + 2 * K2) * L3 * np.sin(t1) - SQRT3 * K1 * L3 * np.cos(t1) + 2 * K2 * SQRT3 * L
    e2 = 2 * (2 * K1 - K2) * L + (K1 + 2 * K2) * L3 * np.cos(t1) + SQRT3 * K1 * L3 * np.sin(t1)
    np.testing.assert_allclose(mech.eta(L3, t1), (e1, e2), rtol=1e-13)
    ts, tu = mech.equilibrium_angles(L3, t1)
    np.testing.assert_allclose(np.tan(ts), e1 / e2, rtol=1e-9)  # eq. (5), both roots
    np.testing.assert_allclose(np.tan(tu), e1 / e2, rtol=1e-9)


def test_forward_grid_matches_scalar_forward(mech):
    L3, t1, _ = random_states(300, seed=9)
    g = mech.forward_grid(L3, t1)
    for i in range(0, 300, 7):
        r = mech.forward(L3[i], t1[i])
        np.testing.assert_allclose([g.x[i], g.y[i], g.theta2[i], g.stiffness[i], g.energy[i],
                                    g.jacobian_determinant[i]],
                                   [r.x, r.y, r.theta2, r.stiffness, r.energy,
                                    r.jacobian_determinant], rtol=1e-13, atol=1e-13)
        np.testing.assert_allclose(g.jacobian[i], r.jacobian, rtol=1e-13, atol=1e-13)
        assert tuple(n for n in g.singular if g.singular[n][i]) == r.singularities


def test_stiffness_eq47_equals_eq42(mech):
    """Eq. (47) (with eq. 46 corrected) is eq. (42) at the paper's root in [0, pi]; on the stable
    root the stiffness is |eq. 47| = L/2 sqrt(eta1^2 + eta2^2)."""
    L3, t1, _ = random_states(1000, seed=10)
    e1, e2 = mech.eta(L3, t1)
    paper_root = np.mod(np.arctan2(e1, e2), math.pi)
    np.testing.assert_allclose(mech.stiffness_eq47(L3, t1), mech.stiffness(L3, t1, paper_root),
                               rtol=EXACT_RTOL * 100)
    g = mech.forward_grid(L3, t1)
    np.testing.assert_allclose(mech.stiffness_closed_form(L3, t1), g.stiffness, rtol=1e-13)
    np.testing.assert_allclose(np.abs(mech.stiffness_eq47(L3, t1)), g.stiffness, rtol=1e-12)
    stable_paper = e1 < 0
    np.testing.assert_allclose(mech.stiffness_eq47(L3, t1)[stable_paper],
                               g.stiffness[stable_paper], rtol=1e-12)


def test_eq46_printed_cos_is_wrong(mech):
    L3, t1, _ = random_states(500, seed=11)
    e1, e2 = mech.eta(L3, t1)
    root = np.mod(np.arctan2(e1, e2), math.pi)
    corrected = np.sqrt(e1 ** 2 / (e1 ** 2 + e2 ** 2)) * e2 / e1
    printed = np.sqrt(e2 ** 2 / (e1 ** 2 + e2 ** 2)) * e2 / e1
    np.testing.assert_allclose(np.sin(root), np.sqrt(e1 ** 2 / (e1 ** 2 + e2 ** 2)), atol=1e-13)
    np.testing.assert_allclose(np.cos(root), corrected, atol=1e-12)
    assert np.max(np.abs(np.cos(root) - printed)) > 1.0


# ---------------------------------------------------------------------- Jacobian
def _fd_jacobian(m: PlanarMechanism, L3, t1, h=H1):
    def xy(a, b):
        g = m.forward_grid(a, b)
        return np.stack([g.x, g.y], axis=-1)
    dL = (xy(L3 + h, t1) - xy(L3 - h, t1)) / (2 * h)
    dt = (xy(L3, t1 + h) - xy(L3, t1 - h)) / (2 * h)
    return np.stack([dL, dt], axis=-1)


def test_jacobian_against_central_differences(mech):
    L3, t1, _ = random_states(1000, seed=12)
    L3 = np.clip(L3, 1e-3, None)
    J = mech.forward_grid(L3, t1).jacobian
    J_fd = _fd_jacobian(mech, L3, t1)
    err = np.max(np.abs(J - J_fd), axis=(-2, -1)) / np.max(np.abs(J), axis=(-2, -1))
    assert err.max() < JACOBIAN_RTOL
    # scalar path too
    r = mech.forward(L3[0], t1[0])
    np.testing.assert_allclose(r.jacobian, J[0], rtol=1e-13)


def test_jacobian_against_central_differences_other_parameters():
    m = PlanarMechanism(L=0.5, K1=3.0, K2=11.0, theta1_min=-math.pi, theta1_max=math.pi)
    rng = np.random.default_rng(13)
    L3, t1 = rng.uniform(0.05, 1.0, 500), rng.uniform(-math.pi, math.pi, 500)
    r = m.singularity_residuals(L3, t1)
    keep = np.abs(r['v']) > 1e-2  # the Jacobian blows up at the fold only through FD error
    L3, t1 = L3[keep], t1[keep]
    J = m.forward_grid(L3, t1).jacobian
    err = np.max(np.abs(J - _fd_jacobian(m, L3, t1)), axis=(-2, -1)) / np.max(
        np.abs(J), axis=(-2, -1))
    assert err.max() < JACOBIAN_RTOL


def test_eq22_dtheta2_is_cos2_times_d_tan(mech):
    """Eq. (22) read as d theta2/dp = cos^2(theta2) d(tan theta2)/dp, tan theta2 = eta1/eta2."""
    L3, t1, _ = random_states(300, seed=14)
    K1, K2 = mech.K1, mech.K2
    c1, s1 = np.cos(t1), np.sin(t1)
    e1, e2 = mech.eta(L3, t1)
    de1_dL3 = (K1 + 2 * K2) * s1 - SQRT3 * K1 * c1
    de2_dL3 = (K1 + 2 * K2) * c1 + SQRT3 * K1 * s1
    de1_dt1 = L3 * de2_dL3
    de2_dt1 = -L3 * de1_dL3
    th2 = mech.forward_grid(L3, t1).theta2
    cos2 = np.cos(th2) ** 2
    eq22_L3 = cos2 * (de1_dL3 * e2 - e1 * de2_dL3) / e2 ** 2
    eq22_t1 = cos2 * (de1_dt1 * e2 - e1 * de2_dt1) / e2 ** 2

    def dstable(a1, b1, a0, b0):  # angle difference, unwrapped across +-pi
        d = mech.equilibrium_angles(a1, b1)[0] - mech.equilibrium_angles(a0, b0)[0]
        return np.angle(np.exp(1j * d)) / (2 * H1)
    fd_L3 = dstable(L3 + H1, t1, L3 - H1, t1)
    fd_t1 = dstable(L3, t1 + H1, L3, t1 - H1)
    np.testing.assert_allclose(eq22_L3, fd_L3, rtol=1e-6, atol=1e-7)
    np.testing.assert_allclose(eq22_t1, fd_t1, rtol=1e-6, atol=1e-7)


def _printed_eq24_detJ(m: PlanarMechanism, L3, t1, t2):
    """Eqs. (23)-(25) with Phi1 as printed (4 L3 L sin theta2)."""
    L, K1, K2 = m.L, m.K1, m.K2
    c1, s1 = np.cos(t1), np.sin(t1)
    e1, e2 = m.eta(L3, t1)
    q = (4 * L ** 2 * (K1 ** 2 + K2 ** 2 - K1 * K2) + L3 ** 2 * (K1 ** 2 + K2 ** 2 + K1 * K2)
         + 2 * L3 * L * c1 * (K1 ** 2 - K2 ** 2) + 2 * SQRT3 * L3 * L * s1 * (K1 ** 2 + K2 ** 2))
    phi2 = e1 * (e1 ** 2 + e2 ** 2)
    phi1 = phi2 + 4 * L3 * L * np.sin(t2) * (K1 + 2 * K2) * q
    return L3 * phi1 / phi2


@pytest.mark.parametrize('L', [1.0, 0.4])
def test_det_jacobian_eq23_corrected_matches_and_printed_fails(L):
    m = PlanarMechanism(L=L, K1=200.0, K2=100.0)
    L3, t1, _ = random_states(1000, seed=15, L3_max=2 * L)
    L3 = np.clip(L3, 1e-3, None)
    g = m.forward_grid(L3, t1)
    det_fd = np.linalg.det(_fd_jacobian(m, L3, t1))
    e1, _ = m.eta(L3, t1)
    defined = np.abs(e1) > 1e-3 * (m.K1 + m.K2) * L
    np.testing.assert_allclose(g.jacobian_determinant, det_fd, rtol=1e-7, atol=1e-9)
    np.testing.assert_allclose(m.jacobian_determinant_eq23(L3, t1, g.theta2)[defined],
                               g.jacobian_determinant[defined], rtol=1e-9)
    # simplified stable-branch form det J = L3 (1 - L^2 (K1/2 + K2) / K)
    np.testing.assert_allclose(L3 * (1 - L ** 2 * m.m_real / g.stiffness),
                               g.jacobian_determinant, rtol=1e-10, atol=1e-13)
    # eq. (23) also holds on the unstable branch with its own theta2 (FD of the unstable FK)
    printed = _printed_eq24_detJ(m, L3, t1, g.theta2)
    assert np.max(np.abs(printed - g.jacobian_determinant)[defined]) > 0.1


def test_det_jacobian_eq23_on_unstable_branch(mech):
    """Eq. (23) is branch-agnostic: with the unstable theta2 it gives the unstable FK's det J."""
    L3, t1, _ = random_states(200, seed=16)
    L3 = np.clip(L3, 1e-2, None)
    _, tu = mech.equilibrium_angles(L3, t1)
    expected = L3 * (1 + mech.L ** 2 * mech.m_real / mech.stiffness_closed_form(L3, t1))

    def xy(a, b):
        th = mech.equilibrium_angles(a, b)[1]
        return np.stack([a * np.cos(b) + np.cos(th), a * np.sin(b) + np.sin(th)], axis=-1)
    dL = (xy(L3 + H1, t1) - xy(L3 - H1, t1)) / (2 * H1)
    dt = (xy(L3, t1 + H1) - xy(L3, t1 - H1)) / (2 * H1)
    np.testing.assert_allclose(np.linalg.det(np.stack([dL, dt], axis=-1)), expected, rtol=1e-7)
    np.testing.assert_allclose(mech.jacobian_determinant_eq23(L3, t1, tu), expected, rtol=1e-9)


# ---------------------------------------------------------------------- paper claims (Figs. 4-7)
def test_figs_4_to_6_stiffness_extremal_at_equilibria():
    """L = 1, L3 = 6, K1 = 100, K2 = 10, theta1 = pi/10 (captions' 'theta2 = pi/10' is theta1):
    K is a local maximum in theta2 at the stable equilibrium, a local minimum at the unstable."""
    m = PlanarMechanism(L=1.0, K1=100.0, K2=10.0, L3_max=6.0)
    L3, t1 = 6.0, math.pi / 10
    r = m.forward(L3, t1)
    assert r.stable and r.theta2_in_range and r.actuator_in_range  # eta1 < 0 here
    for th, kind in ((r.theta2, 'max'), (r.theta2_unstable, 'min')):
        K0 = m.stiffness(L3, t1, th)
        Kp, Km = m.stiffness(L3, t1, th + 1e-3), m.stiffness(L3, t1, th - 1e-3)
        dK = (m.stiffness(L3, t1, th + H1) - m.stiffness(L3, t1, th - H1)) / (2 * H1)
        d2K = (Kp - 2 * K0 + Km) / 1e-6
        assert abs(dK) < 1e-6 * abs(K0)
        if kind == 'max':
            assert K0 > 0 and Kp < K0 and Km < K0 and d2K < 0
        else:
            assert K0 < 0 and Kp > K0 and Km > K0 and d2K > 0
    # Figs. 5-6: moving away from the stable equilibrium, |torque| grows and the stiffness falls
    for sign in (1.0, -1.0):
        th = r.theta2 + sign * np.linspace(0.0, 0.5, 50)
        assert np.all(np.diff(np.abs(m.torque(L3, t1, th))) > 0)
        assert np.all(np.diff(m.stiffness(L3, t1, th)) < 0)


def test_fig7_stiffness_grows_with_L3():
    """Fig. 7 (K1 = 200, K2 = 100): K grows with L3, except near L3 = 0 for theta1 near pi.

    dK/dL3 has the sign of |m|^2 L3 + L ((K1^2 - K2^2) cos theta1 + sqrt3 (K1^2 + K2^2) sin
    theta1); that is positive for every theta1 in [0, pi] once L3 > 3L/7 (for these springs).
    """
    m = PlanarMechanism(L=1.0, K1=200.0, K2=100.0)
    L3, t1 = np.meshgrid(np.linspace(0.0, 2.0, 201), np.linspace(0.0, math.pi, 181),
                         indexing='ij')
    K = m.forward_grid(L3, t1).stiffness
    dK = np.diff(K, axis=0)
    K1, K2 = m.K1, m.K2
    mid = 0.5 * (L3[1:] + L3[:-1])
    sign = (K1 ** 2 + K1 * K2 + K2 ** 2) * mid + m.L * (
        (K1 ** 2 - K2 ** 2) * np.cos(t1[1:]) + SQRT3 * (K1 ** 2 + K2 ** 2) * np.sin(t1[1:]))
    clear = np.abs(sign) > 1e3
    np.testing.assert_array_equal((dK > 0)[clear], (sign > 0)[clear])
    assert np.all(dK[mid > 3.0 / 7.0 + 0.01] > 0)
    assert np.mean(dK > 0) > 0.95
    assert np.all(K[-1] > K[0])


# ---------------------------------------------------------------------- validation
@pytest.mark.parametrize('kwargs, field', [
    (dict(L=float('nan'), K1=1.0, K2=1.0), 'L'),
    (dict(L=-1.0, K1=1.0, K2=1.0), 'L'),
    (dict(L=1.0, K1=0.0, K2=1.0), 'K1'),
    (dict(L=1.0, K1=-3.0, K2=1.0), 'K1'),
    (dict(L=1.0, K1=1.0, K2=0.0), 'K2'),
    (dict(L=1.0, K1=1.0, K2=float('inf')), 'K2'),
    (dict(L=1.0, K1=1.0, K2=1.0, L3_min=-0.1), 'L3_min'),
    (dict(L=1.0, K1=1.0, K2=1.0, L3_max=0.0), 'L3_max'),
    (dict(L=1.0, K1=1.0, K2=1.0, L3_max=float('nan')), 'L3_max'),
    (dict(L=1.0, K1=1.0, K2=1.0, theta1_max=-1.0), 'theta1_max'),
    (dict(L=1.0, K1=1.0, K2=1.0, theta2_min=float('nan')), 'theta2_min'),
    (dict(L=1.0, K1=1.0, K2=1.0, theta2_max=7.0), 'theta2_max'),
    (dict(L=1.0, K1=1.0, K2=1.0, singularity_tol=0.0), 'singularity_tol'),
    (dict(L=1.0, K1='a', K2=1.0), 'K1'),
])
def test_bad_parameters_raise_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=rf'^{field} '):
        PlanarMechanism(**kwargs)


def test_bad_forward_input_raises_naming_the_field(mech):
    with pytest.raises(ValueError, match=r'^L3 must be finite, got nan'):
        mech.forward(float('nan'), 0.3)
    with pytest.raises(ValueError, match=r'^L3 must be >= 0'):
        mech.forward(-0.1, 0.3)
    with pytest.raises(ValueError, match=r'^theta1 must be finite'):
        mech.forward(1.0, float('inf'))
    with pytest.raises(ValueError, match=r'^theta1 must be finite'):
        mech.forward_grid([1.0, 1.0], [0.1, float('nan')])
    with pytest.raises(ValueError, match=r'^L3 must be >= 0'):
        mech.forward_grid([1.0, -1.0], 0.1)


def test_defaults_and_numpy_scalars():
    m = PlanarMechanism(L=np.float64(0.5), K1=np.float32(2.0), K2=3)
    assert (m.L3_min, m.L3_max) == (0.0, 1.0)
    assert (m.theta1_min, m.theta1_max, m.theta2_min, m.theta2_max) == (0.0, math.pi, 0.0,
                                                                        math.pi)
    r = m.forward(np.float64(0.3), np.float32(1.0))
    assert isinstance(r.x, float) and r.actuator_in_range


def test_out_of_range_actuator_is_flagged_not_rejected(mech):
    r = mech.forward(3.0, -0.5)
    assert not r.actuator_in_range and r.stable
    assert mech.forward(1.0, 2 * math.pi + 0.5).actuator_in_range  # same physical angle as 0.5


def test_neutral_point():
    m = PlanarMechanism(L=1.0, K1=200.0, K2=100.0, theta1_min=-math.pi, theta1_max=math.pi)
    u, v = m.neutral_point
    r = m.forward(math.hypot(u, v), math.atan2(v, u))
    assert not r.stable and 'neutral' in r.singularities and math.isnan(r.x)
    assert r.stiffness == 0.0
    g = m.forward_grid([math.hypot(u, v), 1.0], [math.atan2(v, u), 1.0])
    np.testing.assert_array_equal(g.stable, [False, True])
