"""Stiffness control at the actuators: rest-length commands that hold a pose with a chosen K_c.

Every tick, :class:`StiffnessController` turns a :class:`ControlTarget` (a pose of link 2 in {1}
and optionally a target Cartesian stiffness ``K_c*``), what the robot measures (the pose) and the
known or estimated load into rest-length commands a motor can follow (:class:`ControlCommand`).
No rclpy: the node ``stiffness_controller`` wraps it. The method is in ``docs/control.md``.

The math (notation of :mod:`tensegrity_stiffness.mechanics.design`)
--------------------------------------------------------
* **Feedforward: the exact design at the pose.** At a fixed screw the wrench is linear in the
  tensions, ``F = B t`` (Monke & Vikas eq. 9), and ``K_c(t) = K_0 + sum_j t_j M_j`` is affine in
  them (eqs. 10-11 in the Cartesian form; ``M_j``, ``K_0`` as in the design module's docstring,
  for both force laws). The tensions solve the convex QP of ``design_rest_lengths``:
  ``min |W o S (K_c(t) - K*) S|_F^2`` (``W`` the entry weights of
  :attr:`ControlTarget.stiffness_weight`, ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)``), or without a
  target ``min |t - t_mid|^2`` (``t_mid`` the middle of the tension limits and caps, as the
  design: the actuator range constrains but does not move the middle),
  subject to ``S (B t + W_ext) = 0`` and box bounds. The box is the
  tension limits, each string's physical caps (positive rest length, maximum stretch kept, as
  in the design) and the **actuator range as tension bounds** (eq. 8): Hooke
  ``t in [k (l - l0_max), k (l - l0_min)]``, paper law ``t in [k (l - l0_max) / l,
  k (l - l0_min) / l]``; the rest lengths follow as ``l0 = l - t / k`` resp. ``l (1 - t / k)``.
* **Why a QP of our own.** ``design_rest_lengths`` takes scalar tension limits only (no
  per-string range bounds) and starts every solve cold (a phase-1 active set from the middle of
  the box, then phase 2: about 1 ms). Here the QP is the same primal active-set method written
  for warm starts: the working set (strings at a bound) and the tensions of the last tick are
  carried over; the first try is one KKT solve on that face, which is already optimal in steady
  state; otherwise the last tensions are projected onto the new equality and the method
  continues from there. The public design is kept as the reference the tests compare to.
* **Feedback: integral action on the measured pose error.** ``e = log(T* T_m^-1)`` (a spatial
  twist in {1}, screw order ``[omega; v]``) integrates into a correction ``z``; the design is
  done at the shifted pose ``T_d = exp(hat(z + k_p e)) T*``. With an exact model the twin settles
  at ``T_d``, so ``e = -z`` and ``z -> 0``; with a model that is off (every ``k_j`` by 10 %, an
  offset, an unknown load) ``z`` converges to the shift that puts the true pose at ``T*``
  (no steady-state error; the stiffness then follows the model's error, about ``|dk/k|``).
  Anti-windup: ``z`` is frozen while a rate or range limit binds (the commands lag the
  feedforward) or the pose cannot be held, and clamped to ``integral_limit``. So that the
  integral cannot sit at its clamp without a limit binding (issue #42: a target turned by
  180 deg needs the same rest lengths, no limit binds, and the clamped correction of that
  target stayed on after it, also when the target came back in steps smaller than the clamp),
  the integral's reset rule: (1) ``z`` restarts from 0 when the target pose moves by more than
  the clamp in one tick; (2) a pose error beyond the clamp (its rotation or translation part
  larger than that part's clamp: a transient or a pose the correction cannot reach) is not
  integrated: ``z`` leaks toward 0 instead, ``z *= exp(-k_i dt)``; (3) an integral that stays
  at its clamp with no limit binding for longer than its time constant ``1 / k_i`` (the pose
  error did not answer it) rests: it leaks the same way and integrates nothing until the
  target moves by more than the clamp from where it came to rest. The error integrated per
  tick is at most the clamp. A pose error that is not finite (a pose turned by about 180 deg
  from the target, where the error has no direction) is refused by name.
* **Directions the strings do not hold** (issue #39). Where ``S B`` at the joint's unloaded
  pose has singular values below ``UNHELD_DIRECTION_TOLERANCE`` of its largest
  (:func:`unheld_count`: a ring's spin about its axis, about which no string has a moment),
  every tick keeps the equilibrium on the ``6 - k`` strongest wrench directions at the design
  pose only (:func:`held_equilibrium`) and removes the pairing twist of the weak ones (along
  which no string wrench does work) from the pose error before it is integrated; the pose
  settles along it where the strings balance, and the message says so.
* **Limits.** Commands move at most ``max_rate * dt`` per string per tick and stay within
  ``[rest_length_min, rest_length_max]``; a changed target is followed at the rate limit (no
  jump). An infeasible pose keeps the last command (``feasible=False``).
* **Offsets.** ``rest_length_offsets`` d (m): the model's (true) rest length is
  ``l0 = command + d``; commands, limits and the controller's ``rest_lengths`` are motor
  positions (``command = l0 - d``).

:class:`ChainStiffnessController` does the same for a spine (see its docstring).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import exp_se3, hat3, log_se3, single_screw
from tensegrity_stiffness.geometry.transforms import adjoint, inverse_transform, rigid_transform
from tensegrity_stiffness.geometry.validation import (
    finite_array,
    finite_array_of_shape,
    finite_scalar,
    per_string,
)
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.active_set import (
    ACTIVE_SET_TOLERANCE,
    MAX_ACTIVE_SET_ITERATIONS,
    active_set,
    kkt_system,
)
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.design import (
    BOUND_MARGIN,
    DEFAULT_TENSION_MAX,
    DEFAULT_TENSION_MIN,
    FEASIBILITY_TOLERANCE,
    length_scaling,
    relative_stiffness_error,
    rest_from_tensions,
)
from tensegrity_stiffness.mechanics.joint import MIN_STRING_LENGTH, JointModel

__all__ = [
    'ACTIVE_SET_TOLERANCE',
    'CHAIN_IK_ITERATIONS',
    'CHAIN_STIFFNESS_DAMPING',
    'DEFAULT_INTEGRAL_GAIN',
    'DEFAULT_INTEGRAL_LIMIT',
    'DEFAULT_PROPORTIONAL_GAIN',
    'FACE_BOUND_SLACK',
    'FACE_RESIDUAL_TOLERANCE',
    'FEASIBILITY_TOLERANCE',
    'MAX_ACTIVE_SET_ITERATIONS',
    'MIN_QP_ITERATIONS',
    'OUT_OF_TIME',
    'POSE_ROTATION_TOLERANCE',
    'SATURATION_TOLERANCE',
    'STIFFNESS_MET_TOLERANCE',
    'UNHELD_DIRECTION_TOLERANCE',
    'WARM_ACTIVE_SET_ITERATIONS',
    'ActuatorLimits',
    'BoolArray',
    'ChainControlCommand',
    'ChainStiffnessController',
    'ControlCommand',
    'ControlTarget',
    'PoseTerms',
    'QPResult',
    'StiffnessController',
    'adjoint_twist',
    'held_equilibrium',
    'pose_terms',
    'pose_terms_at',
    'pose_terms_numpy',
    'relative_stiffness_error',
    'rest_from_tensions',
    'solve_box_qp',
    'tension_bounds',
    'unheld_count',
    'unheld_twist_text',
    'warm_face',
    'warm_face_numpy',
]

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Default integral gain (1/s): the pose correction's bandwidth, well below the twin's
#: mechanical settling (about 0.3 s with the default damping).
DEFAULT_INTEGRAL_GAIN = 8.0
#: Default proportional gain (dimensionless share of the pose error added to the shift).
DEFAULT_PROPORTIONAL_GAIN = 0.0
#: Default clamp of the integral correction: rotation (rad) and translation (m) parts.
DEFAULT_INTEGRAL_LIMIT = (0.2, 0.01)
#: Largest accepted deviation of R^T R from I in a 4x4 target or measured pose (the controller's
#: since it was written; the library's default, ``geometry.transforms.RIGID_TOLERANCE``, is 1e-9).
POSE_ROTATION_TOLERANCE = 1e-6
#: Iterations of a warm-started active set before it is redone cold.
WARM_ACTIVE_SET_ITERATIONS = 100
#: Iterations of the QP's last resort (scipy's SLSQP) per tick.
SLSQP_MAX_ITERATIONS = 500
#: Iterations of a tick's QP (all phases) done before its deadline is looked at: a joint's
#: tick, warm or cold, converges in at most about 15 (bench/bench_hostile.py), so only a QP
#: that stalls (a degenerate face the active set cycles on: 600 iterations, 90 ms) meets the
#: deadline, however loaded the machine.
MIN_QP_ITERATIONS = 20
#: The reason of a QP or a tick stopped at its deadline (the start of its message).
OUT_OF_TIME = 'time budget exhausted'
#: A stiffness target counts as met when the relative scaled error is at most this.
STIFFNESS_MET_TOLERANCE = 1e-3
#: A command is "saturated" when it differs from the feedforward by more than this (m).
SATURATION_TOLERANCE = 1e-12
#: A direction of the (scaled) string wrenches ``S B`` at the joint's unloaded pose whose
#: singular value is below this share of the largest is one the strings do not hold (a ring's
#: spin about its axis: no string has a moment about it there, exactly 0 to rounding).
UNHELD_DIRECTION_TOLERANCE = 1e-6
#: Gauss-Newton iterations of the spine's redundancy resolution per tick.
CHAIN_IK_ITERATIONS = 3
#: Levenberg damping of the spine's tip-stiffness step, relative to the mean curvature.
CHAIN_STIFFNESS_DAMPING = 1.0


# ---------------------------------------------------------------------------------- inputs
@dataclass(frozen=True)
class ActuatorLimits:
    """Limits of the motors and strings, each a scalar or one value per string.

    ``rest_length_min`` < ``rest_length_max`` (m, motor positions, > 0), ``max_rate`` (m/s,
    > 0), ``tension_min`` (N, > 0) < ``tension_max`` (N). ValueError names the field."""

    rest_length_min: Any
    rest_length_max: Any
    max_rate: Any
    tension_min: Any = DEFAULT_TENSION_MIN
    tension_max: Any = DEFAULT_TENSION_MAX

    def __post_init__(self) -> None:
        names = ('rest_length_min', 'rest_length_max', 'max_rate', 'tension_min', 'tension_max')
        values = {name: per_string(name, getattr(self, name), None) for name in names}
        try:
            np.broadcast_shapes(*(v.shape for v in values.values()))
        except ValueError:
            raise ValueError('rest_length_min, rest_length_max, max_rate, tension_min and '
                             'tension_max must be scalars or have the same length') from None
        if np.any(values['rest_length_min'] <= 0.0):
            raise ValueError('rest_length_min must be > 0')
        if np.any(values['rest_length_min'] >= values['rest_length_max']):
            raise ValueError('rest_length_max must exceed rest_length_min (min >= max)')
        if np.any(values['max_rate'] <= 0.0):
            raise ValueError('max_rate must be > 0 (m/s)')
        if np.any(values['tension_min'] <= 0.0):
            raise ValueError('tension_min must be > 0 (strings must stay taut)')
        if np.any(values['tension_min'] >= values['tension_max']):
            raise ValueError('tension_max must exceed tension_min (min >= max)')
        for name, v in values.items():
            object.__setattr__(self, name, v)

    def for_strings(self, n: int) -> tuple[FloatArray, ...]:
        """(rest_length_min, rest_length_max, max_rate, tension_min, tension_max), each (n,)."""
        out = []
        for name in ('rest_length_min', 'rest_length_max', 'max_rate', 'tension_min',
                     'tension_max'):
            v = getattr(self, name)
            if v.ndim == 1 and v.size != n:
                raise ValueError(f'{name} has {v.size} values for {n} strings')
            out.append(np.broadcast_to(v, (n,)).astype(np.float64))
        return tuple(out)


@dataclass(frozen=True)
class ControlTarget:
    """What to hold: ``pose`` (4x4 or ``[x y z qx qy qz qw]``, link 2 in {1}) or ``screw`` (6,),
    exactly one; ``cartesian_stiffness`` K_c* (6, 6; rows ``[f; m]``, columns
    ``[dx dy dz rx ry rz]``) or ``None`` (tensions nearest the middle of their limits);
    ``stiffness_weight`` (6, 6) entry weights >= 0 of the stiffness objective, or (6,) ``w`` for
    ``w_a w_b`` (default all 1; ``np.eye(6)`` shapes the diagonal only)."""

    pose: Any = None
    screw: Any = None
    cartesian_stiffness: Any = None
    stiffness_weight: Any = None
    transform: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if (self.pose is None) == (self.screw is None):
            raise ValueError('pose: give exactly one of pose and screw')
        if self.pose is not None:
            T = rigid_transform(self.pose, 'pose', POSE_ROTATION_TOLERANCE)
        else:
            T = exp_se3(single_screw(self.screw))
        object.__setattr__(self, 'transform', T)
        if self.cartesian_stiffness is not None:
            object.__setattr__(self, 'cartesian_stiffness', finite_array_of_shape(
                'cartesian_stiffness', self.cartesian_stiffness, (6, 6)).copy())
        if self.stiffness_weight is not None:
            w = finite_array('stiffness_weight', self.stiffness_weight)
            if np.any(w < 0.0):
                raise ValueError('stiffness_weight must be >= 0')
            if w.shape == (6,):
                w = w[:, None] * w[None, :]
            if w.shape != (6, 6) or np.any(w < 0.0) or not np.any(w > 0.0):
                raise ValueError('stiffness_weight must be (6,) or (6, 6), >= 0, not all 0')
            object.__setattr__(self, 'stiffness_weight', w)


@dataclass(frozen=True)
class ControlCommand:
    """One tick's output. ``rest_lengths`` (n,) motor commands (m); ``feasible``: the pose can
    be held under the load within the limits; ``stiffness_error`` = |S (K_c - K*) S|_F /
    |S K* S|_F of the predicted K_c (0 without a target; NaN when infeasible);
    ``predicted_cartesian_stiffness`` (6, 6) and ``tensions`` (n,) the model's prediction of the
    feedforward design (reached once the rate limit has caught up); ``saturated`` (n,) bool,
    strings held by a rate or range limit this tick; ``message`` why a target is not met;
    ``design_pose`` (4, 4) the pose designed for (target shifted by the integral correction);
    ``pose_error`` (6,) measured error ``[dx dy dz rx ry rz]`` (m, rad; zeros without a
    measurement); ``iterations`` of the QP; ``warm`` True when the last tick's face was optimal;
    ``out_of_time`` True when the QP ran past the tick's deadline (held, not feasible)."""

    rest_lengths: FloatArray
    feasible: bool
    stiffness_error: float
    predicted_cartesian_stiffness: FloatArray
    tensions: FloatArray
    saturated: BoolArray
    message: str
    design_pose: FloatArray
    pose_error: FloatArray
    iterations: int = 0
    warm: bool = False
    out_of_time: bool = False


# ---------------------------------------------------------------------------------- the pose
@dataclass(frozen=True)
class PoseTerms:
    """What stays fixed at a screw (design module's notation): ``lengths`` (n,) m, ``B`` (6, n)
    string wrenches per unit tension, ``K0`` (6, 6) and ``M`` (n, 6, 6) with
    ``K_c(t) = K0 + sum_j t_j M_j`` (eqs. 10-11), and ``cap`` (n,) N the physical upper
    tension caps (positive rest length, maximum stretch) shrunk by ``BOUND_MARGIN``."""

    lengths: FloatArray
    B: FloatArray
    K0: FloatArray
    M: FloatArray
    cap: FloatArray


def pose_terms(model: JointModel, screw: ArrayLike) -> PoseTerms:
    """:class:`PoseTerms` of ``model`` at ``screw`` (6,) (the geometry of eqs. 7-11)."""
    return pose_terms_at(model, exp_se3(single_screw(screw)))


def pose_terms_at(model: JointModel, T: FloatArray) -> PoseTerms:
    """:class:`PoseTerms` at the pose ``T`` (4, 4) of link 2 in {1} (no log map needed): in the
    compiled kernel (``tsk_joint_pose_terms``) when the model has it, else in numpy
    (:func:`pose_terms_numpy`, the reference)."""
    kn = model.compiled_kernel
    if kn is None:
        return pose_terms_numpy(model, T)
    buf = np.empty(kn.pose_terms_size)
    buf[:16] = T.reshape(16)
    status = kn.pose_terms(kn.model, kernel.address(buf), kn.pose_terms_size)
    if status != kernel.OK:
        if status != kernel.ERROR_ZERO_LENGTH:
            kernel.check(status, 'tsk_joint_pose_terms')
        raise ValueError('screw: a string has zero length at this screw')
    n = kn.n
    lengths = buf[kn.pose_lengths:kn.pose_B]
    return PoseTerms(lengths, buf[kn.pose_B:kn.pose_K0].reshape(6, n),
                     buf[kn.pose_K0:kn.pose_M].reshape(6, 6),
                     buf[kn.pose_M:kn.pose_terms_size].reshape(n, 6, 6),
                     _tension_caps(model, lengths))


def pose_terms_numpy(model: JointModel, T: FloatArray) -> PoseTerms:
    """:func:`pose_terms_at` in numpy: the reference of the compiled kernel and its fallback."""
    p1 = model.link1_nodes[model.connections[:, 0]]
    q = model.link2_nodes[model.connections[:, 1]] @ T[:3, :3].T + T[:3, 3]
    s = p1 - q
    lengths = np.sqrt(np.einsum('ij,ij->i', s, s))
    if lengths.min() < MIN_STRING_LENGTH:
        raise ValueError('screw: a string has zero length at this screw')
    u = s / lengths[:, None]
    X = np.empty((lengths.size, 6))
    X[:, :3] = u
    X[:, 3] = p1[:, 1] * u[:, 2] - p1[:, 2] * u[:, 1]
    X[:, 4] = p1[:, 2] * u[:, 0] - p1[:, 0] * u[:, 2]
    X[:, 5] = p1[:, 0] * u[:, 1] - p1[:, 1] * u[:, 0]
    hp, hq = hat3(p1), hat3(q)
    n = lengths.size
    ZE = np.empty((n, 6, 6))
    ZE[:, :3, :3] = np.eye(3)
    ZE[:, :3, 3:] = -hq
    ZE[:, 3:, :3] = hp
    ZE[:, 3:, 3:] = -hp @ hq
    k = model.k
    if model.force_law == 'hooke':
        a, b = k, np.zeros(n)
    else:
        a, b = k / lengths, -1.0 / lengths
    XX = X[:, :, None] * X[:, None, :]
    K0 = np.einsum('j,jab->ab', a, XX)
    M = (b - 1.0 / lengths)[:, None, None] * XX + ZE / lengths[:, None, None]
    return PoseTerms(lengths, X.T.copy(), K0, M, _tension_caps(model, lengths))


def _tension_caps(model: JointModel, lengths: FloatArray) -> FloatArray:
    """:attr:`PoseTerms.cap`: the tensions of a zero rest length and of the maximum stretch
    (eq. 8), the smaller, shrunk by ``BOUND_MARGIN``."""
    k, m = model.k, model.max_stretch
    if model.force_law == 'hooke':
        positive, below_max = k * lengths, k * m
    else:
        positive, below_max = k, k * m / lengths
    return (1.0 - BOUND_MARGIN) * np.minimum(positive, below_max)


def tension_bounds(model: JointModel, lengths: FloatArray, rest_min: FloatArray,
                   rest_max: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The (true) rest-length range ``[rest_min, rest_max]`` as tension bounds at ``lengths``
    (eq. 8): Hooke ``[k (l - l0_max), k (l - l0_min)]``, paper ``[k (l - l0_max) / l,
    k (l - l0_min) / l]``."""
    k = model.k
    lo, hi = k * (lengths - rest_max), k * (lengths - rest_min)
    if model.force_law != 'hooke':
        lo, hi = lo / lengths, hi / lengths
    return lo, hi


# ---------------------------------------------------------------------------------- the QP
@dataclass
class QPResult:
    """``t`` (n,), the working set ``at_lo`` / ``at_hi`` (n,), ``iterations``, ``converged``,
    ``warm`` (the start face was optimal: one KKT solve); ``reason`` why it stopped short of the
    optimum (an iteration limit hit, SLSQP's message; with ``converged`` a feasible point SLSQP
    left short of it; :data:`OUT_OF_TIME` at the deadline, with ``out_of_time``), empty
    otherwise."""

    t: FloatArray
    at_lo: BoolArray
    at_hi: BoolArray
    iterations: int
    converged: bool
    warm: bool
    reason: str = ''
    out_of_time: bool = False


#: A face's KKT solution counts as accurate when its residual is at most this times
#: ``1 + |rhs|`` (else the least squares of the face decides).
FACE_RESIDUAL_TOLERANCE = 1e-10
#: The start face's optimum may leave the box by this times ``max(1, hi - lo)`` (then clipped).
FACE_BOUND_SLACK = 1e-12


def _face(P: FloatArray, c: FloatArray, A: FloatArray, b: FloatArray, t: FloatArray,
          free: BoolArray) -> tuple[FloatArray, FloatArray]:
    """Minimiser of ``1/2 t'Pt - c't`` on the face (fixed variables at ``t``) with ``A t = b``:
    the free values and the equality multipliers (least squares when the KKT is singular)."""
    nf = int(np.count_nonzero(free))
    K, rhs = kkt_system(P, c, A, b, t, free)
    try:
        sol = np.linalg.solve(K, rhs)
        # NaN fails the comparison too; a near-singular face gives a large residual
        if not float(np.abs(K @ sol - rhs).max()) <= FACE_RESIDUAL_TOLERANCE * (
                1.0 + float(np.abs(rhs).max())):
            raise np.linalg.LinAlgError
    except np.linalg.LinAlgError:
        sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
    return sol[:nf], sol[nf:]


def _multipliers(P: FloatArray, c: FloatArray, A: FloatArray, t: FloatArray, nu: FloatArray,
                 at_lo: BoolArray, at_hi: BoolArray) -> FloatArray:
    """The bound multipliers of the working set (>= 0 at the optimum), 0 elsewhere."""
    grad = P @ t - c + A.T @ nu
    return np.where(at_lo, grad, np.where(at_hi, -grad, 0.0))


def warm_face(P: FloatArray, c: FloatArray, A: FloatArray, b: FloatArray, lo: FloatArray,
              hi: FloatArray, t_start: FloatArray, at_lo: BoolArray, at_hi: BoolArray,
              use_kernel: bool = True) -> FloatArray | None:
    """Step 1 of :func:`solve_box_qp`: the optimum on the face of the working set ``at_lo`` /
    ``at_hi`` (disjoint; the other tensions from ``t_start``), clipped to the box, when it is
    the QP's optimum (inside the box to :data:`FACE_BOUND_SLACK`, ``A t = b`` to
    ``FEASIBILITY_TOLERANCE``, every bound multiplier >= ``-ACTIVE_SET_TOLERANCE * max(1, |P|,
    |c|)``), else ``None``. In the compiled kernel (``tsk_qp_warm_face``) when it is loaded and
    ``use_kernel``; a singular face, and the numpy path, are :func:`warm_face_numpy`."""
    library = kernel.library() if use_kernel else None
    if library is None:
        return warm_face_numpy(P, c, A, b, lo, hi, t_start, at_lo, at_hi)
    n, m = lo.size, b.size
    # One buffer (inputs copied into it, outputs after them): C reads no other memory.
    out = n * n + m * n + 6 * n + m
    buf = np.concatenate([P.reshape(-1), c, A.reshape(-1), b, lo, hi, t_start, at_lo, at_hi,
                          np.empty(n + m + 1)])
    size = buf.size
    kernel.check(library.qp_warm_face(n, m, FEASIBILITY_TOLERANCE, ACTIVE_SET_TOLERANCE,
                                      FACE_RESIDUAL_TOLERANCE, FACE_BOUND_SLACK,
                                      kernel.address(buf), size), 'tsk_qp_warm_face')
    outcome = buf[size - 1]
    if outcome == kernel.FACE_OPTIMAL:
        return buf[out:out + n]
    if outcome == kernel.FACE_REJECTED:
        return None
    return warm_face_numpy(P, c, A, b, lo, hi, t_start, at_lo, at_hi)


def warm_face_numpy(P: FloatArray, c: FloatArray, A: FloatArray, b: FloatArray,
                    lo: FloatArray, hi: FloatArray, t_start: FloatArray, at_lo: BoolArray,
                    at_hi: BoolArray) -> FloatArray | None:
    """:func:`warm_face` in numpy (its reference; least squares on a singular face)."""
    t = np.where(at_lo, lo, np.where(at_hi, hi, t_start))
    free = ~(at_lo | at_hi)
    if not free.any():
        return None
    tf, nu = _face(P, c, A, b, t, free)
    trial = t.copy()
    trial[free] = tf
    span = FACE_BOUND_SLACK * np.maximum(1.0, np.abs(hi - lo))
    if not (np.all(trial >= lo - span) and np.all(trial <= hi + span)
            and np.linalg.norm(A @ trial - b) <= FEASIBILITY_TOLERANCE):
        return None
    mu = _multipliers(P, c, A, trial, nu, at_lo, at_hi)
    scale = max(1.0, float(np.abs(P).max()), float(np.abs(c).max()))
    if mu.min() >= -ACTIVE_SET_TOLERANCE * scale:
        return np.clip(trial, lo, hi)
    return None


def solve_box_qp(P: FloatArray, c: FloatArray, A: FloatArray, b: FloatArray, lo: FloatArray,
                 hi: FloatArray, t_start: FloatArray, at_lo: BoolArray | None = None,
                 at_hi: BoolArray | None = None, use_kernel: bool = True,
                 max_iterations: int = MAX_ACTIVE_SET_ITERATIONS, deadline: float = math.inf,
                 min_iterations: int = MIN_QP_ITERATIONS) -> QPResult:
    """``min 1/2 t'Pt - c't`` s.t. ``A t = b``, ``lo <= t <= hi`` (P positive semidefinite) by a
    primal active-set method, warm-started from ``t_start`` and the working set ``at_lo`` /
    ``at_hi`` of the last solve. First the start face alone (optimal in steady state:
    :func:`warm_face`); then a
    feasible start: ``t_start`` projected onto ``A t = b`` over its free strings, or if that
    leaves the box, the box least squares ``min |A t - b|`` from it; then the active set.
    ``converged`` is False when no feasible point exists (residual above
    :data:`FEASIBILITY_TOLERANCE`) or the iteration limit is hit (``reason`` says which).
    ``use_kernel``: the first step in the compiled kernel when it is loaded (the controllers
    pass their model's ``uses_kernel``). ``max_iterations`` bounds each active-set phase (the
    warm one at :data:`WARM_ACTIVE_SET_ITERATIONS`) and the SLSQP last resort (at
    :data:`SLSQP_MAX_ITERATIONS`): no input makes a tick unbounded. ``deadline``
    (``time.perf_counter()`` s) bounds it in time after its first ``min_iterations``
    iterations: past it the solve stops unconverged with ``out_of_time`` and the reason
    :data:`OUT_OF_TIME`."""
    n = lo.size
    wl = np.zeros(n, bool) if at_lo is None else at_lo.copy()
    wh = np.zeros(n, bool) if at_hi is None else (at_hi & ~wl)
    # 1. The last face.
    optimum = warm_face(P, c, A, b, lo, hi, t_start, wl, wh, use_kernel)
    if optimum is not None:
        return QPResult(optimum, wl, wh, 1, True, True)
    spent = 0

    def phase(P_: FloatArray, c_: FloatArray, A_: FloatArray, b_: FloatArray, t0: FloatArray,
              limit: int) -> QPResult:
        """One active-set phase under the deadline (the iterations before it count)."""
        nonlocal spent
        sol = _active_set(P_, c_, A_, b_, lo, hi, t0, limit, deadline,
                          max(0, min_iterations - spent))
        spent += sol.iterations
        sol.iterations = spent
        if sol.out_of_time:
            sol.reason = _out_of_time(spent)
        return sol

    # 2. A feasible start.
    t = np.clip(t_start, lo, hi)
    r = b - A @ t
    if np.linalg.norm(r) > FEASIBILITY_TOLERANCE:
        inside = (t > lo) & (t < hi)
        Af = A[:, inside]
        trial = t.copy()
        if inside.any():
            trial[inside] += np.linalg.lstsq(Af, r, rcond=None)[0]
        if (np.all(trial >= lo) and np.all(trial <= hi)
                and np.linalg.norm(A @ trial - b) <= FEASIBILITY_TOLERANCE):
            t = trial
        else:
            phase1 = phase(A.T @ A, A.T @ b, np.zeros((0, n)), np.zeros(0), t,
                           max_iterations)
            t = phase1.t
            if phase1.out_of_time or np.linalg.norm(A @ t - b) > FEASIBILITY_TOLERANCE:
                return replace(phase1, converged=False)
    # 3. The active set; a warm start that stalls (cycling on a degenerate face) is redone cold
    # from the box least squares started at the middle, as the design does.
    sol = phase(P, c, A, b, t, min(WARM_ACTIVE_SET_ITERATIONS, max_iterations))
    if sol.converged or sol.out_of_time:
        return sol
    middle = 0.5 * (lo + hi)
    phase1 = phase(A.T @ A, A.T @ b, np.zeros((0, n)), np.zeros(0), middle, max_iterations)
    if phase1.out_of_time or np.linalg.norm(A @ phase1.t - b) > FEASIBILITY_TOLERANCE:
        return replace(phase1, converged=False)
    cold = phase(P, c, A, b, phase1.t, max_iterations)
    if cold.converged or cold.out_of_time:
        return cold
    last = _slsqp(P, c, A, b, lo, hi, phase1.t, cold.iterations,
                  min(SLSQP_MAX_ITERATIONS, max_iterations), deadline)
    if last.reason and not last.out_of_time:
        last.reason = f'{cold.reason}, then {last.reason}'
    return last


def _out_of_time(iterations: int) -> str:
    """The reason of a QP stopped at its deadline after ``iterations``."""
    return f'{OUT_OF_TIME}: the QP passed its deadline after {iterations} iterations'


class _DeadlineError(Exception):
    """Raised inside SLSQP's objective to stop it at the deadline."""


def _slsqp(P: FloatArray, c: FloatArray, A: FloatArray, b: FloatArray, lo: FloatArray,
           hi: FloatArray, t0: FloatArray, iterations: int,
           max_iterations: int = SLSQP_MAX_ITERATIONS, deadline: float = math.inf
           ) -> QPResult:
    """Last resort for a degenerate face on which the active set cycles (seen on the spine's
    60-string QP with more active bounds than free dofs): scipy's SLSQP from a feasible point
    (at most ``max_iterations``, stopped unconverged at ``deadline``), then the equality
    restored exactly on the strings off their bounds."""
    from scipy.optimize import minimize

    def objective(t: FloatArray) -> float:
        if time.perf_counter() > deadline:
            raise _DeadlineError
        return 0.5 * t @ P @ t - c @ t

    try:
        res = minimize(objective, t0, jac=lambda t: P @ t - c,
                       bounds=list(zip(lo, hi, strict=True)), method='SLSQP',
                       constraints=[{'type': 'eq', 'fun': lambda t: A @ t - b,
                                     'jac': lambda t: A}],
                       options={'ftol': 1e-14, 'maxiter': max_iterations})
    except _DeadlineError:
        n = lo.size
        return QPResult(t0.copy(), np.zeros(n, bool), np.zeros(n, bool), iterations, False,
                        False, _out_of_time(iterations), True)
    t = np.clip(res.x, lo, hi)
    span = 1e-9 * np.maximum(1.0, hi - lo)
    at_lo, at_hi = t - lo <= span, hi - t <= span
    free = ~(at_lo | at_hi)
    if free.any():
        t[free] += np.linalg.lstsq(A[:, free], b - A @ t, rcond=None)[0]
    ok = bool(np.all(t >= lo - span) and np.all(t <= hi + span)
              and np.linalg.norm(A @ t - b) <= FEASIBILITY_TOLERANCE)
    # A feasible point is kept even when SLSQP stopped short (the equilibrium holds; only the
    # stiffness may be off the optimum): its reason says so.
    reason = '' if res.success else (f'SLSQP stopped after {int(res.nit)} of at most '
                                     f'{max_iterations} iterations: {res.message}')
    return QPResult(np.clip(t, lo, hi), at_lo, at_hi & ~at_lo, iterations + int(res.nit), ok,
                    False, reason)


def _active_set(P: FloatArray, c: FloatArray, A: FloatArray, b: FloatArray, lo: FloatArray,
                hi: FloatArray, t0: FloatArray,
                max_iterations: int = MAX_ACTIVE_SET_ITERATIONS, deadline: float = math.inf,
                min_iterations: int = 0) -> QPResult:
    """Primal active set from a feasible ``t0`` (its bounds form the first working set),
    stopped at ``deadline`` after ``min_iterations`` (:func:`active_set`)."""

    def face(t: FloatArray, free: BoolArray, nu: FloatArray) -> tuple[FloatArray, FloatArray]:
        if free.any():
            return _face(P, c, A, b, t, free)
        return np.zeros(0), (np.linalg.lstsq(A.T, c - P @ t, rcond=None)[0] if A.shape[0]
                             else nu)

    sol = active_set(P, c, A, lo, hi, t0, face, max_iterations, deadline, min_iterations)
    reason = '' if sol.converged or sol.out_of_time else (
        f'the active-set method stopped at its limit of {max_iterations} iterations')
    return QPResult(sol.t, sol.at_lo, sol.at_hi, sol.iterations, sol.converged, False, reason,
                    sol.out_of_time)


def _objective(pose: PoseTerms, target: ControlTarget, S: FloatArray, middle: FloatArray
               ) -> tuple[FloatArray, FloatArray]:
    """``P = G'G``, ``c = G'g`` of the stiffness objective, or without a target of
    ``|t - middle|^2`` (the middle of the tension limits and caps, as the design)."""
    n = middle.size
    if target.cartesian_stiffness is None:
        return np.eye(n), middle.copy()
    SS = S[:, None] * S[None, :]
    if target.stiffness_weight is not None:
        SS = SS * target.stiffness_weight
    G = (pose.M * SS).reshape(n, 36).T
    g = ((target.cartesian_stiffness - pose.K0) * SS).ravel()
    return G.T @ G, G.T @ g


def _rate_limited(previous: FloatArray, wanted: FloatArray, step: FloatArray,
                  rest_min: FloatArray, rest_max: FloatArray) -> FloatArray:
    """``wanted`` moved to within ``previous +- step`` and the range (toward the range when
    ``previous`` is outside it, still at most ``step``)."""
    low = np.maximum(rest_min, previous - step)
    high = np.minimum(rest_max, previous + step)
    low = np.minimum(low, previous + step)   # previous below the range: climb at the rate
    high = np.maximum(high, previous - step)  # previous above the range: descend at the rate
    return np.clip(wanted, low, high)


def _pose_error(target: FloatArray, measured: FloatArray) -> tuple[FloatArray, FloatArray]:
    """``e = log(T* T_m^-1)`` (screw order [omega; v]) and the ROS-order error
    ``[p* - p_m; rotation vector of R* R_m^T]``."""
    E = target @ inverse_transform(measured)
    e = log_se3(E)
    ros = np.concatenate([target[:3, 3] - measured[:3, 3], e[:3]])
    return e, ros


def _clamp_integral(z: FloatArray, limit: tuple[float, float]) -> FloatArray:
    out = z.copy()
    for part, lim in ((slice(0, 3), limit[0]), (slice(3, 6), limit[1])):
        norm = float(np.linalg.norm(out[part]))
        if norm > lim:
            out[part] *= lim / norm
    return out


def _at_clamp(z: FloatArray, limit: tuple[float, float]) -> bool:
    """True when a part of the integral ``z`` (rotation, translation) is at its clamp."""
    return any(lim > 0.0 and float(np.linalg.norm(z[part])) >= lim * (1.0 - 1e-9)
               for part, lim in ((slice(0, 3), limit[0]), (slice(3, 6), limit[1])))


def _target_moved(previous: FloatArray | None, target: FloatArray,
                  limit: tuple[float, float]) -> bool:
    """True when ``target`` (4, 4) is farther from ``previous`` than the integral clamp
    ``limit`` (rad, m): rotation angle of ``R_prev^T R`` or the translation's change."""
    if previous is None:
        return False
    cosine = 0.5 * (float(np.trace(previous[:3, :3].T @ target[:3, :3])) - 1.0)
    angle = math.acos(min(1.0, max(-1.0, cosine)))
    return angle > limit[0] or float(np.linalg.norm(target[:3, 3] - previous[:3, 3])) > limit[1]


def _beyond_clamp(e: FloatArray, limit: tuple[float, float]) -> bool:
    """True when a part of the pose error ``e`` (rotation, translation) is larger than that
    part's clamp (a part whose clamp is 0 is not integrated anyway and does not count)."""
    return any(lim > 0.0 and float(np.linalg.norm(e[part])) > lim
               for part, lim in ((slice(0, 3), limit[0]), (slice(3, 6), limit[1])))


def _rest_anchor(anchor: FloatArray | None, previous: FloatArray | None, target: FloatArray,
                 limit: tuple[float, float]) -> FloatArray | None:
    """The integral's rest anchor after a tick at ``target``: ``anchor`` unless the target
    moved by more than the clamp from it or from the ``previous`` tick's target."""
    if anchor is None or _target_moved(anchor, target, limit) or _target_moved(
            previous, target, limit):
        return None
    return anchor


def _exp(kn: kernel.JointKernel | None, xi: FloatArray) -> FloatArray:
    """``exp_se3`` of one finite screw, in the compiled kernel when there is one."""
    return exp_se3(xi) if kn is None else kn.exp_se3(xi)


def _measured(pose: ArrayLike | None, screw: ArrayLike | None,
              kn: kernel.JointKernel | None = None) -> FloatArray | None:
    if pose is not None and screw is not None:
        raise ValueError('pose: give at most one of pose and screw')
    if pose is not None:
        return rigid_transform(pose, 'pose', POSE_ROTATION_TOLERANCE)
    if screw is not None:
        return _exp(kn, single_screw(screw))
    return None


def _check_budget(time_budget: float | None) -> float | None:
    """A tick's time budget: None (none) or finite and >= 0 s; ValueError otherwise."""
    if time_budget is None:
        return None
    budget = finite_scalar('time_budget', time_budget)
    if budget < 0.0:
        raise ValueError(f'time_budget must be >= 0 s, got {budget}')
    return budget


def _deadline(time_budget: float | None) -> float:
    """The deadline (``time.perf_counter()`` s) of a tick starting now (inf: none)."""
    return math.inf if time_budget is None else time.perf_counter() + time_budget


def _check_dt(dt: float) -> float:
    value = finite_scalar('dt', dt)
    if value <= 0.0:
        raise ValueError(f'dt must be > 0 (s), got {value:g}')
    return value


def _gains(integral_gain: float, proportional_gain: float,
           integral_limit: Sequence[float]) -> tuple[float, float, tuple[float, float]]:
    ki = finite_scalar('integral_gain', integral_gain)
    kp = finite_scalar('proportional_gain', proportional_gain)
    if ki < 0.0:
        raise ValueError(f'integral_gain must be >= 0 (1/s), got {ki:g}')
    if not 0.0 <= kp < 1.0:
        raise ValueError(f'proportional_gain must be in [0, 1), got {kp:g}')
    lim = finite_array('integral_limit', integral_limit)
    if lim.shape != (2,) or np.any(lim < 0.0):
        raise ValueError('integral_limit must be (rotation rad, translation m), both >= 0')
    return ki, kp, (float(lim[0]), float(lim[1]))


@dataclass(frozen=True)
class _JointProblem:
    terms: PoseTerms
    lo: FloatArray
    hi: FloatArray
    middle: FloatArray
    A: FloatArray
    b: FloatArray
    start: FloatArray
    #: (k, 6) the twists the strings do not hold at this pose (scaled, unit; k = 0: none).
    unheld: FloatArray


def unheld_count(A: FloatArray) -> int:
    """How many directions of the scaled string wrenches ``A = S B`` (6, n) the strings do not
    hold: singular values below ``UNHELD_DIRECTION_TOLERANCE`` of the largest."""
    s = np.linalg.svd(A, compute_uv=False)
    return int(np.count_nonzero(s < UNHELD_DIRECTION_TOLERANCE * s[0])) + max(0, 6 - s.size)


def held_equilibrium(A: FloatArray, b: FloatArray, k: int
                     ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The equilibrium ``A t = b`` (scaled, 6 rows) on the ``6 - k`` directions of the
    strongest string wrenches (the left singular vectors ``U_h`` of ``A``: ``U_h' A t = U_h'
    b``), and the ``k`` twists left out, in scaled coordinates ``[L omega; v]`` (unit, screw
    order): the pairing duals of the ``k`` weakest wrench directions ``u = [u_f; u_m]``, i.e.
    ``[u_m; u_f]``, along which no string wrench of the pose does work."""
    U = np.linalg.svd(A)[0]
    held, weak = U[:, :6 - k], U[:, 6 - k:]
    twists = np.concatenate([weak[3:], weak[:3]]).T
    largest = np.abs(twists).argmax(axis=1)
    twists *= np.sign(twists[np.arange(k), largest])[:, None]  # a sign that does not flicker
    return held.T @ A, held.T @ b, twists


def unheld_twist_text(twist: FloatArray) -> str:
    """A scaled unit twist ``[L omega; v]`` in words: 'rotation about (x, y, z)' when its
    rotation dominates, else 'translation along (x, y, z)' or the six values."""
    rotation, translation = math.hypot(*twist[:3]), math.hypot(*twist[3:])
    if rotation >= 0.9:
        x, y, z = (round(float(v) / rotation, 2) + 0.0 for v in twist[:3])
        return f'rotation about ({x:.2f}, {y:.2f}, {z:.2f})'
    if translation >= 0.9:
        x, y, z = (round(float(v) / translation, 2) + 0.0 for v in twist[3:])
        return f'translation along ({x:.2f}, {y:.2f}, {z:.2f})'
    return 'twist [L omega; v] ' + np.array2string(twist, precision=2)


def _failure(A: FloatArray, b: FloatArray, sol: QPResult) -> str:
    """Why a tick's QP failed: an iteration limit it hit (its reason), else no feasible
    point (the closest residual)."""
    residual = float(np.linalg.norm(A @ sol.t - b))
    if sol.reason:
        return f'infeasible: {sol.reason} (closest residual so far {residual:.3g} N)'
    if residual > FEASIBILITY_TOLERANCE:
        return ('infeasible: the pose cannot be held under this load within the limits '
                f'(closest residual {residual:.3g} N)')
    return 'infeasible: the active-set method did not converge'


# ---------------------------------------------------------------------------------- joint
class _PoseFeedback:
    """The integral pose feedback the joint's and the spine's controllers share: each sets
    ``integral_gain``, ``integral_limit`` and the integral ``_z`` (6,)."""

    integral_gain: float
    integral_limit: tuple[float, float]
    _z: FloatArray
    #: The target pose of the last committed tick (the integral restarts when it moves far).
    _target_transform: FloatArray | None = None
    #: The target pose at which the integral came to rest (rule 3 of the module docstring:
    #: it sat at its clamp with no limit binding), or None while it integrates.
    _rest_anchor: FloatArray | None = None
    #: How long (s) the committed integral has been at its clamp with no limit binding.
    _clamped_time: float = 0.0
    #: The compiled kernel of the exp maps of the feedback (a joint model's), or None.
    _exp_kernel: kernel.JointKernel | None = None

    def _feedback(self, dt: float, target: ControlTarget, pose: ArrayLike | None,
                  screw: ArrayLike | None, wrench_name: str, wrench: ArrayLike | None
                  ) -> tuple[float, FloatArray, FloatArray, FloatArray, FloatArray]:
        """The checked ``dt`` and wrench (6,) (default 0) of one tick, the pose error ``e`` of
        the measured ``pose`` or ``screw`` (zero when none is given) as the integrator reads it
        and as reported, and the clamped integral after this tick (not yet committed). Bad
        input raises ValueError naming it."""
        dt = _check_dt(dt)
        if not isinstance(target, ControlTarget):
            raise ValueError('target must be a ControlTarget')
        measured = _measured(pose, screw, self._exp_kernel)
        W = np.zeros(6) if wrench is None else finite_array_of_shape(wrench_name, wrench, (6,))
        if measured is not None:
            e, error = _pose_error(target.transform, measured)
            if not (np.all(np.isfinite(e)) and np.all(np.isfinite(error))):
                raise ValueError('pose: the error to the target is not finite (a pose turned '
                                 'by about 180 deg from the target): the tick is skipped')
        else:
            e, error = np.zeros(6), np.zeros(6)
        e = self._held_error(e)
        limit = self.integral_limit
        z0 = self._z
        if _target_moved(self._target_transform, target.transform, limit):
            z0 = np.zeros(6)  # rule 1: a new target far from the last restarts the integral
        resting = _rest_anchor(self._rest_anchor, self._target_transform, target.transform,
                               limit) is not None
        if resting or _beyond_clamp(e, limit):  # rules 3 and 2: leak, integrate nothing
            z = z0 * math.exp(-self.integral_gain * dt)
        else:
            step = _clamp_integral(self.integral_gain * dt * e, limit)
            z = _clamp_integral(z0 + step, limit)
        return dt, W, e, error, z

    def _commit_integral(self, dt: float, target: FloatArray, z: FloatArray,
                         limit_binds: bool) -> None:
        """Commit the integral ``z`` of a tick held at ``target`` (4, 4): frozen while a limit
        binds (anti-windup; a far move of the target still restarts it), and the rest of rule 3
        (module docstring) kept up to date."""
        limit = self.integral_limit
        anchor = _rest_anchor(self._rest_anchor, self._target_transform, target, limit)
        if not limit_binds:
            self._z = z
        elif _target_moved(self._target_transform, target, limit):
            self._z = np.zeros(6)
        if limit_binds or anchor is not None or not _at_clamp(self._z, limit):
            self._clamped_time = 0.0
        else:
            self._clamped_time += dt
            if self._clamped_time * self.integral_gain > 1.0:
                anchor, self._clamped_time = target, 0.0
        self._rest_anchor = anchor
        self._target_transform = target

    def _integral_note(self) -> str:
        """What the tick's message says about the committed integral ('' when nothing)."""
        if self._rest_anchor is not None:
            return ('integral correction at rest: it sat at its clamp with no limit binding '
                    '(the pose error did not answer it) and decays to 0; it restarts when the '
                    'target moves by more than the clamp')
        if _at_clamp(self._z, self.integral_limit):
            return ('integral correction at its clamp with no limit binding (it comes to rest '
                    'after 1 / integral_gain if the pose error does not answer it)')
        return ''

    def _held_error(self, e: FloatArray) -> FloatArray:
        """The pose error ``e`` (6,) on the directions the strings hold (all by default)."""
        return e


class StiffnessController(_PoseFeedback):
    """Closed-loop rest-length commands for one joint (module docstring).

    ``model``: the controller's (nominal) :class:`JointModel`; ``limits``:
    :class:`ActuatorLimits`; ``rest_lengths`` (n,) the motors' present positions (m). Gains:
    ``integral_gain`` k_i (1/s), ``proportional_gain`` k_p (share of the error added to the
    shift, in [0, 1)), ``integral_limit`` (rad, m) clamp of the correction;
    ``rest_length_offsets`` d (n,) m (true rest length = command + d); ``length_scale`` L (m) of
    S (default as the design: the largest distance of a link-1 node from the origin);
    ``time_budget`` (s, None: none) the wall-clock budget of a tick, from the call of
    :meth:`update`: a QP past it (after its first :data:`MIN_QP_ITERATIONS`) holds the tick
    (:data:`OUT_OF_TIME`)."""

    def __init__(self, model: JointModel, limits: ActuatorLimits, rest_lengths: ArrayLike, *,
                 integral_gain: float = DEFAULT_INTEGRAL_GAIN,
                 proportional_gain: float = DEFAULT_PROPORTIONAL_GAIN,
                 integral_limit: Sequence[float] = DEFAULT_INTEGRAL_LIMIT,
                 rest_length_offsets: ArrayLike | None = None,
                 length_scale: float | None = None, time_budget: float | None = None) -> None:
        if not isinstance(model, JointModel):
            raise ValueError('model must be a JointModel')
        if not isinstance(limits, ActuatorLimits):
            raise ValueError('limits must be an ActuatorLimits')
        self.model = model
        self.limits = limits
        self._exp_kernel = model.compiled_kernel
        n = model.n_strings
        (self._rest_min, self._rest_max, self._rate, self._t_min,
         self._t_max) = limits.for_strings(n)
        self.integral_gain, self.proportional_gain, self.integral_limit = _gains(
            integral_gain, proportional_gain, integral_limit)
        self.offsets = np.zeros(n) if rest_length_offsets is None else finite_array_of_shape(
            'rest_length_offsets', rest_length_offsets, (n,)).copy()
        if length_scale is None:
            self.length_scale = float(np.linalg.norm(model.link1_nodes, axis=1).max())
        else:
            self.length_scale = finite_scalar('length_scale', length_scale)
            if self.length_scale <= 0.0:
                raise ValueError('length_scale must be > 0')
        self._S = length_scaling(self.length_scale)
        self.time_budget = _check_budget(time_budget)
        reference = self._S[:, None] * pose_terms(model, model.initial_screw).B
        #: How many directions the strings do not hold at the unloaded pose (a ring: 1, its
        #: spin); those are left out of the equilibrium and of the pose feedback every tick.
        self.unheld_count = unheld_count(reference)
        self._unheld = held_equilibrium(reference, np.zeros(6), self.unheld_count)[2]
        self.reset(rest_lengths)

    @property
    def rest_lengths(self) -> FloatArray:
        """The last command (n,), motor positions (m)."""
        return self._command.copy()

    @property
    def integral(self) -> FloatArray:
        """The integral pose correction z (6,), screw order [omega; v]."""
        return self._z.copy()

    @property
    def unheld_twists(self) -> FloatArray:
        """(k, 6) unit twists in scaled coordinates ``[L omega; v]`` that the strings do not
        hold at the last design pose (at the unloaded pose before the first tick); k =
        :attr:`unheld_count`. The pose settles along them where the strings balance: they are
        not controlled, and the pose feedback leaves them out."""
        return self._unheld.copy()

    def _held_error(self, e: FloatArray) -> FloatArray:
        if not self.unheld_count:
            return e
        scale = np.concatenate([np.full(3, self.length_scale), np.ones(3)])
        scaled = e * scale
        return (scaled - self._unheld.T @ (self._unheld @ scaled)) / scale

    def reset(self, rest_lengths: ArrayLike) -> None:
        """Forget the integral and the warm start; ``rest_lengths`` (n,) the motors' positions."""
        n = self.model.n_strings
        rest = finite_array_of_shape('rest_lengths', rest_lengths, (n,))
        bad = np.flatnonzero(rest + self.offsets <= 0.0)
        if bad.size:
            j = int(bad[0])
            raise ValueError(f'rest_lengths: the true rest length (command + offset) of '
                             f'{self.model.string_names[j]} would be '
                             f'{rest[j] + self.offsets[j]:.4g} m (command {rest[j]:.4g} m, '
                             f'offset {self.offsets[j]:.4g} m); it must be > 0')
        self._command = rest.copy()
        self._z = np.zeros(6)
        self._t = None
        self._target_transform = None
        self._rest_anchor = None
        self._clamped_time = 0.0
        self._at_lo = np.zeros(n, bool)
        self._at_hi = np.zeros(n, bool)

    # ------------------------------------------------------------------ tick
    def update(self, dt: float, target: ControlTarget, pose: ArrayLike | None = None,
               screw: ArrayLike | None = None, external_wrench: ArrayLike | None = None
               ) -> ControlCommand:
        """One tick of ``dt`` (s): the commands for ``target`` given the measured ``pose``
        (4x4 or [x y z qx qy qz qw]) or ``screw`` (none: no feedback this tick) and the known
        or estimated ``external_wrench`` (6,) on link 2 in {1} about its origin (default 0).
        Bad input raises ValueError naming it and leaves the state unchanged."""
        deadline = _deadline(self.time_budget)
        dt, W, e, error, z = self._feedback(dt, target, pose, screw, 'external_wrench',
                                            external_wrench)
        T_d = _exp(self._exp_kernel, z + self.proportional_gain * e) @ target.transform
        return self._tick(dt, target, T_d, W, z, error, deadline)

    def _problem(self, T_d: FloatArray, W: FloatArray) -> _JointProblem | str:
        """The QP data at the design pose under the load W, or why there is none."""
        model, S = self.model, self._S
        try:
            terms = pose_terms_at(model, T_d)
        except ValueError as exc:
            return f'infeasible: {exc}'
        rest_lo = self._rest_min + self.offsets
        rest_hi = self._rest_max + self.offsets
        range_lo, range_hi = tension_bounds(model, terms.lengths, rest_lo, rest_hi)
        upper = np.minimum(self._t_max, terms.cap)
        lo = np.maximum(self._t_min, range_lo)
        hi = np.minimum(upper, range_hi)
        if np.any(hi <= lo):
            bad = [model.string_names[j] for j in np.flatnonzero(hi <= lo)]
            return ('infeasible: no tension within the tension and rest-length limits at this '
                    f'pose for {", ".join(bad)}')
        start = 0.5 * (lo + hi) if self._t is None else self._t
        A, b, unheld = S[:, None] * terms.B, -S * W, self._unheld
        if self.unheld_count:
            A, b, unheld = held_equilibrium(A, b, self.unheld_count)
        return _JointProblem(terms, lo, hi, 0.5 * (self._t_min + upper), A, b, start, unheld)

    def _tick(self, dt: float, target: ControlTarget, T_d: FloatArray, W: FloatArray,
              z: FloatArray, error: FloatArray, deadline: float = math.inf) -> ControlCommand:
        pr = self._problem(T_d, W)
        if isinstance(pr, str):
            return self._hold(T_d, error, pr)
        P, c = _objective(pr.terms, target, self._S, pr.middle)
        sol = solve_box_qp(P, c, pr.A, pr.b, pr.lo, pr.hi, pr.start, self._at_lo, self._at_hi,
                           self.model.uses_kernel, deadline=deadline)
        if sol.out_of_time:
            return self._out_of_time(T_d, error, sol.iterations)
        if not sol.converged:
            return self._hold(T_d, error, _failure(pr.A, pr.b, sol))
        self._unheld = pr.unheld
        return self._apply(dt, target, T_d, z, error, pr.terms, sol)

    def _apply(self, dt: float, target: ControlTarget, T_d: FloatArray, z: FloatArray,
               error: FloatArray, terms: PoseTerms, sol: QPResult) -> ControlCommand:
        """Rate and range limits on the designed rest lengths; commit the tick."""
        model = self.model
        t = sol.t
        wanted = rest_from_tensions(model, terms.lengths, t) - self.offsets
        command = _rate_limited(self._command, wanted, self._rate * dt, self._rest_min,
                                self._rest_max)
        saturated = np.abs(command - wanted) > SATURATION_TOLERANCE
        Kc = terms.K0 + np.einsum('j,jab->ab', t, terms.M)
        if target.cartesian_stiffness is None:
            err = 0.0
        else:
            err = relative_stiffness_error(Kc, target.cartesian_stiffness, self.length_scale)
        self._commit_integral(dt, target.transform, z, bool(saturated.any()))
        messages = []
        if target.cartesian_stiffness is not None and err > STIFFNESS_MET_TOLERANCE:
            at = int(np.count_nonzero(sol.at_lo | sol.at_hi))
            messages.append(f'stiffness target not reachable: closest within the limits has '
                            f'relative error {err:.3g} ({at} strings at a tension bound)')
        if saturated.any():
            messages.append(f'{int(saturated.sum())} strings at the rate or range limit')
        elif self._integral_note():
            messages.append(self._integral_note())
        if self.unheld_count:
            free = ', '.join(unheld_twist_text(u) for u in self._unheld)
            messages.append(f'the strings hold {6 - self.unheld_count} of 6 directions: '
                            f'{free} not held (it settles where the strings balance)')
        self._command = command
        self._t, self._at_lo, self._at_hi = t, sol.at_lo, sol.at_hi
        return ControlCommand(command.copy(), True, err, Kc, t.copy(), saturated,
                              '; '.join(messages) or 'ok', T_d, error, sol.iterations,
                              sol.warm)

    def _out_of_time(self, T_d: FloatArray, error: FloatArray, iterations: int
                     ) -> ControlCommand:
        """Hold a tick whose QP ran past its deadline: the command and the integral are kept;
        the warm start is dropped (a face the active set stalls on would stall every tick from
        it again), so the next tick's QP starts from the middle of the box."""
        n = self.model.n_strings
        self._t = None
        self._at_lo, self._at_hi = np.zeros(n, bool), np.zeros(n, bool)
        budget = math.inf if self.time_budget is None else self.time_budget
        held = self._hold(T_d, error, f'{OUT_OF_TIME}: the QP passed the tick\'s deadline of '
                          f'{budget:.3g} s after {iterations} iterations (the next tick starts '
                          'cold)')
        return replace(held, out_of_time=True, iterations=iterations)

    def _hold(self, T_d: FloatArray, error: FloatArray, message: str) -> ControlCommand:
        """Keep the last safe command (infeasible target): the model's prediction of it at the
        design pose, the integral frozen."""
        n = self.model.n_strings
        try:
            xi_d = log_se3(T_d, reference=self.model.initial_screw)
            state = self.model.evaluate(xi_d, self._command + self.offsets)
            Kc, t = state.cartesian_stiffness.copy(), state.tensions.copy()
        except ValueError:
            Kc, t = np.full((6, 6), np.nan), np.full(n, np.nan)
        return ControlCommand(self._command.copy(), False, math.nan, Kc, t, np.zeros(n, bool),
                              message + '; the last command is kept', T_d, error)


# ---------------------------------------------------------------------------------- spine
#: Ad_T for twists ``[dv; dw]``: ``[[R, hat(p) R], [0, R]]`` (the one adjoint,
#: :func:`~tensegrity_stiffness.geometry.transforms.adjoint`, under the controller's name).
adjoint_twist = adjoint


@dataclass(frozen=True)
class ChainControlCommand:
    """One spine tick: ``rest_lengths`` (N, n) motor commands; ``feasible``; ``stiffness_error``
    of the predicted tip K_c (base frame; exact chain formula) to the target;
    ``predicted_tip_stiffness`` (6, 6); ``tensions`` (N, n); ``saturated`` (N, n);
    ``message``; ``design_screws`` (N, 6); ``pose_error`` (6,) of the tip ``[dx dy dz rx ry
    rz]``; ``joint_commands`` the N joints' :class:`ControlCommand`."""

    rest_lengths: FloatArray
    feasible: bool
    stiffness_error: float
    predicted_tip_stiffness: FloatArray
    tensions: FloatArray
    saturated: BoolArray
    message: str
    design_screws: FloatArray
    pose_error: FloatArray
    joint_commands: tuple[ControlCommand, ...] = ()


class ChainStiffnessController(_PoseFeedback):
    """Closed-loop rest-length commands for a spine: a tip pose target (base frame) and a tip
    K_c* (base frame, about the tip link's origin as :meth:`JointChain.tip_stiffness`).

    Per tick: (1) the integral correction z of the tip pose error shifts the target,
    ``T_d = exp(hat(z)) T*``; (2) the joint screws that reach ``T_d`` closest to the reference
    configuration (``initial_screws``, default the unloaded one): Gauss-Newton on
    ``min |xi - xi_ref|^2 s.t. tip(xi) = T_d`` with :meth:`JointChain.jacobian` (the 6N - 6
    redundant dofs are held at the reference); (3) each joint's load at those screws from
    the chain's exact equilibrium residuals (``residuals - wrenches``: tip load and link
    weights transported to {1}_i); (4) without a tip K_c*, each joint's tensions by its own
    :class:`StiffnessController` QP (middle of the limits); with one, all joints' tensions in
    one QP (each joint's 6 equalities exact, all bounds) whose objective is the tip stiffness of
    the series compliance ``C_tip = sum_i Ad_i K_i^-1 Ad_i^T`` (``Ad_i`` of {1}_i in the base;
    exact without load and weights) linearised at the last tick's tensions: one damped
    Gauss-Newton step per tick, so a reachable target is met over a few ticks. The tip stiffness is
    then reported by the exact chain formula (loads and weights included). Gains and limits as
    :class:`StiffnessController` (the joints' own integrals are off: the tip integral closes the
    loop). Why only this much of the tip K_c can be shaped: ``docs/control.md``.
    ``time_budget`` (s, None: none): as :class:`StiffnessController`'s, for the whole tick."""

    def __init__(self, chain: JointChain, limits: ActuatorLimits | Sequence[ActuatorLimits],
                 rest_lengths: Any, *, integral_gain: float = DEFAULT_INTEGRAL_GAIN,
                 integral_limit: Sequence[float] = DEFAULT_INTEGRAL_LIMIT,
                 rest_length_offsets: Any = None, initial_screws: ArrayLike | None = None,
                 time_budget: float | None = None) -> None:
        if not isinstance(chain, JointChain):
            raise ValueError('chain must be a JointChain')
        N = chain.n_joints
        self.chain = chain
        self._exp_kernel = chain.joints[0].compiled_kernel
        per_limits = [limits] * N if isinstance(limits, ActuatorLimits) else list(limits)
        if len(per_limits) != N:
            raise ValueError(f'limits must be one ActuatorLimits or one per joint ({N})')
        offsets = [None] * N if rest_length_offsets is None else list(rest_length_offsets)
        if len(offsets) != N:
            raise ValueError(f'rest_length_offsets must hold one row per joint ({N})')
        rows = self._rows(rest_lengths)
        self.integral_gain, _, self.integral_limit = _gains(integral_gain, 0.0, integral_limit)
        self.joints = [StiffnessController(m, lim, r, integral_gain=0.0,
                                           rest_length_offsets=d, time_budget=time_budget)
                       for m, lim, r, d in zip(chain.joints, per_limits, rows, offsets,
                                               strict=True)]
        ref = chain.unloaded_screws() if initial_screws is None else finite_array_of_shape(
            'initial_screws', initial_screws, (N, 6))
        self.reference_screws = np.array(ref, dtype=np.float64)
        self._z = np.zeros(6)
        self._xi = self.reference_screws.copy()

    def _rows(self, rest_lengths: Any) -> list[FloatArray]:
        N = self.chain.n_joints
        rows = list(rest_lengths)
        if len(rows) != N:
            raise ValueError(f'rest_lengths must hold one row per joint ({N}), got {len(rows)}')
        return [np.asarray(r, dtype=np.float64) for r in rows]

    @property
    def rest_lengths(self) -> FloatArray:
        """(N, n) the last commands."""
        return np.array([j.rest_lengths for j in self.joints])

    def reset(self, rest_lengths: Any) -> None:
        """Forget the integral and warm starts; ``rest_lengths`` one row per joint."""
        rows = self._rows(rest_lengths)
        for j, r in zip(self.joints, rows, strict=True):
            j.reset(r)
        self._z = np.zeros(6)
        self._target_transform = None
        self._rest_anchor = None
        self._clamped_time = 0.0
        self._xi = self.reference_screws.copy()

    def _screws_for(self, T_d: FloatArray) -> FloatArray:
        """Screws (N, 6) with tip(xi) = T_d nearest the reference (Gauss-Newton)."""
        xi = self._xi.copy()
        ref = self.reference_screws.ravel()
        for _ in range(CHAIN_IK_ITERATIONS):
            tip = self.chain.tip_transform(xi)
            e = log_se3(T_d @ np.linalg.inv(tip))
            r = np.concatenate([e[3:], e[:3]])  # the Jacobian's [dv; dw] order (small e)
            J = self.chain.jacobian(xi)
            x = xi.ravel()
            # min |x + dx - ref|^2 s.t. J dx = r
            dx0 = ref - x
            dx = dx0 + np.linalg.lstsq(J, r - J @ dx0, rcond=None)[0]
            xi = (x + dx).reshape(-1, 6)
        return xi

    def _shape_tip(self, dt: float, target: ControlTarget, transforms: FloatArray,
                   loads: FloatArray, frames: FloatArray, deadline: float = math.inf
                   ) -> list[ControlCommand]:
        """All joints' tensions in one QP: each joint's equilibrium exact (its 6 equalities),
        the tip stiffness of the series compliance ``C = sum_i Ad_i K_i^-1 Ad_i^T`` linearised
        at the last tick's tensions (one Gauss-Newton step per tick, damped by
        :data:`CHAIN_STIFFNESS_DAMPING`), all tension and range bounds."""
        N = self.chain.n_joints
        xi = transforms
        problems = [ctl._problem(x, w) for ctl, x, w in zip(self.joints, xi, loads, strict=True)]
        bad = [(i, p) for i, p in enumerate(problems) if isinstance(p, str)]
        if bad:
            return [ctl._hold(x, np.zeros(6), f'joint {i + 1}: {p}' if isinstance(p, str)
                              else 'another joint is infeasible')
                    for i, (ctl, x, p) in enumerate(zip(self.joints, xi, problems, strict=True))]
        prs: list[_JointProblem] = problems  # type: ignore[assignment]
        S = self.joints[0]._S
        SS = S[:, None] * S[None, :]
        if target.stiffness_weight is not None:
            SS = SS * target.stiffness_weight
        t0 = [np.clip(p.start, p.lo, p.hi) for p in prs]
        Ads = [adjoint_twist(F) for F in frames]
        C = np.zeros((6, 6))
        parts = []
        for p, t, Ad in zip(prs, t0, Ads, strict=True):
            Ci = np.linalg.inv(p.terms.K0 + np.einsum('j,jab->ab', t, p.terms.M))
            parts.append((Ad @ Ci, Ci @ Ad.T))
            C += Ad @ Ci @ Ad.T
        K = np.linalg.inv(C)
        columns = []
        for p, (left, right) in zip(prs, parts, strict=True):
            # dK/dt_j = K Ad C_i M_j C_i Ad^T K (d(K_i^-1) = -K_i^-1 dK_i K_i^-1, dK = -K dC K)
            D = np.einsum('ab,jbc,cd->jad', K @ left, p.terms.M, right @ K)
            columns.append((D * SS).reshape(D.shape[0], 36).T)
        G = np.concatenate(columns, axis=1)
        t_all = np.concatenate(t0)
        g = ((target.cartesian_stiffness - K) * SS).ravel() + G @ t_all
        P = G.T @ G
        damping = CHAIN_STIFFNESS_DAMPING * float(np.trace(P)) / P.shape[0]
        P = P + damping * np.eye(P.shape[0])
        c = G.T @ g + damping * t_all
        n = [p.lo.size for p in prs]
        A = np.zeros((6 * N, sum(n)))
        start = np.concatenate([[0], np.cumsum(n)])
        for i, p in enumerate(prs):
            A[6 * i:6 * i + 6, start[i]:start[i + 1]] = p.A
        b = np.concatenate([p.b for p in prs])
        lo = np.concatenate([p.lo for p in prs])
        hi = np.concatenate([p.hi for p in prs])
        at_lo = np.concatenate([ctl._at_lo for ctl in self.joints])
        at_hi = np.concatenate([ctl._at_hi for ctl in self.joints])
        sol = solve_box_qp(P, c, A, b, lo, hi, t_all, at_lo, at_hi,
                           self.joints[0].model.uses_kernel, deadline=deadline)
        if sol.out_of_time:
            return [ctl._out_of_time(x, np.zeros(6), sol.iterations)
                    for ctl, x in zip(self.joints, xi, strict=True)]
        if not sol.converged:
            text = _failure(A, b, sol)
            return [ctl._hold(x, np.zeros(6), text) for ctl, x in zip(self.joints, xi,
                                                                       strict=True)]
        out = []
        for i, (ctl, p) in enumerate(zip(self.joints, prs, strict=True)):
            part = slice(start[i], start[i + 1])
            joint_sol = QPResult(sol.t[part], sol.at_lo[part], sol.at_hi[part], sol.iterations,
                                 True, sol.warm)
            out.append(ctl._apply(dt, ControlTarget(pose=xi[i]), xi[i], ctl.integral,
                                  np.zeros(6), p.terms, joint_sol))
        return out

    def update(self, dt: float, target: ControlTarget, tip_pose: ArrayLike | None = None,
               tip_wrench: ArrayLike | None = None, gravity: ArrayLike | None = None
               ) -> ChainControlCommand:
        """One tick: ``target`` (tip pose in the base; ``cartesian_stiffness`` the tip K_c* in
        the base), the measured ``tip_pose`` (4x4 or 7) and the known ``tip_wrench`` (6,)
        (base, about the tip link's origin; default 0); ``gravity`` as the chain's."""
        deadline = _deadline(self.joints[0].time_budget)
        dt, W, _, error, z = self._feedback(dt, target, tip_pose, None, 'tip_wrench',
                                            tip_wrench)
        xi = self._screws_for(_exp(self._exp_kernel, z) @ target.transform)
        chain = self.chain
        state = chain.evaluate(xi)
        loads = chain.residuals(xi, W, gravity) - state.wrenches
        if target.cartesian_stiffness is None:
            commands = [ctl._tick(dt, ControlTarget(screw=xi[i]), state.transforms[i],
                                  loads[i], ctl.integral, np.zeros(6), deadline)
                        for i, ctl in enumerate(self.joints)]
        else:
            commands = self._shape_tip(dt, target, state.transforms, loads, state.joint_frames,
                                       deadline)
        feasible = all(c.feasible for c in commands)
        saturated = np.array([c.saturated for c in commands])
        if feasible:
            self._commit_integral(dt, target.transform, z, bool(saturated.any()))
        self._xi = xi
        if feasible:
            designed = [rest_from_tensions(ctl.model, pose_terms(ctl.model, x).lengths,
                                           c.tensions)
                        for c, ctl, x in zip(commands, self.joints, xi, strict=True)]
            K_tip = chain.tip_stiffness(xi, W, gravity, rest_lengths=designed)
        else:
            K_tip = np.full((6, 6), np.nan)
        if target.cartesian_stiffness is None or not feasible:
            err = 0.0 if feasible else math.nan
        else:
            L = self.joints[0].length_scale
            err = relative_stiffness_error(K_tip, target.cartesian_stiffness, L)
        msgs = [f'joint {i + 1}: {c.message}' for i, c in enumerate(commands)
                if c.message != 'ok']
        if target.cartesian_stiffness is not None and feasible and \
                err > STIFFNESS_MET_TOLERANCE:
            msgs.insert(0, f'tip stiffness target not met: relative error {err:.3g}')
        if feasible and not saturated.any() and self._integral_note():
            msgs.append('tip ' + self._integral_note())
        return ChainControlCommand(np.array([c.rest_lengths for c in commands]), feasible, err,
                                   K_tip, np.array([c.tensions for c in commands]), saturated,
                                   '; '.join(msgs) or 'ok', xi, error, tuple(commands))
