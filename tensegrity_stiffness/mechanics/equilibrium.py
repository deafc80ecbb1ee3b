"""Equilibria of a tensegrity joint under an external wrench (Monke & Vikas, Section VI).

Solves ``F(xi) + W = 0`` directly: ``F`` is the string wrench on link 2 and ``W`` an external
wrench on link 2, both expressed in {1} about its origin, ordered [force; moment]. (The paper
minimises energy; with a constant wrench that is not equivalent on SE(3), see ``docs/errata.md``.)

Method: damped Newton with the analytical ``K = dF/dxi`` as Jacobian and a backtracking line
search on ``|F + W|``, steps clipped to a trust radius; if that stalls, scipy's trust-region
``least_squares`` (with the same analytical Jacobian) takes over and Newton polishes its answer;
last, load stepping (continuation from the initial screw in ``CONTINUATION_STEPS`` steps).
Stability: the symmetric part of ``K_c`` is positive definite (equivalently that of
``S = -J^T P K``; at zero load S is the Hessian of the energy).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import least_squares

from tensegrity_stiffness.geometry.screw import CHART_LIMIT, as_screws, log_se3
from tensegrity_stiffness.mechanics import plausibility
from tensegrity_stiffness.mechanics.newton import damped_newton, solve_deadline

if TYPE_CHECKING:  # types only: joint reads its config through this module (no import circle)
    from tensegrity_stiffness.mechanics.joint import JointModel, JointState

FloatArray = NDArray[np.float64]

#: Converged when |F + W| (N and N m together) is at most this.
RESIDUAL_TOLERANCE = 1e-10
#: Newton iterations before the trust-region fallback.
MAX_NEWTON_ITERATIONS = 60
#: Largest rotation change per Newton step (rad).
MAX_ROTATION_STEP = 0.5
#: Largest translation change per Newton step, in units of the mean rest length.
MAX_TRANSLATION_STEP = 0.5
#: Rotation angle beyond which the iterate is re-charted onto the branch |omega| <= pi + margin.
RECHART_ANGLE = CHART_LIMIT - 0.5
#: Newton steps from the start that a time budget does not cut short: an easy solve converges in
#: 3-4 (about 1 ms of CPU), so a worker starved of CPU by a busy machine still answers it.
MIN_NEWTON_ITERATIONS = 4
#: Load steps of the continuation fallback.
CONTINUATION_STEPS = 8
#: Relative tolerance on the smallest eigenvalue of the scaled symmetric part of K_c.
STABILITY_TOLERANCE = 1e-9


@dataclass(frozen=True)
class EquilibriumResult:
    """Outcome of :func:`solve_equilibrium`.

    ``screw`` (6,) is the equilibrium (or the best iterate when ``success`` is False);
    ``residual`` = |F + W|; ``energy`` in J; ``stable`` from the symmetric part of K_c;
    ``state`` the full :class:`JointState` at ``screw`` (None if it could not be evaluated).
    """

    success: bool
    message: str
    screw: FloatArray
    residual: float
    iterations: int
    energy: float
    stable: bool
    state: JointState | None = field(default=None, repr=False)

    @property
    def wrench(self) -> FloatArray | None:
        """String wrench at the solution (6,)."""
        return None if self.state is None else self.state.wrench

    @property
    def stiffness(self) -> FloatArray | None:
        """K at the solution (6, 6)."""
        return None if self.state is None else self.state.stiffness

    @property
    def cartesian_stiffness(self) -> FloatArray | None:
        """K_c at the solution (6, 6)."""
        return None if self.state is None else self.state.cartesian_stiffness

    @property
    def tensions(self) -> FloatArray | None:
        """Tensions at the solution (n,)."""
        return None if self.state is None else self.state.tensions


def stability_margin(cartesian_stiffness: ArrayLike) -> float:
    """Smallest eigenvalue of the symmetric part of K_c scaled by its diagonal (units N/m, N, N m
    mixed, so the margin is dimensionless): > 0 for a stable joint, ``-inf`` when a diagonal entry
    is not positive or an entry is not finite."""
    Kc = np.asarray(cartesian_stiffness, dtype=np.float64)
    S = 0.5 * (Kc + Kc.T)
    diag = np.diag(S)
    if np.any(diag <= 0.0) or not np.all(np.isfinite(S)):
        return -math.inf
    scale = 1.0 / np.sqrt(diag)
    return float(np.linalg.eigvalsh(S * scale[:, None] * scale[None, :])[0])


def is_stable(cartesian_stiffness: ArrayLike, tolerance: float = STABILITY_TOLERANCE) -> bool:
    """True when the symmetric part of K_c is positive definite: its
    :func:`stability_margin` exceeds ``tolerance`` (a relative threshold)."""
    return stability_margin(cartesian_stiffness) > tolerance


def _length_scale(model: JointModel, rest: FloatArray) -> float:
    return float(np.mean(rest))


def _clip_step(step: FloatArray, length: float) -> FloatArray:
    """Scale a Newton step so that it stays within the trust radius."""
    rot = np.linalg.norm(step[:3]) / MAX_ROTATION_STEP
    tra = np.linalg.norm(step[3:]) / (MAX_TRANSLATION_STEP * length)
    worst = max(rot, tra, 1.0)
    return step / worst


def _rechart(xi: FloatArray) -> FloatArray:
    """Keep |omega| away from 2 pi (where the chart is singular) by switching branch."""
    if np.linalg.norm(xi[:3]) < RECHART_ANGLE:
        return xi
    from tensegrity_stiffness.geometry.screw import exp_se3

    return log_se3(exp_se3(xi))


def _newton(model: JointModel, W: FloatArray, rest: FloatArray, x0: FloatArray,
            max_iterations: int, tolerance: float, deadline: float, min_iterations: int = 0
            ) -> tuple[FloatArray, float, int]:
    """Damped Newton (:func:`.newton.damped_newton`) on r(xi) = F(xi) + W with dr/dxi = K
    (eq. 10); the first ``min_iterations`` steps are taken whatever the deadline. Returns
    (xi, |r|, iterations)."""
    length = _length_scale(model, rest)

    def evaluate(xi: FloatArray, tangent: bool) -> tuple[FloatArray, JointState] | None:
        try:
            state = model.evaluate(xi, rest)
        except ValueError:  # a string collapsed to zero length: step too long
            return None
        return state.wrench + W, state

    start = model.evaluate(x0, rest)
    return damped_newton(x0, evaluate, lambda xi, state: state.stiffness,
                         lambda step: _clip_step(step, length), _rechart, tolerance,
                         max_iterations, deadline, min_iterations, (start.wrench + W, start))


def solve_equilibrium(
    model: JointModel,
    external_wrench: ArrayLike,
    rest_lengths: ArrayLike | None = None,
    initial_screw: ArrayLike | None = None,
    *,
    tolerance: float = RESIDUAL_TOLERANCE,
    max_iterations: int = MAX_NEWTON_ITERATIONS,
    time_budget: float | None = None,
    newton_only: bool = False,
) -> EquilibriumResult:
    """Find ``xi`` with ``F(xi) + W = 0`` starting from ``initial_screw``.

    ``external_wrench`` W (6,) = [force (N); moment (N m)] on link 2, in {1} about its origin.
    ``initial_screw`` defaults to ``model.initial_screw``. ``time_budget`` (s) bounds the whole
    solve, except the first :data:`MIN_NEWTON_ITERATIONS` Newton steps. ``newton_only``: at most
    ``max_iterations`` damped Newton steps, without the trust-region fallback and the
    continuation (a cheap first try, e.g. a node's before it asks its worker). Bad input raises
    ValueError, and so do a load and rest lengths outside the joint's range
    (:mod:`~tensegrity_stiffness.mechanics.plausibility`); failure to converge returns
    ``success=False`` with a reason (no exception).
    """
    W = np.asarray(external_wrench, dtype=np.float64)
    if W.shape != (6,):
        raise ValueError(f'external_wrench must have shape (6,), got {W.shape}')
    if not np.all(np.isfinite(W)):
        raise ValueError(f'external_wrench must be finite, got {W}')
    # Finite but absurd inputs are refused by name before any work (mechanics.plausibility);
    # the load's range is the joint's (its own rest lengths): rest lengths that slacken every
    # string are the solver's to report, not a smaller range.
    rest = (model.rest_lengths if rest_lengths is None
            else plausibility.check_rest_lengths(model, rest_lengths))
    plausibility.check_wrench(model, W)
    x0 = as_screws(model.initial_screw if initial_screw is None else initial_screw,
                   'initial_screw')
    if x0.shape != (6,):
        raise ValueError(f'initial_screw must have shape (6,), got {x0.shape}')
    if np.linalg.norm(x0[:3]) >= CHART_LIMIT:
        raise ValueError('initial_screw must have |omega| < 2 pi')
    deadline = solve_deadline(tolerance, max_iterations, time_budget)
    try:
        model.evaluate(x0, rest)
    except ValueError as exc:
        return _failure(model, x0, rest, W, 0, f'initial screw is not admissible: {exc}')

    x, norm, iterations = _newton(model, W, rest, x0, max_iterations, tolerance, deadline,
                                  min(MIN_NEWTON_ITERATIONS, max_iterations))
    if norm > tolerance and not newton_only and time.perf_counter() < deadline:
        x, norm, iterations = _fallback(model, W, rest, x, norm, iterations, tolerance,
                                        max_iterations, deadline)
    if norm > tolerance and not newton_only and time.perf_counter() < deadline:
        x, norm, iterations = _continuation(model, W, rest, x0, x, norm, iterations, tolerance,
                                            max_iterations, deadline)
    state = model.evaluate(x, rest)
    energy = float(model.energy(x, rest))
    if not (np.isfinite(state.wrench).all() and np.isfinite(state.stiffness).all()
            and math.isfinite(energy)):
        return EquilibriumResult(False, 'no usable equilibrium: the state at the last iterate '
                                 'is not finite (string lengths overflow)', x, math.inf,
                                 iterations, math.nan, False, None)
    if norm > tolerance:
        reason = 'time budget exhausted' if time.perf_counter() >= deadline else 'no convergence'
        return EquilibriumResult(False, f'{reason}: residual |F + W| = {norm:.3e} after '
                                 f'{iterations} iterations', x, norm, iterations, energy,
                                 False, state)
    if np.all(state.slack):
        return EquilibriumResult(False, 'all strings are slack: the joint is unconstrained', x,
                                 norm, iterations, energy, False, state)
    stable = is_stable(state.cartesian_stiffness)
    slack = int(np.count_nonzero(state.slack))
    message = 'converged' + (f' ({slack} slack strings)' if slack else '')
    if not stable:
        message += '; equilibrium is not stable'
    return EquilibriumResult(True, message, x, norm, iterations, energy, stable, state)


class _BudgetExhaustedError(Exception):
    """Raised inside scipy's callbacks to stop at the deadline."""


def _fallback(model: JointModel, W: FloatArray, rest: FloatArray, x: FloatArray, norm: float,
              iterations: int, tolerance: float, max_iterations: int, deadline: float
              ) -> tuple[FloatArray, float, int]:
    """Trust-region least squares on F + W with the analytic Jacobian, then Newton polish."""

    def residual(z: FloatArray) -> FloatArray:
        if time.perf_counter() > deadline:
            raise _BudgetExhaustedError
        try:
            return model.evaluate(z, rest).wrench + W
        except ValueError:
            return np.full(6, 1e6)

    def jacobian(z: FloatArray) -> FloatArray:
        try:
            return model.evaluate(z, rest).stiffness
        except ValueError:
            return np.eye(6)

    try:
        sol = least_squares(residual, x, jac=jacobian, method='trf', xtol=1e-15, ftol=1e-15,
                            gtol=1e-15, max_nfev=20 * max_iterations)
    except (ValueError, np.linalg.LinAlgError, _BudgetExhaustedError):
        return x, norm, iterations
    candidate = _rechart(sol.x)
    iterations += int(sol.nfev)
    try:
        cand_norm = float(np.linalg.norm(residual(candidate)))
    except _BudgetExhaustedError:
        return x, norm, iterations
    if cand_norm < norm:
        x, norm = candidate, cand_norm
    if norm > tolerance and time.perf_counter() < deadline:
        x, norm, extra = _newton(model, W, rest, x, max_iterations, tolerance, deadline)
        iterations += extra
    return x, norm, iterations


def _continuation(model: JointModel, W: FloatArray, rest: FloatArray, x0: FloatArray,
                  best: FloatArray, best_norm: float, iterations: int, tolerance: float,
                  max_iterations: int, deadline: float) -> tuple[FloatArray, float, int]:
    """Load stepping: solve for s W, s = 1/m, ..., 1, each from the previous solution."""
    x = x0
    for fraction in np.linspace(0.0, 1.0, CONTINUATION_STEPS + 1)[1:]:
        x, norm, extra = _newton(model, fraction * W, rest, x, max_iterations, tolerance,
                                 deadline)
        iterations += extra
        if norm > tolerance:
            break
    else:
        return x, norm, iterations
    return best, best_norm, iterations


def _failure(model: JointModel, x: FloatArray, rest: FloatArray, W: FloatArray,
             iterations: int, message: str) -> EquilibriumResult:
    return EquilibriumResult(False, message, x, math.inf, iterations, math.nan, False, None)
