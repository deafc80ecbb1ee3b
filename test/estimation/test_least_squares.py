"""The damped least-squares step shared by the estimators and the calibration
(estimation/least_squares.py): Marquardt's damped normal matrix and the damping schedule, held to
the formulas the three fits wrote out before they shared them."""

from __future__ import annotations

import math

import numpy as np

from tensegrity_stiffness.estimation.least_squares import (
    DAMPING_GROWTH,
    INITIAL_DAMPING,
    MAX_DAMPING,
    LevenbergMarquardtDamping,
    clip_screw_step,
    damped_normal_matrix,
    normal_solve,
)
from tensegrity_stiffness.mechanics.equilibrium import MAX_ROTATION_STEP


def _normal_matrices(shape: tuple[int, ...], seed: int) -> np.ndarray:
    rng = np.random.default_rng(seed)
    J = rng.normal(size=shape[:-2] + (2 * shape[-1], shape[-1]))
    return np.swapaxes(J, -1, -2) @ J


def test_damped_normal_matrix_is_marquardt_s() -> None:
    A = _normal_matrices((6, 6), 1)
    np.testing.assert_array_equal(damped_normal_matrix(A, 0.3), A + 0.3 * np.diag(np.diag(A)))
    stack = _normal_matrices((5, 6, 6), 2)
    dA = np.diagonal(stack, axis1=-2, axis2=-1)
    expected = stack + 0.3 * (dA[..., None] * np.eye(6) + 1e-12 * np.eye(6))
    np.testing.assert_array_equal(damped_normal_matrix(stack, 0.3, 1e-12), expected)
    empty = damped_normal_matrix(np.zeros((0, 0)), 0.3, 1e-12)
    assert empty.shape == (0, 0)
    np.testing.assert_array_equal(damped_normal_matrix(A, 0.0), A)
    assert damped_normal_matrix(A, 0.3) is not A


def test_the_estimators_schedule() -> None:
    """Zero while steps are accepted; INITIAL_DAMPING at the first rejection, then times
    DAMPING_GROWTH; back by DAMPING_GROWTH per accepted step, to zero from INITIAL_DAMPING;
    no step left beyond MAX_DAMPING."""
    d = LevenbergMarquardtDamping()
    old = 0.0
    for _ in range(3):
        assert d.rejected()
        old = INITIAL_DAMPING if old == 0.0 else old * DAMPING_GROWTH
        assert d.value == old
    for _ in range(4):
        d.accepted()
        old = 0.0 if old <= INITIAL_DAMPING else old / DAMPING_GROWTH
        assert d.value == old
    assert d.value == 0.0
    steps = 0
    while d.rejected():
        steps += 1
    assert d.value > MAX_DAMPING and steps == round(math.log10(MAX_DAMPING / INITIAL_DAMPING)) + 1


def test_the_calibration_s_schedule() -> None:
    """From its start, times 10 per rejection, a tenth per accepted step down to 1e-12."""
    d = LevenbergMarquardtDamping(1e-3, growth=10.0, floor=1e-12, floor_from=1e-11,
                                  largest=math.inf)
    old = 1e-3
    for accepted in [False, False, True, True, True] + [True] * 12 + [False, True]:
        if accepted:
            d.accepted()
            old = max(old / 10.0, 1e-12)
        else:
            assert d.rejected()
            old *= 10.0
        assert math.isclose(d.value, old, rel_tol=4e-16), (d.value, old)


def test_normal_solve_and_the_clipped_step() -> None:
    A = _normal_matrices((6, 6), 3)
    g = np.arange(6.0)
    np.testing.assert_allclose(normal_solve(A, g), -np.linalg.solve(A, g), rtol=1e-10)
    assert normal_solve(-np.eye(6), g) is None
    step = np.array([10.0, 0.0, 0.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(clip_screw_step(step, 1.0)[0], MAX_ROTATION_STEP, rtol=1e-15)
    small = np.full(6, 1e-3)
    assert clip_screw_step(small, 1.0) is small
