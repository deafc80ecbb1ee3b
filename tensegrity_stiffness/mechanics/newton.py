"""The damped Newton iteration of the equilibrium solvers (a joint's, :mod:`.equilibrium`, and
a spine's, :mod:`.chain`): one implementation for both.

Each step solves ``A dx = -r`` with the caller's analytic Jacobian (least squares where ``A`` is
singular), scales it into the caller's trust region, and backtracks (halving, at most
:data:`MAX_BACKTRACKS` times) until the residual norm falls by the Armijo fraction
``1e-4 alpha`` or below the tolerance. Unknowns may be any shape (a screw (6,), a chain's
screws (N, 6)); residuals any shape (their 2-norm over all entries is minimised).
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

#: Halvings of a step before the iteration gives up.
MAX_BACKTRACKS = 30
#: Armijo fraction: a step of length alpha must cut the residual norm by ``ARMIJO * alpha``.
ARMIJO = 1e-4

#: ``evaluate(x, tangent)``: ``(residual, context)`` at ``x``, or None where ``x`` is not
#: admissible; ``context`` is what ``jacobian`` needs (``tangent=False``: it may be partial).
Evaluate = Callable[[FloatArray, bool], tuple[FloatArray, Any] | None]


def solve_deadline(tolerance: float, max_iterations: int, time_budget: float | None) -> float:
    """Check a solver's ``tolerance`` (finite, > 0) and ``max_iterations`` (>= 1), raising a
    ValueError naming the one that is wrong, and start its clock: the deadline in
    ``time.perf_counter()`` seconds (inf when ``time_budget`` is None)."""
    if not (math.isfinite(tolerance) and tolerance > 0.0):
        raise ValueError(f'tolerance must be finite and > 0, got {tolerance}')
    if max_iterations < 1:
        raise ValueError(f'max_iterations must be >= 1, got {max_iterations}')
    return math.inf if time_budget is None else time.perf_counter() + float(time_budget)


def damped_newton(x0: FloatArray, evaluate: Evaluate,
                  jacobian: Callable[[FloatArray, Any], FloatArray],
                  clip: Callable[[FloatArray], FloatArray],
                  rechart: Callable[[FloatArray], FloatArray], tolerance: float,
                  max_iterations: int, deadline: float, min_iterations: int = 0,
                  initial: tuple[FloatArray, Any] | None = None
                  ) -> tuple[FloatArray, float, int]:
    """Damped Newton from ``x0`` until ``|r| <= tolerance``, ``max_iterations`` steps, a step
    that no backtracking accepts, or ``time.perf_counter() > deadline`` (checked after the first
    ``min_iterations`` steps). ``clip`` scales a step into the trust region, ``rechart`` keeps
    the unknowns in their chart; ``initial``: ``evaluate(x0, True)`` when the caller has it.
    Returns ``(x, |r|, iterations)``."""
    got = initial if initial is not None else evaluate(x0, True)
    if got is None:
        return x0, math.inf, 0
    x = x0.copy()
    r, context = got
    norm = float(np.linalg.norm(r))
    it = 0
    for it in range(1, max_iterations + 1):
        if norm <= tolerance or (it > min_iterations and time.perf_counter() > deadline):
            return x, norm, it - 1
        A = jacobian(x, context)
        rhs = -r.ravel()
        try:
            step = np.linalg.solve(A, rhs)
        except np.linalg.LinAlgError:
            step = np.linalg.lstsq(A, rhs, rcond=None)[0]
        if not np.all(np.isfinite(step)):
            break
        step = clip(step.reshape(x.shape))
        alpha = 1.0
        accepted = None
        for _ in range(MAX_BACKTRACKS):
            trial = rechart(x + alpha * step)
            got = evaluate(trial, False)
            if got is not None:
                trial_norm = float(np.linalg.norm(got[0]))
                if trial_norm < (1.0 - ARMIJO * alpha) * norm or trial_norm <= tolerance:
                    accepted = got
                    break
            alpha *= 0.5
        if accepted is None:
            break
        x, (r, context), norm = trial, accepted, trial_norm
    return x, norm, it
