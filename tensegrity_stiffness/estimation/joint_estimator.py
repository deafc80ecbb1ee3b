"""The joint's estimator (:func:`estimate_joint_state`): the weighted least-squares fit of the
screw to one instant's measurements, its covariance, observability and trust, and the fit
machinery the spine's estimator shares (:class:`EstimatorFit`, :func:`reject_contradicted`).
The method is in :mod:`~tensegrity_stiffness.estimation.estimators`.
"""

from __future__ import annotations

import functools
import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import lapack

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.least_squares import (
    SINGULAR_NORMAL_MATRIX,
    FitClock,
    InitialPointError,
    gauss_newton,
)
from tensegrity_stiffness.estimation.measurements import Measurements, PreparedMeasurements
from tensegrity_stiffness.estimation.trust import (
    CONSISTENCY_PROBABILITY,
    MAX_CONTRADICTED,
    chi2_quantile,
    consistency_threshold,
    suspect_reading,
)
from tensegrity_stiffness.geometry.screw import (
    ScrewKinematics,
    as_screws,
    check_in_chart,
    log_se3,
)
from tensegrity_stiffness.mechanics.equilibrium import (
    solve_equilibrium,
)
from tensegrity_stiffness.mechanics.joint import JointModel, JointState

FloatArray = NDArray[np.float64]

#: Converged when the Gauss-Newton decrement ``g^T A^-1 g`` (the squared length of the step in
#: units of its own std) is below this: the step left is under 0.03 standard deviations, which
#: moves the NEES by about 1e-3 (a tracker's warm start converges in one step).
DECREMENT_TOLERANCE = 1e-3
#: Gauss-Newton / Levenberg-Marquardt iterations before giving up.
MAX_ITERATIONS = 30
#: Singular values of the scaled whitened Jacobian below this fraction of the largest count as
#: zero (an unobservable direction).
RANK_TOLERANCE = 1e-9
#: A singular value of the scaled whitened Jacobian below this fraction of the largest makes
#: the normal matrix numerically singular (condition number above 1e14): a fit that stops on
#: it names that direction as undetermined.
NEAR_SINGULAR_TOLERANCE = 1e-7
#: Central-difference step (rad, m) of dK_c/dxi for the std of K_c.
STIFFNESS_STEP = 1e-6
#: Names of the pose coordinates in the PoseWithCovariance order.
POSE_AXES = ('x', 'y', 'z', 'rx', 'ry', 'rz')
#: The length (m) that scales translations against rotations is at least this: rest lengths of
#: denormal size (a hostile ``~/rest_lengths``) would make it zero.
MIN_LENGTH_SCALE = 1e-6


def translation_scale(rest: FloatArray) -> float:
    """The mean rest length (m), at least :data:`MIN_LENGTH_SCALE`."""
    return max(float(np.add.reduce(rest)) / rest.size, MIN_LENGTH_SCALE)  # sum(), less wrapping


# ---------------------------------------------------------------------------------- joint
@dataclass
class JointEstimate:
    """Outcome of :func:`estimate_joint_state`.

    ``screw`` (6,), ``transform`` (4, 4) and ``covariance`` (6, 6) of the pose in the
    PoseWithCovariance convention; ``screw_covariance`` (6, 6) of the screw coordinates;
    ``external_wrench`` (6,) the load implied at the estimate (``-F(xi)``) with
    ``wrench_covariance`` (6, 6); ``state`` the :class:`JointState` at the estimate (wrench, K,
    K_c, tensions, slack ...); ``cartesian_stiffness_std`` (6, 6) the first-order std of K_c;
    ``chi2`` the weighted squared residual and ``dof`` its degrees of freedom (measured degrees
    of freedom minus 6); ``observable``, ``rank`` (of 6) and ``condition_number`` of the scaled
    whitened Jacobian; ``iterations``. When ``success`` is False the numbers are NaN (never a
    guess) and ``message`` says why.

    Trust: ``redundancy`` the measured degrees of freedom of the readings kept minus the 6
    unknowns (= ``dof``); ``consistent`` the chi-square test of ``chi2`` at
    ``consistency_probability`` (True / False; None without redundancy: the set cannot check
    itself); ``outliers`` the readings left out by name (``tension[<string>]``,
    ``length[<string>]``, ``gravity``, ``pose``, ``wrench``) with ``outlier_reasons`` (why, one
    each: impossible, or contradicted by the others); ``restarted`` when the warm start lost
    track (an inconsistent or failed estimate) and the estimate is a cold start's.

    Motion (the recursive filter's; the static estimator assumes rest: zeros): ``twist`` (6,)
    the rate of the pose in the PoseWithCovariance convention, ``[dp/dt; w]`` in {1} (the
    velocity of {2}'s origin and link 2's angular velocity, both in {1}: the order and frame
    of ``covariance``), with ``twist_covariance`` (6, 6).
    """

    success: bool
    message: str
    screw: FloatArray
    transform: FloatArray
    covariance: FloatArray
    screw_covariance: FloatArray
    external_wrench: FloatArray
    wrench_covariance: FloatArray
    state: JointState | None
    cartesian_stiffness_std: FloatArray
    chi2: float
    dof: int
    observable: bool
    rank: int
    condition_number: float
    iterations: int
    inputs: str = ''
    singular_values: FloatArray = field(default_factory=lambda: np.empty(0), repr=False)
    consistent: bool | None = None
    redundancy: int = 0
    outliers: tuple[str, ...] = ()
    outlier_reasons: tuple[str, ...] = ()
    restarted: bool = False
    twist: FloatArray = field(default_factory=lambda: np.zeros(6))
    twist_covariance: FloatArray = field(default_factory=lambda: np.zeros((6, 6)))


def nan_array(*shape: int) -> FloatArray:
    """A new float array of ``shape`` filled with NaN (the fields of a failed estimate)."""
    out = np.empty(shape)
    out.fill(np.nan)
    return out


def outlier_fields(dropped: Sequence[tuple[str, str]]
                    ) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """An estimate's ``outliers`` and ``outlier_reasons`` from the (name, why) left out."""
    if not dropped:
        return (), ()
    return tuple(name for name, _ in dropped), tuple(f'{name}: {why}' for name, why in dropped)


class JointProblem:
    """The whitened residual and Jacobian of one joint's measurements at a screw."""

    def __init__(self, model: JointModel, prep: PreparedMeasurements, rest: FloatArray) -> None:
        self.model = model
        self.prep = prep
        self.rest = rest
        self.length_scale = translation_scale(rest)

    def evaluate(self, xi: FloatArray, jacobian: bool = True
                 ) -> tuple[FloatArray, FloatArray | None, JointState, ScrewKinematics | None]:
        """Whitened residual (rows,), Jacobian (rows, 6), joint state and kinematics at xi;
        without ``jacobian`` the residual and the state alone (Jacobian None; the kinematics
        too, unless the compiled kernel computed them with the state at no extra cost)."""
        p = self.prep
        r = np.empty(p.rows)
        J = np.empty((p.rows, 6)) if jacobian else None
        kin = None
        row = 0
        if (p.needs_strings and jacobian) or self.model.uses_kernel:
            pred = sm.string_predictions_unchecked(self.model, xi, self.rest)
            state, kin = pred.state, pred.kinematics
            strings = ((pred.tensions, pred.tension_jacobian),
                       (pred.lengths, pred.length_jacobian))
        else:
            state = self.model.evaluate(xi, self.rest)
            strings = ((state.tensions, None), (state.lengths, None))
            if jacobian:
                kin = ScrewKinematics(xi)
        for (index, values, weight), (h, dh) in zip(
                ((p.tension_index, p.tensions, p.tension_weight),
                 (p.length_index, p.lengths, p.length_weight)), strings, strict=True):
            k = index.size
            if k == p.n_strings:  # every string measured: no gather
                np.multiply(h - values, weight, out=r[row:row + k])
                if J is not None:
                    np.multiply(dh, weight[:, None], out=J[row:row + k])
            elif k:
                r[row:row + k] = (h[index] - values) * weight
                if J is not None:
                    J[row:row + k] = dh[index] * weight[:, None]
            row += k
        if p.pose is not None:  # checked in PreparedMeasurements: not again per evaluation
            pose_kin = kin if kin is not None else ScrewKinematics(xi)
            res, jac = sm.pose_residual_unchecked(
                pose_kin.T, p.pose, None if J is None else sm.pose_jacobian(xi, pose_kin))
            r[row:row + 6] = p.pose_whitener @ res
            if J is not None:
                J[row:row + 6] = p.pose_whitener @ jac
            row += 6
        if p.gravity is not None:
            if J is not None:
                g2, jac = sm.gravity_prediction_unchecked(kin, p.gravity_base)
                J[row:row + 3] = jac * p.gravity_weight[:, None]
            else:  # g_2 = R^T g_1 with R of the evaluated state
                g2 = state.transform[:3, :3].T @ p.gravity_base
            r[row:row + 3] = (g2 - p.gravity) * p.gravity_weight
            row += 3
        if p.wrench is not None:
            # e = F(xi) + W_m, de/dxi = K (sensor_models.equilibrium_residual, from this state)
            r[row:row + 6] = p.wrench_whitener @ (state.wrench + p.wrench)
            if J is not None:
                J[row:row + 6] = p.wrench_whitener @ state.stiffness
        return r, J, state, kin


def _scaled_svd(J: FloatArray, length_scale: float) -> tuple[FloatArray, FloatArray]:
    """Singular values (6,) and right singular vectors (rows, in screw coordinates) of the
    whitened Jacobian with the translation columns scaled by ``length_scale`` (zero rows added
    when there are fewer than 6, so that every direction gets a singular value)."""
    scale = np.array([1.0] * 3 + [length_scale] * 3)
    Js = J * scale
    if Js.shape[0] < 6:
        Js = np.vstack([Js, np.zeros((6 - Js.shape[0], 6))])
    _, s, Vt = np.linalg.svd(Js, full_matrices=False)
    return s, Vt * scale


def describe_direction(pose_change: FloatArray, length_scale: float) -> str:
    """A pose change [dp; dtheta] in words, the translation or rotation that dominates
    (``length_scale`` m per rad): how every estimator names an undetermined direction."""
    dp, dth = pose_change[:3], pose_change[3:]
    if np.linalg.norm(dth) * length_scale >= np.linalg.norm(dp):
        kind = 'rotation about'
        axis = dth / np.linalg.norm(dth)
    else:
        kind = 'translation along'
        axis = dp / np.linalg.norm(dp)
    return f'{kind} {axis_words(axis)}'


def axis_words(axis: FloatArray) -> str:
    """An undetermined direction's unit axis (3,) as ``(x, y, z)`` to 2 decimals, its sign
    chosen so that the largest component is positive (the direction's sign is arbitrary) and
    no ``-0.00``."""
    if axis[np.argmax(np.abs(axis))] < 0.0:
        axis = -axis
    x, y, z = np.round(axis, 2) + 0.0
    return f'({x:.2f}, {y:.2f}, {z:.2f})'


def missing_message(prep: PreparedMeasurements, names: Sequence[str], rank: int,
                     null_directions: list[str], slack: Sequence[str]) -> str:
    """Why a joint's measurement set cannot determine the pose, and what would."""
    inputs = prep.describe(names)
    if prep.dof < 6:
        head = (f'{inputs}: {prep.dof} measured degree{"s" if prep.dof != 1 else ""} of '
                f'freedom cannot determine the 6 of the pose')
    else:
        head = f'{inputs}: they determine only {rank} of the 6 pose coordinates'
    if null_directions:
        head += '; undetermined: ' + '; '.join(null_directions)
    if slack:
        head += f'; slack strings carry no tension information ({", ".join(slack)})'
    need = 6 - rank
    load = '' if prep.wrench is not None else ', or the load (external_wrench: zero or measured)'
    return (f'{head}. Add at least {need} independent measurement{"s" if need > 1 else ""}: '
            f'more string tensions or lengths, a pose, gravity (fixes 2 rotations){load}')


def _observability(problem: JointProblem, J: FloatArray, state: JointState,
                   kin: ScrewKinematics, rank_tolerance: float
                   ) -> tuple[int, float, FloatArray, str]:
    """(rank, condition number, singular values, message when rank < 6)."""
    prep = problem.prep
    s, Vt = _scaled_svd(J, problem.length_scale)
    largest = s[0]
    rank = int(np.sum(s > rank_tolerance * largest)) if largest > 0 else 0
    cond = float(largest / s[-1]) if s[-1] > 0 else math.inf
    if rank == 6:
        return rank, cond, s, ''
    P = sm.pose_jacobian(state.screw, kin)
    null = Vt[rank:]
    words = [describe_direction(P @ v, problem.length_scale) for v in null]
    slack = [problem.model.string_names[i] for i in prep.tension_index if state.slack[i]]
    return rank, cond, s, missing_message(prep, problem.model.string_names, rank, words,
                                                slack)


def cartesian_stiffness_jacobian(model: JointModel, xi: ArrayLike,
                                 rest_lengths: ArrayLike | None = None,
                                 step: float = STIFFNESS_STEP) -> FloatArray:
    """``dK_c/dxi`` (6, 6, 6) by central differences (one batched evaluation of 12 screws)."""
    xi = as_screws(xi)
    steps = _STIFFNESS_STEPS if step == STIFFNESS_STEP else np.vstack(
        [np.eye(6), -np.eye(6)]) * step
    Kc = model.evaluate(xi + steps, rest_lengths).cartesian_stiffness
    return np.moveaxis((Kc[:6] - Kc[6:]) / (2.0 * step), 0, -1)


#: dK_c/dxi is reused for the std of K_c while the screw stays within this distance (rad, and
#: metres over the mean rest length) of where it was computed: it changes on the scale of the
#: joint (radians, its size), so the std's relative error stays below about this much (1%: a
#: tracker's consecutive estimates differ by their noise, a few mrad, and reuse it).
STIFFNESS_JACOBIAN_REUSE = 1e-2


_STIFFNESS_JACOBIANS: weakref.WeakKeyDictionary[JointModel, tuple[FloatArray, FloatArray,
                                                                   FloatArray]] = \
    weakref.WeakKeyDictionary()


def stiffness_jacobian_near(model: JointModel, xi: FloatArray, rest: FloatArray) -> FloatArray:
    """:func:`cartesian_stiffness_jacobian` at ``xi``, or the one computed last for this model
    and rest lengths when ``xi`` is within :data:`STIFFNESS_JACOBIAN_REUSE` of its screw (a
    tracker's consecutive estimates: 12 evaluations saved per estimate)."""
    cached = _STIFFNESS_JACOBIANS.get(model)
    if cached is not None:
        at, cached_rest, G = cached
        d = xi - at
        length = translation_scale(rest)
        wx, wy, wz, vx, vy, vz = d.tolist()
        if (max(abs(wx), abs(wy), abs(wz), abs(vx) / length, abs(vy) / length, abs(vz) / length)
                <= STIFFNESS_JACOBIAN_REUSE
                and (rest is cached_rest or np.array_equal(rest, cached_rest))):
            return G
    G = cartesian_stiffness_jacobian(model, xi, rest)
    # the model's own rest lengths are kept by identity (never mutated), others copied
    _STIFFNESS_JACOBIANS[model] = (xi.copy(),
                                   rest if rest is model.rest_lengths else rest.copy(), G)
    return G


#: The 12 central-difference steps of :func:`cartesian_stiffness_jacobian` (+ then -).
_STIFFNESS_STEPS = np.vstack([np.eye(6), -np.eye(6)]) * STIFFNESS_STEP


def entry_std(jacobian: FloatArray, covariance: FloatArray) -> FloatArray:
    """sqrt(diag(g C g^T)) per entry of a matrix with Jacobian (a, b, k)."""
    a, b, k = jacobian.shape
    G = jacobian.reshape(a * b, k)
    variance = np.add.reduce((G @ covariance) * G, axis=1)
    return np.sqrt(np.maximum(variance, 0.0, out=variance)).reshape(a, b)


def _failed_joint(message: str, prep: PreparedMeasurements | None, names: Sequence[str],
                  observable: bool, rank: int, cond: float, iterations: int = 0,
                  s: FloatArray | None = None, dropped: Sequence[tuple[str, str]] = ()
                  ) -> JointEstimate:
    return JointEstimate(False, message, nan_array(6), nan_array(4, 4), nan_array(6, 6),
                         nan_array(6, 6), nan_array(6),
                         nan_array(6, 6), None, nan_array(6, 6), math.nan,
                         0 if prep is None else prep.dof - 6, observable, rank, cond,
                         iterations, '' if prep is None else prep.describe(names),
                         np.empty(0) if s is None else s, None,
                         0 if prep is None else prep.dof - 6, *outlier_fields(dropped))


def _initial_screw(model: JointModel, prep: PreparedMeasurements, rest: FloatArray,
                   initial_screw: ArrayLike | None, clock: FitClock | None = None
                   ) -> FloatArray:
    """The start of a fit: ``initial_screw`` (checked), else the measured pose, else the
    equilibrium under the measured load (solved within the time ``clock`` leaves), else
    ``model.initial_screw``."""
    if initial_screw is not None:
        x0 = np.array(initial_screw, dtype=np.float64)
        if x0.shape != (6,) or not math.isfinite(sum(x0.tolist())):  # NaN or inf in x0
            x0 = as_screws(x0, 'initial_screw')  # names the problem
            raise ValueError(f'initial_screw must have shape (6,), got {x0.shape}')
        check_in_chart(x0, 'initial_screw')
        return x0
    if prep.pose is not None:
        return log_se3(prep.pose, model.initial_screw)
    if prep.wrench is not None:
        res = solve_equilibrium(model, prep.wrench, rest,
                                time_budget=None if clock is None else clock.remaining())
        if res.success:
            return res.screw
    return model.initial_screw.copy()


class EstimatorFit:
    """What the trust rules ask of a fit, a joint's (:class:`_JointFit`) or a spine's (the
    chain estimator's): its whitened residual ``r``, Jacobian ``J`` and covariance ``C``, chi2
    (``r^T r``, inf when the fit has no residual) and redundancy, and whether it converged with
    full rank."""

    r: FloatArray
    J: FloatArray
    C: FloatArray
    chi2: float
    converged: bool
    rank: int

    @property
    def redundancy(self) -> int:
        raise NotImplementedError

    @property
    def ok(self) -> bool:
        return self.converged and self.rank == 6 and math.isfinite(self.chi2)

    def consistent(self, probability: float) -> bool | None:
        """The chi-square test at ``probability`` (checked by the public functions); None
        without redundancy."""
        redundancy = self.redundancy
        if redundancy <= 0:
            return None
        return self.chi2 <= chi2_quantile(redundancy, probability)

    def on_track(self, probability: float) -> bool:
        """Whether the fit succeeded and passes the chi-square test (or has no redundancy)."""
        return self.ok and self.consistent(probability) is not False


_F = TypeVar('_F', bound=EstimatorFit)


@dataclass
class _JointFit(EstimatorFit):
    """One Gauss-Newton fit of a joint's readings and its information (``chi2`` computed
    once: the trust rules ask for it several times)."""

    problem: JointProblem
    x: FloatArray
    r: FloatArray
    J: FloatArray
    state: JointState
    kin: ScrewKinematics
    iterations: int
    converged: bool
    why: str
    C: FloatArray
    s: FloatArray
    rank: int
    cond: float
    chi2: float

    @property
    def redundancy(self) -> int:
        return self.problem.prep.dof - 6


def _fit_joint(model: JointModel, prep: PreparedMeasurements, rest: FloatArray,
               x0: FloatArray, tolerance: float, max_iterations: int, rank_tolerance: float,
               clock: FitClock | None = None) -> _JointFit:
    """Gauss-Newton from ``x0`` (within the estimate's ``clock``) and the covariance, rank and
    condition at the optimum; :class:`InitialPointError` when ``x0`` cannot be evaluated."""
    problem = JointProblem(model, prep, rest)
    x, ev, iterations, converged, why = gauss_newton(
        problem.evaluate, x0, problem.length_scale, max_iterations, tolerance, clock)
    r, J, A, state, kin = ev
    if kin is None:  # the kinematics at the estimate x (J: at the linearisation)
        kin = ScrewKinematics(x)
    C, s = _information(A, problem.length_scale)
    values = s.tolist()  # descending
    largest, smallest = values[0], values[-1]
    rank = sum(1 for v in values if v > rank_tolerance * largest) if largest > 0 else 0
    cond = largest / smallest if smallest > 0 else math.inf
    return _JointFit(problem, x, r, J, state, kin, iterations, converged, why, C, s, rank, cond,
                     float(r @ r))


def better_fit(cold: EstimatorFit, warm: EstimatorFit) -> bool:
    """Whether the cold start's fit beats a warm start's (it succeeded where the warm one did
    not, or reached a lower chi2)."""
    return cold.ok and (not warm.ok or cold.chi2 < warm.chi2)


def _tracked_fit(model: JointModel, prep: PreparedMeasurements, rest: FloatArray,
                 warm: FloatArray | None, probability: float,
                 options: tuple[float, int, float, FitClock]) -> tuple[_JointFit, bool]:
    """The fit from the warm start ``warm`` (a tracker's last estimate) and whether it was
    restarted: a warm start that cannot be evaluated, fails or is inconsistent has lost track
    and is fitted again from a cold start (:func:`_initial_screw` without it), whose fit is
    kept when better. Without ``warm``, the cold start's fit (ValueError when its starting
    point cannot be evaluated). The cold start (with a known load, an equilibrium solve) is
    computed only when it is used."""
    clock = options[3]
    if warm is not None:
        try:
            fit = _fit_joint(model, prep, rest, warm, *options)
        except InitialPointError:
            fit = None
        if fit is not None and fit.on_track(probability):
            return fit, False
        try:
            cold = _fit_joint(model, prep, rest, _initial_screw(model, prep, rest, None, clock),
                              *options)
        except InitialPointError:
            cold = None
        if fit is None:
            if cold is None:
                raise ValueError('initial_screw: neither the warm nor the cold start can be '
                                 'evaluated')
            return cold, True
        return (cold, True) if cold is not None and better_fit(cold, fit) else (fit, False)
    try:
        return _fit_joint(model, prep, rest, _initial_screw(model, prep, rest, None, clock),
                          *options), False
    except InitialPointError as exc:
        raise ValueError(f'initial_screw: {exc}') from None


def _joint_refit_without(model: JointModel, rest: FloatArray, probability: float,
                         options: tuple[float, int, float, FitClock], fit: _JointFit, name: str
                         ) -> tuple[_JointFit, bool] | None:
    """The joint's readings of ``fit`` without the reading ``name``, fitted again from the fit's
    estimate (:func:`_tracked_fit`); None when no start can be evaluated."""
    reduced = fit.problem.prep.without([name], model.string_names)
    try:
        return _tracked_fit(model, reduced, rest, fit.x, probability, options)
    except ValueError:
        return None


def reject_contradicted(fit: _F, restarted: bool, dropped: list[tuple[str, str]],
                         probability: float,
                         readings: Callable[[_F], list[tuple[str, NDArray[np.intp], int]]],
                         refit_without: Callable[[_F, str], tuple[_F, bool] | None]
                         ) -> tuple[_F, bool]:
    """Data snooping (docs/estimation.md#trust): while ``fit`` succeeds but fails the chi-square
    test at ``probability`` with redundancy left, the reading the others contradict
    (:func:`suspect_reading` over ``readings(fit)``) is left out and the rest fitted again by
    ``refit_without(fit, name)`` (its fit and whether it restarted cold; None when it cannot),
    at most :data:`MAX_CONTRADICTED` times. The readings left out are kept out (appended to
    ``dropped``) only when the last refit passes the test; otherwise ``fit`` stands with every
    reading, inconsistent. Returns the fit and whether it restarted cold (or ``restarted``)."""
    trial, trial_restarted, suspects = fit, restarted, []
    while (len(suspects) < MAX_CONTRADICTED and trial.ok and trial.redundancy > 0
           and trial.consistent(probability) is False):
        suspect = suspect_reading(trial.r, trial.J, trial.C, readings(trial), trial.redundancy)
        if suspect is None:
            break
        refit = refit_without(trial, suspect[0])
        if refit is None or not refit[0].ok:
            break
        trial, trial_restarted = refit[0], trial_restarted or refit[1]
        suspects.append(suspect)
    if suspects and trial.consistent(probability) is not False:
        dropped.extend(suspects)
        return trial, trial_restarted
    return fit, restarted


def _failure(fit: _JointFit, prep: PreparedMeasurements, names: Sequence[str],
             clock: FitClock, rank_tolerance: float, dropped: Sequence[tuple[str, str]]
             ) -> JointEstimate | None:
    """The failed estimate of a fit that ran out of time, left a direction undetermined or did
    not converge (each named); None when it succeeded."""
    if clock.exhausted:
        return _failed_joint(clock.message(prep.describe(names)), prep, names, True, fit.rank,
                             fit.cond, clock.iterations, fit.s, dropped)
    if fit.rank < 6:
        rank, cond, s, message = _observability(fit.problem, fit.J, fit.state, fit.kin,
                                                rank_tolerance)
        return _failed_joint(message, prep, names, False, rank, cond, fit.iterations, s,
                             dropped)
    if not fit.converged:
        if fit.why == SINGULAR_NORMAL_MATRIX:
            # Rank 6 at RANK_TOLERANCE, but too weakly determined to solve for: named as the
            # unobservable sets are (a ring joint's spin about its axis from its lengths).
            rank, cond, s, message = _observability(
                fit.problem, fit.J, fit.state, fit.kin,
                max(rank_tolerance, NEAR_SINGULAR_TOLERANCE))
            if message:
                return _failed_joint(message, prep, names, False, rank, cond, fit.iterations,
                                     s, dropped)
        return _failed_joint(f'{prep.describe(names)}: {fit.why}', prep, names, True, fit.rank,
                             fit.cond, fit.iterations, fit.s, dropped)
    return None


def estimate_joint_state(model: JointModel, measurements: Measurements | PreparedMeasurements,
                         rest_lengths: ArrayLike | None = None,
                         initial_screw: ArrayLike | None = None, *,
                         tolerance: float = DECREMENT_TOLERANCE,
                         max_iterations: int = MAX_ITERATIONS,
                         rank_tolerance: float = RANK_TOLERANCE,
                         stiffness_std: bool = True,
                         consistency_probability: float = CONSISTENCY_PROBABILITY,
                         reject_outliers: bool = True,
                         time_budget: float | None = None) -> JointEstimate:
    """Estimate the screw, the pose, the load and the stiffness from ``measurements``.

    ``rest_lengths`` (n,) the encoders' values (default: the model's); ``initial_screw`` the warm
    start (a tracker's previous estimate; default: the measured pose, else the equilibrium under
    a known load, else ``model.initial_screw``). ``stiffness_std=False`` skips the std of K_c
    (NaN). Bad input raises ValueError naming the field; an unobservable set returns
    ``success=False, observable=False`` with a message naming what is missing.

    Trust (docs/estimation.md#trust): impossible readings (:data:`IMPOSSIBLE_STD`) are left out
    by name; a warm start that loses track (inconsistent or failed) is restarted cold; while
    the estimate fails the chi-square test at ``consistency_probability`` and redundancy is
    left, the reading the others contradict (:func:`suspect_reading`) is left out and the rest
    refitted (``reject_outliers=False``: none is). The estimate says ``consistent``,
    ``redundancy`` and ``outliers``.

    ``time_budget`` (s; None: no bound): one deadline for the whole estimate (its fits and a
    cold start's equilibrium), checked between Gauss-Newton iterations once the estimate has
    taken :data:`~tensegrity_stiffness.estimation.least_squares.MIN_FIT_ITERATIONS`; an
    estimate that hits it fails with ``time budget exhausted after <k> iterations (...)``.
    """
    prep = (measurements if isinstance(measurements, PreparedMeasurements)
            else Measurements.prepared(measurements, model.n_strings))
    if prep.n_strings != model.n_strings:
        raise ValueError(f'measurements were prepared for {prep.n_strings} strings, the model '
                         f'has {model.n_strings}')
    consistency_threshold(1, consistency_probability)  # checks the probability
    clock = FitClock(tolerance, max_iterations, time_budget)
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    names = model.string_names
    dropped = prep.impossible(model, rest)
    if dropped:
        prep = prep.without([name for name, _ in dropped], names)
    if prep.dof < 6:
        message = missing_message(prep, names, prep.dof, [], [])
        if dropped:
            message += ' (left out: ' + '; '.join(f'{n} {why}' for n, why in dropped) + ')'
        return _failed_joint(message, prep, names, False, min(prep.dof, 6), math.inf,
                             dropped=dropped)
    options = (tolerance, max_iterations, rank_tolerance, clock)
    warm = None if initial_screw is None else _initial_screw(model, prep, rest, initial_screw)
    fit, restarted = _tracked_fit(model, prep, rest, warm, consistency_probability, options)
    consistent = fit.consistent(consistency_probability)
    if reject_outliers and consistent is False:  # the search runs on an inconsistent fit alone
        fit, restarted = reject_contradicted(
            fit, restarted, dropped, consistency_probability,
            lambda current: current.problem.prep.readings(names),
            functools.partial(_joint_refit_without, model, rest, consistency_probability,
                              options))
        prep = fit.problem.prep
        consistent = fit.consistent(consistency_probability)
    failed = _failure(fit, prep, names, clock, rank_tolerance, dropped)
    if failed is not None:
        return failed
    x, C, state = fit.x, fit.C, fit.state
    P = sm.pose_jacobian(x, fit.kin)  # at the estimate
    pose_cov = P @ C @ P.T
    K = state.stiffness
    Kc_std = (entry_std(stiffness_jacobian_near(model, x, rest), C) if stiffness_std
              else nan_array(6, 6))
    return JointEstimate(True, 'ok', x, state.transform.copy(), 0.5 * (pose_cov + pose_cov.T), C,
                         -state.wrench, K @ C @ K.T, state, Kc_std, fit.chi2, prep.dof - 6,
                         True, fit.rank, fit.cond, fit.iterations, prep.describe(names), fit.s,
                         consistent, prep.dof - 6, *outlier_fields(dropped), restarted)


def _information(A: FloatArray, length_scale: float) -> tuple[FloatArray, FloatArray]:
    """Covariance ``A^-1`` (6, 6) (NaN when singular) of the normal matrix ``A = J^T J`` of
    the whitened Jacobian ``J`` and the singular values (6,) of ``J`` with its translation
    columns scaled by ``length_scale`` (one symmetric eigendecomposition of the scaled normal
    matrix)."""
    outer = _column_scales(length_scale)
    w, V, info = lapack.dsyevd(A * outer)  # ascending eigenvalues (LAPACK)
    if info != 0:
        raise np.linalg.LinAlgError('eigendecomposition of the normal matrix failed')
    w, V = w[::-1], V[:, ::-1]
    s = np.sqrt(np.maximum(w, 0.0))
    if w[-1] <= 0.0:
        return nan_array(6, 6), s
    return (V / w) @ V.T * outer, s  # symmetric: V diag(1/w) V^T, scaled on both sides


_COLUMN_SCALES: dict[float, FloatArray] = {}


def _column_scales(length_scale: float) -> FloatArray:
    """``outer(c, c)`` (6, 6) of the column scale ``c = [1 1 1 L L L]`` (cached per L)."""
    outer = _COLUMN_SCALES.get(length_scale)
    if outer is None:
        scale = np.array([1.0, 1.0, 1.0, length_scale, length_scale, length_scale])
        outer = _COLUMN_SCALES[length_scale] = scale[:, None] * scale
        if len(_COLUMN_SCALES) > 64:  # rest lengths change: keep the cache small
            _COLUMN_SCALES.pop(next(iter(_COLUMN_SCALES)))
    return outer
