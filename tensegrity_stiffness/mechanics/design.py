"""Stiffness design: the rest lengths that hold a pose under a load with a chosen stiffness.

The inverse of what :class:`~tensegrity_stiffness.mechanics.joint.JointModel` computes: given a
target screw
``xi`` (the pose of link 2 in {1}), an external wrench ``W`` on link 2 (in {1} about its origin,
``[f; m]``) and tension limits, choose the strings' rest lengths ``l0`` (what the motors set) so
that the joint is in equilibrium at ``xi`` with every tension inside the limits and with a
Cartesian stiffness ``K_c`` as close as possible to a target.

The math
--------
At a fixed screw the string vectors ``s_j = p1_{a_j} - T p2_{b_j}`` (Monke & Vikas eq. 7), the
lengths ``l_j``, the directions ``u_j = s_j / l_j`` and ``q_j = T p2_{b_j}`` are fixed; only the
tensions ``t_j`` depend on the rest lengths.

* **Tension <-> rest length** (eq. 8, the package's two laws, see :mod:`.joint`): Hooke
  ``t = k (l - l0)``, so ``l0 = l - t / k``; the ``paper`` law ``t = k (l - l0) / l``, so
  ``l0 = l (1 - t / k)``. Both are affine in ``l0``. A designed string must be taut
  (``t > 0``, i.e. ``l0 < l``), have ``l0 > 0`` (``t < k l`` resp. ``t < k``) and stay below its
  maximum length: the model keeps each string's maximum *stretch* ``m = lmax - l0`` when rest
  lengths change, so ``l - l0 < m`` (``t < k m`` resp. ``t < k m / l``). These caps, shrunk by
  the relative :data:`BOUND_MARGIN`, lower the upper tension limit string by string.
* **Wrench** (eq. 9): ``F = sum_j t_j [u_j; p1_{a_j} x u_j] = B t`` with ``B`` (6 x n) fixed at
  the pose. Equilibrium at the target is ``B t + W = 0``: 6 equations in n unknowns; the null
  space of ``B`` is the joint's prestress.
* **Cartesian stiffness** ``K_c = -dF/d(delta)`` (the package's controller-friendly form of the
  screw stiffness ``K = dF/dxi`` of eqs. 10-11; ``K = -K_c P J(xi)``). A spatial twist
  ``delta = [dv; dw]`` moves ``q_j`` by ``dv + dw x q_j``, so ``ds_j = -[I, -hat(q_j)] delta``
  and ``K_c = sum_j Z_j A_j E_j`` with ``Z_j = [I; hat(p1_{a_j})]``, ``E_j = [I, -hat(q_j)]`` and
  ``A_j = df_j/ds_j = (t_j' - t_j/l_j) u_j u_j^T + (t_j/l_j) I`` (``t' = dt/dl``). With
  ``t' = a_j + b_j t_j`` (Hooke: ``a = k, b = 0``; paper: ``a = k/l, b = -1/l``) and
  ``E_j^T u_j = X_j = [u_j; p1_{a_j} x u_j]`` (because ``u_j`` is parallel to ``p1 - q``):

      K_c(t) = K_0 + sum_j t_j M_j,   K_0 = sum_j a_j X_j X_j^T,
      M_j = (b_j - 1/l_j) X_j X_j^T + (1/l_j) Z_j E_j,

  affine in the tensions (for Hooke, ``df/ds = (t/l)(I - u u^T) + k u u^T``).
* **Objective**: without a target, the tensions closest (least squares) to the middle of each
  string's limits, ``min |t - (t_lo + t_hi)/2|^2``; with a target ``K*``,
  ``min |S (K_c(t) - K*) S|_F^2`` with ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)`` so that all four blocks
  are in N/m (``L = length_scale``, default the largest distance of a link-1 node from the origin
  of {1}). The equality is scaled by ``S`` too (moments / L, in N).

Both objectives are ``1/2 |G t - g|^2``: a convex QP with 6 equalities and box bounds, solved
exactly by a primal active-set method (each step one small KKT solve, least squares so that a
singular Hessian on a face is fine; the KKT multipliers are returned). Its feasible start is the
minimiser of ``|S (B t + W)|^2`` over the box (the same active-set method): when that minimum is
not zero the request is infeasible, and the reason names the constraint (the pose cannot take the
load at all, tension_min, tension_max, or a string's rest-length / maximum-length cap).
:func:`stiffness_range` solves the LPs ``min / max K_c(t)[i, i]`` over the same set with scipy's
HiGHS. :func:`rest_length_sensitivity` is ``dK_c/dl0_j = M_j dt_j/dl0_j`` and
``dF/dl0_j = X_j dt_j/dl0_j`` at any rest lengths (slack strings contribute 0; saturated strings
have ``A = (t/l)(I - u u^T)``, and ``dt/dl0 = 0`` for Hooke, ``-k m / lmax^2`` for the paper law).

The service helpers :func:`design_request_from_service` and :func:`design_response_fields` map the
fields of ``srv/DesignRestLengths.srv`` (type ``tensegrity_stiffness/srv/DesignRestLengths``) to
and from this module (plain Python and numpy values, no rclpy).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.components import TWIST_NAMES
from tensegrity_stiffness.geometry.quaternion import quaternion_to_rotation
from tensegrity_stiffness.geometry.screw import (
    as_screws,
    check_in_chart,
    exp_se3,
    hat3,
    log_se3,
    single_screw,
)
from tensegrity_stiffness.geometry.validation import finite_array_of_shape, finite_scalar
from tensegrity_stiffness.mechanics import plausibility
from tensegrity_stiffness.mechanics.active_set import (  # noqa: F401 (re-exported)
    ACTIVE_SET_TOLERANCE,
    MAX_ACTIVE_SET_ITERATIONS,
    active_set,
    kkt_system,
)
from tensegrity_stiffness.mechanics.equilibrium import is_stable
from tensegrity_stiffness.mechanics.joint import MIN_STRING_LENGTH, JointModel, JointState

FloatArray = NDArray[np.float64]

#: Default tension limits (N): the issue's example range.
DEFAULT_TENSION_MIN = 0.1
DEFAULT_TENSION_MAX = 1.5
#: Relative margin below a string's physical tension caps (zero rest length, maximum length),
#: so that a designed string is strictly taut and strictly below lmax.
BOUND_MARGIN = 1e-9
#: Largest scaled residual |S (B t + W)| (N) of a feasible request.
FEASIBILITY_TOLERANCE = 1e-9
#: Diagonal entries of K_c in ROS order and their units (rows of :class:`StiffnessRange`).
DIAGONAL_NAMES = TWIST_NAMES
DIAGONAL_UNITS = ('N/m', 'N/m', 'N/m', 'N m/rad', 'N m/rad', 'N m/rad')


@dataclass(frozen=True)
class DesignResult:
    """Outcome of :func:`design_rest_lengths`.

    ``rest_lengths`` (n,) m, ``tensions`` (n,) N, ``cartesian_stiffness`` K_c and ``stiffness`` K
    (6, 6) are the joint model's own evaluation at the target screw with the designed rest lengths;
    ``stiffness_error`` = |S (K_c - K*) S|_F / |S K* S|_F (0 without a target); ``objective`` the
    minimised ``1/2 |G t - g|^2``. KKT multipliers of the scaled QP: ``equality_multipliers`` (6,)
    for ``S (B t + W) = 0``, ``lower_multipliers`` / ``upper_multipliers`` (n,) >= 0 for the bounds
    ``tension_lower`` / ``tension_upper`` (n,) actually used (the upper one includes each string's
    caps). When ``success`` is False the arrays are NaN and ``message`` names the constraint.
    """

    success: bool
    message: str
    screw: FloatArray
    rest_lengths: FloatArray
    tensions: FloatArray
    cartesian_stiffness: FloatArray
    stiffness: FloatArray
    stable: bool
    stiffness_error: float
    objective: float = math.nan
    iterations: int = 0
    tension_lower: FloatArray = field(default_factory=lambda: np.empty(0), repr=False)
    tension_upper: FloatArray = field(default_factory=lambda: np.empty(0), repr=False)
    equality_multipliers: FloatArray = field(default_factory=lambda: np.full(6, np.nan),
                                             repr=False)
    lower_multipliers: FloatArray = field(default_factory=lambda: np.empty(0), repr=False)
    upper_multipliers: FloatArray = field(default_factory=lambda: np.empty(0), repr=False)
    length_scale: float = math.nan
    state: JointState | None = field(default=None, repr=False)


@dataclass(frozen=True)
class StiffnessRange:
    """Outcome of :func:`stiffness_range`: for each diagonal entry ``K_c[i, i]`` (ROS order
    ``dx dy dz rx ry rz``; N/m, N m/rad) the smallest ``minimum[i]`` and largest ``maximum[i]``
    value over every admissible tension set, and those tension sets ``minimizers`` /
    ``maximizers`` (6, n). NaN when ``success`` is False (``message`` says why)."""

    success: bool
    message: str
    minimum: FloatArray
    maximum: FloatArray
    minimizers: FloatArray
    maximizers: FloatArray


@dataclass(frozen=True)
class RestLengthSensitivity:
    """``cartesian_stiffness`` = dK_c/dl0 (n, 6, 6) (``[j]`` = derivative by ``l0_j``) and
    ``wrench`` = dF/dl0 (6, n) at one screw and set of rest lengths."""

    cartesian_stiffness: FloatArray
    wrench: FloatArray


@dataclass(frozen=True)
class _Pose:
    """What stays fixed at a screw: B (6, n), K_c = K0 + sum t_j M_j, tension caps."""

    lengths: FloatArray
    B: FloatArray
    K0: FloatArray
    M: FloatArray
    cap: FloatArray
    cap_reason: list[str]


# ---------------------------------------------------------------------------------- the pose
def _geometry(model: JointModel, screw: FloatArray) -> tuple[FloatArray, ...]:
    """Lengths (n,), X = [u; p1 x u] (n, 6) and Z_j E_j (n, 6, 6) at ``screw``."""
    T = exp_se3(screw)
    p1 = model.link1_nodes[model.connections[:, 0]]
    q = model.link2_nodes[model.connections[:, 1]] @ T[:3, :3].T + T[:3, 3]
    s = p1 - q
    lengths = np.sqrt(np.einsum('ij,ij->i', s, s))
    if lengths.min() < MIN_STRING_LENGTH:
        bad = np.flatnonzero(lengths < MIN_STRING_LENGTH).tolist()
        raise ValueError(f'strings {bad} have zero length at this screw')
    u = s / lengths[:, None]
    X = np.concatenate([u, np.cross(p1, u)], axis=1)
    hp, hq = hat3(p1), hat3(q)
    n = len(lengths)
    ZE = np.empty((n, 6, 6))
    ZE[:, :3, :3] = np.eye(3)
    ZE[:, :3, 3:] = -hq
    ZE[:, 3:, :3] = hp
    ZE[:, 3:, 3:] = -hp @ hq
    return lengths, X, ZE


def _law(model: JointModel, lengths: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Taut-string law at fixed lengths: dt/dl = a + b t and dt/dl0 (n,) each."""
    k = model.k
    if model.force_law == 'hooke':
        return k.copy(), np.zeros_like(k), -k
    return k / lengths, -1.0 / lengths, -k / lengths


def _pose(model: JointModel, screw: FloatArray) -> _Pose:
    lengths, X, ZE = _geometry(model, screw)
    a, b, _ = _law(model, lengths)
    XX = X[:, :, None] * X[:, None, :]
    K0 = np.einsum('j,jab->ab', a, XX)
    M = (b - 1.0 / lengths)[:, None, None] * XX + ZE / lengths[:, None, None]
    k, m = model.k, model.max_stretch
    if model.force_law == 'hooke':
        positive, below_max = k * lengths, k * m
    else:
        positive, below_max = k.copy(), k * m / lengths
    cap = (1.0 - BOUND_MARGIN) * np.minimum(positive, below_max)
    reason = ['a positive rest length' if p <= c else 'its maximum length (lmax - l0 kept)'
              for p, c in zip(positive, below_max, strict=True)]
    return _Pose(lengths, X.T.copy(), K0, M, cap, reason)


def rest_from_tensions(model: JointModel, lengths: FloatArray, tensions: FloatArray
                       ) -> FloatArray:
    """True rest lengths that give ``tensions`` at ``lengths`` (eq. 8 inverted)."""
    if model.force_law == 'hooke':
        return lengths - tensions / model.k
    return lengths * (1.0 - tensions / model.k)


def length_scaling(length_scale: float) -> FloatArray:
    """The diagonal of ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)`` for ``L = length_scale`` (m)."""
    return np.array([1.0, 1.0, 1.0, 1.0 / length_scale, 1.0 / length_scale, 1.0 / length_scale])


def relative_stiffness_error(Kc: FloatArray, target: FloatArray, length_scale: float) -> float:
    """|S (K_c - K*) S|_F / |S K* S|_F (:attr:`DesignResult.stiffness_error`; the distance
    itself when ``K* = 0``)."""
    S = length_scaling(length_scale)
    denominator = float(np.linalg.norm(S[:, None] * target * S[None, :]))
    distance = float(np.linalg.norm(S[:, None] * (Kc - target) * S[None, :]))
    return distance / denominator if denominator > 0.0 else distance


# ---------------------------------------------------------------------------------- the QP
@dataclass
class _QPSolution:
    t: FloatArray
    nu: FloatArray
    mu_lower: FloatArray
    mu_upper: FloatArray
    iterations: int
    converged: bool


def _kkt_solve(K: FloatArray, rhs: FloatArray) -> FloatArray:
    """``K x = rhs`` by LU when ``K`` is regular, else least squares (singular face)."""
    try:
        x = np.linalg.solve(K, rhs)
        if np.all(np.isfinite(x)) and np.linalg.norm(K @ x - rhs) <= 1e-12 * (
                1.0 + np.linalg.norm(rhs) + np.abs(K).max() * np.linalg.norm(x)):
            return x
    except np.linalg.LinAlgError:
        pass
    return np.linalg.lstsq(K, rhs, rcond=None)[0]


def _box_qp(G: FloatArray, g: FloatArray, A: FloatArray, b: FloatArray, lo: FloatArray,
            hi: FloatArray, t0: FloatArray) -> _QPSolution:
    """Primal active set (:func:`~.active_set.active_set`) for ``min 1/2 |G t - g|^2`` s.t.
    ``A t = b``, ``lo <= t <= hi`` from a box-feasible ``t0`` with ``A t0 = b`` (to rounding).
    Each face is solved by least squares (no equalities) or its KKT system. Returns the
    multipliers of ``grad + A^T nu - mu_lower + mu_upper = 0``."""
    n, m = G.shape[1], A.shape[0]
    P = G.T @ G
    c = G.T @ g

    def face(t: FloatArray, free: NDArray[np.bool_], nu: FloatArray
             ) -> tuple[FloatArray, FloatArray]:
        F = np.flatnonzero(free)
        if m == 0:  # least squares on the face: the smallest step to its minimiser
            step = (np.linalg.lstsq(G[:, F], g - G @ t, rcond=None)[0] if F.size
                    else np.zeros(0))
            return t[F] + step, nu
        sol = _kkt_solve(*kkt_system(P, c, A, b, t, free))
        return sol[:F.size], sol[F.size:]

    result = active_set(P, c, A, lo, hi, t0, face)
    t, nu = result.t, result.nu
    if not result.converged:
        return _QPSolution(t, nu, np.zeros(n), np.zeros(n), result.iterations, False)
    grad = P @ t - c + A.T @ nu
    mu_lo = np.where(result.at_lo, grad, 0.0)
    mu_hi = np.where(result.at_hi, -grad, 0.0)
    return _QPSolution(t, nu, np.maximum(mu_lo, 0.0), np.maximum(mu_hi, 0.0), result.iterations,
                       True)


def _closest_feasible(A: FloatArray, b: FloatArray, lo: FloatArray, hi: FloatArray
                      ) -> tuple[FloatArray, float]:
    """Tensions in the box minimising |A t - b| (active set from the middle), and that norm."""
    t_mid = 0.5 * (lo + np.where(np.isfinite(hi), hi, lo + 1.0))
    sol = _box_qp(A, b, np.zeros((0, A.shape[1])), np.zeros(0), lo, hi, t_mid)
    return sol.t, float(np.linalg.norm(A @ sol.t - b))


def _infeasibility_reason(model: JointModel, A: FloatArray, b: FloatArray, t_min: float,
                          t_max: float, pose: _Pose) -> str:
    """Which constraint makes ``A t = b`` impossible within the limits (a one-line reason)."""
    n = A.shape[1]
    unbounded = np.linalg.lstsq(A, b, rcond=None)[0]
    residual = float(np.linalg.norm(A @ unbounded - b))
    if residual > FEASIBILITY_TOLERANCE:
        return (f'the load cannot be held at this pose by any string tensions (the string '
                f'wrenches span rank {np.linalg.matrix_rank(A)} of 6; residual {residual:.3g} N)')
    lo = np.full(n, t_min)
    _, res_min = _closest_feasible(A, b, lo, np.full(n, np.inf))
    if res_min > FEASIBILITY_TOLERANCE:
        return (f'tension_min: no tensions >= {t_min:g} N hold the load at this pose (closest '
                f'residual {res_min:.3g} N)')
    t, res_max = _closest_feasible(A, b, lo, np.full(n, t_max))
    if res_max > FEASIBILITY_TOLERANCE:
        hi_names = [model.string_names[j] for j in np.flatnonzero(t >= t_max * (1 - 1e-12))]
        return (f'tension_max: the load needs tensions above {t_max:g} N (closest residual '
                f'{res_max:.3g} N with {", ".join(hi_names) or "no string"} at tension_max)')
    return 'string caps: within the tension limits the load needs more tension than ' + \
        _caps_text(model, pose, np.flatnonzero(pose.cap < t_max)) + ' can carry'


def _caps_text(model: JointModel, pose: _Pose, strings: NDArray[np.intp]) -> str:
    """``name cap N, ... (reason)`` for each distinct reason."""
    parts = []
    for reason in dict.fromkeys(pose.cap_reason[j] for j in strings):
        names = [f'{model.string_names[j]} {pose.cap[j]:.4g} N' for j in strings
                 if pose.cap_reason[j] == reason]
        parts.append(', '.join(names) + f' (for {reason})')
    return '; '.join(parts)


# ---------------------------------------------------------------------------------- validation
def _validate(model: JointModel, screw: ArrayLike, external_wrench: ArrayLike | None,
              tension_min: float, tension_max: float, length_scale: float | None
              ) -> tuple[FloatArray, FloatArray, float, float, float]:
    xi = single_screw(screw)
    W = np.zeros(6) if external_wrench is None else finite_array_of_shape(
        'external_wrench', external_wrench, (6,))
    t_min = finite_scalar('tension_min', tension_min)
    t_max = finite_scalar('tension_max', tension_max)
    if t_min <= 0.0:
        raise ValueError(f'tension_min must be > 0 (strings must stay taut), got {t_min:g}')
    if t_max <= t_min:
        raise ValueError(f'tension_max must exceed tension_min ({t_min:g}), got {t_max:g}')
    if length_scale is None:
        L = float(np.linalg.norm(model.link1_nodes, axis=1).max())
        if L <= 0.0:
            raise ValueError('length_scale: every link-1 node is at the origin; give one')
    else:
        L = finite_scalar('length_scale', length_scale)
        if L <= 0.0:
            raise ValueError(f'length_scale must be > 0, got {L:g}')
    return xi, W, t_min, t_max, L


def _constraints(model: JointModel, xi: FloatArray, W: FloatArray, t_min: float, t_max: float,
                 L: float) -> tuple[_Pose, FloatArray, FloatArray, FloatArray, FloatArray,
                                    FloatArray]:
    """The pose terms at ``xi``, ``S`` (6,) and the constraints of the tensions: the scaled
    equilibrium ``A t = b`` (``S (B t + W) = 0``) and the box ``[lo, hi]`` (the limits and the
    strings' caps)."""
    pose = _pose(model, xi)
    S = length_scaling(L)
    lo = np.full(model.n_strings, t_min)
    hi = np.minimum(t_max, pose.cap)
    return pose, S, S[:, None] * pose.B, -S * W, lo, hi


def _nan_result(model: JointModel, xi: FloatArray, message: str, L: float,
                lo: FloatArray | None = None, hi: FloatArray | None = None) -> DesignResult:
    n = model.n_strings
    nan_n, nan_66 = np.full(n, np.nan), np.full((6, 6), np.nan)
    return DesignResult(False, message, xi, nan_n, nan_n.copy(), nan_66, nan_66.copy(), False,
                        math.nan, length_scale=L,
                        tension_lower=np.full(n, np.nan) if lo is None else lo,
                        tension_upper=np.full(n, np.nan) if hi is None else hi,
                        lower_multipliers=nan_n.copy(), upper_multipliers=nan_n.copy())


# ---------------------------------------------------------------------------------- public API
def design_rest_lengths(
    model: JointModel,
    screw: ArrayLike,
    external_wrench: ArrayLike | None = None,
    tension_min: float = DEFAULT_TENSION_MIN,
    tension_max: float = DEFAULT_TENSION_MAX,
    target_stiffness: ArrayLike | None = None,
    length_scale: float | None = None,
) -> DesignResult:
    """Rest lengths (n,) that hold ``screw`` in equilibrium under ``external_wrench`` with every
    tension in ``[tension_min, tension_max]`` (N) and K_c closest to ``target_stiffness``.

    ``screw`` (6,) ``[wx wy wz vx vy vz]`` with |omega| < 2 pi; ``external_wrench`` (6,)
    ``[fx fy fz mx my mz]`` on link 2 in {1} about its origin (default 0); ``target_stiffness``
    a 6x6 K_c (rows ``[f; m]``, columns ``[linear; angular]``), ``None`` for the tensions closest
    to the middle of the limits; ``length_scale`` L (m) of ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)``
    (default: the largest distance of a link-1 node from the origin of {1}). The math is in the
    module docstring. Infeasible requests return ``success=False`` with the constraint that
    fails; bad input raises ValueError naming the field, and so do a screw, a load or a target
    outside the joint's range (:mod:`~tensegrity_stiffness.mechanics.plausibility`: a target
    must be symmetric positive semidefinite and within what the strings can give).
    """
    xi, W, t_min, t_max, L = _validate(model, screw, external_wrench, tension_min, tension_max,
                                       length_scale)
    # Finite but absurd requests are refused by name (mechanics.plausibility).
    plausibility.check_screw(model, xi)
    plausibility.check_wrench(model, W)
    target = None if target_stiffness is None else plausibility.check_target_stiffness(
        model, target_stiffness, length_scale=L, wrench=W)
    pose, S, A, b, lo, hi = _constraints(model, xi, W, t_min, t_max, L)
    n = model.n_strings
    if np.any(hi <= lo):
        return _nan_result(model, xi, 'string caps: at this pose these strings cannot carry '
                           f'tension_min = {t_min:g} N: '
                           + _caps_text(model, pose, np.flatnonzero(hi <= lo)), L, lo, hi)
    t0, residual = _closest_feasible(A, b, lo, hi)
    if residual > FEASIBILITY_TOLERANCE:
        reason = _infeasibility_reason(model, A, b, t_min, t_max, pose)
        return _nan_result(model, xi, f'infeasible: {reason}', L, lo, hi)
    if target is None:
        G, g = np.eye(n), 0.5 * (lo + hi)
    else:
        SS = S[:, None] * S[None, :]
        G = (pose.M * SS).reshape(n, 36).T
        g = ((target - pose.K0) * SS).ravel()
    sol = _box_qp(G, g, A, b, lo, hi, t0)
    if not sol.converged:
        return _nan_result(model, xi, 'the active-set method did not converge in '
                           f'{MAX_ACTIVE_SET_ITERATIONS} iterations', L, lo, hi)
    t = sol.t
    rest = rest_from_tensions(model, pose.lengths, t)
    state = model.evaluate(xi, rest)
    Kc = state.cartesian_stiffness
    error = 0.0 if target is None else relative_stiffness_error(Kc, target, L)
    held = float(np.linalg.norm(S * (state.wrench + W)))
    if np.any(state.slack) or np.any(state.saturated) or held > 10 * FEASIBILITY_TOLERANCE:
        return _nan_result(model, xi, f'internal check failed: residual {held:.3g} N, '
                           f'{int(state.slack.sum())} slack, {int(state.saturated.sum())} '
                           'saturated strings at the design', L, lo, hi)
    stable = is_stable(Kc)
    message = 'designed' + ('' if stable else '; the equilibrium is not stable')
    objective = 0.5 * float(np.sum((G @ t - g) ** 2))
    return DesignResult(True, message, xi, rest, state.tensions, Kc, state.stiffness, stable,
                        error, objective, sol.iterations, lo, hi, sol.nu, sol.mu_lower,
                        sol.mu_upper, L, state)


def stiffness_range(
    model: JointModel,
    screw: ArrayLike,
    external_wrench: ArrayLike | None = None,
    tension_min: float = DEFAULT_TENSION_MIN,
    tension_max: float = DEFAULT_TENSION_MAX,
) -> StiffnessRange:
    """For each diagonal entry of K_c (``dx dy dz rx ry rz``), the smallest and largest value any
    tension set admissible for :func:`design_rest_lengths` reaches at ``screw`` under
    ``external_wrench``: six pairs of LPs over ``{B t + W = 0, t_lo <= t <= t_hi}`` (HiGHS)."""
    from scipy.optimize import linprog

    xi, W, t_min, t_max, L = _validate(model, screw, external_wrench, tension_min, tension_max,
                                       None)
    pose, _, A, b, lo, hi = _constraints(model, xi, W, t_min, t_max, L)
    n = model.n_strings
    nan6, nan6n = np.full(6, np.nan), np.full((6, n), np.nan)

    def failed(message: str) -> StiffnessRange:
        return StiffnessRange(False, message, nan6, nan6.copy(), nan6n, nan6n.copy())

    if np.any(hi <= lo):
        return failed('string caps: some strings cannot carry tension_min at this pose')
    _, residual = _closest_feasible(A, b, lo, hi)
    if residual > FEASIBILITY_TOLERANCE:
        return failed('infeasible: ' + _infeasibility_reason(model, A, b, t_min, t_max, pose))
    diag = np.einsum('jii->ji', pose.M).T  # (6, n): d K_c[i, i] / d t_j
    base = np.diag(pose.K0)
    bounds = list(zip(lo, hi, strict=True))
    options = {'primal_feasibility_tolerance': 1e-10, 'dual_feasibility_tolerance': 1e-10}
    values = np.empty((2, 6))
    argmins = np.empty((2, 6, n))
    for i in range(6):
        for side, sign in enumerate((1.0, -1.0)):
            res = linprog(sign * diag[i], A_eq=A, b_eq=b, bounds=bounds, method='highs',
                          options=options)
            if res.status != 0:
                return failed(f'LP for K_c[{DIAGONAL_NAMES[i]}] failed: {res.message}')
            t = np.clip(res.x, lo, hi)
            argmins[side, i] = t
            values[side, i] = base[i] + diag[i] @ t
    return StiffnessRange(True, 'ok', values[0], values[1], argmins[0], argmins[1])


def rest_length_sensitivity(model: JointModel, screw: ArrayLike, rest_lengths: ArrayLike
                            ) -> RestLengthSensitivity:
    """Analytic dK_c/dl0 (n, 6, 6) and dF/dl0 (6, n) at ``screw`` with ``rest_lengths`` (n,)
    (any rest lengths, not only a design; slack strings give 0)."""
    xi = single_screw(screw)
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    lengths, X, ZE = _geometry(model, xi)
    _, b, dt_dl0 = _law(model, lengths)
    lmax = rest + model.max_stretch
    slack = lengths <= rest
    saturated = ~slack & (lengths >= lmax)
    if np.any(saturated):
        # Saturated: A = (t/l)(I - u u^T) (t' = 0, b = 0); t = k m for Hooke, k m / lmax (paper).
        b = np.where(saturated, 0.0, b)
        m = model.max_stretch
        dsat = 0.0 if model.force_law == 'hooke' else -model.k * m / (lmax * lmax)
        dt_dl0 = np.where(saturated, dsat, dt_dl0)
    dt_dl0 = np.where(slack, 0.0, dt_dl0)
    XX = X[:, :, None] * X[:, None, :]
    M = (b - 1.0 / lengths)[:, None, None] * XX + ZE / lengths[:, None, None]
    return RestLengthSensitivity(M * dt_dl0[:, None, None], (X * dt_dl0[:, None]).T)


# ---------------------------------------------------------------------------------- service
def design_request_from_service(
    target_screw: Sequence[float],
    target_position: Sequence[float],
    target_orientation: Sequence[float],
    external_wrench: Sequence[float],
    tension_min: float,
    tension_max: float,
    target_cartesian_stiffness: Sequence[float],
    reference_screw: ArrayLike,
) -> dict[str, Any]:
    """Keyword arguments of :func:`design_rest_lengths` from the fields of a
    ``DesignRestLengths`` request (plain values, field names as in the .srv).

    ``target_screw``: 6 values, or empty to use the pose (``target_position`` [x y z] m,
    ``target_orientation`` [x y z w]), converted with the log map on the branch nearest
    ``reference_screw`` (the node's current screw). ``external_wrench`` [fx fy fz mx my mz];
    ``target_cartesian_stiffness``: 36 values row-major, or empty for none. ValueError names the
    request field.
    """
    raw = np.asarray(target_screw, dtype=np.float64).ravel()
    if raw.size == 0:
        position = finite_array_of_shape('target_pose.position', target_position, (3,))
        try:
            R = quaternion_to_rotation(target_orientation)
        except ValueError as exc:
            raise ValueError(f'target_pose.orientation: {exc}') from None
        T = np.eye(4)
        T[:3, :3], T[:3, 3] = R, position
        xi = log_se3(T, reference=as_screws(reference_screw, 'reference_screw'))
    elif raw.size == 6:
        xi = finite_array_of_shape('target_screw', raw, (6,))
        check_in_chart(xi, 'target_screw')
    else:
        raise ValueError(f'target_screw must have 6 values or be empty (use target_pose), got '
                         f'{raw.size}')
    W = finite_array_of_shape('external_wrench', external_wrench, (6,))
    stiff = np.asarray(target_cartesian_stiffness, dtype=np.float64).ravel()
    if stiff.size not in (0, 36):
        raise ValueError('target_cartesian_stiffness must have 36 values (6x6 row-major) or be '
                         f'empty, got {stiff.size}')
    target = None if stiff.size == 0 else finite_array_of_shape(
        'target_cartesian_stiffness', stiff, (36,)).reshape(6, 6)
    return {'screw': xi, 'external_wrench': W, 'tension_min': float(tension_min),
            'tension_max': float(tension_max), 'target_stiffness': target}


def design_response_fields(result: DesignResult) -> dict[str, Any]:
    """The response fields of ``DesignRestLengths`` from a :class:`DesignResult`: ``success``,
    ``message``, ``rest_lengths`` / ``tensions`` (lists, empty on failure),
    ``cartesian_stiffness`` / ``stiffness`` (36 values row-major; NaN on failure),
    ``stiffness_error`` and ``stable``."""
    ok = bool(result.success)
    return {
        'success': ok,
        'message': str(result.message),
        'rest_lengths': result.rest_lengths.tolist() if ok else [],
        'tensions': result.tensions.tolist() if ok else [],
        'cartesian_stiffness': np.asarray(result.cartesian_stiffness, float).ravel().tolist(),
        'stiffness': np.asarray(result.stiffness, float).ravel().tolist(),
        'stiffness_error': float(result.stiffness_error),
        'stable': bool(result.stable),
    }
