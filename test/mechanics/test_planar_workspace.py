"""Planar mechanism: singular conditions i-v, workspace curves (Figs. 2-3), maps (Figs. 7-8)."""

import math

import numpy as np
import pytest
from scipy.optimize import brentq

from tensegrity_stiffness.mechanics.planar import (
    SINGULARITY_DESCRIPTIONS,
    SINGULARITY_NAMES,
    PlanarMechanism,
)
from tensegrity_stiffness.mechanics.planar_workspace import (
    actuator_stiffness_map,
    actuator_workspace_boundary,
    actuator_workspace_curves,
    cartesian_stiffness_map,
    cartesian_workspace_boundary,
    cartesian_workspace_curves,
    to_cartesian,
)

SQRT3 = math.sqrt(3.0)
#: Offset (dimensionless residual) that must no longer be reported as singular.
AWAY = 1e-3


@pytest.fixture
def mech() -> PlanarMechanism:
    return PlanarMechanism(L=1.0, K1=200.0, K2=100.0)


@pytest.fixture
def full_mech() -> PlanarMechanism:
    """theta1 over a full turn, so that the fold (curve v, below the X axis) is in range."""
    return PlanarMechanism(L=1.0, K1=200.0, K2=100.0, theta1_min=-math.pi, theta1_max=math.pi)


def _finite(c: np.ndarray) -> np.ndarray:
    return c[np.all(np.isfinite(c), axis=1)]


# ---------------------------------------------------------------------- singular conditions
def test_names_are_documented():
    assert SINGULARITY_NAMES == ('i', 'ii', 'iii', 'iv', 'v')
    assert set(SINGULARITY_NAMES) <= set(SINGULARITY_DESCRIPTIONS)


@pytest.mark.parametrize('name', ['i', 'ii', 'iii', 'iv'])
def test_singular_condition_detected_on_its_curve(mech, name):
    pts = _finite(actuator_workspace_curves(mech, n=101)[name])
    assert len(pts) > 5
    for t1, L3 in pts[::5]:
        r = mech.forward(L3, t1)
        assert name in r.singularities, (L3, t1, r.singularities)
        assert name in mech.singularities(L3, t1)
    g = mech.forward_grid(pts[:, 1], pts[:, 0])
    assert np.all(g.singular[name])


def test_constructed_points_satisfy_the_paper_equations(mech):
    """Curves built from eqs. (26)-(28) and (33) put the stable branch where the paper says."""
    L, K1, K2 = mech.L, mech.K1, mech.K2
    c = actuator_workspace_curves(mech, n=101)
    t1, L3 = _finite(c['iii']).T
    g = mech.forward_grid(L3, t1)
    np.testing.assert_allclose(np.sin(g.theta2), 0.0, atol=1e-12)  # iii: theta2 = 0 or pi
    eta1 = (K1 + 2 * K2) * L3 * np.sin(t1) - SQRT3 * K1 * L3 * np.cos(t1) + 2 * SQRT3 * K2 * L
    np.testing.assert_allclose(eta1 / K1, 0.0, atol=1e-12)  # eq. (28)
    t1, L3 = _finite(c['iv']).T
    g = mech.forward_grid(L3, t1)
    np.testing.assert_allclose(np.sin(g.theta2 - t1), 0.0, atol=1e-12)  # eq. (29), mod pi
    eq33 = 2 * (2 * K1 - K2) * L * np.sin(t1) - 2 * SQRT3 * K2 * L * np.cos(t1) + SQRT3 * K1 * L3
    np.testing.assert_allclose(eq33 / K1, 0.0, atol=1e-12)
    # D3 on the line C1 D1 (the paper's description of iv)
    np.testing.assert_allclose(g.x * np.sin(t1) - g.y * np.cos(t1), 0.0, atol=1e-12)


def test_singular_condition_v_on_the_fold(full_mech):
    m = full_mech
    pts = _finite(actuator_workspace_curves(m, n=100)['v'])
    assert len(pts) > 100
    for t1, L3 in pts[::17]:
        r = m.forward(L3, t1)
        assert 'v' in r.singularities
        assert abs(r.jacobian_determinant) < 1e-9 * L3
        # the two inverse solutions merge there
        sols = m.inverse(r.x, r.y)
        assert len(sols) == 1
        assert abs(sols[0].L3 - L3) < 1e-5 and abs(sols[0].theta1 - t1) < 1e-5


def test_curve_v_numerically(full_mech):
    """det J from central differences of FK vanishes exactly on the closed-form fold circle."""
    m = full_mech
    cx, cy, r = m.fold_circle_actuator()

    def det_fd(L3, t1, h=1e-6):
        def xy(a, b):
            f = m.forward(a, b)
            return np.array([f.x, f.y])
        return np.linalg.det(np.column_stack([(xy(L3 + h, t1) - xy(L3 - h, t1)) / (2 * h),
                                              (xy(L3, t1 + h) - xy(L3, t1 - h)) / (2 * h)]))
    for phi in np.linspace(0.0, 2 * math.pi, 9)[:-1]:
        d = np.array([math.cos(phi), math.sin(phi)])

        def f(rho, d=d):
            u, v = cx + rho * d[0], cy + rho * d[1]
            return det_fd(math.hypot(u, v), math.atan2(v, u))
        rho = brentq(f, 0.5 * r, 1.5 * r, xtol=1e-12)
        assert abs(rho - r) < 1e-6 * r


def test_singularities_not_detected_away_from_curves(mech, full_mech):
    for m in (mech, full_mech):
        rng = np.random.default_rng(30)
        L3 = rng.uniform(0.0, 2.0, 3000)
        t1 = rng.uniform(m.theta1_min, m.theta1_max, 3000)
        res = m.singularity_residuals(L3, t1)
        away = np.all([np.abs(v) > AWAY for v in res.values()], axis=0)
        assert away.sum() > 1000
        g = m.forward_grid(L3, t1)
        assert not np.any([g.singular[n][away] for n in SINGULARITY_NAMES])
        for i in np.flatnonzero(away)[:100]:
            assert m.forward(L3[i], t1[i]).singularities == ()


#: Steps (dL3, dtheta1) that leave each curve (i and ii are lines L3 = 0, theta1 = k pi).
OFF_CURVE_STEPS = {
    'i': [(0.01, 0.0)],
    'ii': [(0.0, 0.01), (0.0, -0.01)],
    'iii': [(0.01, 0.0), (-0.01, 0.0)],
    'iv': [(0.01, 0.0), (-0.01, 0.0)],
    'v': [(0.01, 0.0), (-0.01, 0.0)],
}


@pytest.mark.parametrize('name', SINGULARITY_NAMES)
def test_singular_condition_not_detected_just_off_its_curve(full_mech, name):
    m = full_mech
    pts = _finite(actuator_workspace_curves(m, n=50)[name])
    assert len(pts)
    for t1, L3 in pts[1:-1:7]:
        assert name in m.forward(L3, t1).singularities
        for dL3, dt1 in OFF_CURVE_STEPS[name]:
            if L3 + dL3 >= 0:
                assert name not in m.forward(L3 + dL3, t1 + dt1).singularities


def test_singularity_tolerance_is_a_keyword():
    loose = PlanarMechanism(L=1.0, K1=200.0, K2=100.0, singularity_tol=0.05)
    strict = PlanarMechanism(L=1.0, K1=200.0, K2=100.0)
    assert 'i' in loose.forward(0.01, 1.0).singularities
    assert 'i' not in strict.forward(0.01, 1.0).singularities


def test_L3_zero_point_and_theta1_independence(mech):
    """Condition i: with L3 = 0 D3 does not depend on theta1 (the whole edge maps to one point)."""
    pts = [mech.forward(0.0, t) for t in np.linspace(0.0, math.pi, 7)]
    np.testing.assert_allclose([p.x for p in pts], pts[0].x, atol=1e-15)
    np.testing.assert_allclose([p.y for p in pts], pts[0].y, atol=1e-15)
    assert math.hypot(pts[0].x, pts[0].y) == pytest.approx(mech.L)  # on eq. (34)
    assert pts[0].jacobian_determinant == pytest.approx(0.0, abs=1e-15)


# ---------------------------------------------------------------------- workspace curves
def test_fold_never_enters_the_paper_actuator_workspace():
    """For every K2/K1 the fold circle in the D1 plane lies below the X axis (so curve v of
    Fig. 2 is not the fold of the stable equilibria)."""
    for r in np.logspace(-4, 4, 81):
        m = PlanarMechanism(L=1.0, K1=1.0, K2=float(r))
        _, cy, rad = m.fold_circle_actuator()
        assert cy + rad < -0.25
        assert len(actuator_workspace_curves(m, n=50)['v']) == 0


def test_actuator_curves_layout(mech):
    c = actuator_workspace_curves(mech, n=64)
    assert set(c) == {'i', 'ii', 'iii', 'iv', 'v', 'vi'}
    np.testing.assert_allclose(c['i'][:, 1], 0.0)
    np.testing.assert_allclose(c['vi'][:, 1], mech.L3_max)
    ii = _finite(c['ii'])
    np.testing.assert_allclose(np.sin(ii[:, 0]), 0.0, atol=1e-15)
    assert np.isnan(c['ii']).any()  # two segments (theta1 = 0 and pi) separated by NaN
    for name in c:
        pts = _finite(c[name])
        assert np.all(mech.in_actuator_workspace(pts[:, 1], pts[:, 0]))
    b = actuator_workspace_boundary(mech, n=10)
    np.testing.assert_allclose(b[0], b[-1])
    assert np.all(mech.in_actuator_workspace(b[:, 1], b[:, 0]))


def test_cartesian_curves_against_eqs_34_to_37(mech):
    L, K1, K2 = mech.L, mech.K1, mech.K2
    act = actuator_workspace_curves(mech, n=101)
    cart = cartesian_workspace_curves(mech, n=101)
    # i: one point, on the circle of eq. (34)
    i = _finite(cart['i'])
    np.testing.assert_allclose(i, np.broadcast_to(i[0], i.shape), atol=1e-14)
    np.testing.assert_allclose(np.hypot(i[:, 0], i[:, 1]), L, rtol=1e-14)
    # ii: eq. (35), (x - L3 cos theta1)^2 + y^2 = L^2 with theta1 = 0 (and its mirror at pi)
    ok = np.all(np.isfinite(act['ii']), axis=1)
    t1, L3 = act['ii'][ok].T
    x, y = cart['ii'][ok].T
    np.testing.assert_allclose((x - L3 * np.cos(t1)) ** 2 + y ** 2, L ** 2, rtol=1e-12)
    # iii: theta2 = 0 or pi; the line is sqrt3 K1 x - (K1 + 2K2) y = sqrt3 L (K1 cos th2 + 2 K2)
    ok = np.all(np.isfinite(act['iii']), axis=1)
    t1, L3 = act['iii'][ok].T
    x, y = cart['iii'][ok].T
    c2 = np.cos(mech.forward_grid(L3, t1).theta2)
    np.testing.assert_allclose(np.abs(c2), 1.0, atol=1e-12)
    derived = SQRT3 * K1 * x - (K1 + 2 * K2) * y - SQRT3 * L * (K1 * c2 + 2 * K2)
    np.testing.assert_allclose(derived / K1, 0.0, atol=1e-12)
    printed_36 = 2 * SQRT3 * K1 * x - (K1 + 2 * K2) * y + 2 * SQRT3 * L * (K2 - K1)
    assert np.min(np.abs(printed_36) / K1) > 0.1  # eq. (36) as printed is not this curve
    # iv: D3 on line C1 D1, |D3| = L3 +- L; eq. (37) |D3| = 3L is the bound L3_max + L
    ok = np.all(np.isfinite(act['iv']), axis=1)
    t1, L3 = act['iv'][ok].T
    x, y = cart['iv'][ok].T
    r = np.hypot(x, y)
    np.testing.assert_allclose(np.minimum(np.abs(r - (L3 + L)), np.abs(r - np.abs(L3 - L))), 0.0,
                               atol=1e-12)
    for name in cart:
        pts = _finite(cart[name])
        assert np.all(np.hypot(pts[:, 0], pts[:, 1]) <= 3 * L + 1e-12)


def test_cartesian_fold_circle(full_mech):
    m = full_mech
    cx, cy, r = m.fold_circle_cartesian()
    v = _finite(cartesian_workspace_curves(m, n=100)['v'])
    np.testing.assert_allclose(np.hypot(v[:, 0] - cx, v[:, 1] - cy), r, rtol=1e-12)
    # just inside: no equilibrium at all; just outside: two stable ones (before range checks)
    for phi in np.linspace(0, 2 * math.pi, 7):
        d = np.array([math.cos(phi), math.sin(phi)])
        xin = np.array([cx, cy]) + 0.999 * r * d
        xout = np.array([cx, cy]) + 1.001 * r * d
        assert m.inverse(*xin) == [] and 'fold' in m.inverse(*xin).reason
        K = m.stiffness_from_position(*xout)
        assert np.all(K > 0)


def test_to_cartesian_keeps_nan_breaks(mech):
    c = np.array([[0.5, 1.0], [np.nan, np.nan], [1.0, 1.5]])
    out = to_cartesian(mech, c)
    assert np.isnan(out[1]).all() and np.isfinite(out[[0, 2]]).all()
    r = mech.forward(1.5, 1.0)
    np.testing.assert_allclose(out[2], [r.x, r.y])


def test_workspace_membership(mech):
    rng = np.random.default_rng(31)
    L3, t1 = rng.uniform(-0.5, 2.5, 2000), rng.uniform(-1.0, 4.0, 2000)
    inside = mech.in_actuator_workspace(L3, t1)
    np.testing.assert_array_equal(inside, (L3 >= 0) & (L3 <= 2) & (t1 >= 0) & (t1 <= math.pi))
    ok = inside & (L3 >= 0)
    g = mech.forward_grid(L3[ok], t1[ok])
    assert np.all(mech.in_cartesian_workspace(g.x, g.y))
    assert not mech.in_cartesian_workspace(10.0, 0.0)
    cx, cy, _ = mech.fold_circle_cartesian()
    assert not mech.in_cartesian_workspace(cx, cy)
    b = _finite(cartesian_workspace_boundary(mech, n=50))
    assert np.all(mech.in_cartesian_workspace(b[:, 0], b[:, 1]))


def test_cartesian_workspace_theta2_option(mech):
    L3, t1 = np.meshgrid(np.linspace(0.1, 2, 30), np.linspace(0.05, 3.1, 30))
    g = mech.forward_grid(L3, t1)
    strict = mech.in_cartesian_workspace(g.x, g.y, require_theta2_in_range=True)
    np.testing.assert_array_equal(strict, g.theta2_in_range)


# ---------------------------------------------------------------------- stiffness maps
def test_actuator_stiffness_map_matches_eq42(mech):
    L3, t1 = np.meshgrid(np.linspace(0, 2, 200), np.linspace(0, math.pi, 200), indexing='ij')
    K = actuator_stiffness_map(mech, L3, t1)
    assert K.shape == (200, 200) and np.all(np.isfinite(K))
    g = mech.forward_grid(L3, t1)
    np.testing.assert_allclose(K, mech.stiffness(L3, t1, g.theta2), rtol=1e-12)
    out = actuator_stiffness_map(mech, [1.0, 3.0], [0.5, 0.5])
    assert np.isfinite(out[0]) and np.isnan(out[1])
    assert actuator_stiffness_map(mech, 3.0, 0.5, outside=-1.0) == -1.0


def test_cartesian_stiffness_map_matches_eq42_at_ik(mech):
    x, y = np.meshgrid(np.linspace(-3, 3, 200), np.linspace(-1.5, 3, 200))
    K = cartesian_stiffness_map(mech, x, y)
    assert K.shape == (200, 200, 2)
    g = mech.inverse_grid(x, y)
    ok = g.valid[..., 0]
    assert ok.sum() > 5000
    np.testing.assert_allclose(K[..., 0][ok],
                               mech.stiffness(g.L3[..., 0][ok], g.theta1[..., 0][ok],
                                              g.theta2[..., 0][ok]), rtol=1e-10)
    np.testing.assert_allclose(K[..., 0][ok], mech.stiffness_from_position(x, y)[..., 0][ok],
                               rtol=1e-12)
    assert np.all(np.isnan(K[..., 1]))  # a single solution with theta1 in [0, pi]
    # Fig. 8 is the image of Fig. 7: same values at corresponding points
    L3, t1 = np.linspace(0.2, 1.9, 40), np.linspace(0.1, 3.0, 40)
    f = mech.forward_grid(L3, t1)
    Kc = cartesian_stiffness_map(mech, f.x, f.y)[:, 0]
    np.testing.assert_allclose(Kc, actuator_stiffness_map(mech, L3, t1), rtol=1e-10)
