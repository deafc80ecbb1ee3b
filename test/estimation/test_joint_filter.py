"""The recursive filter (tensegrity_stiffness.estimation.joint_filter) on the forward model: its
body-form dynamics against JointDynamics, every new Jacobian against central differences, the
prediction against an integration of JointDynamics.acceleration, agreement with the static
estimator at rest, and its trust rules (NIS, a broken sensor named, impossible readings, an
unobservable set, a lost track restarted)."""

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from scipy.stats import chi2
from support import REPO
from support.estimation_trials import SENSOR_SETS, TENSION_STD, measure, truth_from_model

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.estimators import (
    JointEstimate,
    Measurements,
    estimate_joint_state,
)
from tensegrity_stiffness.estimation.joint_filter import JointFilter, ProcessNoise, body_dynamics
from tensegrity_stiffness.estimation.least_squares import MIN_FIT_ITERATIONS
from tensegrity_stiffness.geometry.screw import ScrewKinematics
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.dynamics import (
    JointDynamics,
    body_jacobian,
    body_jacobian_rate,
)
from tensegrity_stiffness.mechanics.joint import JointModel

CONFIG = REPO / 'config' / 'default_joint.yaml'
GRAVITY = np.array([0.0, -9.81, 0.0])
SPREAD = np.array([0.02] * 3 + [5e-4] * 3)
RATE_SPREAD = np.array([0.5] * 3 + [0.02] * 3)
LOAD_SPREAD = np.array([0.05] * 3 + [0.001] * 3)
ACCEL_STD = 0.05
GYRO_STD = 0.01


@pytest.fixture(scope='module')
def model():
    return JointModel.from_yaml(CONFIG)


def random_state(model, rng):
    return (model.initial_screw + rng.normal(scale=SPREAD), rng.normal(scale=RATE_SPREAD),
            rng.normal(scale=LOAD_SPREAD))


def central(f, x, step):
    cols = []
    for k in range(x.size):
        d = np.zeros_like(x)
        d[k] = step
        cols.append((f(x + d) - f(x - d)) / (2.0 * step))
    return np.stack(cols, axis=-1)


def dynamics_at(jd, xi, V, W):
    return body_dynamics(jd, sm.string_predictions_unchecked(jd.model, xi, jd.model.rest_lengths),
                         V, W)


# ------------------------------------------------------------------ dynamics
@pytest.mark.parametrize('damping', [0.0, 0.5])
def test_body_form_is_joint_dynamics(model, damping):
    """dV/dt = J_b xi_ddot + Jdot_b xi_dot with xi_ddot of JointDynamics.acceleration."""
    jd = JointDynamics(model, None, damping)
    rng = np.random.default_rng(1)
    for _ in range(5):
        xi, xid, W = random_state(model, rng)
        Jb = body_jacobian(xi)
        expected = Jb @ jd.acceleration(xi, xid, None, W) + body_jacobian_rate(xi, xid)
        bd = dynamics_at(jd, xi, Jb @ xid, W)
        scale = np.abs(expected).max()
        np.testing.assert_allclose(bd.twist_rate, expected, rtol=0, atol=1e-9 * scale)
        np.testing.assert_allclose(bd.screw_rate, xid, rtol=0, atol=1e-12)


@pytest.mark.parametrize('damping, moving', [(0.0, True), (0.5, False)])
def test_body_dynamics_jacobians(model, damping, moving):
    """Exact where the model says so: with damping the pose dependence of the damping is left
    out, which is zero at rest."""
    jd = JointDynamics(model, None, damping)
    rng = np.random.default_rng(2)
    for _ in range(3):
        xi, xid, W = random_state(model, rng)
        V = body_jacobian(xi) @ xid if moving else np.zeros(6)
        bd = dynamics_at(jd, xi, V, W)
        for J, f, x, step in (
                (bd.d_screw, lambda x, V=V, W=W: dynamics_at(jd, x, V, W).twist_rate, xi,
                 1e-7),
                (bd.d_twist, lambda x, xi=xi, W=W: dynamics_at(jd, xi, x, W).twist_rate, V,
                 1e-6),
                (bd.d_load, lambda x, xi=xi, V=V: dynamics_at(jd, xi, V, x).twist_rate, W,
                 1e-6)):
            num = central(f, x, step)
            np.testing.assert_allclose(J, num, rtol=0, atol=1e-6 * np.abs(J).max())
        # and with damping the twist Jacobian is exact at any velocity
        if damping:
            V2 = body_jacobian(xi) @ xid
            bd2 = dynamics_at(jd, xi, V2, W)
            num = central(lambda x, xi=xi, W=W: dynamics_at(jd, xi, x, W).twist_rate, V2,
                          1e-6)
            np.testing.assert_allclose(bd2.d_twist, num, rtol=0,
                                       atol=1e-6 * np.abs(bd2.d_twist).max())


# ------------------------------------------------------------------ sensor models
def test_specific_force_and_gyro_jacobians(model):
    rng = np.random.default_rng(3)
    for _ in range(5):
        xi, _, _ = random_state(model, rng)
        V, Vd = rng.normal(size=6), rng.normal(size=6) * 10.0

        def f(xi=xi, V=V, Vd=Vd):
            return sm.predicted_specific_force(ScrewKinematics(xi), V, Vd, GRAVITY).value

        p = sm.predicted_specific_force(ScrewKinematics(xi), V, Vd, GRAVITY)
        np.testing.assert_allclose(p.screw, central(lambda x: f(xi=x), xi, 1e-7), atol=1e-6)
        np.testing.assert_allclose(p.twist, central(lambda x: f(V=x), V, 1e-6), atol=1e-8)
        np.testing.assert_allclose(p.twist_rate, central(lambda x: f(Vd=x), Vd, 1e-6),
                                   atol=1e-8)
        w, dw = sm.predicted_angular_velocity(V)
        np.testing.assert_array_equal(w, V[:3])
        np.testing.assert_allclose(dw, central(lambda x: sm.predicted_angular_velocity(x)[0],
                                               V, 1e-6), atol=1e-9)
        _, du = sm.gravity_direction_jacobian(p.value)
        np.testing.assert_allclose(du, central(lambda x: sm.gravity_direction_jacobian(x)[0],
                                               p.value, 1e-6), atol=1e-8)
    # at rest the accelerometer's direction is the static model's gravity direction
    xi = model.initial_screw
    p = sm.predicted_specific_force(ScrewKinematics(xi), np.zeros(6), np.zeros(6), GRAVITY)
    g2, _ = sm.predicted_gravity(xi, GRAVITY)
    np.testing.assert_allclose(sm.gravity_direction_jacobian(p.value)[0], g2, atol=1e-15)


def imu_readings(model, xi, rng=None, twist=None):
    """12 tensions, an accelerometer and a gyro of a joint at rest at ``xi`` (noise-free
    without ``rng``)."""
    st = model.evaluate(xi)
    noise = (lambda s, n: rng.normal(scale=s, size=n)) if rng is not None else \
        (lambda s, n: np.zeros(n))
    return Measurements(tensions=st.tensions + noise(TENSION_STD, 12), tension_std=TENSION_STD,
                        specific_force=-st.transform[:3, :3].T @ GRAVITY + noise(ACCEL_STD, 3),
                        specific_force_std=ACCEL_STD,
                        angular_velocity=noise(GYRO_STD, 3), angular_velocity_std=GYRO_STD)


@pytest.mark.parametrize('load', ['unknown', 'known'])
def test_measurement_jacobian(model, load):
    """The stacked update's Jacobian in the state (the accelerometer chained through the
    dynamics) against central differences of its residual, on a moving joint (no damping:
    then every term is exact)."""
    rng = np.random.default_rng(4)
    flt = JointFilter(model, load=load)
    xi, _, W = random_state(model, rng)
    st = model.evaluate(xi)
    T = st.transform
    m = Measurements(tensions=st.tensions, tension_std=TENSION_STD, lengths=st.lengths,
                     length_std=1e-4, pose=T, pose_covariance=np.eye(6) * 1e-8,
                     specific_force=np.array([0.0, 9.81, 0.0]), specific_force_std=ACCEL_STD,
                     gravity=np.array([0.0, -1.0, 0.0]), gravity_std=0.01,
                     gravity_base=[0.0, -1.0, 0.0],
                     angular_velocity=np.zeros(3), angular_velocity_std=GYRO_STD,
                     **({'external_wrench': W, 'wrench_covariance': np.eye(6) * 1e-4}
                        if load == 'unknown' else {}))
    twist = np.concatenate([T[:3, :3] @ rng.normal(scale=0.02, size=3),
                            T[:3, :3] @ rng.normal(scale=0.5, size=3)])
    known = None if load == 'unknown' else W

    def residual(x):
        flt.set_state(x, np.eye(flt.size))
        return flt.measurement_model(m, known_load=known)[0]

    flt.reset(xi, twist=twist, load=W if load == 'unknown' else None)
    x0 = flt.state
    _, H, labels = flt.measurement_model(m, known_load=known)
    assert labels.count('imu') == 3 and labels.count('gyro') == 3 and labels.count('pose') == 6
    steps = np.r_[[1e-7] * 6, [1e-6] * (flt.size - 6)]
    num = np.stack([(residual(x0 + np.eye(flt.size)[k] * steps[k]) -
                     residual(x0 - np.eye(flt.size)[k] * steps[k])) / (2 * steps[k])
                    for k in range(flt.size)], axis=1)
    scale = np.abs(H).max(axis=1, keepdims=True)
    np.testing.assert_allclose(H / scale, num / scale, atol=1e-6)


# ------------------------------------------------------------------ prediction
def test_prediction_follows_joint_dynamics(model):
    """Released from rest off its equilibrium, the filter's predicted screw and twist follow
    an accurate integration of JointDynamics.acceleration (RK45 at rtol 1e-9) to within the
    error of 1 ms steps (first order: a 1e-3 fraction of the travel, 1e-2 of the speed)."""
    jd = JointDynamics(model, None, 0.5)
    rng = np.random.default_rng(5)
    xi0 = model.initial_screw + rng.normal(scale=[0.01] * 3 + [2e-4] * 3)
    W = rng.normal(scale=LOAD_SPREAD)
    horizon = 0.02

    def rhs(_, y):
        return np.concatenate([y[6:], jd.acceleration(y[:6], y[6:], None, W)])

    sol = solve_ivp(rhs, (0.0, horizon), np.r_[xi0, np.zeros(6)], rtol=1e-9, atol=1e-12)
    flt = JointFilter(jd, load='known')
    flt.reset(xi0)
    for k in range(0, 21):
        flt.predict(k * 1e-3, known_load=W)
    xi_f = flt.state[:6]
    xi_t, xid_t = sol.y[:6, -1], sol.y[6:, -1]
    travel = np.abs(xi_t - xi0).max()
    assert travel > 1e-3  # it moved
    np.testing.assert_allclose(xi_f, xi_t, atol=2e-3 * travel)
    V_t = body_jacobian(xi_t) @ xid_t
    np.testing.assert_allclose(flt.state[6:12], V_t, atol=1e-2 * np.abs(V_t).max())
    # one 20 ms prediction (split into 1 ms steps internally) lands at the same place
    other = JointFilter(jd, load='known')
    other.reset(xi0)
    other.predict(0.0, known_load=W)
    other.predict(horizon, known_load=W)
    np.testing.assert_allclose(other.state, flt.state, atol=1e-12)


# ------------------------------------------------------------------ at rest
def test_at_rest_the_filter_agrees_with_the_static_estimator(model):
    """On 30 resting states, after 40 updates with the same sensors the filter's estimate
    lies within the static estimate's covariance of it (the filter has more information: its
    std is below the static one). The difference ``d`` has a covariance below the static
    estimate's ``C`` (the filter's error is nearly independent of the last reading's), so
    ``d^T C^-1 d`` is at most chi-square with 6 dof: bounded at the quantile of a family-wise
    false alarm of 1e-3 over the 30 states. (A bound of 3 std per coordinate, 180 of them,
    fails one in two seeded draws once the filter at rest averages its readings: issue 37's
    process noise that follows the rest lengths.)"""
    rng = np.random.default_rng(6)
    bound = chi2.ppf(1.0 - 1e-3 / 30, 6)
    for _ in range(30):
        xi = model.initial_screw + rng.normal(scale=SPREAD)
        flt = JointFilter(model, string_damping=0.5, stiffness_std=False)
        for k in range(40):
            m = imu_readings(model, xi, rng)
            est = flt.step(k * 1e-3, m)
        assert est.success and est.consistent, est.chi2
        static = estimate_joint_state(model, Measurements(
            tensions=m.tensions, tension_std=m.tension_std,
            gravity=sm.gravity_from_specific_force(m.specific_force),
            gravity_std=ACCEL_STD / 9.81, gravity_base=GRAVITY / 9.81), stiffness_std=False)
        d = sm.pose_error(est.transform, static.transform)
        std = np.sqrt(np.diag(static.covariance))
        assert d @ np.linalg.solve(static.covariance, d) <= bound, d / std
        assert np.all(np.sqrt(np.diag(est.covariance)) <= std)
        np.testing.assert_allclose(est.external_wrench, static.external_wrench,
                                   atol=3.0 * np.sqrt(np.diag(static.wrench_covariance)).max())


def test_first_step_is_the_static_estimate(model):
    rng = np.random.default_rng(7)
    xi = model.initial_screw + rng.normal(scale=SPREAD)
    flt = JointFilter(model)
    est = flt.step(0.0, imu_readings(model, xi, rng))
    assert isinstance(est, JointEstimate) and est.success
    assert est.twist.shape == (6,) and est.twist_covariance.shape == (6, 6)
    np.testing.assert_allclose(est.twist, 0.0)
    assert np.all(np.diag(est.twist_covariance) > 0.0)


# ------------------------------------------------------------------ trust
def tracking_filter(model, xi, rng, steps=30):
    flt = JointFilter(model, string_damping=0.5, stiffness_std=False)
    for k in range(steps):
        flt.step(k * 1e-3, imu_readings(model, xi, rng))
    return flt, steps * 1e-3


@pytest.mark.parametrize('fault', ['load cell at -0.3 N', 'load cell 0.8 N off', 'IMU flipped'])
def test_a_broken_sensor_is_named(model, fault):
    rng = np.random.default_rng(8)
    xi = model.initial_screw + rng.normal(scale=SPREAD)
    flt, t = tracking_filter(model, xi, rng)
    for k in range(10):
        m = imu_readings(model, xi, rng)
        if fault == 'IMU flipped':
            m.specific_force = -m.specific_force
            name = 'imu'
        else:
            j = 5
            m.tensions[j] = -0.3 if fault.startswith('load cell at') else m.tensions[j] + 0.8
            name = f'tension[{model.string_names[j]}]'
        est = flt.step(t + k * 1e-3, m)
        assert est.outliers == (name,), (est.outliers, est.outlier_reasons)
        assert est.consistent is True
        assert not est.restarted


def test_impossible_reading_left_out(model):
    rng = np.random.default_rng(9)
    xi = model.initial_screw + rng.normal(scale=SPREAD)
    flt, t = tracking_filter(model, xi, rng)
    m = imu_readings(model, xi, rng)
    m.tensions[3] = 1e4
    est = flt.step(t, m)
    assert est.outliers == (f'tension[{model.string_names[3]}]',)
    assert 'impossible' in est.outlier_reasons[0]


def test_unobservable_set_is_named(model):
    flt = JointFilter(model)
    t = np.full(12, np.nan)
    t[:3] = 1.0
    est = flt.step(0.0, Measurements(tensions=t, tension_std=TENSION_STD))
    assert not est.success and not est.observable
    assert '3 measured degrees of freedom' in est.message
    assert not flt.initialized


def test_lost_track_restarts_from_the_static_estimator(model):
    rng = np.random.default_rng(10)
    xi = model.initial_screw + rng.normal(scale=SPREAD)
    flt, t = tracking_filter(model, xi, rng)
    other = model.initial_screw + rng.normal(scale=SPREAD)  # the joint "jumps"
    restarted = []
    for k in range(8):
        est = flt.step(t + k * 1e-3, imu_readings(model, other, rng))
        restarted.append(est.restarted)
    assert any(restarted)
    assert est.success
    np.testing.assert_allclose(sm.pose_error(est.transform, model.evaluate(other).transform),
                               0.0, atol=5e-3)


def test_known_load(model):
    rng = np.random.default_rng(11)
    W = rng.normal(scale=LOAD_SPREAD)
    from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
    xi = solve_equilibrium(model, W).screw
    flt = JointFilter(model, load='known', string_damping=0.5, stiffness_std=False)
    assert flt.size == 12
    for k in range(20):
        est = flt.step(k * 1e-3, imu_readings(model, xi, rng), known_load=W)
    assert est.success and est.consistent
    np.testing.assert_array_equal(est.external_wrench, W)
    d = sm.pose_error(est.transform, model.evaluate(xi).transform)
    assert np.all(np.abs(d) <= 4.0 * np.sqrt(np.diag(est.covariance)))


def test_process_noise_follows_the_rest_lengths(model):
    """ProcessNoise.motion_scale: the accelerations' variance densities scale with
    ``hold_fraction + (rdot / rest_rate)^2`` of the RMS rest-length rate over the step (1
    before two sets of rest lengths, and with ``rest_rate = 0``); the filter's prediction adds
    exactly that ``Q`` to the twist."""
    noise = ProcessNoise(hold_fraction=0.01)
    r0 = model.rest_lengths.copy()
    dt = 1e-3  # one substep: the prediction adds Q to a zero covariance
    moving = r0 + noise.rest_rate * dt * np.sign(np.arange(r0.size) - 5.5)  # RMS rest_rate
    assert noise.motion_scale(None, moving, dt) == 1.0
    assert noise.motion_scale(r0, r0, dt) == 0.01
    assert noise.motion_scale(r0, moving, dt) == pytest.approx(1.01, rel=1e-12)
    assert noise.motion_scale(r0, r0 + 2.0 * (moving - r0), dt) == pytest.approx(4.01,
                                                                                 rel=1e-12)
    assert ProcessNoise(rest_rate=0.0).motion_scale(r0, moving, dt) == 1.0
    for bad in ({'rest_rate': -1.0}, {'hold_fraction': math.nan}):
        with pytest.raises(ValueError, match=f'process_noise.{next(iter(bad))}'):
            ProcessNoise(**bad)
    for use_kernel in (True, False):
        flt = JointFilter(model, process_noise=noise, load='known', string_damping=0.5,
                          use_kernel=use_kernel)
        flt.reset(model.initial_screw, covariance=np.zeros((12, 12)))
        flt.predict(0.0, r0)
        flt.predict(dt, r0)  # no rest lengths before: the factor 1
        for t, rest, factor in ((2 * dt, r0, 0.01), (3 * dt, moving, 1.01)):
            flt.set_state(flt.state, np.zeros((12, 12)))
            flt.predict(t, rest)
            np.testing.assert_allclose(np.diag(flt.covariance)[6:12],
                                       noise.twist_density() * factor * dt, rtol=1e-12)


def test_bad_input(model):
    flt = JointFilter(model)
    with pytest.raises(ValueError, match='load must be one of'):
        JointFilter(model, load='maybe')
    with pytest.raises(ValueError, match='process_noise'):
        JointFilter(model, process_noise=ProcessNoise(force_rate=-1.0))
    with pytest.raises(ValueError, match='gravity'):
        JointFilter(model, gravity=[0.0, 1.0])
    m = imu_readings(model, model.initial_screw)
    flt.step(1.0, m)
    with pytest.raises(ValueError, match='earlier'):
        flt.step(0.5, m)
    with pytest.raises(ValueError, match='specific_force_std'):
        flt.step(1.1, Measurements(tensions=m.tensions, tension_std=TENSION_STD,
                                   specific_force=[0.0, 9.81, 0.0]))
    with pytest.raises(ValueError, match='known_load'):
        flt.step(1.2, m, known_load=np.zeros(6))
    with pytest.raises(ValueError, match="no state"):
        JointFilter(model).predict(0.0)


def test_static_estimator_ignores_the_filter_fields(model):
    """The new IMU fields leave the static estimator's figures unchanged."""
    rng = np.random.default_rng(12)
    xi = model.initial_screw + rng.normal(scale=SPREAD)
    m = imu_readings(model, xi, rng)
    plain = Measurements(tensions=m.tensions, tension_std=m.tension_std)
    a = estimate_joint_state(model, plain, stiffness_std=False)
    b = estimate_joint_state(model, m, stiffness_std=False)
    np.testing.assert_array_equal(a.screw, b.screw)
    np.testing.assert_array_equal(a.covariance, b.covariance)
    np.testing.assert_array_equal(b.twist, np.zeros(6))


# ------------------------------------------------------------------ the compiled kernel
def _run(model, use_kernel, load='unknown', damping=0.5, dt=1e-3):
    """A seeded run with a moving joint, rest lengths that change (the process noise's motion
    factor, ProcessNoise.motion_scale, at every step), a broken load cell, a flipped IMU, a
    gap, a lost track and a step over several substeps: every estimate's numbers."""
    rng = np.random.default_rng(21)
    phase = np.arange(model.n_strings)
    flt = JointFilter(model, load=load, string_damping=damping, use_kernel=use_kernel)
    assert flt.use_kernel == (use_kernel and kernel.available())
    xi = model.initial_screw + rng.normal(scale=SPREAD)
    out, t = [], 0.0
    for k in range(60):
        xi = xi + rng.normal(scale=1e-4 * SPREAD)
        m = imu_readings(model, xi, rng)
        if 20 <= k < 24:
            m.tensions[5] += 0.8
        if 30 <= k < 32:
            m.specific_force = -m.specific_force
        if 40 <= k < 45:  # the joint jumps: a lost track
            m = imu_readings(model, xi + SPREAD, rng)
        t += 2.5 * dt if k % 7 == 0 else dt
        if k == 50:
            t += 0.6  # a gap: restart
        rest = model.rest_lengths + 1e-5 * np.sin(0.3 * k + phase)
        est = flt.step(t, m, rest, known_load=np.zeros(6) if load == 'known' else None)
        out.append((est.screw, est.screw_covariance, est.twist, est.twist_covariance,
                    est.external_wrench, est.chi2, est.outliers, est.consistent,
                    est.restarted))
    return out


@pytest.mark.skipif(not kernel.available(), reason=kernel.status())
@pytest.mark.parametrize('load, damping', [('unknown', 0.5), ('unknown', 0.0), ('known', 0.5)])
def test_kernel_run_equals_numpy(model, load, damping):
    """A whole seeded run (moving joint, outliers, a lost track, a gap, substeps) gives the
    same estimates with the compiled kernel as with the numpy reference: the same decisions,
    the screw, its covariance and the load to 1e-12 of their scale, the twist to 1e-11 and
    its covariance and the NIS to 1e-10 (measured: 2e-16, 1e-14, 1e-14; 1e-12, 5e-12,
    2e-12: rounding carried over 60 steps)."""
    a = _run(model, True, load, damping)
    b = _run(model, False, load, damping)
    for k, (ea, eb) in enumerate(zip(a, b, strict=True)):
        assert ea[6:] == eb[6:], k
        for x, y, rel in zip(ea[:6], eb[:6], (1e-12, 1e-12, 1e-11, 1e-10, 1e-12, 1e-10),
                             strict=True):
            scale = max(np.abs(y).max(), 1e-300)
            np.testing.assert_allclose(x, y, rtol=0, atol=rel * scale, err_msg=str(k))


def test_a_start_within_restart_time_budget(model):
    """``restart_time_budget`` bounds the (re)start's static estimate (issue #42 item 2): with
    0 s a cold start that needs more than the uncut iterations (a joint turned 0.26 rad from
    its unloaded screw, 12 load cells) fails by name and the next reading tries again; without
    a budget the same start succeeds; a bad budget is refused."""
    xi = model.initial_screw + 0.15 * np.array([1.0, -1.0, 1.0, 1 / 6, -1 / 6, 1 / 6])
    m = measure(truth_from_model(model, xi), SENSOR_SETS['12 tensions'],
                np.random.default_rng(1))
    assert JointFilter(model).step(0.0, m).success
    flt = JointFilter(model, restart_time_budget=0.0)
    est = flt.step(0.0, m)
    assert not est.success
    assert est.message.startswith(f'time budget exhausted after {MIN_FIT_ITERATIONS} '
                                  'iterations'), est.message
    for bad in (-1.0, math.inf, math.nan):
        with pytest.raises(ValueError, match='restart_time_budget'):
            JointFilter(model, restart_time_budget=bad)
