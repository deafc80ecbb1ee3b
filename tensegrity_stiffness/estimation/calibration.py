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
  is its true load ``W = -F(xi)`` instead of its screw
  (:meth:`~.calibration_model.CalibrationProblem.normal_equations`: the screw is the equilibrium
  under ``W``, solved by Newton after every step,
  :meth:`~.calibration_model.CalibrationProblem.advance`), so that a precise reading converges; an
  **exact** load (zeros, or every known load when the load noise is 0:
  :attr:`CalibrationNoise.exact_loads`) is no unknown: the equilibrium under it is a constraint and
  its rows are no residuals;
* load cells: ``(phi_j(xi; theta) - t_j) / sigma`` for every measured string (eq. 8, the
  model's force law);
* string lengths: ``(l_j(xi) - l_m) / sigma`` (eq. 7).

Jacobians (analytic). :mod:`tensegrity_stiffness.estimation.sensor_models` defines every
measurement model
and its Jacobians for one screw (shared with the estimator); the calibration evaluates the same
models for all samples at once (:class:`~.calibration_model.CalibrationProblem`, one batched
:meth:`JointModel.evaluate` per iteration), held to ``sensor_models`` sample by sample and to
central differences in
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

from tensegrity_stiffness.estimation.calibration_model import (  # noqa: F401 (public here)
    EQUILIBRIUM_ITERATIONS,
    EQUILIBRIUM_TOLERANCE,
    OFFSET_UNIT,
    RANK_TOLERANCE,
    SCREW_ITERATIONS,
    SCREW_TOLERANCE,
    STIFFNESS_UNIT,
    SUM_BLOCK_ROWS,
    model_with_parameters,
)
from tensegrity_stiffness.estimation.calibration_results import (  # noqa: F401 (public here)
    FIT_KINDS,
    PARAMETER_NAMES,
    PARAMETER_UNITS,
    CalibrationResult,
    Identifiability,
    identifiability,
    residual_block,
)
from tensegrity_stiffness.estimation.calibration_samples import (  # noqa: F401 (public here)
    RECORDED_ROTATION_TOLERANCE,
    RESIDUAL_KINDS,
    RESIDUAL_UNITS,
    SCALE_TEST_PROBABILITY,
    CalibrationNoise,
    CalibrationSample,
    measures_force,
)
from tensegrity_stiffness.estimation.chain_calibration import (  # noqa: F401 (public here)
    ChainCalibrationSample,
    calibrate_chain,
)
from tensegrity_stiffness.estimation.joint_calibration import (  # noqa: F401 (public here)
    DAMPING,
    DAMPING_FLOOR,
    FIT_TOLERANCE,
    HOLD_PASSES,
    LOSSES,
    MAX_ITERATIONS,
    MAX_REJECTED_STEPS,
    OUTLIER_PROBABILITY,
    ROBUST_SCALE,
    ROBUST_TOLERANCE,
    SLACK_MARGIN,
    WARM_DAMPING,
    calibrate_joint,
    cramer_rao_std,
    initial_screws,
)



