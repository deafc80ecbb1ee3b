"""The small shared rules of geometry/: the per-string check, the single-screw check, the
adjoints in both twist orders, the small adjoint, the SE(3) inverse and the block exponential,
each against the definition it comes from."""

from __future__ import annotations

import math

import numpy as np
import pytest
import scipy.linalg

from tensegrity_stiffness.geometry.errors import NotFiniteError, OutsideChartError
from tensegrity_stiffness.geometry.screw import (
    BLOCK_SWAP,
    exp_se3,
    hat,
    single_screw,
    small_adjoint,
)
from tensegrity_stiffness.geometry.screw_jacobians import block_exponential
from tensegrity_stiffness.geometry.transforms import (
    adjoint,
    adjoint_screw_order,
    inverse_transform,
)
from tensegrity_stiffness.geometry.validation import per_string

EPS = np.finfo(float).eps
#: Central-difference step and the tolerance of its comparison (relative to the largest entry).
STEP = 1e-6
DERIVATIVE_TOLERANCE = 1e-7


def _poses(count: int, seed: int) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [exp_se3(np.concatenate([rng.normal(size=3), rng.normal(scale=0.1, size=3)]))
            for _ in range(count)]


# ---------------------------------------------------------------------------- per_string
def test_per_string_exact_count() -> None:
    out = per_string('rest_lengths', [[0.1, 0.2, 0.3]], 3)
    assert out.shape == (3,) and out.dtype == np.float64
    with pytest.raises(ValueError, match=r'^rest_lengths must have 3 values \(one per string\), '
                                         r'got 2$'):
        per_string('rest_lengths', [0.1, 0.2], 3)
    with pytest.raises(NotFiniteError, match=r'^rest_lengths must be finite, got nan at string '
                                             r'1$'):
        per_string('rest_lengths', [0.1, math.nan, 0.3], 3)
    with pytest.raises(ValueError, match=r'^rest_lengths must be numeric'):
        per_string('rest_lengths', ['a', 'b', 'c'], 3)


def test_per_string_repeats_one_value() -> None:
    np.testing.assert_array_equal(per_string('stiffness', 200.0, 4, repeat_one=True),
                                  np.full(4, 200.0))
    np.testing.assert_array_equal(per_string('stiffness', [200.0], 2, repeat_one=True),
                                  [200.0, 200.0])
    with pytest.raises(ValueError, match=r'^stiffness must have 4 values \(one per string\), '
                                         r'got 2 \(or one value for all\)$'):
        per_string('stiffness', [1.0, 2.0], 4, repeat_one=True)


def test_per_string_not_measured() -> None:
    out = per_string('tensions', [1.0, math.nan, 2.0], 3, not_measured=True)
    assert np.isnan(out[1]) and out[0] == 1.0
    assert np.isnan(per_string('tensions', None, 3, not_measured=True)).all()
    with pytest.raises(NotFiniteError, match=r'^tensions must be finite or NaN \(not measured\), '
                                             r'got inf at string 2$'):
        per_string('tensions', [1.0, 2.0, math.inf], 3, not_measured=True)
    with pytest.raises(ValueError, match=r'NaN = not measured\), got 4$'):
        per_string('tensions', np.ones(4), 3, not_measured=True)


def test_per_string_unknown_count_and_unchecked_values() -> None:
    assert per_string('max_rate', 0.5, None).shape == ()
    assert per_string('max_rate', [0.5, 0.6], None).shape == (2,)
    with pytest.raises(ValueError, match=r'^max_rate must be a scalar or one value per string'):
        per_string('max_rate', np.ones((2, 2)), None)
    with pytest.raises(NotFiniteError, match=r'^max_rate must be finite, got inf$'):
        per_string('max_rate', math.inf, None)
    out = per_string('max_lengths', math.inf, 3, repeat_one=True, finite=False)
    assert np.isinf(out).all() and out.shape == (3,)


# ---------------------------------------------------------------------------- single_screw
def test_single_screw() -> None:
    xi = single_screw([0.1, 0.0, 0.0, 0.0, 0.0, 0.02], 'xi')
    assert xi.shape == (6,) and xi.dtype == np.float64
    with pytest.raises(ValueError, match=r'^xi must have 6 values'):
        single_screw(np.zeros((2, 6)), 'xi')
    with pytest.raises(NotFiniteError, match=r'^xi must be finite'):
        single_screw([math.nan, 0, 0, 0, 0, 0], 'xi')
    outside = [2.0 * math.pi, 0, 0, 0, 0, 0]
    with pytest.raises(OutsideChartError, match=r'^screw: '):
        single_screw(outside)
    np.testing.assert_array_equal(single_screw(outside, in_chart=False), outside)


# ---------------------------------------------------------------------------- adjoints
def test_adjoints_map_twists_as_the_definition() -> None:
    """``hat(Ad_T V) = T hat(V) T^-1`` in both orders (``[v; w]`` and ``[w; v]``)."""
    rng = np.random.default_rng(4)
    for T in _poses(8, 5):
        V = rng.normal(size=6)  # [w; v]
        expected = T @ hat(V) @ np.linalg.inv(T)
        got = hat(adjoint_screw_order(T) @ V)
        np.testing.assert_allclose(got, expected, rtol=0.0, atol=64 * EPS * np.abs(expected).max())
        np.testing.assert_allclose(adjoint(T)[np.ix_(BLOCK_SWAP, BLOCK_SWAP)],
                                   adjoint_screw_order(T), rtol=0.0, atol=0.0)


def test_small_adjoint_is_the_lie_bracket() -> None:
    rng = np.random.default_rng(6)
    for _ in range(8):
        V, U = rng.normal(size=6), rng.normal(size=6)
        bracket = hat(V) @ hat(U) - hat(U) @ hat(V)
        np.testing.assert_allclose(hat(small_adjoint(V) @ U), bracket, rtol=0.0,
                                   atol=16 * EPS * np.abs(bracket).max())


def test_small_adjoint_is_the_derivative_of_the_adjoint() -> None:
    """``d/dt Ad_{exp(t hat V)} = ad_V`` at t = 0 (central differences)."""
    V = np.array([0.3, -0.2, 0.5, 0.01, 0.02, -0.03])
    ref = (adjoint_screw_order(scipy.linalg.expm(hat(STEP * V)))
           - adjoint_screw_order(scipy.linalg.expm(hat(-STEP * V)))) / (2 * STEP)
    np.testing.assert_allclose(small_adjoint(V), ref, rtol=0.0,
                               atol=DERIVATIVE_TOLERANCE * np.abs(ref).max())


# ---------------------------------------------------------------------------- inverse
def test_inverse_transform() -> None:
    for T in _poses(8, 7):
        Ti = inverse_transform(T)
        np.testing.assert_allclose(Ti @ T, np.eye(4), rtol=0.0, atol=16 * EPS)
        np.testing.assert_array_equal(Ti[3], [0.0, 0.0, 0.0, 1.0])
    np.testing.assert_array_equal(inverse_transform(np.eye(4)), np.eye(4))


# ---------------------------------------------------------------------------- block exponential
def test_block_exponential_against_central_differences() -> None:
    """``T``, ``dT/dt`` and ``d^2 T/dt^2 / 2`` along ``xi + t rate`` (scipy's expm)."""
    rng = np.random.default_rng(8)
    h = 1e-4
    for _ in range(4):
        xi, rate = rng.normal(size=6), rng.normal(size=6)

        def along(t: float, xi: np.ndarray = xi, rate: np.ndarray = rate) -> np.ndarray:
            return scipy.linalg.expm(hat(xi + t * rate))

        T, T1, S = block_exponential(xi, rate)
        np.testing.assert_allclose(T, along(0.0), rtol=0.0, atol=1e-13)
        d1 = (along(h) - along(-h)) / (2 * h)
        d2 = (along(h) - 2.0 * along(0.0) + along(-h)) / h ** 2
        np.testing.assert_allclose(T1, d1, rtol=0.0, atol=1e-6 * np.abs(d1).max())
        np.testing.assert_allclose(2.0 * S, d2, rtol=0.0, atol=1e-5 * np.abs(d2).max())


def test_dynamics_keeps_the_jacobians_it_re_exports() -> None:
    from tensegrity_stiffness.geometry import screw_jacobians
    from tensegrity_stiffness.mechanics import dynamics
    for name in ('body_jacobian', 'body_jacobian_rate', 'jacobian_derivatives'):
        assert getattr(dynamics, name) is getattr(screw_jacobians, name)
