"""Calibration of a joint model from a recording: each string's stiffness ``k_j`` and rest-length
offset ``d_j`` (true rest length = commanded + ``d_j``), with identifiability and uncertainty.

Data model (one :class:`CalibrationSample` per quasi-static instant i)
----------------------------------------------------------------------
The unknowns are the parameters ``theta`` (the chosen subset of ``k``, ``d``) and every sample's
screw ``xi_i`` (the measured pose is a noisy measurement, not the truth: holding the screw at the
measured pose biases the stiffness low and the bias does not shrink with more samples). Each
measurement gives whitened residuals (measurement noise std ``sigma`` from
:class:`CalibrationNoise`):

* pose (motion capture): ``[p(xi) - p_m; log(R(xi) R_m^T)] / sigma`` -- the
  ``PoseWithCovariance`` convention (``p -> p + dp``, ``R -> exp(hat(dtheta)) R``, in {1}, ordered
  ``[x y z rx ry rz]``); a measured ``screw`` is the pose ``exp(hat(screw))``;
* equilibrium with a measured external wrench ``W_m`` (force-torque sensor on link 2, in {1}
  about its origin; zeros for "unloaded"): ``(F(xi; theta) + W_m) / sigma`` (Monke & Vikas eq. 9
  for ``F``); no residual when the load is unknown. With a known load the sample's own unknown
  is its true load ``W = -F(xi)`` instead of its screw (:meth:`_Problem.normal_equations`: the
  screw is the equilibrium under ``W``, solved by Newton after every step,
  :meth:`_Problem.advance`), so that a precise reading converges; an **exact** load (zeros,
  or every known load when the load noise is 0: :attr:`CalibrationNoise.exact_loads`) is no
  unknown: the equilibrium under it is a constraint and its rows are no residuals;
* load cells: ``(phi_j(xi; theta) - t_j) / sigma`` for every measured string (eq. 8, the
  model's force law);
* string lengths: ``(l_j(xi) - l_m) / sigma`` (eq. 7).

Jacobians (analytic). :mod:`tensegrity_stiffness.estimation.sensor_models` defines every
measurement model
and its Jacobians for one screw (shared with the estimator); the calibration evaluates the same
models for all samples at once (:class:`_Problem`, one batched :meth:`JointModel.evaluate` per
iteration), held to ``sensor_models`` sample by sample and to central differences in
``test/estimation/test_calibration_jacobians.py``. With ``u_j = s_j / l_j``, ``m_j = p1_j x u_j``,
``w_j = [u_j; m_j]`` and ``J`` the SE(3) left Jacobian (twist ``[omega; v] = J dxi``):
``d l_j / d xi = -[m_j^T, u_j^T] J``, ``d phi_j / d xi = phi_j' d l_j / d xi``,
``d F / d xi = K`` (eq. 10), pose ``[[-hat(p), I], [Jl^-1(phi), 0]] J``; parameters
(``sensor_models.string_parameter_jacobians``): ``d phi_j / d k_j = phi_j / k_j``,
``d phi_j / d d_j = d phi_j / d l0_j``, ``d F / d k_j = (phi_j / k_j) w_j``,
``d F / d d_j = (d phi_j / d l0_j) w_j``.

Method
------
1. Initial screws: the measured pose (log map on the branch nearest the previous sample's),
   else the nominal model's equilibrium under the measured (or zero) load; then every screw is
   refined with the parameters at nominal (batched Gauss-Newton per sample).
2. Identifiability at nominal: the screws are eliminated (Schur complement per sample), which
   leaves the parameters' information ``S = sum_i C_i - B_i^T A_i^+ B_i`` (``A = Jx^T Jx``,
   ``B = Jx^T Jp``, ``C = Jp^T Jp`` of the whitened Jacobian); its eigenvalues are the squared
   singular values of the weighted Jacobian with the screws projected out. In the scaled
   coordinates ``z_k = (k - k_nom) / (STIFFNESS_UNIT k_nom)``, ``z_d = d / OFFSET_UNIT``, a
   direction is unidentifiable when its singular value is below ``RANK_TOLERANCE`` times the
   largest or its standard deviation exceeds 1 (the data determine it worse than
   :data:`STIFFNESS_UNIT` of the nominal stiffness or :data:`OFFSET_UNIT` of offset). The fit
   moves only in the identifiable subspace: unidentifiable directions stay at nominal. Without
   a force measurement (no load cell, known loads zero within their noise:
   :func:`measures_force`) the common scale of the stiffnesses is held as well.
3. Fit (:func:`_solve`): Levenberg-Marquardt over the subspace coordinates and every screw,
   the screws eliminated per sample (one q x q system per iteration, q <= 24: the sparse
   structure "parameters + one screw per sample" solved exactly), with the robust ``loss`` (the
   losses of ``scipy.optimize.least_squares``, acting beyond :data:`ROBUST_SCALE` sigma) by
   iteratively re-weighted least squares, to :data:`ROBUST_TOLERANCE` (it only finds the
   outliers); samples whose whitened chi-square exceeds the ``1 - OUTLIER_PROBABILITY``
   quantile are outliers; a plain least-squares fit on the inliers, warm-started (the first fit
   itself for the linear loss; to the same tolerance), finds the strings to hold, and a final
   plain least-squares fit gives the estimate. ``scipy.optimize.least_squares`` with the same
   sparse Jacobian (LSMR) reaches the same plain least-squares estimate (0.001 std apart with no
   string held; ``bench/bench_calibration.py`` prints both, the library's with the strings held
   below: 0.5 std apart, scipy 2.8x the time at 1,000 samples); the elimination solves each step
   exactly and gives the information of step 2 and the covariance from the same blocks.
   That final fit holds every string that is not clearly slack at the plain fit (its stretch
   ``l_j - l0_j`` above ``-SLACK_MARGIN`` std) on its taut branch (:func:`_taut_branch`: eq. 8
   continued below ``l0``, smooth) and is repeated until that set stops changing the model
   (:func:`_hold_taut`): the model is not smooth at ``l = l0``, and a fit free to slacken a
   string that is taut in truth leans on the lost information and reports too small a std.
   The samples with a string within ``SLACK_MARGIN`` std of slack at the plain fit are counted
   (``near_slack``).
4. Covariance ``V (V^T S V)^-1 V^T`` (``V`` the identifiable subspace, ``S`` at the estimate):
   the Gauss-Newton covariance, equal to the Cramer-Rao bound of the same data model at the
   truth (:func:`cramer_rao_std`).
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtri

from tensegrity_stiffness.estimation.least_squares import (
    LevenbergMarquardtDamping,
    damped_normal_matrix,
)
from tensegrity_stiffness.geometry.screw import (
    as_screws,
    exp_se3,
    hat3,
    left_jacobian_se3,
    left_jacobian_so3_inverse,
    log_se3,
    log_se3_sequence,
    log_so3_batch,
    single_screw,
)
from tensegrity_stiffness.geometry.transforms import adjoint, rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array, finite_scalar, per_string
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel, JointState

#: Largest max-abs deviation of R^T R from I accepted in a recorded (4, 4) pose (poses read
#: from recordings carry the rounding of their source).
RECORDED_ROTATION_TOLERANCE = 1e-6

FloatArray = NDArray[np.float64]

#: Parameter kinds that :func:`calibrate_joint` can fit (``fit=``), in the order of the vector.
FIT_KINDS = ('stiffness', 'rest_length_offsets')
#: Name of parameter j of each kind (``parameters`` keys).
PARAMETER_NAMES = {'stiffness': 'stiffness[{j}]', 'rest_length_offsets': 'rest_length_offset[{j}]'}
#: Units of each kind (tables).
PARAMETER_UNITS = {'stiffness': 'N/m', 'rest_length_offsets': 'm'}
#: Scaled coordinates: one unit is this fraction of the nominal stiffness ...
STIFFNESS_UNIT = 0.5
#: ... and this offset (m). A direction whose std exceeds one unit is unidentifiable.
OFFSET_UNIT = 5e-3
#: Singular values below this fraction of the largest count as zero (numerical rank).
RANK_TOLERANCE = 1e-6
#: Residual kinds (rows of a sample: pose 6, wrench 6, tensions n, lengths n) and their units.
RESIDUAL_KINDS = ('position', 'rotation', 'force', 'moment', 'tension', 'length')
RESIDUAL_UNITS = {'position': 'm', 'rotation': 'rad', 'force': 'N', 'moment': 'N m',
                  'tension': 'N', 'length': 'm'}
#: The robust loss acts beyond this many standard deviations (``f_scale`` of least_squares).
ROBUST_SCALE = 3.0
#: A sample is an outlier when its chi-square has this upper-tail probability or less.
OUTLIER_PROBABILITY = 1e-4
#: Known loads measure a force when their chi-square has this upper-tail probability or less.
SCALE_TEST_PROBABILITY = 1e-3
#: Robust losses of scipy.optimize.least_squares.
LOSSES = ('linear', 'soft_l1', 'huber', 'cauchy', 'arctan')
#: Gauss-Newton iterations of the per-sample screw refinement ...
SCREW_ITERATIONS = 8
#: ... in which a sample stops when its step moves no screw coordinate more than this (rad,
#: m; far below any sensor's noise: the fit moves every screw again).
SCREW_TOLERANCE = 1e-6
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
#: Rows of each product in a sum over the samples (:func:`_sum_of_products`): small enough that
#: BLAS computes it on one thread.
SUM_BLOCK_ROWS = 256
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
#: A sample with a known load is at equilibrium when every component of ``F + W`` is below this
#: (N, N m) ...
EQUILIBRIUM_TOLERANCE = 1e-11
#: ... within this many Newton iterations.
EQUILIBRIUM_ITERATIONS = 30


@dataclass(frozen=True)
class CalibrationNoise:
    """Standard deviation of each measurement kind (the defaults: a motion-capture system, a
    six-axis force-torque sensor, inline load cells, string encoders)."""

    position: float = 1e-4          # m (0.1 mm)
    rotation: float = math.radians(0.1)  # rad (0.1 deg)
    force: float = 0.01             # N
    moment: float = 5e-4            # N m
    tension: float = 0.005          # N
    length: float = 1e-4            # m

    def __post_init__(self) -> None:
        for kind in RESIDUAL_KINDS:
            value = finite_scalar(f'noise.{kind}', getattr(self, kind))
            if value < 0.0 or (value == 0.0 and kind not in ('force', 'moment')):
                raise ValueError(f'noise.{kind} must be > 0, got {value}')
        if (self.force == 0.0) != (self.moment == 0.0):
            raise ValueError('noise.force and noise.moment must both be 0 (the known loads are '
                             f'exact) or both > 0, got {self.force} and {self.moment}')

    @property
    def exact_loads(self) -> bool:
        """Whether the known loads are exact (force and moment noise 0): each is a constraint
        on its sample's screw, not a reading."""
        return self.force == 0.0

    @classmethod
    def of(cls, noise: CalibrationNoise | Mapping[str, float] | None) -> CalibrationNoise:
        """``noise`` as a :class:`CalibrationNoise` (a mapping overrides the defaults it
        names; ``pose`` sets position (m) and ``wrench`` force (N) for short)."""
        if noise is None:
            return cls()
        if isinstance(noise, CalibrationNoise):
            return noise
        values = dict(noise)
        if 'pose' in values:
            values.setdefault('position', values.pop('pose'))
        if 'wrench' in values:
            values.setdefault('force', values.pop('wrench'))
        unknown = sorted(set(values) - set(RESIDUAL_KINDS))
        if unknown:
            raise ValueError(f'noise: unknown kinds {unknown} '
                             f'(known: {", ".join(RESIDUAL_KINDS)})')
        return cls(**{k: float(v) for k, v in values.items()})

    def row_std(self, n: int) -> FloatArray:
        """Std of every residual row of a sample: pose (6), wrench (6), tensions (n),
        lengths (n)."""
        return np.concatenate([np.full(3, self.position), np.full(3, self.rotation),
                               np.full(3, self.force), np.full(3, self.moment),
                               np.full(n, self.tension), np.full(n, self.length)])


@dataclass(frozen=True)
class CalibrationSample:
    """One quasi-static instant of a recording.

    ``rest_lengths`` (n,) m: the commanded values (encoders); ``pose``: link 2 in {1} measured by
    motion capture, (4, 4) or ``[x y z qx qy qz qw]``; ``screw`` (6,): the same as a screw (give
    one of the two); ``tensions`` (n,) N from load cells, NaN where none; ``lengths`` (n,) m
    measured string lengths, NaN where none; ``external_wrench`` (6,) a force-torque reading on
    link 2 in the library's convention ([N; N m], in {1} about its origin): None when unknown,
    zeros when unloaded.
    """

    rest_lengths: ArrayLike
    pose: ArrayLike | None = None
    screw: ArrayLike | None = None
    tensions: ArrayLike | None = None
    lengths: ArrayLike | None = None
    external_wrench: ArrayLike | None = None


@dataclass
class _Data:
    """The samples as arrays (N samples, n strings); absent measurements NaN / masked."""

    rest: FloatArray            # (N, n) commanded
    poses: FloatArray           # (N, 4, 4), NaN where no pose
    has_pose: NDArray[np.bool_]
    wrench: FloatArray          # (N, 6), 0 where unknown
    has_wrench: NDArray[np.bool_]
    tensions: FloatArray        # (N, n) NaN where none
    lengths: FloatArray         # (N, n) NaN where none

    @property
    def n_samples(self) -> int:
        return self.rest.shape[0]

    def mask(self) -> NDArray[np.bool_]:
        """(N, 12 + 2n) rows that carry a measurement."""
        return np.hstack([np.repeat(self.has_pose[:, None], 6, axis=1),
                          np.repeat(self.has_wrench[:, None], 6, axis=1),
                          np.isfinite(self.tensions), np.isfinite(self.lengths)])


def _samples_data(model: JointModel, samples: Sequence[CalibrationSample]) -> _Data:
    """Validate the samples (ValueError naming ``samples[i].field``) into arrays."""
    n = model.n_strings
    N = len(samples)
    rest = np.empty((N, n))
    poses = np.full((N, 4, 4), np.nan)
    has_pose = np.zeros(N, bool)
    wrench = np.zeros((N, 6))
    has_wrench = np.zeros(N, bool)
    tensions = np.full((N, n), np.nan)
    lengths = np.full((N, n), np.nan)
    for i, s in enumerate(samples):
        where = f'samples[{i}]'
        if not isinstance(s, CalibrationSample):
            raise ValueError(f'{where} is not a CalibrationSample')
        rest[i] = per_string(f'{where}.rest_lengths', s.rest_lengths, n)
        if np.any(rest[i] <= 0.0):
            raise ValueError(f'{where}.rest_lengths must be > 0')
        if s.pose is not None and s.screw is not None:
            raise ValueError(f'{where}: give pose or screw, not both')
        if s.pose is not None:
            poses[i] = rigid_transform(s.pose, f'{where}.pose', RECORDED_ROTATION_TOLERANCE)
            has_pose[i] = True
        elif s.screw is not None:
            poses[i] = exp_se3(single_screw(s.screw, f'{where}.screw', in_chart=False))
            has_pose[i] = True
        tensions[i] = per_string(f'{where}.tensions', s.tensions, n, not_measured=True)
        lengths[i] = per_string(f'{where}.lengths', s.lengths, n, not_measured=True)
        if s.external_wrench is not None:
            w = finite_array(f'{where}.external_wrench', s.external_wrench)
            if w.shape != (6,):
                raise ValueError(f'{where}.external_wrench must have shape (6,), got {w.shape}')
            wrench[i] = w
            has_wrench[i] = True
    return _Data(rest, poses, has_pose, wrench, has_wrench, tensions, lengths)


# ------------------------------------------------------------------------------ the model
def model_with_parameters(model: JointModel, stiffness: ArrayLike,
                          rest_lengths: ArrayLike | None = None) -> JointModel:
    """A copy of ``model`` with stiffness ``k`` (n,) and rest lengths (n,) (default its own);
    each string keeps its maximum stretch."""
    rest = model.rest_lengths if rest_lengths is None else model.validate_rest_lengths(
        rest_lengths, batched=False)
    return JointModel(model.link1_nodes, model.connections, stiffness, rest,
                      link2_nodes=model.link2_nodes, max_lengths=rest + model.max_stretch,
                      force_law=model.force_law, node_names=model.node_names,
                      link2_node_names=model.link2_node_names, string_names=model.string_names,
                      initial_screw=model.initial_screw, use_kernel=model.uses_kernel)


def _tension_rest_length_slopes(model: JointModel, state: JointState, rest: FloatArray
                                ) -> FloatArray:
    """``d phi / d l0`` of every string for a batch of states (eq. 8 and the model's force law;
    the maximum stretch ``lmax - l0`` is held, as :class:`JointModel` does): the batched form of
    ``sensor_models.string_parameter_jacobians(...).tension_rest_length``."""
    k = model.k
    taut = ~(state.slack | state.saturated)
    if model.force_law == 'hooke':
        return np.where(taut, -k, 0.0)
    # 'paper': -k / l taut, -k s_max / lmax^2 (= -phi / lmax) saturated
    lmax = rest + model.max_stretch
    with np.errstate(invalid='ignore'):
        saturated_slope = -k * model.max_stretch / (lmax * lmax)
    return np.where(taut, -k / state.lengths, np.where(state.saturated, saturated_slope, 0.0))


def _taut_branch(model: JointModel, state: JointState, xi: FloatArray, rest: FloatArray,
                 held: NDArray[np.bool_]) -> tuple[JointState, FloatArray]:
    """``state`` (N samples) with every string of ``held`` (N, n) that it finds slack continued
    on its taut branch (eq. 8 without the clamp at zero: a slightly negative tension), and
    ``d phi / d l`` (N, n) to match: the model of a fit that holds those strings taut, smooth
    across ``l = l0``. Each continued string adds ``phi_j w_j`` to the wrench and
    ``Z_j A_j [hat(q_j), -I] J`` to ``K`` (eq. 10, ``A_j = gamma_j s_j s_j^T + beta_j I``)."""
    dphi = model.string_forces(state.lengths, rest)[1]
    cont = held & state.slack & ~state.saturated
    if not cont.any():
        return state, dphi
    i, j = np.nonzero(cont)
    length, l0, k = state.lengths[i, j], rest[i, j], model.k[j]
    if model.force_law == 'hooke':
        phi, slope = k * (length - l0), k
    else:  # 'paper'
        phi, slope = k * (length - l0) / length, k * l0 / (length * length)
    s = state.string_vectors[i, j]
    p1 = model.link1_string_nodes[j]
    beta = phi / length
    gamma = (slope - beta) / (length * length)
    A = gamma[:, None, None] * s[:, :, None] * s[:, None, :] + beta[:, None, None] * np.eye(3)
    Z = np.concatenate([np.broadcast_to(np.eye(3), A.shape), hat3(p1)], axis=1)  # (m, 6, 3)
    motion = np.concatenate([hat3(p1 - s), np.broadcast_to(-np.eye(3), A.shape)], axis=2)
    K = Z @ A @ motion @ left_jacobian_se3(xi[i])
    tensions, wrench, stiffness = state.tensions.copy(), state.wrench.copy(), \
        state.stiffness.copy()
    tensions[i, j] = phi
    dphi = dphi.copy()
    dphi[i, j] = slope
    np.add.at(wrench, i, beta[:, None] * (Z @ s[..., None])[..., 0])
    np.add.at(stiffness, i, K)
    slack = state.slack & ~cont
    return replace(state, tensions=tensions, slack=slack, wrench=wrench, stiffness=stiffness), dphi


def _string_wrench_directions(model: JointModel, state: JointState) -> FloatArray:
    """``w_j = [u_j; p1_j x u_j]`` (..., n, 6): the wrench of a unit tension in string j."""
    u = state.string_vectors / state.lengths[..., None]
    return np.concatenate([u, np.cross(model.link1_string_nodes, u)], axis=-1)


def _empty() -> FloatArray:
    """The placeholder (0,) of an array not computed."""
    return np.empty(0)


@dataclass
class _Evaluation:
    """Whitened residuals (N, R) and their Jacobians w.r.t. the screws and the scaled parameters
    at one point (rows: pose 6, wrench 6, tensions n, lengths n). The Jacobians are kept for the
    rows some sample measures only (``rows``, m of R: :attr:`_Problem.rows`), and the one w.r.t.
    the parameters for those of them that depend on the parameters (the wrench and the
    tensions: ``rows[parameter_block]``); :attr:`jac_screw` and :attr:`jac_parameters` spread
    them over all R rows."""

    residuals: FloatArray
    raw: FloatArray  # unwhitened residuals (N, R)
    wrench: FloatArray  # F(xi; theta) (N, 6), every sample
    stretch: FloatArray  # l_j - l0_j (N, n): negative when slack
    index: NDArray[np.intp]  # the samples evaluated (N,)
    rows: NDArray[np.intp]  # the residual rows of the Jacobians (m,)
    parameter_block: slice  # the rows of ``rows`` that depend on the parameters
    # With the Jacobians (else empty):
    screw_rows: FloatArray = field(default_factory=_empty)  # d r / d xi (N, m, 6) whitened
    wrench_screw: FloatArray = field(default_factory=_empty)  # d F / d xi = K (N, 6, 6)
    # K^-1 (N, 6, 6) of the samples with a known load (:meth:`_Problem.normal_equations`), else 0
    wrench_screw_inverse: FloatArray = field(default_factory=_empty)
    stretch_screw: FloatArray = field(default_factory=_empty)  # d l_j / d xi (N, n, 6)
    # With the parameter Jacobians (else empty):
    parameter_rows: FloatArray = field(default_factory=_empty)  # d r / d z (N, mp, 2n) whitened
    wrench_parameters: FloatArray = field(default_factory=_empty)  # d F / d z (N, 6, 2n)

    def subset(self, samples: NDArray[np.int64]) -> _Evaluation:
        """The evaluation of the samples ``samples`` (positions in this one) only (this one
        itself when they are all of its samples)."""
        if np.array_equal(samples, np.arange(len(self.index))):
            return self
        return replace(self, **{name: a[samples] for name, a in self._per_sample().items()})

    def assign(self, samples: NDArray[np.int64], other: _Evaluation) -> None:
        """Overwrite the samples ``samples`` (positions in this one) with ``other`` (their
        evaluation)."""
        for name, a in self._per_sample().items():
            a[samples] = getattr(other, name)

    def _per_sample(self) -> dict[str, FloatArray]:
        """The arrays with one entry per sample (those computed: not (0,))."""
        return {f.name: getattr(self, f.name) for f in fields(self)
                if f.name not in ('rows', 'parameter_block')
                and getattr(self, f.name).shape != (0,)}

    @property
    def jac_screw(self) -> FloatArray:
        """d r / d xi (N, R, 6) over all rows (zeros where no sample measures)."""
        out = np.zeros(self.residuals.shape + (6,))
        out[:, self.rows] = self.screw_rows
        return out

    @property
    def jac_parameters(self) -> FloatArray:
        """d r / d z (N, R, 2n) over all rows (zeros where no parameter acts)."""
        out = np.zeros(self.residuals.shape + self.parameter_rows.shape[-1:])
        out[:, self.rows[self.parameter_block]] = self.parameter_rows
        return out


@dataclass
class _NormalEquations:
    """The Gauss-Newton blocks of the (weighted) whitened problem in the coordinates of
    :meth:`_Problem.normal_equations`: per sample ``A = Jx^T Jx`` (N, 6, 6),
    ``B = Jx^T Jz`` (N, 6, 2n), ``gx = Jx^T r`` (N, 6); summed over the samples
    ``C = sum Jz^T Jz`` (2n, 2n) and ``gp = sum Jz^T r`` (2n,) (``B``, ``C``, ``gp`` empty
    without the parameter Jacobians)."""

    A: FloatArray
    B: FloatArray
    C: FloatArray
    gx: FloatArray
    gp: FloatArray


class _Problem:
    """The calibration problem on fixed data: evaluation of residuals and Jacobians at
    (stiffness k, offsets d, screws xi)."""

    def __init__(self, model: JointModel, data: _Data, noise: CalibrationNoise) -> None:
        self.model = model
        self.data = data
        self.n = model.n_strings
        std = noise.row_std(self.n)
        self.std = np.where(std > 0.0, std, 1.0)  # exact loads: constraints, no residual rows
        # Known loads: each sample's own unknown is its true load (the screw is the equilibrium
        # under it); exact loads (zeros: "unloaded", or zero load noise) have none.
        self.loaded = data.has_wrench.copy()
        self.exact = data.has_wrench & (noise.exact_loads | np.all(data.wrench == 0.0, axis=1))
        self.mask = data.mask()
        self.mask[self.exact, 6:12] = False
        #: The residual rows some sample measures: the Jacobians are kept for these only; the
        #: block of them that depends on the parameters (the wrench and the tensions).
        self.rows = np.flatnonzero(self.mask.any(axis=0))
        self.parameter_block = slice(*np.searchsorted(self.rows, [6, 12 + self.n]))
        self.k_nominal = model.k.copy()
        # Scaled coordinates: k = k_nom (1 + STIFFNESS_UNIT z_k), d = OFFSET_UNIT z_d.
        self.unit = np.concatenate([STIFFNESS_UNIT * self.k_nominal, np.full(self.n, OFFSET_UNIT)])
        self._models: dict[bytes, JointModel] = {}
        #: (N, n) strings held on their taut branch (:func:`_taut_branch`): none at first.
        self.taut = np.zeros((data.n_samples, self.n), bool)

    def parameters(self, z: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(k, d) of scaled coordinates z (2n,)."""
        p = z * self.unit
        return self.k_nominal + p[:self.n], p[self.n:]

    def _model(self, k: FloatArray) -> JointModel:
        key = k.tobytes()
        found = self._models.get(key)
        if found is None:
            if len(self._models) > 8:
                self._models.clear()
            found = self._models[key] = model_with_parameters(self.model, k)
        return found

    def evaluate(self, z: FloatArray, xi: FloatArray, jacobians: bool = True,
                 parameter_jacobians: bool = True,
                 samples: NDArray[np.intp] | None = None) -> _Evaluation:
        """Residuals at (z, xi) of the samples ``samples`` (default all; ``xi`` theirs); with
        ``jacobians`` their Jacobian w.r.t. the screws, and with ``parameter_jacobians`` as well
        the one w.r.t. the parameters."""
        n, data = self.n, self.data
        sel: Any = slice(None) if samples is None else samples  # all: views, no copies
        k, d = self.parameters(z)
        if np.any(k <= 0.0):
            raise ValueError('a stiffness reached zero')
        model = self._model(k)
        rest = data.rest[sel] + d
        if np.any(rest <= 0.0):
            raise ValueError('a rest length reached zero')
        state, dphi_dl = _taut_branch(model, model.evaluate(xi, rest), xi, rest,
                                      self.taut[sel])
        N = xi.shape[0]
        raw = np.zeros((N, 12 + 2 * n))
        T = state.transform
        p = T[:, :3, 3]
        poses = data.poses[sel]
        has_pose = data.has_pose[sel]
        posed: Any = slice(None) if has_pose.all() else has_pose
        phi = np.zeros((N, 3))
        if has_pose.any():
            raw[posed, :3] = p[posed] - poses[posed, :3, 3]
            phi[posed] = log_so3_batch(
                T[posed, :3, :3] @ np.swapaxes(poses[posed, :3, :3], -1, -2))
            raw[:, 3:6] = phi
        raw[:, 6:12] = state.wrench + data.wrench[sel]
        raw[:, 12:12 + n] = state.tensions - data.tensions[sel]
        raw[:, 12 + n:] = state.lengths - data.lengths[sel]
        mask = self.mask[sel]
        raw = np.where(mask, raw, 0.0)
        residuals = raw / self.std
        stretch = state.lengths - rest
        index = np.arange(N) if samples is None else np.array(samples)
        ev = _Evaluation(residuals, raw, state.wrench, stretch, index, self.rows,
                         self.parameter_block)
        if not jacobians:
            return ev
        J = left_jacobian_se3(xi)  # (N, 6, 6): twist [omega; v] = J dxi
        # Pose: d p = omega x p + v, d log(R R_m^T) = Jl^-1(phi) omega.
        jt = np.zeros((N, 6, 6))
        jt[:, :3, :3] = -hat3(p)
        jt[:, :3, 3:] = np.eye(3)
        jt[:, 3:, :3] = left_jacobian_so3_inverse(phi)
        w = _string_wrench_directions(model, state)  # (N, n, 6)
        dl = -np.concatenate([w[..., 3:], w[..., :3]], axis=-1) @ J  # (N, n, 6)
        jx = np.concatenate([jt @ J, state.stiffness, dphi_dl[..., None] * dl, dl], axis=1)
        scale = mask / self.std  # (N, R)
        ev.screw_rows = jx[:, self.rows] * scale[:, self.rows, None]
        ev.wrench_screw, ev.stretch_screw = state.stiffness, dl
        loaded = self.loaded[sel]
        if loaded.all():
            ev.wrench_screw_inverse = np.linalg.inv(state.stiffness)
        else:
            ev.wrench_screw_inverse = np.zeros((N, 6, 6))
            if loaded.any():
                ev.wrench_screw_inverse[loaded] = np.linalg.inv(state.stiffness[loaded])
        if parameter_jacobians:
            ev.parameter_rows, ev.wrench_parameters = self._parameter_jacobians(
                model, state, w, rest, scale)
        return ev

    def _parameter_jacobians(self, model: JointModel, state: JointState, w: FloatArray,
                             rest: FloatArray, scale: FloatArray) -> tuple[FloatArray, FloatArray]:
        """(whitened d r / d z (N, mp, 2n) of the rows that depend on the parameters and some
        sample measures (``rows[parameter_block]``: wrench, tensions), unwhitened d F / d z
        (N, 6, 2n)) in scaled coordinates, for the string wrench directions ``w`` and the row
        scales ``mask / std`` (N, R)."""
        n = self.n
        unit_k, unit_d = self.unit[:n], self.unit[n:]
        dphi_dk = state.tensions / model.k * unit_k
        dphi_dl0 = _tension_rest_length_slopes(model, state, rest) * unit_d
        wrench_parameters = np.swapaxes(np.concatenate(
            [w * dphi_dk[..., None], w * dphi_dl0[..., None]], axis=1), 1, 2)
        rows = self.rows[self.parameter_block]
        jp = np.zeros((len(w), rows.size, 2 * n))
        wrench = np.flatnonzero(rows < 12)  # wrench rows 6-11, then tension rows 12 + j
        jp[:, wrench] = wrench_parameters[:, rows[wrench] - 6] * scale[:, rows[wrench], None]
        at = np.flatnonzero(rows >= 12)
        j = rows[at] - 12
        jp[:, at, j] = dphi_dk[:, j] * scale[:, rows[at]]
        jp[:, at, n + j] = dphi_dl0[:, j] * scale[:, rows[at]]
        return jp, wrench_parameters

    # -------------------------------------------------------------- known loads
    def normal_equations(self, ev: _Evaluation, weights: FloatArray | None = None
                         ) -> _NormalEquations:
        """The Gauss-Newton blocks at ``ev`` (rows weighted by ``weights`` (N, R), else 1),
        with every sample with a known load in the chart of its true load ``W = -F(xi)``
        instead of its screw (the screw is the equilibrium under ``W``:
        ``d xi = M (dW + dF/dz dz)``, ``M = -K^-1``): ``Jx' = Jx M``, ``Jz' = Jz + Jx H``,
        ``H = M dF/dz``, taken on the blocks (``A' = M^T A M``, ``B' = M^T (B + A H)``,
        ``C' = C + B^T H + H^T (B + A H)``, ``gx' = M^T gx``, ``gp' = gp + H^T gx``) rather than
        on the (N, R, .) Jacobians. An exact load is no unknown (``Jx' = 0``): the equilibrium
        is a constraint and the parameters' Jacobian is that of the constrained model."""
        jx, jp, r = ev.screw_rows, ev.parameter_rows, ev.residuals[:, ev.rows]
        block = ev.parameter_block
        if weights is not None:
            sw = np.sqrt(weights[:, ev.rows])
            jx, r = jx * sw[..., None], r * sw
            jp = jp * sw[:, block, None]
        jxt = np.swapaxes(jx, -1, -2)
        A = jxt @ jx
        gx = (jxt @ r[..., None])[..., 0]
        parameters = ev.wrench_parameters.size > 0
        B = C = gp = _empty()
        if parameters:
            B = jxt[:, :, block] @ jp
            C = _sum_of_products(jp, jp)
            gp = _sum_of_products(jp, r[:, block, None])[:, 0]
        loaded: Any = self.loaded[ev.index]
        if loaded.any():
            loaded = slice(None) if loaded.all() else np.flatnonzero(loaded)  # views: no copies
            M = -ev.wrench_screw_inverse[loaded]
            Mt = np.swapaxes(M, -1, -2)
            A_l, gx_l = A[loaded], gx[loaded]
            if parameters:
                H = M @ ev.wrench_parameters[loaded]  # d xi / d z under a fixed load
                B_l = B[loaded]
                moved = B_l + A_l @ H  # Jx^T Jz'
                C += _sum_of_products(B_l, H) + _sum_of_products(H, moved)
                gp += _sum_of_products(H, gx_l[..., None])[:, 0]
                B[loaded] = Mt @ moved
            A[loaded] = Mt @ A_l @ M
            gx[loaded] = (Mt @ gx_l[..., None])[..., 0]
            exact = self.exact[ev.index]
            if exact.any():
                A[exact], gx[exact] = 0.0, 0.0
                if parameters:
                    B[exact] = 0.0
        return _NormalEquations(A, B, C, gx, gp)

    def advance(self, z: FloatArray, xi: FloatArray, ev: _Evaluation, z_new: FloatArray,
                step: FloatArray) -> tuple[FloatArray, NDArray[np.bool_]]:
        """The screws after a step from ``(z, xi)`` (evaluated: ``ev``, of its samples) to
        ``z_new`` with ``step`` (N, 6) in :meth:`normal_equations`' coordinates: ``xi + step``
        without a known load; else the equilibrium at ``z_new`` under the true load
        ``-F(xi) + step`` (an exact load: the load itself), by Newton from the linear
        prediction. Returns (screws, found)."""
        xi_new = xi + step
        rows = np.flatnonzero(self.loaded[ev.index])
        found = np.ones(len(xi), bool)
        if rows.size == 0:
            return xi_new, found
        samples = ev.index[rows]
        target = np.where(self.exact[samples, None], self.data.wrench[samples],
                          -ev.wrench[rows] + step[rows])
        change = target + ev.wrench[rows]
        if ev.wrench_parameters.size:  # parameters moved as well
            change = change + ev.wrench_parameters[rows] @ (z_new - z)
        start = xi[rows] - (ev.wrench_screw_inverse[rows] @ change[..., None])[..., 0]
        xi_new[rows], found[rows] = self.settle(z_new, start, target, samples)
        return xi_new, found

    def settle(self, z: FloatArray, xi: FloatArray, loads: FloatArray, rows: NDArray[np.intp]
               ) -> tuple[FloatArray, NDArray[np.bool_]]:
        """Screws of the samples ``rows`` at equilibrium under ``loads`` (``F(xi; z) + W = 0``
        within :data:`EQUILIBRIUM_TOLERANCE`) by Newton's method from ``xi``, each iteration on
        the samples not at equilibrium yet. Returns (screws, found)."""
        k, d = self.parameters(z)
        model = self._model(k)
        rest = self.data.rest[rows] + d
        xi = xi.copy()
        found = np.zeros(len(rows), bool)
        todo = np.arange(len(rows))
        for _ in range(EQUILIBRIUM_ITERATIONS):
            at = xi[todo]
            try:
                state = _taut_branch(model, model.evaluate(at, rest[todo]), at, rest[todo],
                                     self.taut[rows[todo]])[0]
            except ValueError:
                return xi, np.zeros(len(rows), bool)
            error = state.wrench + loads[todo]
            done = np.max(np.abs(error), axis=1) <= EQUILIBRIUM_TOLERANCE
            found[todo[done]] = True
            if done.all():
                break
            try:
                step = np.linalg.solve(state.stiffness[~done], error[~done, :, None])[..., 0]
            except np.linalg.LinAlgError:
                return xi, np.zeros(len(rows), bool)
            todo = todo[~done]
            xi[todo] = at[~done] - step
            if not np.isfinite(xi[todo]).all():
                return xi, np.zeros(len(rows), bool)
        return xi, found

    # -------------------------------------------------------------- screws with fixed theta
    def refine_screws(self, z: FloatArray, xi: FloatArray,
                      iterations: int = SCREW_ITERATIONS) -> FloatArray:
        """Every sample's screw by Gauss-Newton with the parameters fixed (batched, with
        :meth:`_screw_line_search`; a sample stops when its step is below
        :data:`SCREW_TOLERANCE`)."""
        xi = self.settle_exact(z, xi)
        ev = self.evaluate(z, xi, parameter_jacobians=False)
        cost = np.sum(ev.residuals ** 2, axis=1)
        for _ in range(iterations):
            eq = self.normal_equations(ev)
            step = -(_pinv_psd(eq.A) @ eq.gx[..., None])[..., 0]
            moving = np.max(np.abs(step), axis=1) >= SCREW_TOLERANCE
            if not moving.any():
                break
            # Only the samples still moving iterate on.
            ev, step, cost = ev.subset(np.flatnonzero(moving)), step[moving], cost[moving]
            xi[ev.index], ev = self._screw_line_search(z, xi[ev.index], ev, step, cost)
            cost = np.sum(ev.residuals ** 2, axis=1)
        return xi

    def _screw_line_search(self, z: FloatArray, xi: FloatArray, ev: _Evaluation,
                           step: FloatArray, cost: FloatArray) -> tuple[FloatArray, _Evaluation]:
        """The screws of the samples of ``ev`` (at ``xi``, their costs ``cost``) after the
        Gauss-Newton ``step`` with the parameters ``z`` fixed, and their evaluation (with the
        screw Jacobians: the next iteration's): a step that raises a sample's cost is halved
        up to 4 times (only those samples are tried again), else that sample keeps its
        screw."""
        trial, tev = xi.copy(), None
        alpha = np.ones(len(xi))
        retry = np.arange(len(xi))
        for _ in range(5):
            tried = ev.subset(retry)
            moved, found = self.advance(z, xi[retry], tried, z, alpha[retry, None] * step[retry])
            moved[~found] = xi[retry][~found]
            try:
                moved_ev = self.evaluate(z, moved, parameter_jacobians=False,
                                         samples=tried.index)
            except ValueError:
                alpha[retry] *= 0.5
                continue
            worse = ~found | (np.sum(moved_ev.residuals ** 2, axis=1)
                              > cost[retry] * (1 + 1e-12) + 1e-300)
            trial[retry] = moved
            if tev is None:
                tev = moved_ev
            else:
                tev.assign(retry, moved_ev)
            if not worse.any():
                return trial, tev
            retry = retry[worse]
            alpha[retry] *= 0.5
        trial[retry] = xi[retry]  # still worse: the screw stays
        if tev is None:
            return trial, ev
        tev.assign(retry, ev.subset(retry))
        return trial, tev

    def settle_exact(self, z: FloatArray, xi: FloatArray) -> FloatArray:
        """``xi`` with every sample of an exact load at its equilibrium under it (Newton from
        ``xi``, else the equilibrium solver); ValueError naming a sample without one."""
        start = xi
        xi = xi.copy()
        rows = np.flatnonzero(self.exact)
        if rows.size == 0:
            return xi
        xi[rows], found = self.settle(z, xi[rows], self.data.wrench[rows], rows)
        if found.all():
            return xi
        k, d = self.parameters(z)
        model = self._model(k)
        for i in rows[~found]:
            eq = solve_equilibrium(model, self.data.wrench[i], self.data.rest[i] + d,
                                   initial_screw=start[i])
            if not eq.success:
                raise ValueError(f'samples[{i}]: no equilibrium under its exact load '
                                 f'{self.data.wrench[i].tolist()} ({eq.message})')
            xi[i] = eq.screw
        return xi

    # -------------------------------------------------------------- information
    def information(self, ev: _Evaluation, columns: NDArray[np.int64]) -> FloatArray:
        """Parameters' information with the screws eliminated (Schur complement per sample),
        scaled coordinates, over ``columns`` of the parameter vector."""
        return _schur(self.normal_equations(ev), columns)[0]


def _schur(eq: _NormalEquations, columns: NDArray[np.int64]
           ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(information ``S = C - sum B^T A^+ B`` over ``columns``, ``A^+`` (N, 6, 6),
    ``A^+ B`` (N, 6, P)): the screws eliminated per sample."""
    A_pinv = _pinv_psd(eq.A)
    B = eq.B[:, :, columns]
    AB = A_pinv @ B
    return eq.C[np.ix_(columns, columns)] - _sum_of_products(B, AB), A_pinv, AB


def _sum_of_products(a: FloatArray, b: FloatArray) -> FloatArray:
    """``sum_i a_i^T b_i`` (p, q) of batches ``a`` (N, r, p) and ``b`` (N, r, q), as a stack of
    products of :data:`SUM_BLOCK_ROWS` rows each: one 2-D product of all N r rows would be one
    large BLAS call, which OpenBLAS spreads over threads, and on a shared machine the threads
    cost more than they save (the whole calibration 2-3x slower than with one thread)."""
    rows = a.shape[0] * a.shape[1]
    a2, b2 = a.reshape(rows, a.shape[-1]), b.reshape(rows, b.shape[-1])
    blocks = rows // SUM_BLOCK_ROWS
    full = blocks * SUM_BLOCK_ROWS
    out = a2[full:].T @ b2[full:]
    if blocks:
        blocks_a = a2[:full].reshape(blocks, SUM_BLOCK_ROWS, a2.shape[-1])
        blocks_b = b2[:full].reshape(blocks, SUM_BLOCK_ROWS, b2.shape[-1])
        out += (np.swapaxes(blocks_a, 1, 2) @ blocks_b).sum(axis=0)
    return out


def _pinv_psd(A: FloatArray) -> FloatArray:
    """``A^+`` of a batch of symmetric positive semi-definite (N, 6, 6) ``A`` (directions with
    no information get none)."""
    lam, V = np.linalg.eigh(A)
    cut = RANK_TOLERANCE ** 2 * np.maximum(lam[:, -1:], 1e-300)
    inv = np.where(lam > cut, 1.0 / np.where(lam > cut, lam, 1.0), 0.0)
    return (V * inv[:, None, :]) @ np.swapaxes(V, -1, -2)


# ------------------------------------------------------------------------------ results
@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate_joint`.

    ``parameters`` maps a name (``stiffness[j]`` in N/m, ``rest_length_offset[j]`` in m, in the
    fitted kinds) to its value; unidentifiable ones hold their nominal value (0 for an offset).
    ``std`` the standard deviation of each (NaN where not identifiable), ``covariance`` over
    ``names`` (units as the values), ``identifiable`` per name, ``unidentifiable`` the directions
    the data cannot determine in words, ``singular_values`` of the weighted Jacobian (screws
    eliminated, scaled coordinates), ``residual_rms_before`` / ``residual_rms_after`` per
    measurement kind (its unit, :data:`RESIDUAL_UNITS`; before: nominal parameters with each
    screw fitted), ``outliers`` the sample indices left out, ``near_slack`` the (inlier) samples
    with a string within :data:`SLACK_MARGIN` std of slack at the first plain least-squares
    fit (kept; the strings not clearly slack held on their taut branch), ``screws`` (N, 6) the
    fitted screws,
    ``chi2`` and ``dof`` of the final fit (``chi2 / dof`` near 1 when the noise model is right).
    """

    success: bool
    message: str
    model: JointModel
    names: list[str]
    parameters: dict[str, float]
    std: dict[str, float]
    covariance: FloatArray
    identifiable: dict[str, bool]
    unidentifiable: list[str]
    singular_values: FloatArray
    residual_rms_before: dict[str, float]
    residual_rms_after: dict[str, float]
    outliers: list[int]
    iterations: int
    screws: FloatArray
    chi2: float
    dof: int
    nominal: dict[str, float] = field(default_factory=dict)
    offsets: FloatArray = field(default_factory=lambda: np.zeros(0))
    residuals_before: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    residuals_after: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    seconds: float = 0.0
    near_slack: list[int] = field(default_factory=list)

    def residuals(self, kind: str, after: bool = True) -> FloatArray:
        """Residuals (N, m) of one measurement kind (:data:`RESIDUAL_KINDS`, its unit) of every
        sample, NaN where not measured; outliers included (``after``: at the estimate, else at
        nominal)."""
        table = self.residuals_after if after else self.residuals_before
        return table[:, residual_block(kind, self.model.n_strings)]

    def table(self) -> list[dict[str, Any]]:
        """Rows ``name, string, nominal, fitted, std, identifiable`` (units of the name)."""
        rows = []
        for name in self.names:
            j = int(re.search(r'\[(\d+)\]', name).group(1))
            rows.append({'name': name, 'string': self.model.string_names[j],
                         'nominal': self.nominal[name], 'fitted': self.parameters[name],
                         'std': self.std[name], 'identifiable': self.identifiable[name]})
        return rows


def residual_block(kind: str, n: int) -> slice:
    """Columns of one measurement kind in a sample's residual rows (pose 6, wrench 6,
    tensions n, lengths n)."""
    blocks = {'position': slice(0, 3), 'rotation': slice(3, 6), 'force': slice(6, 9),
              'moment': slice(9, 12), 'tension': slice(12, 12 + n), 'length': slice(12 + n, None)}
    if kind not in blocks:
        raise ValueError(f'unknown residual kind {kind!r} (known: {", ".join(RESIDUAL_KINDS)})')
    return blocks[kind]


def _rms_by_kind(raw: FloatArray, mask: NDArray[np.bool_], n: int) -> dict[str, float]:
    out = {}
    for kind in RESIDUAL_KINDS:
        sl = residual_block(kind, n)
        m = mask[:, sl]
        if m.any():
            out[kind] = float(np.sqrt(np.mean(raw[:, sl][m] ** 2)))
    return out


def _parameter_names(kinds: Sequence[str], n: int) -> list[str]:
    return [PARAMETER_NAMES[kind].format(j=j) for kind in kinds for j in range(n)]


def _fit_columns(kinds: Sequence[str], n: int) -> NDArray[np.int64]:
    return np.concatenate([np.arange(n) + FIT_KINDS.index(kind) * n for kind in kinds])


def _check_fit(fit: Sequence[str] | str) -> tuple[str, ...]:
    kinds = (fit,) if isinstance(fit, str) else tuple(fit)
    aliases = {'rest_length_offset': 'rest_length_offsets', 'offsets': 'rest_length_offsets'}
    kinds = tuple(aliases.get(k, k) for k in kinds)
    unknown = [k for k in kinds if k not in FIT_KINDS]
    if unknown or not kinds:
        raise ValueError(f'fit must name some of {FIT_KINDS}, got {list(fit)}')
    return tuple(k for k in FIT_KINDS if k in kinds)


@dataclass
class Identifiability:
    """The identifiable subspace of the scaled parameters: ``basis`` (P, q) orthonormal,
    ``null`` (P, P - q) its complement, the singular values, and words for each null
    direction."""

    basis: FloatArray
    null: FloatArray
    singular_values: FloatArray
    descriptions: list[str]
    zero_columns: NDArray[np.int64]


def identifiability(information: FloatArray, names: Sequence[str],
                    describe: Callable[[FloatArray], str] | None = None,
                    held: FloatArray | None = None) -> Identifiability:
    """Split the scaled parameter space into what the information ``S`` (P, P) determines and
    what it does not: parameters no measurement depends on (zero diagonal) first, each on its
    own, then the eigen-directions of the rest whose singular value ``sqrt(lambda)`` is below
    :data:`RANK_TOLERANCE` of the largest or below 1 (std above one scaled unit). ``held``
    (P, h) orthonormal: directions known to be unidentifiable (their information is removed)."""
    P = information.shape[0]
    if held is not None and held.shape[1]:
        project = np.eye(P) - held @ held.T
        information = project @ information @ project
    diag = np.diag(information)
    top = float(diag.max()) if P else 0.0
    zero = np.flatnonzero(diag <= (RANK_TOLERANCE ** 2) * max(top, 1e-300))
    rest = np.setdiff1d(np.arange(P), zero)
    null_vectors = [np.eye(P)[:, j] for j in zero]
    basis = []
    singular = []
    if rest.size:
        lam, V = np.linalg.eigh(information[np.ix_(rest, rest)])
        s = np.sqrt(np.maximum(lam, 0.0))
        cut = max(RANK_TOLERANCE * float(s.max()), 1.0)
        for value, vec in zip(s, V.T, strict=True):
            full = np.zeros(P)
            full[rest] = vec
            (basis if value > cut else null_vectors).append(full)
            singular.append(value)
    describe = describe or (lambda v: _combination_words(v, names))
    return Identifiability(
        np.array(basis).T.reshape(P, len(basis)),
        np.array(null_vectors).T.reshape(P, len(null_vectors)),
        np.sort(np.array(singular))[::-1], [describe(v) for v in null_vectors], zero)


def _combination_words(v: FloatArray, names: Sequence[str], limit: int = 6) -> str:
    order = np.argsort(-np.abs(v))
    big = [j for j in order[:limit] if abs(v[j]) >= 0.1 * abs(v[order[0]])]
    terms = ' '.join(f'{v[j]:+.2f} {names[j]}' for j in big)
    more = ' ...' if np.count_nonzero(np.abs(v) >= 0.1 * abs(v[order[0]])) > len(big) else ''
    return f'the combination {terms}{more} (scaled units)'


def _describe(v: FloatArray, names: Sequence[str], model: JointModel, data: _Data,
              kinds: Sequence[str], noise: CalibrationNoise) -> str:
    """Words for one unidentifiable direction ``v`` of the scaled parameters."""
    n = model.n_strings
    force = measures_force(data, noise)
    nz = np.flatnonzero(np.abs(v) > 1e-9)
    if nz.size == 1:
        name = names[nz[0]]
        j = int(re.search(r'\[(\d+)\]', name).group(1))
        what = (f"{name} (string {model.string_names[j]}): no measurement depends on it")
        if name.startswith('stiffness') or not force:
            if not np.isfinite(data.tensions[:, j]).any() and not data.has_wrench.any():
                what += ' (its tension is not measured and no sample has a known load)'
        return what
    if 'stiffness' in kinds:
        ks = v[:n] if kinds[0] == 'stiffness' else np.zeros(n)
        if np.linalg.norm(ks) > 0.99 * np.linalg.norm(v) and \
                abs(ks.sum()) > 0.99 * math.sqrt(n) * np.linalg.norm(ks):
            reason = ('no sample measures a force' if not force
                      else 'the forces measured do not fix it')
            return (f'the common scale of all stiffnesses: {reason} (a tension or a known '
                    'load); the ratios between them are fitted, the scale is held at nominal')
    return _combination_words(v, names)


# ------------------------------------------------------------------------------ the fit
def measures_force(data: _Data, noise: CalibrationNoise,
                   probability: float = SCALE_TEST_PROBABILITY) -> bool:
    """Whether the samples measure a force: a load cell, an exact load other than zero, or
    noisy known loads that differ from zero beyond their noise (their whitened chi-square
    exceeds its ``1 - probability`` quantile; zeros are exact, "unloaded"). Without one, the
    common scale of the stiffnesses is unidentifiable: ``F(c k) = c F(k)`` and ``F = -W = 0`` at
    every sample, whatever ``c``."""
    if np.isfinite(data.tensions).any():
        return True
    loads = data.wrench[data.has_wrench]
    loads = loads[np.any(loads != 0.0, axis=1)]
    if loads.size == 0:
        return False
    if noise.exact_loads:
        return True
    std = np.concatenate([np.full(3, noise.force), np.full(3, noise.moment)])
    return float(np.sum((loads / std) ** 2)) > chdtri(loads.size, probability)


def initial_screws(model: JointModel, data: _Data) -> FloatArray:
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


def _min_rows(data: _Data) -> int:
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


def _solve(problem: _Problem, z0: FloatArray, basis: FloatArray, xi0: FloatArray, loss: str,
           rows: NDArray[np.bool_], ev: _Evaluation | None = None,
           max_iterations: int = MAX_ITERATIONS, tolerance: float = FIT_TOLERANCE,
           damping: float = DAMPING) -> tuple[FloatArray, FloatArray, _Evaluation, int, bool]:
    """Levenberg-Marquardt over ``z = z0 + basis y`` and every sample's screw, with the screws
    eliminated per sample (Schur complement: one q x q system per iteration) and the robust
    ``loss`` by iteratively re-weighted least squares (a descent method for these concave
    losses); only the residual rows ``rows`` (N, R) count; ``ev``: the evaluation at the start,
    when known; ``damping``: the initial Levenberg-Marquardt damping. Returns (z, screws, their
    evaluation, iterations, converged)."""
    q = basis.shape[1]
    z, xi = z0.copy(), xi0.copy()
    mask = rows.astype(np.float64)

    def cost_of(ev: _Evaluation) -> tuple[float, FloatArray]:
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
            S = damped_normal_matrix(C, lam.value, DAMPING_FLOOR) - _sum_of_products(B, Ainv_B)
            rhs = gp - _sum_of_products(B, Ainv_g[..., None])[:, 0]
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
                     ) -> tuple[tuple[str, ...], CalibrationNoise, dict, _Data, list[str],
                                NDArray[np.intp]]:
    """:func:`calibrate_joint`'s arguments checked: the fitted kinds, the noise, the bounds, the
    samples as arrays, the parameter names and their columns; ValueError names the problem
    (bad arguments, no samples, nothing that fixes the configuration, too few measurements)."""
    kinds = _check_fit(fit)
    noise = CalibrationNoise.of(noise)
    if loss not in LOSSES:
        raise ValueError(f'loss must be one of {LOSSES}, got {loss!r}')
    bounds = dict(bounds or {})
    for key, pair in bounds.items():
        if _check_fit(key)[0] not in kinds or len(pair) != 2 or not pair[0] < pair[1]:
            raise ValueError(f'bounds[{key!r}] must be (low, high) with low < high for a '
                             'fitted kind')
    data = _samples_data(model, samples)
    n = model.n_strings
    N = data.n_samples
    if N == 0:
        raise ValueError('no samples')
    if not data.has_pose.any() and not data.has_wrench.any() and \
            not np.isfinite(data.lengths).any():
        raise ValueError('the samples carry no pose, no known load and no string lengths: '
                         'nothing fixes the configuration')
    names = _parameter_names(kinds, n)
    columns = _fit_columns(kinds, n)
    P = columns.size
    total_rows = _min_rows(data)
    if total_rows < 6 * N + P:
        raise ValueError(f'too few measurements: {total_rows} values for {6 * N} screw '
                         f'coordinates ({N} samples) and {P} parameters; record more samples '
                         'or add a sensor (pose, wrench, tensions)')
    return kinds, noise, bounds, data, names, columns


def _outliers(problem: _Problem, ev: _Evaluation, loss: str, n_parameters: int
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
        kind = _check_fit(key)[0]
        for name in names:
            if name.startswith(PARAMETER_NAMES[kind].split('[')[0] + '[') and \
                    not low <= parameters[name] <= high:
                message = f'{name} = {parameters[name]:.6g} is outside bounds [{low}, {high}]'
    return message


def _identified_basis(problem: _Problem, before: Any, columns: NDArray[np.intp],
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
                            lambda v: _describe(v, names, model, data, kinds, noise), held)
    basis_full = np.zeros((2 * n, ident.basis.shape[1]))
    basis_full[columns] = ident.basis
    return ident, basis_full


def _covariance(problem: _Problem, ev: Any, columns: NDArray[np.intp], basis: FloatArray
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
    problem = _Problem(model, data, noise)
    z_nominal = np.zeros(2 * n)
    xi = problem.refine_screws(z_nominal, initial_screws(model, data))
    before = problem.evaluate(z_nominal, xi)
    rms_before = _rms_by_kind(before.raw, problem.mask, n)
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
    rms_after = _rms_by_kind(ev.raw, mask_in, n)
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


def _hold_taut(problem: _Problem, z: FloatArray, xi: FloatArray, ev: _Evaluation,
               basis_full: FloatArray, rows: NDArray[np.bool_], inliers: NDArray[np.intp],
               columns: NDArray[np.intp], basis: FloatArray, refit: bool
               ) -> tuple[FloatArray, FloatArray, _Evaluation, int, bool, NDArray[np.intp]]:
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


def _stretch_std(problem: _Problem, ev: _Evaluation, columns: NDArray[np.intp],
                 basis: FloatArray) -> tuple[FloatArray, FloatArray]:
    """(stretch ``l_j - l0_j``, its std) (N, n) of the samples of ``ev`` (a linear fit's
    inliers, with Jacobians). The std is linearized in the sample's own unknown and the
    parameters with their joint covariance (Schur complement:
    ``Cov u = A^+ + A^+ B C B^T A^+``, ``Cov(u, z) = -A^+ B C``; the screw
    ``d xi = G du + H dz``, ``G = -K^-1``, ``H = G dF/dz`` for a known load, else ``G = I``,
    ``H = 0``): ``Cov xi = G A^+ G^T + D C D^T``, ``Cov(xi, z) = -D C`` with
    ``D = G A^+ B - H``."""
    n = problem.n
    information, A_pinv, AB = _schur(problem.normal_equations(ev), columns)
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
    kinds = _check_fit(fit)
    data = _samples_data(model, samples)
    problem = _Problem(model, data, CalibrationNoise.of(noise))
    n = model.n_strings
    k = np.asarray(true_stiffness, dtype=np.float64)
    z = np.concatenate([(k - problem.k_nominal) / (STIFFNESS_UNIT * problem.k_nominal),
                        np.asarray(true_offsets, dtype=np.float64) / OFFSET_UNIT])
    ev = problem.evaluate(z, as_screws(true_screws))
    columns = _fit_columns(kinds, n)
    info = problem.information(ev, columns)
    V = np.eye(columns.size) if basis is None else basis
    cov = _subspace_covariance(info, V)
    unit = problem.unit[columns]
    return np.sqrt(np.maximum(np.diag(cov), 0.0)) * unit


# ------------------------------------------------------------------------------ spines
@dataclass(frozen=True)
class ChainCalibrationSample:
    """One quasi-static instant of a spine (N joints, n strings each).

    ``rest_lengths`` (N, n) commanded per joint; ``link_poses`` (N, 4, 4) or (N, 7): the
    measured pose of every link {2}_i in the base; ``tip_wrench`` (6,) the load on link N in the
    base about its origin (None when unknown, zeros when unloaded); ``tensions`` (N, n) N, NaN
    where none.
    """

    rest_lengths: ArrayLike
    link_poses: ArrayLike
    tip_wrench: ArrayLike | None = None
    tensions: ArrayLike | None = None


def _chain_joint_samples(chain: Any, samples: Sequence[ChainCalibrationSample], noise:
                         CalibrationNoise) -> tuple[list[list[CalibrationSample]],
                                                    list[CalibrationNoise]]:
    """Per joint: samples in the joint's own frames (relative pose, load moved into {1}_i) and
    the relative pose's noise."""

    N = chain.n_joints
    per_joint: list[list[CalibrationSample]] = [[] for _ in range(N)]
    spans = np.zeros(N)
    arms = np.zeros(N)
    g = chain.gravity
    weights = chain.has_weights(g)
    for s_index, s in enumerate(samples):
        where = f'samples[{s_index}]'
        raw = finite_array(f'{where}.link_poses', s.link_poses)
        if raw.shape not in ((N, 4, 4), (N, 7)):
            raise ValueError(f'{where}.link_poses must have shape ({N}, 4, 4) or ({N}, 7), got '
                             f'{raw.shape}')
        L = np.array([rigid_transform(p, f'{where}.link_poses[{i}]', RECORDED_ROTATION_TOLERANCE)
                      for i, p in enumerate(raw)])
        P = np.empty_like(L)
        P[0] = np.eye(4)
        for i in range(1, N):
            P[i] = L[i - 1] @ chain.link_offsets[i - 1]
        rest = finite_array(f'{where}.rest_lengths', s.rest_lengths)
        if rest.ndim != 2 or rest.shape[0] != N:
            raise ValueError(f'{where}.rest_lengths must have one row per joint ({N}), got '
                             f'shape {rest.shape}')
        tensions = None if s.tensions is None else np.asarray(s.tensions, dtype=np.float64)
        loads = None
        if s.tip_wrench is not None:
            W = finite_array(f'{where}.tip_wrench', s.tip_wrench)
            if W.shape != (6,):
                raise ValueError(f'{where}.tip_wrench must have shape (6,), got {W.shape}')
            B = np.broadcast_to(W, (N, 6))
            if weights:
                w, _ = chain.link_weights(L, g)
                B = W + np.cumsum(w[::-1], axis=0)[::-1]
            loads = (np.swapaxes(adjoint(P), 1, 2) @ B[:, :, None])[:, :, 0]
        for i in range(N):
            T = np.linalg.solve(P[i], L[i])
            spans[i] = max(spans[i], float(np.linalg.norm(L[i][:3, 3] - P[i][:3, 3])))
            arms[i] = max(arms[i], float(np.linalg.norm(P[i][:3, 3])))
            per_joint[i].append(CalibrationSample(
                rest[i], pose=T, tensions=None if tensions is None else tensions[i],
                external_wrench=None if loads is None else loads[i]))
    noises = [noise]
    for i in range(1, N):
        # Two measured poses: sqrt(2) their noise, plus link i-1's rotation noise acting on
        # the distance between the frames; the load's force noise acting on the arm from the
        # base origin to {1}_i (isotropic, first order).
        position = math.sqrt(2.0 * noise.position ** 2
                             + (2.0 / 3.0) * (spans[i] * noise.rotation) ** 2)
        moment = math.sqrt(noise.moment ** 2 + (2.0 / 3.0) * (arms[i] * noise.force) ** 2)
        noises.append(CalibrationNoise(position=position, rotation=math.sqrt(2.0) * noise.rotation,
                                       force=noise.force, moment=moment,
                                       tension=noise.tension, length=noise.length))
    return per_joint, noises


def calibrate_chain(chain: Any, samples: Sequence[ChainCalibrationSample],
                    fit: Sequence[str] | str = ('stiffness', 'rest_length_offsets'),
                    noise: CalibrationNoise | Mapping[str, float] | None = None,
                    loss: str = 'soft_l1') -> list[CalibrationResult]:
    """Calibrate every joint of a spine
    (:class:`~tensegrity_stiffness.mechanics.chain.JointChain`) from
    recordings with every link's pose: joint i is fitted by :func:`calibrate_joint` to the
    pose of {2}_i in {1}_i (``P_i^-1 L_i``, ``P_i = L_{i-1} O_{i-1}``) and to the load it
    carries moved into {1}_i, ``Ad_{P_i}^T (W + sum_{k >= i} w_k)`` (the chain's link weights
    ``w_k`` at the measured poses; :mod:`tensegrity_stiffness.mechanics.chain`). A relative pose
    carries
    the noise of two measured poses: its std is taken as ``sqrt(2)`` times the rotation noise
    and ``sqrt(2 sp^2 + 2/3 (d sr)^2)`` in position (``d`` the largest distance between the two
    frames), and the moved load's moment noise as ``sqrt(sm^2 + 2/3 (a sf)^2)`` (``a`` the
    largest distance of {1}_i from the base origin); the correlation between neighbouring joints
    (they share a link's pose) is left out. One :class:`CalibrationResult` per joint."""
    noise = CalibrationNoise.of(noise)
    per_joint, noises = _chain_joint_samples(chain, samples, noise)
    return [calibrate_joint(model, joint_samples, fit=fit, noise=joint_noise, loss=loss)
            for model, joint_samples, joint_noise in zip(chain.joints, per_joint, noises,
                                                         strict=True)]
