"""The joint's calibration (:func:`calibrate_joint`): the robust Levenberg-Marquardt fit of the
strings' stiffnesses and rest-length offsets with every sample's screw, its outliers, the
taut-branch passes, the covariance and the Cramer-Rao bound (:func:`cramer_rao_std`). The
method is in :mod:`~tensegrity_stiffness.estimation.calibration`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtri

from tensegrity_stiffness.estimation.calibration_model import (
    OFFSET_UNIT,
    STIFFNESS_UNIT,
    CalibrationEvaluation,
    CalibrationProblem,
    model_with_parameters,
    schur_complement,
    sum_of_products,
)
from tensegrity_stiffness.estimation.calibration_results import (
    PARAMETER_NAMES,
    CalibrationResult,
    Identifiability,
    checked_fit_kinds,
    describe_null_direction,
    fit_columns,
    identifiability,
    parameter_names,
    rms_by_kind,
)
from tensegrity_stiffness.estimation.calibration_samples import (
    CalibrationData,
    CalibrationNoise,
    CalibrationSample,
    measures_force,
    samples_data,
)
from tensegrity_stiffness.estimation.least_squares import (
    LevenbergMarquardtDamping,
    damped_normal_matrix,
)
from tensegrity_stiffness.geometry.screw import (
    as_screws,
    log_se3,
    log_se3_sequence,
)
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel

FloatArray = NDArray[np.float64]

#: The robust loss acts beyond this many standard deviations (``f_scale`` of least_squares).
ROBUST_SCALE = 3.0
#: A sample is an outlier when its chi-square has this upper-tail probability or less.
OUTLIER_PROBABILITY = 1e-4
#: Robust losses of scipy.optimize.least_squares.
LOSSES = ('linear', 'soft_l1', 'huber', 'cauchy', 'arctan')
#: The fit has converged when an iteration lowers the cost by less than this fraction.
FIT_TOLERANCE = 1e-8
#: ... and the fits before the final one (with the robust loss: it finds the outliers; the
#: plain fit on the inliers: it finds the strings to hold; the final fit polishes).
ROBUST_TOLERANCE = 1e-4
#: A sample with a string whose stretch is within this many std of 0 (slack) is left out.
SLACK_MARGIN = 3.0
#: Passes of "hold the strings not clearly slack on their taut branch, fit again" (until the
#: held set stops changing).
HOLD_PASSES = 4
#: Levenberg-Marquardt damping at the start of a fit from the nominal parameters ...
DAMPING = 1e-3
#: ... and of a refit from a fit's solution (the taut-branch passes: near their solution, the
#: steps are nearly Gauss-Newton's).
WARM_DAMPING = 1e-5
#: The smallest Levenberg-Marquardt damping of a fit, which is also the ridge that keeps a zero
#: diagonal entry of its normal matrices damped.
DAMPING_FLOOR = 1e-12
#: Rejected steps (damping grown tenfold each) before a fit stage stops at its point.
MAX_REJECTED_STEPS = 12
#: Levenberg-Marquardt iterations of one fit stage.
MAX_ITERATIONS = 100


def initial_screws(model: JointModel, data: CalibrationData) -> FloatArray:
    """A starting screw per sample: the measured pose's (on the rotation branch nearest the
    previous sample's screw), else the nominal model's equilibrium under the measured load
    (zero when unknown) from the previous screw."""
    if data.has_pose.all():
        return log_se3_sequence(data.poses, model.initial_screw)
    xi = np.empty((data.n_samples, 6))
    previous = model.initial_screw
    for i in range(data.n_samples):
        if data.has_pose[i]:
            xi[i] = log_se3(data.poses[i], reference=previous)
        else:
            eq = solve_equilibrium(model, data.wrench[i] if data.has_wrench[i] else np.zeros(6),
                                   data.rest[i], initial_screw=previous)
            xi[i] = eq.screw
        previous = xi[i]
    return xi


def _min_rows(data: CalibrationData) -> int:
    return int(data.mask().sum())


def _robust_weights(residuals: FloatArray, loss: str) -> tuple[FloatArray, FloatArray]:
    """Loss values ``rho`` and IRLS weights ``rho'`` of whitened residuals for scipy's losses
    (``rho(z)`` of ``z = (r / f)^2`` scaled by ``f^2``, ``f`` = :data:`ROBUST_SCALE`)."""
    f2 = ROBUST_SCALE ** 2
    z = residuals * residuals / f2
    if loss == 'linear':
        return z * f2, np.ones_like(z)
    if loss == 'soft_l1':
        t = np.sqrt(1.0 + z)
        return 2.0 * (t - 1.0) * f2, 1.0 / t
    if loss == 'huber':
        big = z > 1.0
        root = np.sqrt(np.where(big, z, 1.0))
        return np.where(big, 2.0 * root - 1.0, z) * f2, np.where(big, 1.0 / root, 1.0)
    if loss == 'cauchy':
        return np.log1p(z) * f2, 1.0 / (1.0 + z)
    return np.arctan(z) * f2, 1.0 / (1.0 + z * z)  # arctan


def _solve(problem: CalibrationProblem, z0: FloatArray, basis: FloatArray, xi0: FloatArray,
           loss: str, rows: NDArray[np.bool_], ev: CalibrationEvaluation | None = None,
           max_iterations: int = MAX_ITERATIONS, tolerance: float = FIT_TOLERANCE,
           damping: float = DAMPING
           ) -> tuple[FloatArray, FloatArray, CalibrationEvaluation, int, bool]:
    """Levenberg-Marquardt over ``z = z0 + basis y`` and every sample's screw, with the screws
    eliminated per sample (Schur complement: one q x q system per iteration) and the robust
    ``loss`` by iteratively re-weighted least squares (a descent method for these concave
    losses); only the residual rows ``rows`` (N, R) count; ``ev``: the evaluation at the start,
    when known; ``damping``: the initial Levenberg-Marquardt damping. Returns (z, screws, their
    evaluation, iterations, converged)."""
    q = basis.shape[1]
    z, xi = z0.copy(), xi0.copy()
    mask = rows.astype(np.float64)

    def cost_of(ev: CalibrationEvaluation) -> tuple[float, FloatArray]:
        rho, weight = _robust_weights(ev.residuals * mask, loss)
        return float(np.sum(rho * mask)), weight * mask

    if ev is None:
        ev = problem.evaluate(z, xi)
    cost, weight = cost_of(ev)
    lam = LevenbergMarquardtDamping(damping, growth=10.0, floor=DAMPING_FLOOR,
                                    floor_from=10.0 * DAMPING_FLOOR, largest=math.inf)
    converged = False
    iterations = 0
    for iterations in range(1, max_iterations + 1):  # noqa: B007 (returned)
        eq = problem.normal_equations(ev, weight)
        A, gx = eq.A, eq.gx
        B = eq.B @ basis  # (N, 6, q)
        C = basis.T @ eq.C @ basis
        gp = basis.T @ eq.gp
        accepted = False
        for _ in range(MAX_REJECTED_STEPS):
            A_inv = np.linalg.inv(damped_normal_matrix(A, lam.value, DAMPING_FLOOR))
            Ainv_B = A_inv @ B
            Ainv_g = (A_inv @ gx[..., None])[..., 0]
            S = damped_normal_matrix(C, lam.value, DAMPING_FLOOR) - sum_of_products(B, Ainv_B)
            rhs = gp - sum_of_products(B, Ainv_g[..., None])[:, 0]
            dy = -np.linalg.solve(S, rhs) if q else np.zeros(0)
            dxi = -(Ainv_g + Ainv_B @ dy)
            z_trial = z + basis @ dy
            try:
                xi_trial, found = problem.advance(z, xi, ev, z_trial, dxi)
                if not found.all():
                    raise ValueError('no equilibrium under a known load')
                ev_trial = problem.evaluate(z_trial, xi_trial)
            except ValueError:
                lam.rejected()
                continue
            cost_trial, weight_trial = cost_of(ev_trial)
            if cost_trial <= cost:
                accepted = True
                break
            lam.rejected()
        if not accepted:
            converged = True  # no descent direction left at working precision
            break
        decrease = cost - cost_trial
        z, xi, ev, weight = z_trial, xi_trial, ev_trial, weight_trial
        cost = cost_trial
        lam.accepted()
        if decrease <= tolerance * max(cost, 1.0):
            converged = True
            break
    return z, xi, ev, iterations, converged


def _checked_request(model: JointModel, samples: Sequence[CalibrationSample],
                     fit: Sequence[str] | str, noise: Any, loss: str,
                     bounds: Mapping[str, tuple[float, float]] | None
                     ) -> tuple[tuple[str, ...], CalibrationNoise, dict, CalibrationData,
                                list[str], NDArray[np.intp]]:
    """:func:`calibrate_joint`'s arguments checked: the fitted kinds, the noise, the bounds, the
    samples as arrays, the parameter names and their columns; ValueError names the problem
    (bad arguments, no samples, nothing that fixes the configuration, too few measurements)."""
    kinds = checked_fit_kinds(fit)
    noise = CalibrationNoise.of(noise)
    if loss not in LOSSES:
        raise ValueError(f'loss must be one of {LOSSES}, got {loss!r}')
    bounds = dict(bounds or {})
    for key, pair in bounds.items():
        if checked_fit_kinds(key)[0] not in kinds or len(pair) != 2 or not pair[0] < pair[1]:
            raise ValueError(f'bounds[{key!r}] must be (low, high) with low < high for a '
                             'fitted kind')
    data = samples_data(model, samples)
    n = model.n_strings
    N = data.n_samples
    if N == 0:
        raise ValueError('no samples')
    if not data.has_pose.any() and not data.has_wrench.any() and \
            not np.isfinite(data.lengths).any():
        raise ValueError('the samples carry no pose, no known load and no string lengths: '
                         'nothing fixes the configuration')
    names = parameter_names(kinds, n)
    columns = fit_columns(kinds, n)
    P = columns.size
    total_rows = _min_rows(data)
    if total_rows < 6 * N + P:
        raise ValueError(f'too few measurements: {total_rows} values for {6 * N} screw '
                         f'coordinates ({N} samples) and {P} parameters; record more samples '
                         'or add a sensor (pose, wrench, tensions)')
    return kinds, noise, bounds, data, names, columns


def _outliers(problem: CalibrationProblem, ev: CalibrationEvaluation, loss: str, n_parameters: int
              ) -> tuple[NDArray[np.intp], NDArray[np.intp]]:
    """(outliers, inliers) sample indices at the robust estimate (its evaluation ``ev``):
    samples whose whitened chi-square is improbable for their degrees of freedom (none for the
    linear loss); ValueError when the inliers leave too few measurements."""
    N = problem.mask.shape[0]
    sample_chi2 = np.sum(ev.residuals ** 2, axis=1)
    dof_i = problem.mask.sum(axis=1) - 6 * ~problem.exact
    limit = np.where(dof_i > 0, chdtri(np.maximum(dof_i, 1), OUTLIER_PROBABILITY), np.inf)
    outliers = np.flatnonzero(sample_chi2 > limit) if loss != 'linear' else np.zeros(0, int)
    inliers = np.setdiff1d(np.arange(N), outliers)
    if 6 * int(np.sum(~problem.exact[inliers])) + n_parameters > int(problem.mask[inliers].sum()):
        raise ValueError(f'too many outliers ({outliers.size} of {N} samples) left too few '
                         'measurements')
    return outliers, inliers


def _std_map(names: list[str], std: FloatArray, flags: Any, ident: Any,
             kinds: tuple[str, ...], n_parameters: int) -> dict[str, float]:
    """The std by parameter name: NaN where not identifiable, except the stiffness ratios of a
    scale-free fit, which keep their (constrained) std."""
    std_map = {name: (float(s) if flag else math.nan)
               for name, s, flag in zip(names, std, flags, strict=True)}
    if 'stiffness' in kinds and not ident.basis.shape[1] == n_parameters:
        for name, s, flag in zip(names, std, flags, strict=True):
            if not flag and name.startswith('stiffness') and _only_scale_unidentifiable(
                    ident, names, name):
                std_map[name] = float(s)
    return std_map


def _outside_bounds(bounds: Mapping[str, tuple[float, float]], names: list[str],
                    parameters: Mapping[str, float]) -> str:
    """The message for the last fitted value outside its kind's ``bounds`` ('' when none)."""
    message = ''
    for key, (low, high) in bounds.items():
        kind = checked_fit_kinds(key)[0]
        for name in names:
            if name.startswith(PARAMETER_NAMES[kind].split('[')[0] + '[') and \
                    not low <= parameters[name] <= high:
                message = f'{name} = {parameters[name]:.6g} is outside bounds [{low}, {high}]'
    return message


def _identified_basis(problem: CalibrationProblem, before: Any, columns: NDArray[np.intp],
                      kinds: tuple[str, ...], names: list[str], noise: CalibrationNoise
                      ) -> tuple[Any, FloatArray]:
    """The identifiability of the fitted parameters at the nominal ``before`` (the overall
    stiffness scale held when no force is measured) and its basis in all 2n parameters."""
    model, data = problem.model, problem.data
    n = model.n_strings
    P = columns.size
    held = np.zeros((P, 0))
    if 'stiffness' in kinds and not measures_force(data, noise):
        held = np.zeros((P, 1))
        held[:n, 0] = 1.0 / math.sqrt(n)  # stiffness columns come first
    ident = identifiability(problem.information(before, columns), names,
                            lambda v: describe_null_direction(v, names, model, data, kinds,
                                                              noise), held)
    basis_full = np.zeros((2 * n, ident.basis.shape[1]))
    basis_full[columns] = ident.basis
    return ident, basis_full


def _covariance(problem: CalibrationProblem, ev: Any, columns: NDArray[np.intp], basis: FloatArray
                ) -> FloatArray:
    """The fitted parameters' covariance (physical units) at the evaluation ``ev`` of the
    inliers, within the identifiable subspace ``basis``."""
    cov_scaled = _subspace_covariance(problem.information(ev, columns), basis)
    unit = problem.unit[columns]
    return cov_scaled * unit[:, None] * unit[None, :]


def calibrate_joint(model: JointModel, samples: Sequence[CalibrationSample],
                    fit: Sequence[str] | str = ('stiffness', 'rest_length_offsets'),
                    noise: CalibrationNoise | Mapping[str, float] | None = None,
                    loss: str = 'soft_l1',
                    bounds: Mapping[str, tuple[float, float]] | None = None,
                    progress: Callable[[int, int], None] | None = None) -> CalibrationResult:
    """Fit each string's stiffness and rest-length offset of ``model`` (the nominal) to
    ``samples``; see the module docstring for the data model and the method.

    ``fit``: kinds of :data:`FIT_KINDS`; ``noise``: :class:`CalibrationNoise` or a mapping of
    its fields (defaults: pose 0.1 mm and 0.1 deg, wrench 0.01 N and 0.0005 N m, tension
    0.005 N, length 0.1 mm); ``loss``: one of :data:`LOSSES` (robust losses act beyond
    :data:`ROBUST_SCALE` sigma); ``bounds``: ``{kind: (low, high)}`` plausibility limits on the
    fitted values (stiffness in N/m, offsets in m): a value outside makes ``success`` False and
    names it. ``progress(done, total)`` is called between the stages. Bad input raises
    ValueError naming the field; too few samples or measurements raise ValueError saying what
    is missing. (Long: the four stages in order, each a helper: check, identify, fit, and the
    statistics of the estimate.)
    """
    started = time.perf_counter()
    kinds, noise, bounds, data, names, columns = _checked_request(
        model, samples, fit, noise, loss, bounds)
    n = model.n_strings
    P = columns.size
    stages = 4
    if progress:
        progress(0, stages)
    problem = CalibrationProblem(model, data, noise)
    z_nominal = np.zeros(2 * n)
    xi = problem.refine_screws(z_nominal, initial_screws(model, data))
    before = problem.evaluate(z_nominal, xi)
    rms_before = rms_by_kind(before.raw, problem.mask, n)
    ident, basis_full = _identified_basis(problem, before, columns, kinds, names, noise)
    if progress:
        progress(1, stages)

    rows = problem.mask.copy()
    iterations = 0
    converged = True
    z, xi_fit, ev_all = z_nominal, xi, before
    if basis_full.shape[1]:
        # The first fit only finds the outliers (and for the linear loss the strings to hold;
        # the final fit polishes): a looser tolerance.
        z, xi_fit, ev_all, used, converged = _solve(
            problem, z_nominal, basis_full, xi, loss, rows, before,
            tolerance=ROBUST_TOLERANCE)
        iterations += used
    if progress:
        progress(2, stages)
    outliers, inliers = _outliers(problem, ev_all, loss, P)
    message = 'converged'
    rows[outliers] = False
    near_slack = np.zeros(0, np.intp)
    if basis_full.shape[1] and loss != 'linear':
        # Plain least squares on the inliers, from the robust solution: the strings to hold are
        # found at a plain fit (loose: the final fit polishes).
        z, xi_fit, ev_all, used, converged = _solve(problem, z, basis_full, xi_fit, 'linear',
                                                    rows, ev_all, tolerance=ROBUST_TOLERANCE)
        iterations += used
    if basis_full.shape[1]:
        # The final estimate: plain least squares on the inliers, the strings not clearly
        # slack held on their taut branch.
        z, xi_fit, ev_all, used, converged, near_slack = _hold_taut(
            problem, z, xi_fit, ev_all, basis_full, rows, inliers, columns, ident.basis,
            refit=True)
        iterations += used
    success = True
    if not basis_full.shape[1]:
        success, message = False, ('no parameter is identifiable from these samples: all held '
                                   'at nominal')
    elif not converged:
        success, message = False, f'no convergence in {MAX_ITERATIONS} iterations'
    if progress:
        progress(3, stages)

    # The evaluation at the estimate: the inliers' rows give the statistics, all rows the
    # residuals after (every sample's rows depend on its own screw only).
    ev = ev_all.subset(inliers)
    mask_in = problem.mask[inliers]
    rms_after = rms_by_kind(ev.raw, mask_in, n)
    chi2_value = float(np.sum(ev.residuals ** 2))
    dof = int(mask_in.sum()) - 6 * int(np.sum(~problem.exact[inliers])) - ident.basis.shape[1]
    covariance = _covariance(problem, ev, columns, ident.basis)
    k, d = problem.parameters(z)
    values_all = np.concatenate([k, d])
    nominal_all = np.concatenate([model.k, np.zeros(n)])
    ident_flags = _identifiable_flags(ident, P)
    std = np.sqrt(np.maximum(np.diag(covariance), 0.0))
    parameters = {name: float(values_all[c]) for name, c in zip(names, columns, strict=True)}
    nominal = {name: float(nominal_all[c]) for name, c in zip(names, columns, strict=True)}
    std_map = _std_map(names, std, ident_flags, ident, kinds, P)
    bounds_problem = _outside_bounds(bounds, names, parameters)
    if bounds_problem:
        success, message = False, bounds_problem
    calibrated = model_with_parameters(model, k, model.rest_lengths + d)
    if progress:
        progress(4, stages)
    return CalibrationResult(
        success=success, message=message, model=calibrated, names=names,
        parameters=parameters, std=std_map, covariance=covariance,
        identifiable=dict(zip(names, map(bool, ident_flags), strict=True)),
        unidentifiable=ident.descriptions, singular_values=ident.singular_values,
        residual_rms_before=rms_before, residual_rms_after=rms_after,
        outliers=outliers.tolist(), near_slack=near_slack.tolist(), iterations=iterations,
        screws=xi_fit, chi2=chi2_value, dof=dof, nominal=nominal, offsets=d,
        residuals_before=np.where(problem.mask, before.raw, np.nan),
        residuals_after=np.where(problem.mask, ev_all.raw, np.nan),
        seconds=time.perf_counter() - started)


def _hold_taut(problem: CalibrationProblem, z: FloatArray, xi: FloatArray,
               ev: CalibrationEvaluation, basis_full: FloatArray, rows: NDArray[np.bool_],
               inliers: NDArray[np.intp],
               columns: NDArray[np.intp], basis: FloatArray, refit: bool
               ) -> tuple[FloatArray, FloatArray, CalibrationEvaluation, int, bool,
                          NDArray[np.intp]]:
    """The plain least-squares fit of the residual rows ``rows`` from ``(z, xi)`` (evaluated:
    ``ev``) with every string of the inliers that is not clearly slack there (stretch above
    ``-SLACK_MARGIN`` std, :func:`_stretch_std`) held on its taut branch (:func:`_taut_branch`),
    repeated until the held set stops changing the model (at most :data:`HOLD_PASSES` fits;
    holding a string changes the model only where it is slack, so a change elsewhere needs no
    fit). ``refit``: ``(z, xi)`` is a loose fit only, so the first fit is made whatever it
    holds. Near ``l = l0`` the model is not smooth: a fit
    free to slacken a string that is taut in truth (its fitted stretch a little below zero
    through the noise) loses that string's information there and leans on it, and its error
    exceeds the covariance (docs/calibration.md, "Near a string's slack boundary"). Returns
    (z, screws, their evaluation, iterations, converged, the samples with a string within
    ``SLACK_MARGIN`` std of slack at ``(z, xi)``)."""
    stretch, std = _stretch_std(problem, ev.subset(inliers), columns, basis)
    near = inliers[np.any(np.abs(stretch) < SLACK_MARGIN * std, axis=1)]
    iterations, converged = 0, True
    for _ in range(HOLD_PASSES):
        held = stretch > -SLACK_MARGIN * std
        if not refit and not np.any((held != problem.taut[inliers]) & (stretch <= 0.0)):
            break
        refit = False
        problem.taut[inliers] = held
        xi = problem.settle_exact(z, xi)  # the held strings move the equilibria
        z, xi, ev, used, converged = _solve(problem, z, basis_full, xi, 'linear', rows,
                                            damping=WARM_DAMPING)
        iterations += used
        if not converged:
            break
        stretch, std = _stretch_std(problem, ev.subset(inliers), columns, basis)
    return z, xi, ev, iterations, converged, near


def _stretch_std(problem: CalibrationProblem, ev: CalibrationEvaluation, columns: NDArray[np.intp],
                 basis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(stretch ``l_j - l0_j``, its std) (N, n) of the samples of ``ev`` (a linear fit's
    inliers, with Jacobians). The std is linearized in the sample's own unknown and the
    parameters with their joint covariance (Schur complement:
    ``Cov u = A^+ + A^+ B C B^T A^+``, ``Cov(u, z) = -A^+ B C``; the screw
    ``d xi = G du + H dz``, ``G = -K^-1``, ``H = G dF/dz`` for a known load, else ``G = I``,
    ``H = 0``): ``Cov xi = G A^+ G^T + D C D^T``, ``Cov(xi, z) = -D C`` with
    ``D = G A^+ B - H``."""
    n = problem.n
    information, A_pinv, AB = schur_complement(problem.normal_equations(ev), columns)
    C = _subspace_covariance(information, basis)
    loaded = problem.loaded[ev.index][:, None, None]
    G = np.where(loaded, -ev.wrench_screw_inverse, np.eye(6))
    H = np.where(loaded, G @ ev.wrench_parameters[:, :, columns], 0.0)
    L = ev.stretch_screw  # (N, n, 6)
    LG = L @ G
    LD = L @ (G @ AB - H)  # (N, n, P)
    LDC = LD @ C
    var = np.sum((LG @ A_pinv) * LG, axis=-1) + np.sum(LDC * LD, axis=-1)
    for j in range(n):  # the offset d_j = OFFSET_UNIT z_{n+j} when fitted
        at = np.flatnonzero(columns == n + j)
        if at.size:
            c = int(at[0])
            var[:, j] += OFFSET_UNIT * (OFFSET_UNIT * C[c, c] + 2.0 * LDC[:, j, c])
    return ev.stretch, np.sqrt(np.maximum(var, 0.0))


def _only_scale_unidentifiable(ident: Identifiability, names: Sequence[str], name: str) -> bool:
    return any(text.startswith('the common scale') for text in ident.descriptions) and \
        name not in [names[j] for j in ident.zero_columns]


def _identifiable_flags(ident: Identifiability, P: int) -> NDArray[np.bool_]:
    """A parameter is identifiable when no unidentifiable direction involves it."""
    if ident.null.shape[1] == 0:
        return np.ones(P, bool)
    return np.max(np.abs(ident.null), axis=1) < 1e-6


def _subspace_covariance(information: FloatArray, basis: FloatArray) -> FloatArray:
    """``V (V^T S V)^-1 V^T``: the covariance with the unidentifiable directions held."""
    if basis.shape[1] == 0:
        return np.zeros_like(information)
    reduced = basis.T @ information @ basis
    return basis @ np.linalg.solve(reduced, basis.T)


def cramer_rao_std(model: JointModel, true_stiffness: ArrayLike, true_offsets: ArrayLike,
                   true_screws: ArrayLike, samples: Sequence[CalibrationSample],
                   fit: Sequence[str] | str = ('stiffness', 'rest_length_offsets'),
                   noise: CalibrationNoise | Mapping[str, float] | None = None,
                   basis: FloatArray | None = None) -> FloatArray:
    """Cramer-Rao bound (std, units of each parameter, order of ``result.names``) of the
    parameters for the data model of :func:`calibrate_joint`, at the true parameters and
    screws: the inverse of the information with the screws eliminated (in the subspace
    ``basis`` (P, q) of the scaled coordinates when some directions are held)."""
    kinds = checked_fit_kinds(fit)
    data = samples_data(model, samples)
    problem = CalibrationProblem(model, data, CalibrationNoise.of(noise))
    n = model.n_strings
    k = np.asarray(true_stiffness, dtype=np.float64)
    z = np.concatenate([(k - problem.k_nominal) / (STIFFNESS_UNIT * problem.k_nominal),
                        np.asarray(true_offsets, dtype=np.float64) / OFFSET_UNIT])
    ev = problem.evaluate(z, as_screws(true_screws))
    columns = fit_columns(kinds, n)
    info = problem.information(ev, columns)
    V = np.eye(columns.size) if basis is None else basis
    cov = _subspace_covariance(info, V)
    unit = problem.unit[columns]
    return np.sqrt(np.maximum(np.diag(cov), 0.0)) * unit
