"""Screw algebra: exp, log, left Jacobian and the closed-form dT/dxi (eqs. 1-5, 12-18)."""

import math

import numpy as np
import pytest
from scipy.linalg import expm
from support.screw_samples import random_screws, reference_dexp

from tensegrity_stiffness.geometry.screw import (
    SERIES_THRESHOLD,
    ScrewKinematics,
    as_screws,
    dexp_se3,
    exp_se3,
    exp_so3,
    hat,
    hat3,
    left_jacobian_se3,
    left_jacobian_so3,
    left_jacobian_so3_inverse,
    log_se3,
    log_so3,
    rotation_coefficients,
    vee,
    vee3,
)

CD_STEP = 1e-6  # the paper's central-difference step (eq. 21)
SPECIAL_ANGLES = [0.0, 1e-12, 1e-8, 1e-6, 1e-4, SERIES_THRESHOLD * (1 - 1e-9),
                  SERIES_THRESHOLD * (1 + 1e-9), 1.0, math.pi - 1e-6, math.pi - 1e-9, math.pi,
                  math.pi + 1e-9, 4.0, 2 * math.pi - 0.1]


def screw_with_angle(rng, theta):
    axis = rng.normal(size=3)
    return np.r_[axis / np.linalg.norm(axis) * theta, rng.normal(size=3)]


def central_dexp(xi, step=CD_STEP):
    """dT/dxi by central differences (eq. 21) of one screw (6,) or a batch (N, 6)."""
    xi = np.asarray(xi, dtype=np.float64)
    out = np.zeros(xi.shape[:-1] + (4, 4, 6))
    for i in range(6):
        e = np.zeros(6)
        e[i] = step
        out[..., i] = (exp_se3(xi + e) - exp_se3(xi - e)) / (2 * step)
    return out


def test_hat_vee_round_trip_and_cross_product():
    rng = np.random.default_rng(0)
    a, b = rng.normal(size=(2, 3))
    np.testing.assert_allclose(hat3(a) @ b, np.cross(a, b), atol=1e-15)
    np.testing.assert_allclose(vee3(hat3(a)), a)
    xi = rng.normal(size=6)
    np.testing.assert_allclose(vee(hat(xi)), xi)
    assert hat(xi).shape == (4, 4) and np.all(hat(xi)[3] == 0.0)


def test_coefficients_match_closed_forms_and_series_at_the_threshold():
    t = np.array([1e-3, 0.1, SERIES_THRESHOLD - 1e-12, SERIES_THRESHOLD, 0.7, 2.0, 3.1])
    a, b, c, b1, c1 = rotation_coefficients(t)
    # Above 1e-1 the closed forms (eqs. 3, 4, 16) are accurate to ~1e-12: compare there.
    m = t >= 0.1
    tm = t[m]
    np.testing.assert_allclose(a[m], np.sin(tm) / tm, rtol=1e-13)
    np.testing.assert_allclose(b[m], (1 - np.cos(tm)) / tm**2, rtol=1e-12)
    np.testing.assert_allclose(c[m], (tm - np.sin(tm)) / tm**3, rtol=1e-10)
    np.testing.assert_allclose(b1[m], (tm * np.sin(tm) + 2 * np.cos(tm) - 2) / tm**4, rtol=1e-8)
    np.testing.assert_allclose(c1[m], (3 * np.sin(tm) - tm * np.cos(tm) - 2 * tm) / tm**5,
                               rtol=1e-7)
    # Limits at 0: 1, 1/2, 1/6, -1/12, -1/60.
    np.testing.assert_allclose([x[0] for x in rotation_coefficients(np.array([0.0]))],
                               [1, 0.5, 1 / 6, -1 / 12, -1 / 60], rtol=1e-15)


def test_closed_form_c_loses_all_digits_at_small_angles_the_series_does_not():
    # Errata (docs/errata.md): c = (t - sin t) / t^3 in closed form loses its digits at small t,
    # and the derivative coefficient c1 = (3 sin t - t cos t - 2 t) / t^5 far earlier.
    t = 1e-6
    closed = (t - math.sin(t)) / t**3
    series = rotation_coefficients(np.array([t]))[2][0]
    assert abs(closed - 1 / 6) / (1 / 6) > 1e-5  # 11 of 16 digits gone
    assert abs(series - (1 / 6 - t * t / 120)) < 1e-16
    t = 1e-2
    closed_c1 = (3 * math.sin(t) - t * math.cos(t) - 2 * t) / t**5
    series_c1 = rotation_coefficients(np.array([t]))[4][0]
    assert abs(closed_c1 - (-1 / 60)) / (1 / 60) > 1e-6
    assert abs(series_c1 - (-1 / 60 + t * t / 1260)) < 1e-12


def test_exp_matches_matrix_exponential():
    rng = np.random.default_rng(1)
    for xi in random_screws(rng, 200, max_angle=2 * math.pi):
        np.testing.assert_allclose(exp_se3(xi), expm(hat(xi)), atol=1e-13)
    for theta in SPECIAL_ANGLES:
        xi = screw_with_angle(rng, theta)
        np.testing.assert_allclose(exp_se3(xi), expm(hat(xi)), atol=1e-13)


def test_pure_translation_is_eq_5():
    v = np.array([0.1, -0.2, 0.3])
    T = exp_se3(np.r_[0, 0, 0, v])
    np.testing.assert_array_equal(T[:3, :3], np.eye(3))
    np.testing.assert_array_equal(T[:3, 3], v)


def test_single_and_batched_paths_agree():
    rng = np.random.default_rng(2)
    xs = random_screws(rng, 50, max_angle=2 * math.pi)
    xs[0, :3] = 0.0
    batch = ScrewKinematics(xs)
    for k, xi in enumerate(xs):
        single = ScrewKinematics(xi)
        for name in ('R', 't', 'G', 'D', 'Q', 'T', 'J'):
            np.testing.assert_allclose(getattr(single, name), getattr(batch, name)[k],
                                       atol=1e-14, err_msg=name)
    np.testing.assert_allclose(dexp_se3(xs)[7], dexp_se3(xs[7]), atol=1e-14)


def test_dexp_against_central_differences_10000_screws():
    """The paper's check (eqs. 21-22, Table II: 2.4e-10) over |omega| <= pi."""
    rng = np.random.default_rng(3)
    xs = random_screws(rng, 10_000)
    analytic = dexp_se3(xs)  # (N, 4, 4, 6)
    numeric = central_dexp(xs)
    err = (np.linalg.norm((analytic - numeric).reshape(len(xs), -1), axis=1)
           / np.linalg.norm(analytic.reshape(len(xs), -1), axis=1))
    assert err.mean() <= 1e-8, err.mean()
    assert err.max() <= 1e-6


@pytest.mark.parametrize('theta', SPECIAL_ANGLES)
def test_dexp_exact_at_special_angles(theta):
    """Against the exact block-exponential derivative (central differences fail at tiny theta)."""
    rng = np.random.default_rng(4)
    xi = screw_with_angle(rng, theta)
    np.testing.assert_allclose(dexp_se3(xi), reference_dexp(xi), atol=2e-13, rtol=0)


def test_dexp_at_zero_is_not_zero():
    # Errata (docs/errata.md): the authors' code sets dT/domega = 0 near theta = 0; the truth is
    # dR/domega_i = hat(e_i) and dp/domega_i = (e_i x v) / 2.
    v = np.array([0.3, -0.1, 0.2])
    d = dexp_se3(np.r_[0, 0, 0, v])
    for i in range(3):
        e = np.eye(3)[i]
        np.testing.assert_allclose(d[:3, :3, i], hat3(e), atol=1e-16)
        np.testing.assert_allclose(d[:3, 3, i], np.cross(e, v) / 2, atol=1e-16)
        np.testing.assert_allclose(d[:3, 3, 3 + i], e, atol=1e-16)


def _eq13(omega, i, as_printed):
    """Eq. (13) of the paper; printed, its first two terms are multiplied (a '+' was lost)."""
    th = np.linalg.norm(omega)
    s, c = math.sin(th), math.cos(th)
    e = np.eye(3)[i]
    W = hat3(omega)
    t1 = (1 - c) / th**2 * (np.outer(e, omega) + np.outer(omega, e)
                            - 2 * omega[i] * np.outer(omega, omega) / th**2)
    t2 = (c * W / th**2 + s * W @ W / th**3) * omega[i]
    t3 = s / th * hat3(e - omega[i] * omega / th**2)
    return t1 @ t2 + t3 if as_printed else t1 + t2 + t3


def test_eq13_is_a_sum_of_three_terms_not_the_printed_product():
    rng = np.random.default_rng(5)
    for _ in range(20):
        omega = rng.normal(size=3)
        d = dexp_se3(np.r_[omega, 0, 0, 0])
        for i in range(3):
            np.testing.assert_allclose(_eq13(omega, i, as_printed=False), d[:3, :3, i],
                                       atol=1e-13)
        printed_err = max(np.abs(_eq13(omega, i, True) - d[:3, :3, i]).max() for i in range(3))
        assert printed_err > 1e-2


def test_gallego_yezzi_form_of_the_rotation_derivative():
    rng = np.random.default_rng(6)
    omega = rng.normal(size=3)
    R = exp_so3(omega)
    d = dexp_se3(np.r_[omega, 0, 0, 0])
    th2 = omega @ omega
    for i in range(3):
        e = np.eye(3)[i]
        gy = (omega[i] * hat3(omega) + hat3(np.cross(omega, (np.eye(3) - R) @ e))) @ R / th2
        np.testing.assert_allclose(d[:3, :3, i], gy, atol=1e-14)


def test_left_jacobians():
    rng = np.random.default_rng(7)
    for theta in SPECIAL_ANGLES[:-1]:
        xi = screw_with_angle(rng, theta)
        G = left_jacobian_so3(xi[:3])
        np.testing.assert_allclose(left_jacobian_so3_inverse(xi[:3]) @ G, np.eye(3), atol=1e-12)
        J = left_jacobian_se3(xi)
        T = exp_se3(xi)
        # exp(hat(xi + d)) = exp(hat(J d)) T + O(d^2): compare twists from central differences.
        dT = central_dexp(xi)
        for i in range(6):
            np.testing.assert_allclose(vee(dT[:, :, i] @ np.linalg.inv(T)), J[:, i], atol=2e-8)


def test_left_jacobian_translation_block_is_half_hat_v_at_zero():
    v = np.array([0.4, 0.5, -0.6])
    J = left_jacobian_se3(np.r_[0, 0, 0, v])
    np.testing.assert_allclose(J[3:, :3], hat3(v) / 2, atol=1e-16)


@pytest.mark.parametrize('theta', SPECIAL_ANGLES[:-1] + [math.pi + 1e-6, 5.0])
def test_exp_log_round_trip(theta):
    rng = np.random.default_rng(8)
    for _ in range(20):
        xi = screw_with_angle(rng, theta)
        T = exp_se3(xi)
        np.testing.assert_allclose(exp_se3(log_se3(T)), T, atol=1e-12)
        back = log_se3(T, reference=xi)
        np.testing.assert_allclose(exp_se3(back), T, atol=1e-12)
        if abs(theta - math.pi) > 1e-8:  # the branch nearest the reference is xi itself
            np.testing.assert_allclose(back, xi, atol=1e-8)


def test_log_within_1e9_of_pi_round_trips_and_follows_the_reference():
    rng = np.random.default_rng(9)
    for delta in (1e-9, 1e-12, 0.0, -1e-12, -1e-9):
        for _ in range(50):
            xi = screw_with_angle(rng, math.pi - delta)
            T = exp_se3(xi)
            np.testing.assert_allclose(exp_se3(log_se3(T)), T, atol=1e-12)
            back = log_se3(T, reference=xi)
            np.testing.assert_allclose(back[:3], xi[:3], atol=1e-7)
            flipped = log_se3(T, reference=-xi)
            np.testing.assert_allclose(flipped[:3], -xi[:3], atol=1e-7)
            np.testing.assert_allclose(exp_se3(flipped), T, atol=1e-12)


def test_log_without_reference_is_principal():
    rng = np.random.default_rng(10)
    xi = screw_with_angle(rng, 4.0)
    back = log_se3(exp_se3(xi))
    assert np.linalg.norm(back[:3]) <= math.pi + 1e-12
    np.testing.assert_allclose(np.linalg.norm(log_so3(np.eye(3))), 0.0)


def test_bad_input_raises():
    with pytest.raises(ValueError, match=r'shape \(6,\) or \(N, 6\)'):
        exp_se3(np.zeros(5))
    with pytest.raises(ValueError, match='finite'):
        exp_se3([0, 0, np.nan, 0, 0, 0])
    with pytest.raises(ValueError, match='finite'):
        dexp_se3([0, 0, np.inf, 0, 0, 0])
    with pytest.raises(ValueError, match=r'shape \(6,\) or \(N, 6\)'):
        as_screws(np.zeros((2, 3, 6)))
    with pytest.raises(ValueError, match='rotation matrix'):
        log_se3(np.diag([1.0, 1.0, -1.0, 1.0]))
    with pytest.raises(ValueError, match=r'shape \(4, 4\)'):
        log_se3(np.eye(3))
    with pytest.raises(ValueError, match='finite'):
        log_se3(np.full((4, 4), np.nan))
