"""Planar mechanism: inverse kinematics, its cross-check with the paper's closed form (eqs. 9-16,
Appendix A) and the stiffness as a function of (x, y) (eqs. 48-52).

Printed coefficients found wrong (``docs/errata.md``): F3 of eq. (12) (a sqrt3 is missing), phi3 of
(C.3) (brackets lost: it is a product of two factors), eq. (49) (overall sign and the sign of the
y term). Each is kept below as a ``printed`` variant with a test that shows it fails.
"""

import math

import numpy as np
import pytest

from tensegrity_stiffness.mechanics.planar import (
    PlanarInverseResult,
    PlanarInverseSolution,
    PlanarMechanism,
)

SQRT3 = math.sqrt(3.0)
#: Round-trip tolerance of the issue (m and rad).
ROUND_TRIP_TOL = 1e-9
#: Residuals of the actuator states kept for IK(FK): away from every singular curve.
AWAY_FROM_SINGULAR = 1e-3


@pytest.fixture
def mech() -> PlanarMechanism:
    return PlanarMechanism(L=1.0, K1=200.0, K2=100.0)


def _actuator_samples(m: PlanarMechanism, n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return (rng.uniform(m.L3_min, m.L3_max, n), rng.uniform(m.theta1_min, m.theta1_max, n))


# ---------------------------------------------------------------------- round trips
@pytest.mark.parametrize('K1, K2, L', [(200.0, 100.0, 1.0), (100.0, 10.0, 1.0), (5.0, 40.0, 0.3)])
def test_ik_of_fk_contains_the_actuator_state(K1, K2, L):
    m = PlanarMechanism(L=L, K1=K1, K2=K2)
    rng = np.random.default_rng(20)
    kept = 0
    while kept < 1000:
        L3, t1 = rng.uniform(0.0, 2 * L), rng.uniform(0.0, math.pi)
        res = m.singularity_residuals(L3, t1)
        if min(abs(float(v)) for v in res.values()) < AWAY_FROM_SINGULAR:
            continue
        kept += 1
        r = m.forward(L3, t1)
        sols = m.inverse(r.x, r.y)
        assert sols, sols.reason
        err = min(max(abs(s.L3 - L3), abs(s.theta1 - t1)) for s in sols)
        assert err < ROUND_TRIP_TOL
        best = min(sols, key=lambda s: abs(s.L3 - L3) + abs(s.theta1 - t1))
        assert abs(best.theta2 - r.theta2) < ROUND_TRIP_TOL
        assert best.stable and abs(best.stiffness - r.stiffness) < 1e-9 * r.stiffness
        assert best.singularities == r.singularities == ()
        assert abs(best.jacobian_determinant - r.jacobian_determinant) < 1e-9


@pytest.mark.parametrize('K1, K2', [(200.0, 100.0), (100.0, 10.0), (1.0, 3.0)])
def test_fk_of_ik_returns_the_point(K1, K2):
    """1,000 random reachable points, found by rejection in a box around the workspace."""
    m = PlanarMechanism(L=1.0, K1=K1, K2=K2)
    rng = np.random.default_rng(21)
    checked = n_two = 0
    while checked < 1000:
        x, y = rng.uniform(-3.0, 3.0), rng.uniform(-2.0, 3.0)
        sols = m.inverse(x, y)
        if not sols:
            assert sols.reason
            continue
        checked += 1
        n_two += len(sols) == 2
        for s in sols:
            assert s.stable and s.stiffness > 0
            assert m.L3_min <= s.L3 <= m.L3_max + m.range_tol
            r = m.forward(s.L3, s.theta1)
            assert math.hypot(r.x - x, r.y - y) < ROUND_TRIP_TOL
            assert abs(r.stiffness - s.stiffness) < 1e-9 * s.stiffness
        assert [s.stiffness for s in sols] == sorted((s.stiffness for s in sols), reverse=True)
    assert n_two == 0  # see test_second_stable_solution_lies_inside_the_fold_circle


@pytest.mark.parametrize('K1, K2', [(200.0, 100.0), (1.0, 3.0), (1.0, 300.0)])
def test_second_stable_solution_lies_inside_the_fold_circle(K1, K2):
    """The paper's 'up to two' solutions: two stable ones exist, but the softer one always has D1
    inside the actuator fold circle (curve v), which lies below the X axis: with
    0 <= theta1 <= pi the inverse has at most one stable solution."""
    full = PlanarMechanism(L=1.0, K1=K1, K2=K2, theta1_min=-math.pi, theta1_max=math.pi,
                           L3_max=10.0)
    x, y = np.meshgrid(np.linspace(-4, 4, 161), np.linspace(-4, 4, 161))
    g = full.inverse_grid(x, y)
    two = g.count == 2
    assert np.any(two)
    cx, cy, r = full.fold_circle_actuator()
    u, v = g.L3 * np.cos(g.theta1), g.L3 * np.sin(g.theta1)
    inside = np.hypot(u - cx, v - cy) < r
    np.testing.assert_array_equal(inside[g.valid[..., 0], 0], False)
    assert np.all(inside[g.valid[..., 1], 1])
    assert np.all(v[g.valid[..., 1], 1] < 0)
    i = tuple(np.argwhere(two)[0])
    sols = full.inverse(x[i], y[i])
    assert len(sols) == 2 and sols[0].stiffness > sols[1].stiffness > 0
    for s in sols:
        rf = full.forward(s.L3, s.theta1)
        assert math.hypot(rf.x - x[i], rf.y - y[i]) < ROUND_TRIP_TOL
    paper = PlanarMechanism(L=1.0, K1=K1, K2=K2, L3_max=10.0)
    assert np.max(paper.inverse_grid(x, y).count) == 1


def test_inverse_grid_matches_scalar_inverse(mech):
    rng = np.random.default_rng(22)
    x, y = rng.uniform(-3, 3, 400), rng.uniform(-2, 3, 400)
    g = mech.inverse_grid(x, y)
    for i in range(400):
        sols = mech.inverse(x[i], y[i])
        assert len(sols) == g.count[i]
        got = [(g.L3[i, k], g.theta1[i, k], g.theta2[i, k], g.stiffness[i, k])
               for k in range(2) if g.valid[i, k]]
        exp = [(s.L3, s.theta1, s.theta2, s.stiffness) for s in sols]
        np.testing.assert_allclose(np.array(got).reshape(-1, 4), np.array(exp).reshape(-1, 4),
                                   rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(mech.in_cartesian_workspace(x, y), g.count > 0)


def test_include_unstable_returns_the_other_equilibrium():
    m = PlanarMechanism(L=1.0, K1=200.0, K2=100.0, L3_max=10.0,
                        theta1_min=-math.pi, theta1_max=math.pi)
    r = m.forward(1.5, 0.6)
    xu, yu = r.x_unstable, r.y_unstable
    sols = m.inverse(xu, yu, include_unstable=True)
    unstable = [s for s in sols if not s.stable]
    assert any(abs(s.L3 - 1.5) < 1e-9 and abs(s.theta1 - 0.6) < 1e-9 for s in unstable)
    for s in unstable:
        assert s.stiffness < 0
        th = m.equilibrium_angles(s.L3, s.theta1)[1]
        assert abs(math.remainder(th - s.theta2, 2 * math.pi)) < 1e-9
        assert abs(m.torque(s.L3, s.theta1, s.theta2)) < 1e-9 * abs(s.stiffness)
    assert all(s.stable for s in m.inverse(xu, yu))


def test_unreachable_points_give_a_reason_not_an_exception(mech):
    far = mech.inverse(10.0, 10.0)
    assert isinstance(far, PlanarInverseResult) and isinstance(far, list)
    assert far == [] and len(far) == 0 and 'outside' in far.reason
    assert (far.x, far.y) == (10.0, 10.0)
    cx, cy, _ = mech.fold_circle_cartesian()
    inside = mech.inverse(cx, cy)
    assert inside == [] and 'fold' in inside.reason
    ok = mech.inverse(mech.forward(1.0, 1.0).x, mech.forward(1.0, 1.0).y)
    assert ok and ok.reason == '' and isinstance(ok[0], PlanarInverseSolution)
    with pytest.raises(ValueError, match=r'^x must be finite, got nan'):
        mech.inverse(float('nan'), 0.0)
    with pytest.raises(ValueError, match=r'^y must be finite'):
        mech.inverse(0.0, float('inf'))
    with pytest.raises(ValueError, match=r'^y must be finite'):
        mech.inverse_grid([0.0], [float('nan')])


def test_require_theta2_in_range(mech):
    L3, t1 = _actuator_samples(mech, 300, seed=23)
    g = mech.forward_grid(L3, t1)
    for i in range(300):
        sols = mech.inverse(g.x[i], g.y[i], require_theta2_in_range=True)
        assert all(s.theta2_in_range for s in sols)
        if not sols:
            assert 'theta2' in sols.reason
    assert any(g.theta2_in_range) and not all(g.theta2_in_range)


# ---------------------------------------------------------------------- paper's closed form
def _E_F(m: PlanarMechanism, x, y, t1, printed_F3=False):
    """Coefficients of eqs. (10) and (12) (F3 as printed, or with the missing sqrt3)."""
    L, K1, K2 = m.L, m.K1, m.K2
    c1, s1 = np.cos(t1), np.sin(t1)
    E = (1.0, -2 * (x * c1 + y * s1), x ** 2 + y ** 2 - L ** 2)
    F1 = SQRT3 * K1 * L
    F2 = (L * (K1 + 2 * K2) * (x * s1 - y * c1) - SQRT3 * L * c1 * (K1 * x + 2 * K2 * L)
          + (2 * (2 * K1 - K2) * L - SQRT3 * K1 * y) * L * s1)
    F3 = ((1.0 if printed_F3 else SQRT3) * 2 * K2 * L ** 2 * x
          - 2 * (2 * K1 - K2) * L ** 2 * y)
    return E, (F1, F2, F3)


def _phis(m: PlanarMechanism, x, y, printed_phi3=False):
    """Appendix A, (C.1)-(C.4), transcribed; phi3 as printed or as the product of two factors."""
    L, K1, K2 = m.L, m.K1, m.K2
    r2 = x ** 2 + y ** 2
    phi1 = L * (L * (L ** 2 - r2) * (4 * K1 * L - 2 * K2 * L + K1 * x + 2 * K2 * x
                                     - SQRT3 * K1 * y)
                - 4 * L ** 2 * y * (K2 * y - 2 * K1 * y + SQRT3 * K2 * x)) * (
        4 * K1 * L - 2 * K2 * L + K1 * x + 2 * K2 * x + SQRT3 * K1 * y)
    phi2 = ((4 * L ** 3 * y * (K2 * y - 2 * K1 * y + SQRT3 * K2 * x)
             + L ** 2 * (r2 - L ** 2) * (4 * K1 * L - 2 * K2 * L + K1 * x + 2 * K2 * x
                                         - SQRT3 * K1 * y))
            * (K1 * y + 2 * K2 * y + 2 * SQRT3 * K2 * L - SQRT3 * K1 * x)
            - L * (4 * L ** 2 * x * (K2 * y - 2 * K1 * y + SQRT3 * K2 * x)
                   - L * (r2 - L ** 2) * (K1 * y + 2 * K2 * y + 2 * SQRT3 * K2 * L
                                          + SQRT3 * K1 * x))
            * (4 * K1 * L - 2 * K2 * L + K1 * x + 2 * K2 * x + SQRT3 * K1 * y))
    first = L * (r2 - L ** 2) * (K1 * y + 2 * K2 * y + 2 * SQRT3 * K2 * L + SQRT3 * K1 * x)
    second = 4 * L ** 2 * x * (K2 * y - 2 * K1 * y + SQRT3 * K2 * x)
    last = -L * y * (K1 + 2 * K2) - 2 * SQRT3 * L ** 2 * K2 + SQRT3 * K1 * L * x
    phi3 = (first + last - second) if printed_phi3 else (first - second) * last
    phi4 = -L ** 2 * (2 * SQRT3 * K2 * L * x - 2 * (2 * K1 - K2) * L * y
                      + SQRT3 * K1 * (L ** 2 - r2)) ** 2
    return phi1, phi2, phi3, phi4


def _bezout(E, F):
    """Left side of eq. (13)."""
    (E1, E2, E3), (F1, F2, F3) = E, F
    return (E1 * F2 - E2 * F1) * (E2 * F3 - E3 * F2) - (E1 * F3 - E3 * F1) ** 2


def _paper_candidates(m: PlanarMechanism, x: float, y: float) -> list[tuple[float, float]]:
    """(L3, theta1) from eqs. (16) and (14) with the corrected coefficients, theta1 in [0, pi)."""
    p1, p2, p3, p4 = _phis(m, x, y)
    a, b, c = p1 + p4, p2, p3 + p4
    disc = b * b - 4 * a * c
    if disc < 0:
        return []
    out = []
    for sgn in (1.0, -1.0):
        t1 = math.atan((-b + sgn * math.sqrt(disc)) / (2 * a)) % math.pi  # eq. (16)
        (E1, E2, E3), (F1, F2, F3) = _E_F(m, x, y, t1)
        L3 = -(E2 * F3 - E3 * F2) / (E1 * F3 - E3 * F1)  # eq. (14)
        out.append((L3, t1))
    return out


def test_appendix_A_coefficients_against_eq13(mech):
    """C.1, C.2, C.4 are right; C.3 as printed is not, the bracketed product is; F3 needs sqrt3."""
    rng = np.random.default_rng(24)
    x, y, t1 = rng.uniform(-3, 3, 500), rng.uniform(-2, 3, 500), rng.uniform(0, math.pi, 500)
    lhs = _bezout(*_E_F(mech, x, y, t1))
    scale = np.max(np.abs(lhs))
    p1, p2, p3, p4 = _phis(mech, x, y)
    t = np.tan(t1)
    eq15 = np.cos(t1) ** 2 * ((p1 + p4) * t ** 2 + p2 * t + p3 + p4)
    np.testing.assert_allclose(eq15 / scale, lhs / scale, atol=1e-12)
    p3_printed = _phis(mech, x, y, printed_phi3=True)[2]
    eq15_printed = np.cos(t1) ** 2 * ((p1 + p4) * t ** 2 + p2 * t + p3_printed + p4)
    assert np.max(np.abs(eq15_printed - lhs)) / scale > 1e-2
    lhs_printed_F3 = _bezout(*_E_F(mech, x, y, t1, printed_F3=True))
    assert np.max(np.abs(eq15 - lhs_printed_F3)) / scale > 1e-2


def test_eq11_with_printed_F3_fails_at_true_solutions(mech):
    L3, t1 = _actuator_samples(mech, 200, seed=25)
    g = mech.forward_grid(L3, t1)
    for printed, ok in ((False, True), (True, False)):
        E, (F1, F2, F3) = _E_F(mech, g.x, g.y, t1, printed_F3=printed)
        eq9 = L3 ** 2 + E[1] * L3 + E[2]
        eq11 = F1 * L3 ** 2 + F2 * L3 + F3
        np.testing.assert_allclose(eq9, 0.0, atol=1e-12)
        scale = mech.K1 * mech.L ** 3
        assert (np.max(np.abs(eq11)) / scale < 1e-12) == ok


@pytest.mark.parametrize('K1, K2', [(200.0, 100.0), (100.0, 10.0), (1.0, 3.0)])
def test_paper_closed_form_gives_the_same_solutions(K1, K2):
    """Eqs. (14)-(16) with the corrected coefficients, filtered as docs/errata.md says (unstable
    and negative-L3 candidates dropped), give the same set as :meth:`inverse`."""
    m = PlanarMechanism(L=1.0, K1=K1, K2=K2)
    rng = np.random.default_rng(26)
    compared = 0
    for _ in range(400):
        x, y = rng.uniform(-3, 3), rng.uniform(-2, 3)
        ours = sorted((s.L3, s.theta1) for s in m.inverse(x, y))
        paper = []
        for L3, t1 in _paper_candidates(m, x, y):
            if L3 < m.L3_min or L3 > m.L3_max:
                continue  # includes the negative-L3 candidates (D1 below the X axis)
            r = m.forward(L3, t1)
            if math.hypot(r.x - x, r.y - y) > 1e-7:
                continue  # D3 is there only at the unstable equilibrium
            paper.append((L3, t1))
        paper = sorted(paper)
        assert len(paper) == len(ours)
        if ours:
            np.testing.assert_allclose(paper, ours, rtol=1e-7, atol=1e-8)
            compared += 1
    assert compared > 50


# ---------------------------------------------------------------------- stiffness of (x, y)
def _eq52(m: PlanarMechanism, x, y, *, root=1.0, printed_49=False):
    """Eq. (52): theta2 from the half-angle solution of eq. (48), then eq. (49)."""
    L, K1, K2 = m.L, m.K1, m.K2
    d1 = (K1 + 2 * K2) * y - SQRT3 * K1 * x + 2 * SQRT3 * K2 * L  # eq. (50)
    d2 = 2 * (2 * K1 - K2) * L + (K1 + 2 * K2) * x + SQRT3 * K1 * y  # eq. (51)
    with np.errstate(invalid='ignore'):  # NaN inside the fold circle
        th = 2 * np.arctan((d2 + root * np.sqrt(d1 ** 2 + d2 ** 2 - 3 * K1 ** 2 * L ** 2))
                           / (SQRT3 * K1 * L - d1))
    return _eq49(m, x, y, th, printed=printed_49), th


def _eq49(m: PlanarMechanism, x, y, th, *, printed=False):
    L, K1, K2 = m.L, m.K1, m.K2
    b = (K1 / 2 + K2) * L ** 2
    if printed:
        return (((2 * K1 - K2) * L ** 2 + (K1 / 2 + K2) * L * x - SQRT3 / 2 * K1 * L * y)
                * np.cos(th) + ((K1 / 2 + K2) * L * y - SQRT3 / 2 * K1 * L * x
                                + SQRT3 * K2 * L ** 2) * np.sin(th) - b)
    return (-((2 * K1 - K2) * L ** 2 + (K1 / 2 + K2) * L * x + SQRT3 / 2 * K1 * L * y)
            * np.cos(th) - ((K1 / 2 + K2) * L * y - SQRT3 / 2 * K1 * L * x
                            + SQRT3 * K2 * L ** 2) * np.sin(th) + b)


def test_eq48_and_eq49_at_ik_solutions(mech):
    L3, t1 = _actuator_samples(mech, 500, seed=27)
    g = mech.forward_grid(L3, t1)
    x, y, th = g.x, g.y, g.theta2
    L, K1, K2 = mech.L, mech.K1, mech.K2
    d1 = (K1 + 2 * K2) * y - SQRT3 * K1 * x + 2 * SQRT3 * K2 * L
    d2 = 2 * (2 * K1 - K2) * L + (K1 + 2 * K2) * x + SQRT3 * K1 * y
    np.testing.assert_allclose((d1 * np.cos(th) - d2 * np.sin(th) + SQRT3 * K1 * L) / K1, 0.0,
                               atol=1e-12)  # eq. (48)
    np.testing.assert_allclose(_eq49(mech, x, y, th), g.stiffness, rtol=1e-12)
    printed = _eq49(mech, x, y, th, printed=True)
    assert np.max(np.abs(printed - g.stiffness) / g.stiffness) > 0.5
    # the sign alone does not explain the printed form: the y term is wrong too
    assert np.max(np.abs(-printed - g.stiffness) / g.stiffness) > 0.1


@pytest.mark.parametrize('K1, K2', [(200.0, 100.0), (100.0, 10.0), (1.0, 3.0)])
def test_eq52_equals_eq42_at_the_ik_solution(K1, K2):
    """Eq. (52) with the corrected eq. (49) and the printed '+' root is the stiffness of the
    stiffer stable solution; the '-' root gives the other equilibrium (stable iff K > 0)."""
    m = PlanarMechanism(L=1.0, K1=K1, K2=K2)
    rng = np.random.default_rng(28)
    x, y = rng.uniform(-3, 3, 4000), rng.uniform(-2, 3, 4000)
    g = m.inverse_grid(x, y)
    reach = g.count > 0
    assert reach.sum() > 400
    K_plus, th_plus = _eq52(m, x, y, root=1.0)
    K_minus, _ = _eq52(m, x, y, root=-1.0)
    K_xy = m.stiffness_from_position(x, y)
    np.testing.assert_allclose(K_plus[reach], K_xy[reach, 0], rtol=1e-11)
    np.testing.assert_allclose(K_minus[reach], K_xy[reach, 1], rtol=1e-9,
                               atol=1e-11 * K1 * m.L ** 2)
    for k in range(2):
        ok = g.valid[:, k]
        # eq. (42) at the IK solution, evaluated from (L3, theta1, theta2)
        K42 = m.stiffness(g.L3[ok, k], g.theta1[ok, k], g.theta2[ok, k])
        np.testing.assert_allclose(K_xy[ok, k], K42, rtol=1e-10)
    ok = g.valid[:, 0]
    np.testing.assert_allclose(np.cos(th_plus[ok]), np.cos(g.theta2[ok, 0]), atol=1e-9)
    K_printed, _ = _eq52(m, x, y, root=1.0, printed_49=True)
    assert np.max(np.abs(K_printed[reach] - K_xy[reach, 0]) / K_xy[reach, 0]) > 0.5
