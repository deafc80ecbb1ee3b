"""The calibration's model: the joint with drawn string parameters (:func:`model_with_parameters`),
every sample's residual and its Jacobians (:class:`CalibrationEvaluation`) and the normal
equations of the fit with the screws eliminated per sample (:class:`CalibrationProblem`,
:func:`schur_complement`). The method is in :mod:`~tensegrity_stiffness.estimation.calibration`.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation.calibration_samples import CalibrationData, CalibrationNoise
from tensegrity_stiffness.geometry.screw import (
    hat3,
    left_jacobian_se3,
    left_jacobian_so3_inverse,
    log_so3_batch,
)
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel, JointState

FloatArray = NDArray[np.float64]

#: Scaled coordinates: one unit is this fraction of the nominal stiffness ...
STIFFNESS_UNIT = 0.5
#: ... and this offset (m). A direction whose std exceeds one unit is unidentifiable.
OFFSET_UNIT = 5e-3
#: Singular values below this fraction of the largest count as zero (numerical rank).
RANK_TOLERANCE = 1e-6
#: Gauss-Newton iterations of the per-sample screw refinement ...
SCREW_ITERATIONS = 8
#: ... in which a sample stops when its step moves no screw coordinate more than this (rad,
#: m; far below any sensor's noise: the fit moves every screw again).
SCREW_TOLERANCE = 1e-6
#: Rows of each product in a sum over the samples (:func:`sum_of_products`): small enough that
#: BLAS computes it on one thread.
SUM_BLOCK_ROWS = 256
#: A sample with a known load is at equilibrium when every component of ``F + W`` is below this
#: (N, N m) ...
EQUILIBRIUM_TOLERANCE = 1e-11
#: ... within this many Newton iterations.
EQUILIBRIUM_ITERATIONS = 30


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
class CalibrationEvaluation:
    """Whitened residuals (N, R) and their Jacobians w.r.t. the screws and the scaled parameters
    at one point (rows: pose 6, wrench 6, tensions n, lengths n). The Jacobians are kept for the
    rows some sample measures only (``rows``, m of R: :attr:`CalibrationProblem.rows`), and the
    one w.r.t. the parameters for those of them that depend on the parameters (the wrench and the
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
    # K^-1 (N, 6, 6) of the samples with a known load
    # (:meth:`CalibrationProblem.normal_equations`), else 0
    wrench_screw_inverse: FloatArray = field(default_factory=_empty)
    stretch_screw: FloatArray = field(default_factory=_empty)  # d l_j / d xi (N, n, 6)
    # With the parameter Jacobians (else empty):
    parameter_rows: FloatArray = field(default_factory=_empty)  # d r / d z (N, mp, 2n) whitened
    wrench_parameters: FloatArray = field(default_factory=_empty)  # d F / d z (N, 6, 2n)

    def subset(self, samples: NDArray[np.int64]) -> CalibrationEvaluation:
        """The evaluation of the samples ``samples`` (positions in this one) only (this one
        itself when they are all of its samples)."""
        if np.array_equal(samples, np.arange(len(self.index))):
            return self
        return replace(self, **{name: a[samples] for name, a in self._per_sample().items()})

    def assign(self, samples: NDArray[np.int64], other: CalibrationEvaluation) -> None:
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
    :meth:`CalibrationProblem.normal_equations`: per sample ``A = Jx^T Jx`` (N, 6, 6),
    ``B = Jx^T Jz`` (N, 6, 2n), ``gx = Jx^T r`` (N, 6); summed over the samples
    ``C = sum Jz^T Jz`` (2n, 2n) and ``gp = sum Jz^T r`` (2n,) (``B``, ``C``, ``gp`` empty
    without the parameter Jacobians)."""

    A: FloatArray
    B: FloatArray
    C: FloatArray
    gx: FloatArray
    gp: FloatArray


class CalibrationProblem:
    """The calibration problem on fixed data: evaluation of residuals and Jacobians at
    (stiffness k, offsets d, screws xi)."""

    def __init__(self, model: JointModel, data: CalibrationData, noise: CalibrationNoise) -> None:
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
                 samples: NDArray[np.intp] | None = None) -> CalibrationEvaluation:
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
        ev = CalibrationEvaluation(residuals, raw, state.wrench, stretch, index, self.rows,
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
    def normal_equations(self, ev: CalibrationEvaluation, weights: FloatArray | None = None
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
            C = sum_of_products(jp, jp)
            gp = sum_of_products(jp, r[:, block, None])[:, 0]
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
                C += sum_of_products(B_l, H) + sum_of_products(H, moved)
                gp += sum_of_products(H, gx_l[..., None])[:, 0]
                B[loaded] = Mt @ moved
            A[loaded] = Mt @ A_l @ M
            gx[loaded] = (Mt @ gx_l[..., None])[..., 0]
            exact = self.exact[ev.index]
            if exact.any():
                A[exact], gx[exact] = 0.0, 0.0
                if parameters:
                    B[exact] = 0.0
        return _NormalEquations(A, B, C, gx, gp)

    def advance(self, z: FloatArray, xi: FloatArray, ev: CalibrationEvaluation, z_new: FloatArray,
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

    def _screw_line_search(self, z: FloatArray, xi: FloatArray, ev: CalibrationEvaluation,
                           step: FloatArray, cost: FloatArray
                           ) -> tuple[FloatArray, CalibrationEvaluation]:
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
    def information(self, ev: CalibrationEvaluation, columns: NDArray[np.int64]) -> FloatArray:
        """Parameters' information with the screws eliminated (Schur complement per sample),
        scaled coordinates, over ``columns`` of the parameter vector."""
        return schur_complement(self.normal_equations(ev), columns)[0]


def schur_complement(eq: _NormalEquations, columns: NDArray[np.int64]
           ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(information ``S = C - sum B^T A^+ B`` over ``columns``, ``A^+`` (N, 6, 6),
    ``A^+ B`` (N, 6, P)): the screws eliminated per sample."""
    A_pinv = _pinv_psd(eq.A)
    B = eq.B[:, :, columns]
    AB = A_pinv @ B
    return eq.C[np.ix_(columns, columns)] - sum_of_products(B, AB), A_pinv, AB


def sum_of_products(a: FloatArray, b: FloatArray) -> FloatArray:
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
