"""The spine's estimator (:func:`estimate_chain_state`): every joint's screw fitted at once on the
chain's equilibria (Levenberg-Marquardt on their tangent, Newton's restoration onto them), the
tip's pose and stiffness with their uncertainty. The method is in
:mod:`~tensegrity_stiffness.estimation.estimators`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.joint_estimator import (
    DECREMENT_TOLERANCE,
    MAX_ITERATIONS,
    MIN_LENGTH_SCALE,
    NEAR_SINGULAR_TOLERANCE,
    RANK_TOLERANCE,
    STIFFNESS_STEP,
    EstimatorFit,
    JointProblem,
    axis_words,
    better_fit,
    describe_direction,
    entry_std,
    nan_array,
    outlier_fields,
    reject_contradicted,
)
from tensegrity_stiffness.estimation.least_squares import (
    SINGULAR_NORMAL_MATRIX,
    STALL_TOLERANCE,
    TIME_BUDGET_EXHAUSTED,
    FitClock,
    LevenbergMarquardtDamping,
    clip_screw_step,
    damped_normal_matrix,
)
from tensegrity_stiffness.estimation.measurements import (
    Measurements,
    PreparedMeasurements,
    reading_covariance,
)
from tensegrity_stiffness.estimation.trust import CONSISTENCY_PROBABILITY, consistency_threshold
from tensegrity_stiffness.geometry.screw import (
    hat3,
)
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import (
    finite_array,
)
from tensegrity_stiffness.mechanics.chain import ChainState, JointChain

FloatArray = NDArray[np.float64]

#: The chain's equilibria count as met when every residual is below this (N, N m).
CHAIN_EQUILIBRIUM_TOLERANCE = 1e-9
#: Newton corrections onto the chain's equilibria after each step.
MAX_RESTORATION_STEPS = 8


# ---------------------------------------------------------------------------------- spine
@dataclass
class ChainEstimate:
    """Outcome of :func:`estimate_chain_state` (N joints).

    ``screws`` (N, 6) with ``screw_covariance`` (6N, 6N) (joint-major); ``joint_covariances``
    (N, 6, 6) each joint's pose covariance in its own {1}_i (PoseWithCovariance convention);
    ``tip_wrench`` (6,) in the base about its origin with ``tip_wrench_covariance``;
    ``tip_transform`` (4, 4) with ``tip_pose_covariance`` (6, 6) in the base;
    ``tip_stiffness`` (6, 6) the exact tip stiffness under the estimated load (base frame, rows
    [f; m], columns [dv; dw]) with ``tip_stiffness_std`` (first order, central differences);
    ``chi2``, ``dof``, ``observable``, ``rank`` (of 6N + 6), ``condition_number``,
    ``iterations``; ``state`` the :class:`ChainState` at the estimate; ``consistent``,
    ``redundancy``, ``outliers``, ``outlier_reasons`` and ``restarted`` as
    :class:`JointEstimate`'s (a joint's readings named ``joint <i> tension[<string>]``,
    ``joint <i> length[<string>]``, ``joint <i> pose``; the tip's ``pose`` and ``wrench``).
    ``screw_rates`` (N, 6) and ``screw_rate_covariance`` (6N, 6N): the chain filter's
    (:class:`~tensegrity_stiffness.estimation.chain_filter.ChainFilter`); empty from the static
    estimator, which assumes rest.
    """

    success: bool
    message: str
    screws: FloatArray
    screw_covariance: FloatArray
    joint_covariances: FloatArray
    tip_wrench: FloatArray
    tip_wrench_covariance: FloatArray
    tip_transform: FloatArray
    tip_pose_covariance: FloatArray
    tip_stiffness: FloatArray
    tip_stiffness_std: FloatArray
    chi2: float
    dof: int
    observable: bool
    rank: int
    condition_number: float
    iterations: int
    state: ChainState | None = field(default=None, repr=False)
    consistent: bool | None = None
    redundancy: int = 0
    outliers: tuple[str, ...] = ()
    outlier_reasons: tuple[str, ...] = ()
    restarted: bool = False
    screw_rates: FloatArray = field(default_factory=lambda: np.zeros((0, 6)))
    screw_rate_covariance: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))


class _ChainProblem:
    """Unknowns ``z = [xi_1 .. xi_N, W]``. Measurement residuals (whitened): each joint's
    tensions, lengths and pose, the tip pose, the tip load when it is known; constraints: each
    joint's equilibrium ``c_i = F_i + Ad_{P_i}^T B_i = 0`` (exact, Jacobian from
    :meth:`JointChain.residual_jacobian`'s blocks and ``dc_i/dW = Ad_{P_i}^T``)."""

    def __init__(self, chain: JointChain, preps: list[PreparedMeasurements | None],
                 rest: list[FloatArray | None], gravity: FloatArray,
                 tip_pose: FloatArray | None, tip_pose_whitener: FloatArray | None,
                 tip_wrench: FloatArray | None, tip_wrench_whitener: FloatArray | None) -> None:
        self.chain = chain
        self.n = chain.n_joints
        self.rest = rest
        self.gravity = gravity
        self.tip_pose = tip_pose
        self.tip_pose_whitener = tip_pose_whitener
        self.tip_wrench = tip_wrench
        self.tip_wrench_whitener = tip_wrench_whitener
        self.problems = [
            None if p is None or p.rows == 0
            else JointProblem(model, p, model.validate_rest_lengths(r, False))
            for model, p, r in zip(chain.joints, preps, rest, strict=True)]
        self.length_scale = max(float(np.mean([np.mean(m.rest_lengths) for m in chain.joints])),
                                MIN_LENGTH_SCALE)
        size = 6 * self.n + 6
        #: Column scale of z for rank and clipping: radians, metres / length_scale, the load.
        self.scale = np.array(([1.0] * 3 + [self.length_scale] * 3) * self.n + [1.0] * 6)
        self.size = size

    def constraints(self, z: FloatArray) -> tuple[FloatArray, FloatArray, ChainState]:
        """(c (6N,), dc/dz (6N, size), chain state) at z."""
        n = self.n
        xi = z[:6 * n].reshape(n, 6)
        chain = self.chain
        state = chain.evaluate(xi, self.rest)
        c, D, AdT, _ = chain.equilibrium_system(state, z[6 * n:], self.gravity)
        Jc = np.empty((6 * n, self.size))
        Jc[:, :6 * n] = chain.residual_screw_jacobian(D, xi)
        Jc[:, 6 * n:] = AdT.reshape(6 * n, 6)
        return c.reshape(-1), Jc, state

    def measurements(self, z: FloatArray, state: ChainState) -> tuple[FloatArray, FloatArray]:
        """(r, dr/dz) whitened at z (``state`` the chain's at z)."""
        n, size = self.n, self.size
        xi = z[:6 * n].reshape(n, 6)
        W = z[6 * n:]
        rows_r: list[FloatArray] = []
        rows_J: list[FloatArray] = []
        for i, problem in enumerate(self.problems):
            if problem is None:
                continue
            r, J, _, _ = problem.evaluate(xi[i])
            block = np.zeros((r.size, size))
            block[:, 6 * i:6 * i + 6] = J
            rows_r.append(r)
            rows_J.append(block)
        if self.tip_pose is not None:
            T = state.tip_transform
            jac = np.zeros((6, size))
            jac[:, :6 * n] = tip_pose_jacobian(self.chain, xi, T)
            r, jac = sm.pose_residual_unchecked(T, self.tip_pose, jac)
            rows_r.append(self.tip_pose_whitener @ r)
            rows_J.append(self.tip_pose_whitener @ jac)
        if self.tip_wrench is not None:
            jac = np.zeros((6, size))
            jac[:, 6 * n:] = self.tip_wrench_whitener
            rows_r.append(self.tip_wrench_whitener @ (W - self.tip_wrench))
            rows_J.append(jac)
        r = np.concatenate(rows_r) if rows_r else np.empty(0)
        J = np.vstack(rows_J) if rows_J else np.empty((0, size))
        return r, J

    def restore(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, ChainState
                                               ] | None:
        """Newton's minimum-norm corrections onto the equilibria from z: (z, c, dc/dz, state)
        once every residual is below :data:`CHAIN_EQUILIBRIUM_TOLERANCE`; None when that fails
        (or a string collapses)."""
        z = z.copy()
        for _ in range(MAX_RESTORATION_STEPS):
            try:
                c, Jc, state = self.constraints(z)
            except ValueError:
                return None
            if not np.all(np.isfinite(c)):
                return None
            if np.max(np.abs(c)) < CHAIN_EQUILIBRIUM_TOLERANCE:
                return z, c, Jc, state
            try:
                Q1, _, R = _tangent(Jc)
                step = Q1 @ np.linalg.solve(R.T, -c)
            except np.linalg.LinAlgError:
                return None
            for i in range(self.n):
                step[6 * i:6 * i + 6] = clip_screw_step(step[6 * i:6 * i + 6], self.length_scale)
            z = z + step
        return None


def tip_pose_jacobian(chain: JointChain, xi: FloatArray, tip: FloatArray) -> FloatArray:
    """``d[dp; dtheta]/dxi`` (6, 6N) of the tip pose (PoseWithCovariance convention in the base)
    from the tip's spatial twist ``[dv; dw]`` (:meth:`JointChain.jacobian`):
    ``dp = dv + dw x p``, ``dtheta = dw``."""
    twist = chain.jacobian(xi)
    out = np.empty_like(twist)
    out[:3] = twist[:3] - hat3(tip[:3, 3]) @ twist[3:]
    out[3:] = twist[3:]
    return out


def _tangent(Jc: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Orthonormal bases of the range (Q1) and null space (Q2) of ``Jc^T`` and ``R`` with
    ``Jc^T = Q1 R`` (complete QR)."""
    m = Jc.shape[0]
    Q, R = np.linalg.qr(Jc.T, mode='complete')
    return Q[:, :m], Q[:, m:], R[:m]


def _constrained_gauss_newton(problem: _ChainProblem, z0: FloatArray, max_iterations: int,
                              tolerance: float, clock: FitClock | None = None
                              ) -> tuple[FloatArray, Any, int, bool, str]:
    """Levenberg-Marquardt on the measurements over the equilibria (a manifold of dimension 6):
    each step lies in the tangent (the null space of dc/dz) and is followed by Newton's
    restoration onto the equilibria (:meth:`_ChainProblem.restore`); a step is kept when the
    restored point lowers the cost. Converged when the decrement is below ``tolerance``; not
    converged (:data:`TIME_BUDGET_EXHAUSTED`) when the estimate's ``clock`` refuses a step.
    Returns (z, (r, J, c, dc/dz, state), iterations, converged, message)."""
    restored = problem.restore(z0)
    if restored is None:
        return z0, None, 0, False, ('no equilibrium of the chain near the initial screws and '
                                    'tip load')
    z, c, Jc, state = restored
    r, J = problem.measurements(z, state)
    cost = float(r @ r)
    damping = LevenbergMarquardtDamping()
    for it in range(1, max_iterations + 1):
        _, Q2, _ = _tangent(Jc)
        M = J @ Q2
        A = M.T @ M
        g = M.T @ r
        try:
            full = -np.linalg.solve(A, g)
        except np.linalg.LinAlgError:
            return z, (r, J, c, Jc, state), it - 1, False, SINGULAR_NORMAL_MATRIX
        if float(-g @ full) < tolerance:
            return z, (r, J, c, Jc, state), it - 1, True, ''
        if clock is not None and not clock.next_iteration():
            return z, (r, J, c, Jc, state), it - 1, False, TIME_BUDGET_EXHAUSTED
        while True:
            y = full if damping.value == 0.0 else -np.linalg.solve(
                damped_normal_matrix(A, damping.value), g)
            step = Q2 @ y
            for i in range(problem.n):
                step[6 * i:6 * i + 6] = clip_screw_step(step[6 * i:6 * i + 6],
                                                        problem.length_scale)
            trial = problem.restore(z + step)
            if trial is not None:
                trial_r, trial_J = problem.measurements(trial[0], trial[3])
                trial_cost = float(trial_r @ trial_r)
                if trial_cost <= cost:
                    stalled = cost - trial_cost <= STALL_TOLERANCE * max(cost, 1.0)
                    z, c, Jc, state = trial
                    r, J, cost = trial_r, trial_J, trial_cost
                    if stalled:  # see gauss_newton
                        return z, (r, J, c, Jc, state), it, True, ''
                    damping.accepted()
                    break
            if not damping.rejected():  # a minimum (see gauss_newton)
                return z, (r, J, c, Jc, state), it, True, ''
    return z, (r, J, c, Jc, state), max_iterations, False, (
        f'not converged in {max_iterations} iterations')


def _chain_information(problem: _ChainProblem, J: FloatArray, Jc: FloatArray,
                       rank_tolerance: float) -> tuple[FloatArray, int, float, FloatArray]:
    """Covariance of z (size, size) on the equilibria, ``Q2 (M^T M)^-1 Q2^T`` with
    ``M = J Q2``, the rank (of 6: the equilibria leave 6 directions, those of the load), the
    condition number and the scaled null directions (rows, in z) when rank < 6."""
    scale = problem.scale
    _, Q2, _ = _tangent(Jc * scale)  # the tangent in scaled coordinates
    M = (J * scale) @ Q2
    k = Q2.shape[1]
    Ms = M if M.shape[0] >= k else np.vstack([M, np.zeros((k - M.shape[0], k))])
    _, s, Vt = np.linalg.svd(Ms)
    rank = int(np.sum(s > rank_tolerance * s[0])) if s.size and s[0] > 0 else 0
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else math.inf
    if rank < k:
        return nan_array(problem.size, problem.size), rank, cond, (Q2 @ Vt[rank:].T).T * scale
    C = Q2 @ np.linalg.inv(M.T @ M) @ Q2.T
    C = C * np.outer(scale, scale)
    return 0.5 * (C + C.T), rank, cond, np.empty((0, problem.size))


def _load_words(load: FloatArray, length_scale: float) -> str:
    """A tip-load direction ``[f; m]`` in words: the force or moment that dominates (moments
    over ``length_scale``)."""
    f, m = load[:3], load[3:]
    if np.linalg.norm(m) >= np.linalg.norm(f) * length_scale:
        return f'moment about {axis_words(m / np.linalg.norm(m))}'
    return f'force along {axis_words(f / np.linalg.norm(f))}'


def _chain_missing_message(problem: _ChainProblem, z: FloatArray, null: FloatArray,
                           inputs: str, rank: int) -> str:
    """Why the readings leave ``6 - rank`` of the unknowns open: each undetermined direction
    (a row of ``null``, in z) by the joints it moves, each joint's part in the joint
    estimator's words (:func:`describe_direction`, its link's pose change in {1}_i), and the
    tip load's part."""
    n = problem.n
    xi = z[:6 * n].reshape(n, 6)
    words = []
    for v in null:
        weight = np.linalg.norm((v / problem.scale).reshape(n + 1, 6), axis=1)
        involved = weight > 0.1 * weight.max()
        parts = [f'joint {i + 1} ' + describe_direction(
            sm.pose_jacobian(xi[i]) @ v[6 * i:6 * i + 6], problem.length_scale)
            for i in range(n) if involved[i]]
        if involved[n]:
            parts.append(f'the tip load ({_load_words(v[6 * n:], problem.length_scale)})')
        words.append(' with '.join(parts))
    return (f'{inputs}: with the equilibria they determine only {rank} of the 6 remaining '
            f'unknowns (the tip load, or the configuration it implies); undetermined: '
            f'{"; ".join(words)}. Add string tensions or lengths on those joints, a joint or '
            f'tip pose, or the tip load (tip_wrench)')


def estimate_chain_state(chain: JointChain,
                         joint_measurements: Sequence[Measurements | None],
                         tip_pose: ArrayLike | None = None,
                         tip_pose_covariance: ArrayLike | None = None,
                         tip_wrench: ArrayLike | None = None,
                         tip_wrench_covariance: ArrayLike | None = None,
                         gravity: ArrayLike | None = None, *,
                         rest_lengths: Any = None,
                         initial_screws: ArrayLike | None = None,
                         initial_tip_wrench: ArrayLike | None = None,
                         tolerance: float = DECREMENT_TOLERANCE,
                         max_iterations: int = MAX_ITERATIONS,
                         rank_tolerance: float = RANK_TOLERANCE,
                         stiffness_std: bool = True,
                         consistency_probability: float = CONSISTENCY_PROBABILITY,
                         reject_outliers: bool = True,
                         time_budget: float | None = None) -> ChainEstimate:
    """Every joint's screw, the tip load, the tip pose and the exact tip stiffness of a spine,
    each with its covariance.

    ``joint_measurements``: one :class:`Measurements` (or None) per joint with its strings'
    tensions / lengths and optionally the joint's own pose (of {2}_i in {1}_i). The load is the
    spine's: ``tip_wrench`` (6,) in the base about its origin with ``tip_wrench_covariance``, or
    None for an unknown tip load, shared by every joint's equilibrium (which is what makes a few
    load cells per vertebra enough). The equilibria ``F_i + Ad_{P_i}^T B_i = 0`` are exact
    constraints (null-space Gauss-Newton), so 6 unknowns remain whatever N: the tip load (or
    the configuration it implies). ``tip_pose`` (the tool frame in the base, (4, 4) or 7
    values) with ``tip_pose_covariance`` (6, 6, PoseWithCovariance convention). ``gravity``
    (3,) for the link weights (default ``chain.gravity``). ``initial_screws`` (N, 6) and
    ``initial_tip_wrench`` warm-start (default: the unloaded screws and the known load or
    zero). Trust as :func:`estimate_joint_state`'s: impossible readings left out, a lost warm
    start restarted cold, contradicted readings left out while redundancy remains; a
    ``time_budget`` (s; None: no bound) as :func:`estimate_joint_state`'s (its fits'
    iterations, not the restorations onto the equilibria, which are bounded in iterations).
    """
    inputs = _chain_inputs(chain, joint_measurements, tip_pose, tip_pose_covariance, tip_wrench,
                           tip_wrench_covariance, gravity, rest_lengths, initial_screws,
                           initial_tip_wrench, consistency_probability)
    clock = FitClock(tolerance, max_iterations, time_budget)
    dropped = inputs.dropped
    measured = _measured_dof(inputs.preps, inputs.tip)
    if measured < 6:
        return _failed_chain(
            f'{inputs.text}: {measured} measured degrees of freedom cannot determine the 6 '
            'unknowns left by the equilibria (the tip load). Add string tensions or lengths, a '
            'pose, or the tip load (tip_wrench)', chain.n_joints, measured, dropped, False,
            measured, math.inf)
    fitter = _ChainFitter(chain, inputs, tolerance, max_iterations, rank_tolerance,
                          consistency_probability, clock)
    fit, restarted = fitter.tracked(inputs.preps, inputs.tip, inputs.z0,
                                    initial_screws is not None)
    if reject_outliers:
        fit, restarted = reject_contradicted(fit, restarted, dropped, consistency_probability,
                                              fitter.readings, fitter.refit_without)
    if clock.exhausted:
        return _failed_chain(clock.message(inputs.text), chain.n_joints,
                             _measured_dof(fit.preps, fit.tip), dropped, True, fit.rank,
                             fit.cond, clock.iterations)
    return _chain_estimate(chain, inputs, fit, restarted, dropped, stiffness_std,
                           consistency_probability)


def _measured_dof(preps: list[PreparedMeasurements | None], tip: frozenset[str]) -> int:
    """The degrees of freedom measured by the joints' readings ``preps`` and the tip's ``tip``."""
    return sum(p.dof for p in preps if p is not None) + 6 * len(tip)


@dataclass
class _ChainInputs:
    """The checked inputs of :func:`estimate_chain_state`: each joint's prepared readings
    (impossible ones left out, named in ``dropped``), the gravity, the rest lengths, the tip's
    readings with their whiteners, the starting point ``z0 = [xi_1 .. xi_N, W]`` and ``text``
    naming the inputs for messages."""

    preps: list[PreparedMeasurements | None]
    dropped: list[tuple[str, str]]
    gravity: FloatArray
    rest: list[FloatArray | None]
    tip_pose: FloatArray | None
    tip_pose_whitener: FloatArray | None
    tip_wrench: FloatArray | None
    tip_wrench_whitener: FloatArray | None
    z0: FloatArray
    text: str

    @property
    def tip(self) -> frozenset[str]:
        """The tip's readings present (``pose``, ``wrench``)."""
        return frozenset(name for name, value in (('pose', self.tip_pose),
                                                  ('wrench', self.tip_wrench))
                         if value is not None)


def _chain_preps(chain: JointChain, joint_measurements: Sequence[Measurements | None]
                 ) -> list[PreparedMeasurements | None]:
    """Each joint's readings prepared (None: none); ValueError naming the joint's entry."""
    n = chain.n_joints
    if len(joint_measurements) != n:
        raise ValueError(f'joint_measurements must hold one entry per joint ({n}), '
                         f'got {len(joint_measurements)}')
    preps: list[PreparedMeasurements | None] = []
    for i, (model, m) in enumerate(zip(chain.joints, joint_measurements, strict=True)):
        if m is None:
            preps.append(None)
            continue
        if m.external_wrench is not None or m.gravity is not None:
            raise ValueError(f'joint_measurements[{i}]: a spine takes its load as tip_wrench '
                             'and gravity as gravity (per-joint external_wrench / gravity are '
                             'not supported)')
        try:
            preps.append(m.prepared(model.n_strings))
        except ValueError as exc:
            raise ValueError(f'joint_measurements[{i}].{exc}') from None
    return preps


def _drop_impossible(chain: JointChain, preps: list[PreparedMeasurements | None],
                     rest: list[FloatArray | None]) -> list[tuple[str, str]]:
    """Leaves the impossible readings out of ``preps`` (in place); returns them as
    (``joint <i> <reading>``, why)."""
    dropped: list[tuple[str, str]] = []
    for i, (model, p) in enumerate(zip(chain.joints, preps, strict=True)):
        if p is not None:
            bad = p.impossible(model, model.validate_rest_lengths(rest[i], False))
            if bad:
                preps[i] = p.without([name for name, _ in bad], model.string_names)
                dropped += [(f'joint {i + 1} {name}', why) for name, why in bad]
    return dropped


def _chain_inputs(chain: JointChain, joint_measurements: Sequence[Measurements | None],
                  tip_pose: ArrayLike | None, tip_pose_covariance: ArrayLike | None,
                  tip_wrench: ArrayLike | None, tip_wrench_covariance: ArrayLike | None,
                  gravity: ArrayLike | None, rest_lengths: Any,
                  initial_screws: ArrayLike | None, initial_tip_wrench: ArrayLike | None,
                  consistency_probability: float) -> _ChainInputs:
    """The arguments of :func:`estimate_chain_state` checked (ValueError naming the argument)
    and prepared, impossible readings left out."""
    preps = _chain_preps(chain, joint_measurements)
    consistency_threshold(1, consistency_probability)  # checks the probability
    g = chain.resolved_gravity(gravity)
    rest = chain.rest_lengths_per_joint(rest_lengths)
    dropped = _drop_impossible(chain, preps, rest)
    pose_T = pose_whitener = None
    if tip_pose is not None:
        pose_T = rigid_transform(tip_pose, 'tip_pose')
        _, pose_whitener = reading_covariance('tip_pose_covariance', tip_pose_covariance, 6)
    W_m = W_whitener = None
    if tip_wrench is not None:
        W_m = finite_array('tip_wrench', tip_wrench)
        if W_m.shape != (6,):
            raise ValueError(f'tip_wrench must have shape (6,), got {W_m.shape}')
        _, W_whitener = reading_covariance('tip_wrench_covariance', tip_wrench_covariance, 6)
    x0 = (chain.unloaded_screws(rest) if initial_screws is None
          else chain.validated_screws(initial_screws).copy())
    if initial_tip_wrench is None:
        W0 = W_m.copy() if W_m is not None else np.zeros(6)
    else:
        W0 = finite_array('initial_tip_wrench', initial_tip_wrench)
        if W0.shape != (6,):
            raise ValueError(f'initial_tip_wrench must have shape (6,), got {W0.shape}')
    names = [f'joint {i + 1}: {p.describe(model.string_names, load=False)}'
             for i, (model, p) in enumerate(zip(chain.joints, preps, strict=True))
             if p is not None and p.rows]
    if pose_T is not None:
        names.append('a tip pose')
    names.append('a known tip load' if W_m is not None else 'unknown tip load')
    return _ChainInputs(preps, dropped, g, rest, pose_T, pose_whitener, W_m, W_whitener,
                        np.concatenate([x0.reshape(-1), W0]), '; '.join(names))


@dataclass
class _ChainFit(EstimatorFit):
    """One constrained fit of a spine's readings (``preps`` of the joints, ``tip`` of the tip)
    and its information (``C``, ``rank``, ``cond``, the null directions ``null``) when it
    reached the equilibria (``ev`` not None)."""

    problem: _ChainProblem
    preps: list[PreparedMeasurements | None]
    tip: frozenset[str]
    z: FloatArray
    ev: Any
    iterations: int
    converged: bool
    why: str
    rank: int = 0
    cond: float = math.inf
    C: FloatArray = field(default_factory=lambda: nan_array(0, 0))
    null: FloatArray = field(default_factory=lambda: nan_array(0, 0))

    @property
    def r(self) -> FloatArray:  # type: ignore[override]
        return self.ev[0]

    @property
    def J(self) -> FloatArray:  # type: ignore[override]
        return self.ev[1]

    @property
    def chi2(self) -> float:
        return math.inf if self.ev is None else float(self.ev[0] @ self.ev[0])

    @property
    def redundancy(self) -> int:
        return _measured_dof(self.preps, self.tip) - 6


@dataclass
class _ChainFitter:
    """A spine's fits with one set of inputs and solver settings: :meth:`fit` from a start,
    :meth:`tracked` (restarted cold when a warm start lost track), :meth:`readings` (the
    named rows of a fit's residual) and :meth:`refit_without` a reading."""

    chain: JointChain
    inputs: _ChainInputs
    tolerance: float
    max_iterations: int
    rank_tolerance: float
    probability: float
    clock: FitClock | None = None

    def fit(self, preps: list[PreparedMeasurements | None], tip: frozenset[str],
            z0: FloatArray) -> _ChainFit:
        """The readings ``preps`` and ``tip`` fitted from ``z0``
        (:func:`_constrained_gauss_newton`)."""
        inputs = self.inputs
        problem = _ChainProblem(self.chain, preps, inputs.rest, inputs.gravity,
                                inputs.tip_pose if 'pose' in tip else None,
                                inputs.tip_pose_whitener,
                                inputs.tip_wrench if 'wrench' in tip else None,
                                inputs.tip_wrench_whitener)
        z, ev, iterations, converged, why = _constrained_gauss_newton(
            problem, z0, self.max_iterations, self.tolerance, self.clock)
        out = _ChainFit(problem, preps, tip, z, ev, iterations, converged, why)
        if ev is not None:
            out.C, out.rank, out.cond, out.null = _chain_information(problem, ev[1], ev[3],
                                                                     self.rank_tolerance)
        return out

    def tracked(self, preps: list[PreparedMeasurements | None], tip: frozenset[str],
                z0: FloatArray, warm: bool) -> tuple[_ChainFit, bool]:
        """The fit from ``z0`` and whether it was restarted: a ``warm`` start that fails or is
        inconsistent is fitted again from the cold start (the unloaded screws, the known tip
        load or zero), kept when better."""
        first = self.fit(preps, tip, z0)
        if not warm or first.on_track(self.probability):
            return first, False
        inputs = self.inputs
        W_cold = inputs.tip_wrench.copy() if 'wrench' in tip else np.zeros(6)
        cold = self.fit(preps, tip, np.concatenate(
            [self.chain.unloaded_screws(inputs.rest).reshape(-1), W_cold]))
        return (cold, True) if better_fit(cold, first) else (first, False)

    def readings(self, fit: _ChainFit) -> list[tuple[str, NDArray[np.intp], int]]:
        """The readings of ``fit`` (name, rows of the residual, degrees of freedom): each
        joint's as ``joint <i> <reading>``, then the tip's ``pose`` and ``wrench``."""
        out: list[tuple[str, NDArray[np.intp], int]] = []
        row = 0
        for i, (model, p) in enumerate(zip(self.chain.joints, fit.preps, strict=True)):
            if p is None or not p.rows:
                continue
            out += [(f'joint {i + 1} {name}', rows + row, dof)
                    for name, rows, dof in p.readings(model.string_names)]
            row += p.rows
        for name in ('pose', 'wrench'):
            if name in fit.tip:
                out.append((name, np.arange(row, row + 6), 6))
                row += 6
        return out

    def refit_without(self, fit: _ChainFit, name: str) -> tuple[_ChainFit, bool]:
        """The readings of ``fit`` without ``name`` (of :meth:`readings`) fitted again from
        its estimate (a warm start): the tip pose, the tip load (which becomes unknown) or a
        joint's reading."""
        reduced, kept = list(fit.preps), fit.tip
        if name in kept:
            kept = kept - {name}
        else:
            joint, _, reading = name.partition(' ')[2].partition(' ')
            i = int(joint) - 1
            reduced[i] = reduced[i].without([reading], self.chain.joints[i].string_names)
        return self.tracked(reduced, kept, fit.z, True)


def _failed_chain(message: str, n: int, measured: int, dropped: Sequence[tuple[str, str]],
                  observable: bool, rank: int, cond: float, iterations: int = 0
                  ) -> ChainEstimate:
    return ChainEstimate(False, message, nan_array(n, 6), nan_array(6 * n, 6 * n),
                         nan_array(n, 6, 6), nan_array(6), nan_array(6, 6), nan_array(4, 4),
                         nan_array(6, 6), nan_array(6, 6), nan_array(6, 6), math.nan,
                         measured - 6, observable, rank, cond, iterations, None, None,
                         measured - 6,
                         *outlier_fields(dropped))


def _chain_estimate(chain: JointChain, inputs: _ChainInputs, fit: _ChainFit, restarted: bool,
                    dropped: Sequence[tuple[str, str]], stiffness_std: bool,
                    probability: float) -> ChainEstimate:
    """The :class:`ChainEstimate` of the last fit: a failure naming what is missing or why it
    did not converge, else the screws, the tip load, pose and stiffness with covariances."""
    n = chain.n_joints
    measured = _measured_dof(fit.preps, fit.tip)
    z, ev, iterations = fit.z, fit.ev, fit.iterations
    if ev is None:
        return _failed_chain(f'{inputs.text}: {fit.why}', n, measured, dropped, True, 0,
                             math.inf, iterations)
    r, _, _, _, state = ev
    C, rank, cond = fit.C, fit.rank, fit.cond
    if rank < 6:
        return _failed_chain(_chain_missing_message(fit.problem, z, fit.null, inputs.text,
                                                    rank), n, measured, dropped, False, rank,
                             cond, iterations)
    if not fit.converged:
        if fit.why == SINGULAR_NORMAL_MATRIX:
            # Rank 6 at the rank tolerance, but too weakly determined to solve for: named as
            # the undetermined directions are (as the joint estimator does).
            _, near, _, null = _chain_information(fit.problem, ev[1], ev[3],
                                                  NEAR_SINGULAR_TOLERANCE)
            if near < 6:
                return _failed_chain(_chain_missing_message(fit.problem, z, null, inputs.text,
                                                            near), n, measured, dropped,
                                     False, near, cond, iterations)
        return _failed_chain(f'{inputs.text}: {fit.why}', n, measured, dropped, True, rank,
                             cond, iterations)
    g, rest = inputs.gravity, inputs.rest
    xi = z[:6 * n].reshape(n, 6)
    W = z[6 * n:]
    joint_cov = np.empty((n, 6, 6))
    for i in range(n):
        P = sm.pose_jacobian(xi[i])
        joint_cov[i] = P @ C[6 * i:6 * i + 6, 6 * i:6 * i + 6] @ P.T
    T_tip = state.tip_transform
    M = np.zeros((6, 6 * n + 6))
    M[:, :6 * n] = tip_pose_jacobian(chain, xi, T_tip)
    tip_cov = M @ C @ M.T
    K_tip = chain.tip_stiffness_from_state(state, W, g)
    K_tip_std = tip_stiffness_std(chain, z, C, g, rest) if stiffness_std else nan_array(6, 6)
    return ChainEstimate(True, 'ok', xi.copy(), C[:6 * n, :6 * n], joint_cov, W.copy(),
                         C[6 * n:, 6 * n:], T_tip.copy(), 0.5 * (tip_cov + tip_cov.T), K_tip,
                         K_tip_std, float(r @ r), measured - 6, True, rank, cond, iterations,
                         state, fit.consistent(probability), measured - 6,
                         *outlier_fields(dropped), restarted)


def tip_stiffness_std(chain: JointChain, z: FloatArray, C: FloatArray, g: FloatArray,
                       rest: Any) -> FloatArray:
    """First-order std (6, 6) of the exact tip stiffness: central differences of
    :meth:`JointChain.tip_stiffness` over ``z = [xi; W]`` propagated with ``C``."""
    n = chain.n_joints
    grads = np.empty((6, 6, z.size))
    for k in range(z.size):
        values = []
        for sign in (1.0, -1.0):
            zk = z.copy()
            zk[k] += sign * STIFFNESS_STEP
            values.append(chain.tip_stiffness(zk[:6 * n].reshape(n, 6), zk[6 * n:], g,
                                              rest_lengths=rest))
        grads[:, :, k] = (values[0] - values[1]) / (2.0 * STIFFNESS_STEP)
    return entry_std(grads, C)
