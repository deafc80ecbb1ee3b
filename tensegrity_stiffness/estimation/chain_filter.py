"""A recursive estimator of a moving spine: the extended Kalman filter of
:mod:`~tensegrity_stiffness.estimation.joint_filter` on
:class:`~tensegrity_stiffness.mechanics.chain_dynamics.ChainDynamics` (no rclpy;
docs/estimation.md#spines-chainfilter).

State ``x = [xi (6N); xi_dot (6N); W (6)]``: every joint's screw and screw rate (joint-major)
and, with ``load='unknown'``, the tip wrench ``W`` (base frame, about its origin) as a random
walk. Prediction: ``M xi_ddot = Q`` with
:meth:`~tensegrity_stiffness.mechanics.chain_dynamics.ChainDynamics.mass_matrix` and
:meth:`~tensegrity_stiffness.mechanics.chain_dynamics.ChainDynamics.generalized_force` (strings,
string damping, the links' weights, the tip load); the velocity-product terms of
``ChainDynamics.acceleration`` (quadratic in the rates: a spine moves slowly; they cost one 12x12
matrix exponential per joint) are left to the process noise. Integrated as the joint filter does
(one linearly implicit trapezoidal step per at most
:data:`~tensegrity_stiffness.estimation.joint_filter.MAX_SUBSTEP`), with the Jacobian of the linear
model of ``ChainDynamics`` (``M^-1 diag(J_l^T Pi) dr/dxi``, ``-M^-1 L^T C L``,
``M^-1 diag(J_l^T Pi) Ad^T``; the derivatives of ``J_l`` and ``M`` off the equilibria left out, as
there). Updates: each joint's tensions, lengths and pose, the tip pose and, with an unknown load, a
measured tip load; the trust rules are the joint filter's
(:func:`~tensegrity_stiffness.estimation.joint_filter.kalman_update`), a lost track restarts from
:func:`~tensegrity_stiffness.estimation.estimators.estimate_chain_state`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.chain_estimator import (
    ChainEstimate,
    estimate_chain_state,
    tip_pose_jacobian,
    tip_stiffness_std,
)
from tensegrity_stiffness.estimation.joint_filter import (
    DEFAULT_CHAIN_PROCESS_NOISE,
    INITIAL_ANGULAR_VELOCITY_STD,
    INITIAL_LINEAR_VELOCITY_STD,
    KNOWN_LOAD_STD,
    LOST_TRACK_STEPS,
    MAX_PREDICTION,
    MAX_SUBSTEP,
    FilterTrack,
    ProcessNoise,
    checked_prediction_time,
    checked_restart_budget,
    kalman_update,
    resolved_load,
    validated_filter_options,
)
from tensegrity_stiffness.estimation.measurements import Measurements, PreparedMeasurements
from tensegrity_stiffness.estimation.trust import CONSISTENCY_PROBABILITY
from tensegrity_stiffness.geometry.screw import BLOCK_SWAP, ScrewKinematics, check_in_chart
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array, optional_vector
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.chain_dynamics import ChainDynamics
from tensegrity_stiffness.mechanics.inertia import LinkInertia

__all__ = ['ChainFilter']

FloatArray = NDArray[np.float64]
#: Sensor patterns whose readings :meth:`ChainFilter._readings` keeps (then it starts over).
MAX_PATTERNS = 64



class ChainFilter(FilterTrack):
    """Extended Kalman filter of a spine's screws, screw rates and tip load (module docstring).

    ``chain``: a :class:`~tensegrity_stiffness.mechanics.chain.JointChain` (with ``inertias``,
    one :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia` per link, and
    ``string_damping``) or a :class:`~tensegrity_stiffness.mechanics.chain_dynamics.ChainDynamics`;
    ``process_noise`` a :class:`~tensegrity_stiffness.estimation.joint_filter.ProcessNoise`
    (its accelerations act on each joint's ``xi_ddot``, its rates on the tip load; default
    :data:`~tensegrity_stiffness.estimation.joint_filter.DEFAULT_CHAIN_PROCESS_NOISE`);
    ``load`` ``'unknown'`` or ``'known'``; the rest (``restart_time_budget`` included: of
    ``estimate_chain_state``) as
    :class:`~tensegrity_stiffness.estimation.joint_filter.JointFilter`'s."""

    def __init__(self, chain: JointChain | ChainDynamics,
                 inertias: Sequence[LinkInertia] | None = None,
                 process_noise: ProcessNoise | None = None, load: str = 'unknown', *,
                 string_damping: Any = 0.0,
                 consistency_probability: float = CONSISTENCY_PROBABILITY,
                 stiffness_std: bool = True, reject_outliers: bool = True,
                 restart_time_budget: float | None = None) -> None:
        if isinstance(chain, ChainDynamics):
            if inertias is not None:
                raise ValueError('inertias: give them to the ChainDynamics, not to the filter')
            self.dynamics = chain
        elif isinstance(chain, JointChain):
            self.dynamics = ChainDynamics(chain, inertias, string_damping)
        else:
            raise ValueError(f'chain must be a JointChain or a ChainDynamics, got '
                             f'{type(chain).__name__}')
        process_noise = validated_filter_options(load, process_noise,
                                                 DEFAULT_CHAIN_PROCESS_NOISE,
                                                 consistency_probability)
        self.chain = self.dynamics.chain
        self.n = self.chain.n_joints
        self.load = load
        self.process_noise = process_noise
        self.consistency_probability = consistency_probability
        self.stiffness_std = stiffness_std
        self.reject_outliers = reject_outliers
        self.restart_time_budget = checked_restart_budget(restart_time_budget)
        n = self.n
        self.size = 12 * n + (6 if load == 'unknown' else 0)
        # the screw rates' acceleration densities at ProcessNoise.motion_scale's factor 1
        self._rate_q0 = np.tile(process_noise.twist_density(), n)
        self._rate_q = self._rate_q0
        self._load_q = process_noise.load_density()
        self._gravity = self.chain.resolved_gravity(None)
        self._patterns: dict[Any, tuple[list[tuple[str, NDArray[np.intp], int]], int]] = {}
        self.reset()

    # ------------------------------------------------------------------ state
    # (initialized, state ``[xi; xi_dot; W]`` and covariance: FilterTrack's)
    def reset(self, screws: ArrayLike | None = None, estimate: ChainEstimate | None = None
              ) -> None:
        """Forget the track; with ``estimate`` (a successful :class:`ChainEstimate`) start from
        its screws and tip load (at rest), with ``screws`` (N, 6) from those at rest (1e-3 rad /
        1e-5 m, 1 N / 0.01 N m); without either the next :meth:`step` starts from the static
        estimator."""
        self._t: float | None = None
        self._last_rest: FloatArray | None = None
        self._x: FloatArray | None = None
        self._P: FloatArray | None = None
        self._inconsistent = 0
        self._suspected: set[str] = set()
        self._cache: tuple[Any, ...] | None = None
        if screws is not None and estimate is not None:
            raise ValueError('reset takes screws or an estimate, not both')
        n = self.n
        if estimate is not None:
            if not isinstance(estimate, ChainEstimate) or not estimate.success:
                raise ValueError('estimate must be a successful ChainEstimate')
            x = np.zeros(self.size)
            P = np.zeros((self.size, self.size))
            x[:6 * n] = estimate.screws.reshape(-1)
            P[:6 * n, :6 * n] = estimate.screw_covariance
            P[6 * n:12 * n, 6 * n:12 * n] = np.diag(self._initial_rate_variance())
            if self.size > 12 * n:
                x[12 * n:] = estimate.tip_wrench
                P[12 * n:, 12 * n:] = estimate.tip_wrench_covariance
            self._x, self._P = x, 0.5 * (P + P.T)
        elif screws is not None:
            xi = self.chain.validated_screws(screws)
            x = np.zeros(self.size)
            x[:6 * n] = xi.reshape(-1)
            diag = np.r_[np.tile([1e-6] * 3 + [1e-10] * 3, n), self._initial_rate_variance(),
                         [1.0] * 3 * (self.size > 12 * n), [1e-4] * 3 * (self.size > 12 * n)]
            self._x, self._P = x, np.diag(diag)

    def _initial_rate_variance(self) -> FloatArray:
        return np.tile([INITIAL_ANGULAR_VELOCITY_STD ** 2] * 3 +
                       [INITIAL_LINEAR_VELOCITY_STD ** 2] * 3, self.n)

    # ------------------------------------------------------------------ step
    def step(self, t: float, joint_measurements: Sequence[Measurements | None],
             rest_lengths: Any = None, tip_pose: ArrayLike | None = None,
             tip_pose_covariance: ArrayLike | None = None,
             tip_wrench: ArrayLike | None = None,
             tip_wrench_covariance: ArrayLike | None = None,
             known_load: ArrayLike | None = None) -> ChainEstimate:
        """Predict to ``t`` (s) with ``rest_lengths`` (one entry per joint, None: the model's)
        and update with each joint's readings (:class:`Measurements` or None: tensions,
        lengths, its pose), the tip pose and, with an unknown load, a measured tip load.
        ``known_load`` (6,) with ``load='known'`` (default: ``tip_wrench``, else zero).
        Returns a :class:`ChainEstimate` with ``screw_rates`` and their covariance."""
        n = self.n
        chain = self.chain
        t = checked_prediction_time(t, self._t)
        if len(joint_measurements) != n:
            raise ValueError(f'joint_measurements must hold one entry per joint ({n}), got '
                             f'{len(joint_measurements)}')
        rest = [m.validate_rest_lengths(r, batched=False) for m, r in
                zip(chain.joints, chain.rest_lengths_per_joint(rest_lengths), strict=True)]
        preps, dropped = self._prepared(joint_measurements, rest)
        pose_T = pose_whitener = None
        if tip_pose is not None:
            pose_T = rigid_transform(tip_pose, 'tip_pose')
            pose_whitener = _whitener('tip_pose_covariance', tip_pose_covariance)
        W_m = W_whitener = None
        if tip_wrench is not None:
            W_m = optional_vector('tip_wrench', tip_wrench)
            W_whitener = _whitener('tip_wrench_covariance', tip_wrench_covariance)
        load = self._known(known_load, W_m)
        measured = sum(p.dof for p in preps if p is not None) + 6 * (pose_T is not None) + \
            6 * (W_m is not None or self.load == 'known')
        if self._x is not None and self._t is not None and t - self._t > MAX_PREDICTION:
            self.reset()
        if measured < 6:
            if self._x is not None and self._t is not None:
                self._predict(t - self._t, rest, load)
                self._t = t
            return _failed(f'{measured} measured degrees of freedom cannot determine the 6 '
                           'unknowns left by the equilibria (the tip load). Add string '
                           'tensions or lengths, a pose, or the tip load (tip_wrench)', n,
                           measured, dropped)
        static_args = (joint_measurements, tip_pose, tip_pose_covariance, tip_wrench,
                       tip_wrench_covariance, rest, load)
        if self._x is None:
            start = self._static_start(static_args, None)
            if not start.success:
                return start
            self._t = t
            self._last_rest = np.concatenate(rest)
            return self._estimate(rest, load, start.chi2, start.dof, start.consistent, False,
                                  dropped, start.outliers, start.outlier_reasons)
        self._predict(t - self._t, rest, load)
        self._t = t
        lin = self._linearize(rest, load)
        r, H, readings = self._rows(lin, preps, pose_T, pose_whitener, W_m, W_whitener)
        out = kalman_update(self._P, r, H, readings, self._suspected,
                            self.consistency_probability, self.reject_outliers)
        self._suspected = {name for name, _ in out.left_out}
        if out.raw_consistent is not None:
            self._inconsistent = 0 if out.raw_consistent else self._inconsistent + 1
        xn = self._x + out.correction
        check_in_chart(xn[:6 * n].reshape(n, 6), 'screws')
        self._x, self._P = xn, out.covariance
        self._cache = (xn, lin, _key(rest, load), out.correction)
        if self._inconsistent >= LOST_TRACK_STEPS:
            start = self._static_start(static_args, self._x[:6 * n].reshape(n, 6).copy())
            if start.success:
                return self._estimate(rest, load, start.chi2, start.dof, start.consistent,
                                      True, dropped, start.outliers, start.outlier_reasons)
        return self._estimate(rest, load, out.nis, out.dof, out.consistent, False,
                              dropped + out.left_out)

    def _prepared(self, joint_measurements: Sequence[Measurements | None],
                  rest: list[FloatArray]
                  ) -> tuple[list[PreparedMeasurements | None], list[tuple[str, str]]]:
        """Each joint's readings prepared (ValueError naming the entry), impossible ones left
        out and named ``joint <i> <reading>``."""
        preps: list[PreparedMeasurements | None] = []
        dropped: list[tuple[str, str]] = []
        for i, (model, m) in enumerate(zip(self.chain.joints, joint_measurements, strict=True)):
            if m is None:
                preps.append(None)
                continue
            if m.external_wrench is not None or m.gravity is not None:
                raise ValueError(f'joint_measurements[{i}]: a spine takes its load as tip_wrench '
                                 'and gravity from its chain')
            try:
                p = m.prepared(model.n_strings)
            except ValueError as exc:
                raise ValueError(f'joint_measurements[{i}].{exc}') from None
            bad = p.impossible(model, rest[i])
            if bad:
                p = p.without([name for name, _ in bad], model.string_names)
                dropped += [(f'joint {i + 1} {name}', why) for name, why in bad]
            preps.append(p)
        return preps, dropped

    def predict(self, t: float, rest_lengths: Any = None, known_load: ArrayLike | None = None
                ) -> None:
        """Only the prediction to ``t`` (s); ValueError without a state."""
        if self._x is None:
            raise ValueError('the filter has no state: reset it with screws or an estimate, or '
                             'step it with readings')
        t = checked_prediction_time(t, self._t)
        rest = [m.validate_rest_lengths(r, batched=False) for m, r in
                zip(self.chain.joints, self.chain.rest_lengths_per_joint(rest_lengths),
                    strict=True)]
        load = self._known(known_load, None)
        if self._t is not None:
            self._predict(t - self._t, rest, load)
        self._t = t

    def _known(self, known_load: ArrayLike | None, measured: FloatArray | None) -> FloatArray:
        return resolved_load(self.load, known_load, measured,
                             'a measured tip load goes into tip_wrench')

    # ------------------------------------------------------------------ model
    def _load_of(self, load: FloatArray) -> FloatArray:
        return self._x[12 * self.n:] if self.size > 12 * self.n else load

    def _linearize(self, rest: list[FloatArray], load: FloatArray) -> dict[str, Any]:
        """At the current state: the screw accelerations, the linear model's blocks, the
        chain's state and each joint's string predictions."""
        n, chain, cd = self.n, self.chain, self.dynamics
        x = self._x
        xi = x[:6 * n].reshape(n, 6)
        rates = x[6 * n:12 * n].reshape(n, 6)
        W = self._load_of(load)
        state = chain.evaluate(xi, rest)
        _, D, AdT, _ = chain.equilibrium_system(state, W, self._gravity)
        dr = chain.residual_screw_jacobian(D, xi)
        Minv = np.linalg.inv(cd.mass_matrix(xi))
        # M xi_ddot = Q (the velocity-product terms, quadratic in the rates, left out)
        acc = Minv @ cd.generalized_force(xi, rates, rest, W)
        preds = [sm.string_predictions_unchecked(m, xi[i], rest[i])
                 for i, m in enumerate(chain.joints)]
        JT = np.zeros((6 * n, 6 * n))
        damping = np.zeros((6 * n, 6 * n))
        for i, (jd, pred) in enumerate(zip(cd.joint_dynamics, preds, strict=True)):
            blk = slice(6 * i, 6 * i + 6)
            JT[blk, blk] = pred.kinematics.J.T[:, BLOCK_SWAP]
            if jd.damped:
                L = pred.length_jacobian
                damping[blk, blk] = (L.T * jd.string_damping) @ L
        MJ = Minv @ JT
        return {'acc': acc, 'd_screw': MJ @ dr, 'd_rate': -Minv @ damping,
                'd_load': MJ @ AdT.reshape(6 * n, 6), 'state': state, 'preds': preds}

    def _predict(self, dt: float, rest: list[FloatArray], load: FloatArray) -> None:
        if dt <= 0.0:
            return
        # the accelerations' densities of this prediction (the joint filter's rule)
        every = np.concatenate(rest)
        self._rate_q = self._rate_q0 * self.process_noise.motion_scale(self._last_rest, every,
                                                                       dt)
        self._last_rest = every
        steps = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
        h = dt / steps
        n = self.n
        m = 12 * n
        for _ in range(steps):
            cache = self._cache
            if cache is not None and cache[0] is self._x and cache[2] == _key(rest, load):
                # the last update's linearisation (at its prior) carried to its posterior to
                # first order: one linearisation per step
                lin, dx = cache[1], cache[3]
            else:
                lin, dx = self._linearize(rest, load), None
            A = np.zeros((m, m))
            A[:6 * n, 6 * n:] = np.eye(6 * n)
            A[6 * n:, :6 * n] = lin['d_screw']
            A[6 * n:, 6 * n:] = lin['d_rate']
            f = np.concatenate([self._x[6 * n:12 * n], lin['acc']])
            if dx is not None:
                f[6 * n:] += A[6 * n:] @ dx[:m]
                if self.size > m:
                    f[6 * n:] += lin['d_load'] @ dx[m:]
            E = np.eye(m) - 0.5 * h * A
            rhs = [f[:, None] * h, np.eye(m) + 0.5 * h * A]
            if self.size > m:
                rhs.append(np.vstack([np.zeros((6 * n, 6)), h * lin['d_load']]))
            sol = np.linalg.solve(E, np.hstack(rhs))
            Phi = np.eye(self.size)
            Phi[:m, :m] = sol[:, 1:m + 1]
            if self.size > m:
                Phi[:m, m:] = sol[:, m + 1:]
            xn = self._x.copy()
            xn[:m] += sol[:, 0]
            check_in_chart(xn[:6 * n].reshape(n, 6), 'screws')
            q = self._rate_q
            Q = np.zeros((self.size, self.size))
            Q[:6 * n, :6 * n] = np.diag(q * h ** 3 / 3.0)
            Q[:6 * n, 6 * n:m] = Q[6 * n:m, :6 * n] = np.diag(q * h * h / 2.0)
            Q[6 * n:m, 6 * n:m] = np.diag(q * h)
            if self.size > m:
                Q[m:, m:] = np.diag(self._load_q * h)
            Pn = Phi @ self._P @ Phi.T + Q
            self._x, self._P = xn, 0.5 * (Pn + Pn.T)

    def _rows(self, lin: dict[str, Any], preps: list[PreparedMeasurements | None],
              pose_T: FloatArray | None, pose_whitener: FloatArray | None,
              W_m: FloatArray | None, W_whitener: FloatArray | None
              ) -> tuple[FloatArray, FloatArray, list[tuple[str, NDArray[np.intp], int]]]:
        """The whitened residuals ``r``, their Jacobian ``H`` and the readings (name, rows,
        dof) in row order: each joint's tensions, lengths and pose, the tip pose, the tip load;
        one block per joint and kind of reading (the readings kept per sensor pattern)."""
        n, size = self.n, self.size
        x = self._x
        load_rows = W_m is not None and size > 12 * n
        readings, count = self._readings(preps, pose_T is not None, load_rows)
        r = np.empty(count)
        H = np.zeros((count, size))
        row = 0
        for i, (p, pred) in enumerate(zip(preps, lin['preds'], strict=True)):
            if p is None:
                continue
            cols = slice(6 * i, 6 * i + 6)
            for index, values, weight, h, dh in (
                    (p.tension_index, p.tensions, p.tension_weight, pred.tensions,
                     pred.tension_jacobian),
                    (p.length_index, p.lengths, p.length_weight, pred.lengths,
                     pred.length_jacobian)):
                k = index.size
                if k:
                    block = slice(row, row + k)
                    r[block] = (h[index] - values) * weight
                    H[block, cols] = dh[index] * np.reshape(weight, (-1, 1))
                    row += k
            if p.pose is not None:
                kin = pred.kinematics
                res, jac = sm.pose_residual_unchecked(kin.T, p.pose,
                                                      sm.pose_jacobian(x[cols], kin))
                r[row:row + 6] = p.pose_whitener @ res
                H[row:row + 6, cols] = p.pose_whitener @ jac
                row += 6
        if pose_T is not None:
            T = lin['state'].tip_transform
            jac = np.zeros((6, size))
            jac[:, :6 * n] = tip_pose_jacobian(self.chain, x[:6 * n].reshape(n, 6), T)
            res, jac = sm.pose_residual_unchecked(T, pose_T, jac)
            r[row:row + 6] = pose_whitener @ res
            H[row:row + 6] = pose_whitener @ jac
            row += 6
        if load_rows:
            r[row:row + 6] = W_whitener @ (x[12 * n:] - W_m)
            H[row:row + 6, 12 * n:] = W_whitener
        return r, H, readings

    def _readings(self, preps: list[PreparedMeasurements | None], tip_pose: bool,
                  tip_load: bool) -> tuple[list[tuple[str, NDArray[np.intp], int]], int]:
        """The readings of a sensor pattern (name, rows, dof) in :meth:`_rows`' order and the
        row count, kept per pattern (a tracker's pattern rarely changes)."""
        key = (tuple(None if p is None else (p.tension_index.tobytes(),
                                             p.length_index.tobytes(), p.pose is not None)
                     for p in preps), tip_pose, tip_load)
        kept = self._patterns.get(key)
        if kept is not None:
            return kept
        readings: list[tuple[str, NDArray[np.intp], int]] = []
        row = 0

        def add(name: str, dof: int) -> None:
            nonlocal row
            readings.append((name, np.arange(row, row + dof), dof))
            row += dof

        for i, (model, p) in enumerate(zip(self.chain.joints, preps, strict=True)):
            if p is None:
                continue
            for label, index in (('tension', p.tension_index), ('length', p.length_index)):
                for j in index.tolist():
                    add(f'joint {i + 1} {label}[{model.string_names[j]}]', 1)
            if p.pose is not None:
                add(f'joint {i + 1} pose', 6)
        if tip_pose:
            add('pose', 6)
        if tip_load:
            add('wrench', 6)
        if len(self._patterns) >= MAX_PATTERNS:
            self._patterns.clear()
        self._patterns[key] = kept = (readings, row)
        return kept

    # ------------------------------------------------------------------ (re)starts, output
    def _static_start(self, args: tuple, warm: FloatArray | None) -> ChainEstimate:
        joint_measurements, tip_pose, tip_pose_cov, tip_wrench, tip_wrench_cov, rest, load = args
        if self.load == 'known':
            tip_wrench, tip_wrench_cov = load, np.eye(6) * KNOWN_LOAD_STD ** 2
        est = estimate_chain_state(self.chain, joint_measurements, tip_pose, tip_pose_cov,
                                   tip_wrench, tip_wrench_cov, rest_lengths=rest,
                                   initial_screws=warm, stiffness_std=False,
                                   consistency_probability=self.consistency_probability,
                                   reject_outliers=self.reject_outliers,
                                   time_budget=self.restart_time_budget)
        if est.success:
            t = self._t
            self.reset(estimate=est)
            self._t = t
        return est

    def _estimate(self, rest: list[FloatArray], load: FloatArray, nis: float, dof: int,
                  consistent: bool | None, restarted: bool, dropped: list[tuple[str, str]],
                  outliers: tuple[str, ...] = (), reasons: tuple[str, ...] = ()
                  ) -> ChainEstimate:
        n, chain = self.n, self.chain
        x, P = self._x, self._P
        xi = x[:6 * n].reshape(n, 6).copy()
        C = P[:6 * n, :6 * n].copy()
        state = chain.evaluate(xi, rest)
        joint_cov = np.empty((n, 6, 6))
        for i in range(n):
            Pj = sm.pose_jacobian(xi[i], ScrewKinematics(xi[i]))
            joint_cov[i] = Pj @ C[6 * i:6 * i + 6, 6 * i:6 * i + 6] @ Pj.T
        T_tip = state.tip_transform
        Mt = tip_pose_jacobian(chain, xi, T_tip)
        tip_cov = Mt @ C @ Mt.T
        if self.size > 12 * n:
            W, W_cov = x[12 * n:].copy(), P[12 * n:, 12 * n:].copy()
            idx = np.r_[np.arange(6 * n), np.arange(12 * n, 12 * n + 6)]
            Cz = P[np.ix_(idx, idx)]
        else:
            W, W_cov = load.copy(), np.zeros((6, 6))
            Cz = np.zeros((6 * n + 6, 6 * n + 6))
            Cz[:6 * n, :6 * n] = C
        K_tip = chain.tip_stiffness_from_state(state, W, self._gravity)
        K_std = (tip_stiffness_std(chain, np.r_[xi.reshape(-1), W], Cz, self._gravity, rest)
                 if self.stiffness_std else np.full((6, 6), np.nan))
        names = tuple(name for name, _ in dropped) + tuple(outliers)
        why = tuple(f'{name}: {w}' for name, w in dropped) + tuple(reasons)
        return ChainEstimate(True, 'ok', xi, C, joint_cov, W, W_cov, T_tip.copy(),
                             0.5 * (tip_cov + tip_cov.T), K_tip, K_std, float(nis), int(dof),
                             True, 6, math.nan, 1, state, consistent, int(dof), names, why,
                             restarted, x[6 * n:12 * n].reshape(n, 6).copy(),
                             P[6 * n:12 * n, 6 * n:12 * n].copy())


def _key(rest: list[FloatArray], load: FloatArray) -> bytes:
    """The inputs a linearisation holds for (rest lengths and a known load), as bytes."""
    return b''.join(r.tobytes() for r in rest) + load.tobytes()


def _whitener(name: str, covariance: ArrayLike | None) -> FloatArray:
    if covariance is None:
        raise ValueError(f'{name} is required with its measurement')
    C = finite_array(name, covariance)
    if C.shape != (6, 6):
        raise ValueError(f'{name} must have shape (6, 6), got {C.shape}')
    try:
        return np.linalg.inv(np.linalg.cholesky(0.5 * (C + C.T)))
    except np.linalg.LinAlgError:
        raise ValueError(f'{name} must be positive definite') from None


def _failed(message: str, n: int, measured: int, dropped: list[tuple[str, str]]
            ) -> ChainEstimate:
    def nan(*shape: int) -> FloatArray:
        return np.full(shape, np.nan)

    return ChainEstimate(False, message, nan(n, 6), nan(6 * n, 6 * n), nan(n, 6, 6), nan(6),
                         nan(6, 6), nan(4, 4), nan(6, 6), nan(6, 6), nan(6, 6), math.nan,
                         measured - 6, False, 0, math.inf, 0, None, None, measured - 6,
                         tuple(name for name, _ in dropped),
                         tuple(f'{name}: {w}' for name, w in dropped), False, nan(n, 6),
                         nan(6 * n, 6 * n))
