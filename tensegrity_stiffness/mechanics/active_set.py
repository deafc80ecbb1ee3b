"""The primal active-set iteration of the tension QPs, one implementation for the stiffness
design (:mod:`.design`) and the stiffness controller (:mod:`tensegrity_stiffness.control`).

Both minimise a convex quadratic ``1/2 t'Pt - c't`` over tensions ``t`` with ``A t = b`` and the
box ``lo <= t <= hi``. From a box-feasible start whose bounds form the first working set, each
iteration moves the free variables towards the minimiser of the current face (the caller's
``face`` solver: the designs and the controller solve the face's KKT system with their own
fallbacks); a bound that blocks the step joins the working set, and at a face's minimiser the
bound with the most negative multiplier leaves it, until none is negative.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Relative tolerance of the active-set method (steps, multiplier signs).
ACTIVE_SET_TOLERANCE = 1e-12
#: Active-set iterations per QP before giving up (n = 12 strings need about 5-20).
MAX_ACTIVE_SET_ITERATIONS = 500

#: ``face(t, free, nu)``: the minimiser of the QP on the face where the variables not ``free``
#: stay at ``t``, as the values of the free variables and the equality multipliers (``nu``: the
#: last multipliers, for a face that does not determine them).
FaceSolver = Callable[[FloatArray, BoolArray, FloatArray], tuple[FloatArray, FloatArray]]


@dataclass
class ActiveSetResult:
    """``t`` (n,), the equality multipliers ``nu`` (m,), the working set ``at_lo`` / ``at_hi``
    (n,), ``iterations`` and ``converged`` (False: the iteration limit or, with
    ``out_of_time``, the deadline was hit; ``t`` is then the last feasible iterate)."""

    t: FloatArray
    nu: FloatArray
    at_lo: BoolArray
    at_hi: BoolArray
    iterations: int
    converged: bool
    out_of_time: bool = False


def kkt_system(P: FloatArray, c: FloatArray, A: FloatArray, b: FloatArray, t: FloatArray,
               free: BoolArray) -> tuple[FloatArray, FloatArray]:
    """The KKT matrix and right-hand side of the face of ``free`` (the other variables fixed at
    ``t``): ``[[P_FF, A_F'], [A_F, 0]] [t_F; nu] = [c_F - P_FX t_X; b - A_X t_X]``."""
    F = np.flatnonzero(free)
    X = np.flatnonzero(~free)
    nf, m = F.size, A.shape[0]
    K = np.zeros((nf + m, nf + m))
    PF = P[F]
    AF = A[:, F]
    K[:nf, :nf] = PF[:, F]
    K[:nf, nf:] = AF.T
    K[nf:, :nf] = AF
    rhs = np.concatenate([c[F] - PF[:, X] @ t[X], b - A[:, X] @ t[X]])
    return K, rhs


def active_set(P: FloatArray, c: FloatArray, A: FloatArray, lo: FloatArray, hi: FloatArray,
               t0: FloatArray, face: FaceSolver,
               max_iterations: int = MAX_ACTIVE_SET_ITERATIONS, deadline: float = math.inf,
               min_iterations: int = 0) -> ActiveSetResult:
    """Primal active set for ``min 1/2 t'Pt - c't`` s.t. ``A t = b``, ``lo <= t <= hi`` from a
    feasible ``t0`` (its bounds form the first working set); ``face`` solves each face (``b``
    is the face solver's). Multipliers count as nonnegative down to
    ``-ACTIVE_SET_TOLERANCE * max(1, |P|, |c|)``. Stops unconverged with ``out_of_time`` when
    ``time.perf_counter() > deadline``, looked at after the first ``min_iterations``."""
    scale = max(1.0, float(np.abs(P).max()), float(np.abs(c).max()))
    t = np.clip(t0, lo, hi)
    span = np.maximum(hi - lo, 1e-300)
    at_lo = t - lo <= 1e-12 * span
    at_hi = ~at_lo & (hi - t <= 1e-12 * span)
    t[at_lo], t[at_hi] = lo[at_lo], hi[at_hi]
    nu = np.zeros(A.shape[0])
    for it in range(1, max_iterations + 1):
        if it > min_iterations and time.perf_counter() > deadline:
            return ActiveSetResult(t, nu, at_lo, at_hi, it - 1, False, True)
        free = ~(at_lo | at_hi)
        F = np.flatnonzero(free)
        target, nu = face(t, free, nu)
        step = target - t[F]
        if np.all(np.abs(step) <= 1e-13 * (1.0 + np.abs(t[F]))):
            t[F] = target
            grad = P @ t - c + A.T @ nu
            mu = np.where(at_lo, grad, np.where(at_hi, -grad, 0.0))
            j = int(np.argmin(mu))
            if mu[j] >= -ACTIVE_SET_TOLERANCE * scale:
                return ActiveSetResult(t, nu, at_lo, at_hi, it, True)
            at_lo[j] = at_hi[j] = False
            continue
        # Longest step along `step` that keeps the free variables inside their bounds.
        with np.errstate(divide='ignore', invalid='ignore'):
            ratio = np.where(step < 0.0, (lo[F] - t[F]) / step,
                             np.where(step > 0.0, (hi[F] - t[F]) / step, np.inf))
        k = int(np.argmin(ratio))
        alpha = min(1.0, float(ratio[k]))
        t[F] += alpha * step
        if alpha < 1.0:
            j = F[k]
            if step[k] < 0.0:
                at_lo[j], t[j] = True, lo[j]
            else:
                at_hi[j], t[j] = True, hi[j]
        t = np.clip(t, lo, hi)
    return ActiveSetResult(t, nu, at_lo, at_hi, max_iterations, False)
