"""Sensor models: every prediction against the geometry it came from, every Jacobian against
central differences (default joint, random joints with slack and saturated strings, both force
laws, small and large rotations)."""


import numpy as np
import pytest
from support import REPO
from support.joint_compare import random_model

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import ScrewKinematics, dexp_se3, exp_se3, exp_so3
from tensegrity_stiffness.mechanics.joint import JointModel

CONFIG = REPO / 'config' / 'default_joint.yaml'
#: Central-difference step (screw coordinates, rad and m) and the tolerance it supports.
CD_STEP = 1e-6
CD_RTOL = 1e-6


def central(f, x, step=CD_STEP):
    """Central-difference Jacobian of f at x (columns = coordinates of x)."""
    x = np.asarray(x, dtype=float)
    cols = []
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = step
        cols.append((np.asarray(f(x + e)) - np.asarray(f(x - e))) / (2.0 * step))
    return np.stack(cols, axis=-1)


def assert_jacobian(analytic, numeric, rtol=CD_RTOL, name=''):
    scale = max(np.max(np.abs(numeric)), 1e-12)
    np.testing.assert_allclose(analytic, numeric, rtol=0.0, atol=rtol * scale, err_msg=name)


@pytest.fixture(scope='module')
def model():
    return JointModel.from_yaml(CONFIG)


def screws(model, rng, count=6):
    """The unloaded equilibrium (rotation by pi), perturbations of it, a zero-rotation screw and
    a small rotation (series branches), both lifted so that no string has zero length."""
    out = [model.initial_screw, np.array([0.0, 0.0, 0.0, 0.001, 0.0, 0.04]),
           np.array([1e-4, -2e-4, 3e-5, 0.001, 0.0, 0.04])]
    for _ in range(count):
        out.append(model.initial_screw + rng.normal(scale=[0.1] * 3 + [0.003] * 3))
    return out


def test_lengths_and_tensions_match_evaluate_and_geometry(model):
    rng = np.random.default_rng(1)
    for xi in screws(model, rng):
        pred = sm.string_predictions(model, xi)
        state = model.evaluate(xi)
        np.testing.assert_allclose(pred.tensions, state.tensions, rtol=0, atol=1e-15)
        T = exp_se3(xi)
        q = model.link2_nodes[model.connections[:, 1]] @ T[:3, :3].T + T[:3, 3]
        direct = np.linalg.norm(model.link1_nodes[model.connections[:, 0]] - q, axis=1)
        np.testing.assert_allclose(pred.lengths, direct, rtol=1e-13)


def clear_of_boundaries(model, lengths, rest, margin=1e-4):
    """Strings further than ``margin`` (m) from a region boundary (slack / saturated), where
    central differences of the tension have one-sided slopes."""
    return ((np.abs(lengths - rest) > margin)
            & (np.abs(lengths - rest - model.max_stretch) > margin))


def check_string_jacobians(m, xi):
    pred = sm.string_predictions(m, xi)
    lengths_cd = central(lambda x: m.evaluate(x).lengths, xi)
    tensions_cd = central(lambda x: m.evaluate(x).tensions, xi)
    assert_jacobian(pred.length_jacobian, lengths_cd, name='dl/dxi')
    clear = clear_of_boundaries(m, pred.lengths, m.rest_lengths)
    assert_jacobian(pred.tension_jacobian[clear], tensions_cd[clear], name='dphi/dxi')


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_string_jacobians_central_differences(force_law, model):
    rng = np.random.default_rng(2)
    for _ in range(6):
        check_string_jacobians(random_model(rng, force_law=force_law),
                               rng.normal(scale=[0.8] * 3 + [0.02] * 3))
    for xi in screws(model, rng, 3):
        check_string_jacobians(model, xi)


def test_regions_are_covered():
    """The random joints of the Jacobian test have slack, taut and saturated strings."""
    rng = np.random.default_rng(2)
    seen = np.zeros(3, dtype=bool)
    for _ in range(6):
        m = random_model(rng)
        xi = rng.normal(scale=[0.8] * 3 + [0.02] * 3)
        state = m.evaluate(xi)
        seen |= [state.slack.any(), (~state.slack & ~state.saturated).any(),
                 state.saturated.any()]
    assert seen.all()


def test_length_jacobian_is_dexp_applied_to_nodes(model):
    """dl/dxi equals u^T (-dT/dxi p2) with the (4, 4, 6) closed form of screw.dexp_se3."""
    rng = np.random.default_rng(3)
    for xi in screws(model, rng, 3):
        pred = sm.string_predictions(model, xi)
        dT = dexp_se3(xi)
        p2h = np.hstack([model.link2_nodes[model.connections[:, 1]],
                         np.ones((model.n_strings, 1))])
        dq = np.einsum('ikm,jk->jim', dT[:3], p2h)
        u = pred.state.string_vectors / pred.lengths[:, None]
        np.testing.assert_allclose(pred.length_jacobian, -np.einsum('ji,jim->jm', u, dq),
                                   rtol=0, atol=1e-13)
        points = p2h[:, :3] @ exp_se3(xi)[:3, :3].T + exp_se3(xi)[:3, 3]
        np.testing.assert_allclose(sm.link2_points_jacobian(points, ScrewKinematics(xi)), dq,
                                   rtol=0, atol=1e-13)


def test_wrappers(model):
    xi = model.initial_screw
    pred = sm.string_predictions(model, xi)
    lengths, dl = sm.predicted_lengths(model, xi)
    tensions, dphi = sm.predicted_tensions(model, xi)
    np.testing.assert_array_equal(lengths, pred.lengths)
    np.testing.assert_array_equal(dl, pred.length_jacobian)
    np.testing.assert_array_equal(tensions, pred.tensions)
    np.testing.assert_array_equal(dphi, pred.tension_jacobian)


def test_overridden_rest_lengths(model):
    xi = model.initial_screw
    rest = model.rest_lengths * 0.97
    tensions, dphi = sm.predicted_tensions(model, xi, rest)
    np.testing.assert_allclose(tensions, model.evaluate(xi, rest).tensions, rtol=1e-14)
    assert_jacobian(dphi, central(lambda x: model.evaluate(x, rest).tensions, xi))


def check_parameter_jacobians(m, xi):
    jac = sm.string_parameter_jacobians(m, xi)
    rest, k = m.rest_lengths, m.k
    clear = clear_of_boundaries(m, m.evaluate(xi).lengths, rest)

    def with_k(kk):
        return JointModel(m.link1_nodes, m.connections, kk, rest, link2_nodes=m.link2_nodes,
                          max_lengths=m.max_lengths, force_law=m.force_law).evaluate(xi)

    dphi_dk = central(lambda kk: with_k(kk).tensions, k, step=1e-4)
    dF_dk = central(lambda kk: with_k(kk).wrench, k, step=1e-4)
    dphi_dl0 = central(lambda r: m.evaluate(xi, r).tensions, rest)
    dF_dl0 = central(lambda r: m.evaluate(xi, r).wrench, rest)
    assert_jacobian(np.diag(jac.tension_stiffness), dphi_dk, name='dphi/dk')
    assert_jacobian(jac.wrench_stiffness, dF_dk, name='dF/dk')
    assert_jacobian(np.diag(jac.tension_rest_length)[clear], dphi_dl0[clear], name='dphi/dl0')
    assert_jacobian(jac.wrench_rest_length[:, clear], dF_dl0[:, clear], name='dF/dl0')


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_parameter_jacobians_central_differences(force_law):
    rng = np.random.default_rng(4)
    for _ in range(5):
        check_parameter_jacobians(random_model(rng, force_law=force_law),
                                  rng.normal(scale=[0.8] * 3 + [0.02] * 3))


def random_rotation(rng, scale=0.3):
    return exp_so3(rng.normal(scale=scale, size=3))


def test_pose_error_convention():
    """pose_error(T, T_ref) is the [dp; dtheta] that maps T_ref to T (p + dp, exp(dtheta) R)."""
    rng = np.random.default_rng(5)
    T_ref = np.eye(4)
    T_ref[:3, :3] = random_rotation(rng, 1.0)
    T_ref[:3, 3] = rng.normal(size=3)
    d = rng.normal(scale=[0.01, 0.02, 0.03, 0.1, 0.2, 0.05])
    T = T_ref.copy()
    T[:3, 3] += d[:3]
    T[:3, :3] = exp_so3(d[3:]) @ T_ref[:3, :3]
    np.testing.assert_allclose(sm.pose_error(T, T_ref), d, rtol=1e-13, atol=1e-15)
    quat = rotation_to_quaternion(T[:3, :3])
    np.testing.assert_allclose(sm.pose_error(np.concatenate([T[:3, 3], quat]), T_ref), d,
                               rtol=1e-12, atol=1e-14)


def test_pose_jacobian_central_differences(model):
    rng = np.random.default_rng(6)
    for xi in screws(model, rng):
        T0 = exp_se3(xi)
        numeric = central(lambda x, T0=T0: sm.pose_error(exp_se3(x), T0), xi)
        assert_jacobian(sm.pose_jacobian(xi), numeric, name='d[dp; dtheta]/dxi')


def test_pose_covariance_first_order(model):
    xi = model.initial_screw
    C = np.diag([1e-4, 2e-4, 3e-4, 1e-6, 2e-6, 3e-6])
    P = sm.pose_jacobian(xi)
    np.testing.assert_allclose(sm.pose_covariance(xi, C), P @ C @ P.T, rtol=1e-14)


def test_pose_residual_and_jacobian(model):
    rng = np.random.default_rng(7)
    for xi in screws(model, rng):
        T_true = exp_se3(xi)
        d = rng.normal(scale=[1e-3] * 3 + [0.05] * 3)
        T_m = T_true.copy()
        T_m[:3, 3] += d[:3]
        T_m[:3, :3] = exp_so3(d[3:]) @ T_true[:3, :3]
        r, J = sm.pose_residual(xi, T_m)
        np.testing.assert_allclose(r[:3], -d[:3], rtol=1e-12, atol=1e-16)
        # r = log(R R_m^T) = log(exp(-d)) exactly, as R R_m^T = exp(-d)
        np.testing.assert_allclose(r[3:], -d[3:], rtol=1e-10, atol=1e-16)
        numeric = central(lambda x, T_m=T_m: sm.pose_residual(x, T_m)[0], xi)
        assert_jacobian(J, numeric, name='pose residual')


def test_gravity_prediction_and_jacobian(model):
    rng = np.random.default_rng(8)
    g1 = np.array([0.1, -0.3, -9.0])
    for xi in screws(model, rng):
        g2, J = sm.predicted_gravity(xi, g1)
        R = exp_se3(xi)[:3, :3]
        np.testing.assert_allclose(R @ g2, g1 / np.linalg.norm(g1), rtol=1e-13)
        assert_jacobian(J, central(lambda x: sm.predicted_gravity(x, g1)[0], xi), name='dg/dxi')
        assert np.abs(g2 @ J).max() < 1e-12  # the unit length carries no information
    with pytest.raises(ValueError, match='gravity_base'):
        sm.predicted_gravity(np.zeros(6), np.zeros(3))


def test_equilibrium_residual(model):
    rng = np.random.default_rng(9)
    for xi in screws(model, rng):
        W = rng.normal(scale=[1.0] * 3 + [0.02] * 3)
        r, J = sm.equilibrium_residual(model, xi, W)
        state = model.evaluate(xi)
        np.testing.assert_allclose(r, state.wrench + W, rtol=1e-14, atol=1e-15)
        x = np.concatenate([xi, W])
        numeric = central(lambda z: sm.equilibrium_residual(model, z[:6], z[6:])[0], x)
        assert_jacobian(J, numeric, rtol=1e-5, name='[K, I]')


def test_bad_input(model):
    with pytest.raises(ValueError, match='screw'):
        sm.predicted_tensions(model, np.ones(5))
    with pytest.raises(ValueError, match='screw'):
        sm.predicted_lengths(model, [np.nan] * 6)
    with pytest.raises(ValueError, match='rest_lengths'):
        sm.predicted_tensions(model, np.zeros(6), np.ones(3))
    with pytest.raises(ValueError, match='external_wrench'):
        sm.equilibrium_residual(model, np.zeros(6), np.ones(5))
    with pytest.raises(ValueError, match='measured pose'):
        sm.pose_residual(np.zeros(6), np.ones((3, 3)))
    with pytest.raises(ValueError, match='transform'):
        sm.pose_error(np.eye(4) * 2.0, np.eye(4))


def test_gravity_from_specific_force():
    np.testing.assert_allclose(sm.gravity_from_specific_force([0.0, 9.81, 0.0]), [0, -1.0, 0])
    with pytest.raises(ValueError, match='specific_force'):
        sm.gravity_from_specific_force([0.0, np.nan, 0.0])
