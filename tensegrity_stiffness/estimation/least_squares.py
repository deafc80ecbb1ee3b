"""The damped least-squares step shared by the estimators and the calibration, and the
estimators' Levenberg-Marquardt fit of a whitened residual.

A fit minimises ``|r(x)|^2`` of a whitened residual with Jacobian ``J``: the normal matrix
``A = J^T J`` and gradient ``g = J^T r`` give the Gauss-Newton step ``-A^-1 g``; a step that
does not lower the cost is taken again with Marquardt's damping,
``(A + lambda diag(A)) step = -g`` (:func:`damped_normal_matrix`), whose ``lambda`` follows one
schedule (:class:`LevenbergMarquardtDamping`): zero while steps are accepted, grown at every
rejected step, and a minimum once it passes its largest value. The joint estimator
(:func:`gauss_newton`), the chain estimator (on the tangent of the equilibria) and the
calibration (per-sample Schur complements) each form their own ``A`` and ``g`` and share the
damping and the schedule.

An estimate's time budget (:class:`FitClock`): one deadline for all its fits (a warm start,
its cold restart, the refits without a contradicted reading), checked between iterations once
the estimate has taken its first ``min_iterations``; a fit stopped by it reports
:data:`TIME_BUDGET_EXHAUSTED` and the estimate fails.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy.linalg import lapack

from tensegrity_stiffness.mechanics.equilibrium import MAX_ROTATION_STEP, MAX_TRANSLATION_STEP
from tensegrity_stiffness.mechanics.newton import solve_deadline

FloatArray = NDArray[np.float64]

#: Why a Gauss-Newton fit stopped when its normal matrix could not be solved.
SINGULAR_NORMAL_MATRIX = 'singular normal matrix'
#: Why a fit stopped at its estimate's deadline; an estimate so stopped fails with a message
#: that starts with it and names the iterations.
TIME_BUDGET_EXHAUSTED = 'time budget exhausted'
#: Iterations of one joint or spine estimate (over all its fits) that a time budget does not
#: cut short. Measured on the tests (test_estimation*.py, test_estimation_twin.py): a fit from
#: a tracker's last estimate or a measured pose converges in 1-3 iterations (joint: 99.9 % of
#: 17 600 fits; spine: 97 % of 1 600, the rest 4-24), a cold start from the unloaded screw in
#: 5-14; so a tracked estimate is never cut short on a machine that starves it of CPU, and past
#: the deadline an estimate takes at most this many iterations.
MIN_FIT_ITERATIONS = 4
#: Damping factor of the first rejected step and the factor it grows by.
INITIAL_DAMPING = 1e-4
DAMPING_GROWTH = 10.0
#: An accepted step that lowers the cost by less than this fraction of it ends the iteration:
#: the iterate creeps along a kink of the cost (a string at its slack or saturation boundary).
STALL_TOLERANCE = 1e-9
#: Beyond this damping (a step a 1e-10 fraction of the gradient step) the iterate is a minimum.
MAX_DAMPING = 1e10


@dataclass
class LevenbergMarquardtDamping:
    """The damping ``lambda`` of one Levenberg-Marquardt fit (``value``, 0: Gauss-Newton).

    :meth:`rejected` grows it by ``growth`` (from ``initial`` when it is 0) and says whether a
    step is left (``value <= largest``); :meth:`accepted` lowers it by ``growth``, to ``floor``
    once it is at most ``floor_from``. The defaults are the estimators' schedule; the
    calibration starts at its own damping and keeps a floor of 1e-12."""

    value: float = 0.0
    initial: float = INITIAL_DAMPING
    growth: float = DAMPING_GROWTH
    floor: float = 0.0
    floor_from: float = INITIAL_DAMPING
    largest: float = MAX_DAMPING

    def rejected(self) -> bool:
        """A step did not lower the cost: grow; False when no step is left (a minimum)."""
        self.value = self.initial if self.value == 0.0 else self.value * self.growth
        return self.value <= self.largest

    def accepted(self) -> None:
        """A step lowered the cost: relax towards Gauss-Newton."""
        self.value = self.floor if self.value <= self.floor_from else self.value / self.growth


def damped_normal_matrix(A: FloatArray, damping: float, ridge: float = 0.0) -> FloatArray:
    """Marquardt's damped normal matrix ``A + damping (diag(A) + ridge)`` of one or a stack
    (..., k, k) of normal matrices (a new array; ``ridge`` keeps a zero diagonal entry
    damped)."""
    out = np.array(A, dtype=np.float64)
    k = out.shape[-1]
    diagonal = np.diagonal(A, axis1=-2, axis2=-1)
    out[..., range(k), range(k)] += damping * (diagonal + ridge) if ridge else damping * diagonal
    return out


def clip_screw_step(step: FloatArray, length_scale: float) -> FloatArray:
    """The step scaled into the equilibrium solver's trust radius (rotation, translation)."""
    wx, wy, wz, vx, vy, vz = step.tolist()
    worst = max(math.sqrt(wx * wx + wy * wy + wz * wz) / MAX_ROTATION_STEP,
                math.sqrt(vx * vx + vy * vy + vz * vz) / (MAX_TRANSLATION_STEP * length_scale),
                1.0)
    return step if worst == 1.0 else step / worst


def normal_solve(A: FloatArray, g: FloatArray) -> FloatArray | None:
    """The Gauss-Newton step ``-A^-1 g`` for a symmetric positive definite normal matrix ``A``
    (LAPACK's Cholesky solver ``dposv``); None when ``A`` is not positive definite."""
    _, x, info = lapack.dposv(A, g)
    return -x if info == 0 else None


class FitClock:
    """The time budget of one estimate, shared by its fits: the deadline, started once
    (:func:`~tensegrity_stiffness.mechanics.newton.solve_deadline`, which checks the tolerance
    and the iterations; inf when ``time_budget`` is None), the ``iterations`` taken so far and
    whether a fit was cut short (``exhausted``; it stays so: every later fit stops at once)."""

    __slots__ = ('deadline', 'exhausted', 'iterations', 'min_iterations')

    def __init__(self, tolerance: float, max_iterations: int, time_budget: float | None,
                 min_iterations: int = MIN_FIT_ITERATIONS) -> None:
        self.deadline = solve_deadline(tolerance, max_iterations, time_budget)
        self.min_iterations = min_iterations
        self.iterations = 0
        self.exhausted = False

    def next_iteration(self) -> bool:
        """Whether a fit may take one more iteration (then counted): not once the estimate has
        taken its first ``min_iterations`` and the deadline has passed."""
        if not self.exhausted and self.iterations >= self.min_iterations:
            self.exhausted = time.perf_counter() > self.deadline
        if self.exhausted:
            return False
        self.iterations += 1
        return True

    def remaining(self) -> float | None:
        """The time left (s, >= 0) as a solver's ``time_budget``; None without a budget."""
        return None if self.deadline == math.inf else max(0.0, self.deadline - time.perf_counter())

    def message(self, inputs: str) -> str:
        """The failure of an estimate of ``inputs`` cut short."""
        return f'{TIME_BUDGET_EXHAUSTED} after {self.iterations} iterations ({inputs})'


class InitialPointError(ValueError):
    """The starting point of :func:`gauss_newton` cannot be evaluated."""


def gauss_newton(evaluate: Any, x0: FloatArray, length_scale: float, max_iterations: int,
                  tolerance: float, clock: FitClock | None = None
                  ) -> tuple[FloatArray, Any, int, bool, str]:
    """Levenberg-Marquardt on the whitened residual of ``evaluate(x, jacobian) -> (r, J,
    state, kinematics)``.

    Trial points are evaluated without their Jacobian (the cost decides); at an accepted point
    the decrement is first taken with the Jacobian it was stepped from (a chord step), and only
    when that is not below ``tolerance`` is the Jacobian evaluated there. So a warm start near
    the optimum costs one evaluation with the Jacobian and one without, and the covariance is
    linearised at the last point where the Jacobian was evaluated (within ``tolerance`` of the
    optimum in units of its own std). The damping scales the normal matrix's diagonal
    (Marquardt); it is zero while steps reduce the cost. Returns (x, (r, J, A, state,
    kinematics) with J of the linearisation point and ``A = J^T J`` its normal matrix, r, state
    and the kinematics of x (None when ``evaluate`` gave none there), iterations, converged,
    message). ``clock``: the estimate's time budget, asked before every step (not converged,
    :data:`TIME_BUDGET_EXHAUSTED`, when it refuses).
    """
    x = x0.copy()
    try:
        r, J, state, kin = evaluate(x)
    except ValueError as exc:  # the trial steps below catch theirs: this one is the caller's
        raise InitialPointError(str(exc)) from None
    cost = float(r @ r)
    damping = LevenbergMarquardtDamping()
    for it in range(1, max_iterations + 1):
        A = J.T @ J
        g = J.T @ r
        full_step = normal_solve(A, g)
        if full_step is None:
            return x, (r, J, A, state, kin), it - 1, False, SINGULAR_NORMAL_MATRIX
        if float(-g @ full_step) < tolerance:
            return x, (r, J, A, state, kin), it - 1, True, ''
        if clock is not None and not clock.next_iteration():
            return x, (r, J, A, state, kin), it - 1, False, TIME_BUDGET_EXHAUSTED
        while True:
            if damping.value == 0.0:
                step = full_step
            else:
                step = normal_solve(damped_normal_matrix(A, damping.value), g)
                if step is None:
                    return x, (r, J, A, state, kin), it, False, SINGULAR_NORMAL_MATRIX
            trial = x + clip_screw_step(step, length_scale)
            try:
                trial_r, _, trial_state, trial_kin = evaluate(trial, False)
            except ValueError:  # a string of zero length, outside the chart: step too long
                trial_r = None
            if trial_r is not None:
                trial_cost = float(trial_r @ trial_r)
                if trial_cost <= cost:
                    stalled = cost - trial_cost <= STALL_TOLERANCE * max(cost, 1.0)
                    x, r, state, kin, cost = trial, trial_r, trial_state, trial_kin, trial_cost
                    if stalled:  # creeping along a kink (a string at its slack boundary)
                        return x, (r, J, A, state, kin), it, True, ''
                    damping.accepted()
                    break
            if not damping.rejected():
                # Not even a short gradient step lowers the cost: a minimum, where the cost has
                # a kink (a string at its slack or saturation boundary) or is flat to rounding.
                return x, (r, J, A, state, kin), it, True, ''
        chord_g = J.T @ r
        chord = normal_solve(A, chord_g)
        if chord is not None and float(-chord_g @ chord) < tolerance:
            return x, (r, J, A, state, kin), it, True, ''
        r, J, state, kin = evaluate(x)
    return x, (r, J, J.T @ J, state, kin), max_iterations, False, (
        f'not converged in {max_iterations} iterations')
