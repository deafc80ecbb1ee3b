"""Reference evaluation of the joint model: the readable implementation that the fast paths of
:class:`~tensegrity_stiffness.joint.JointModel` are tested and benchmarked against.

This is the computation of the module docstring of :mod:`tensegrity_stiffness.joint` written out
step by step (eqs. 7-10): with ``A_j = df/ds`` and ``q_j = T p2_{b_j}``,
``ds_j/dxi = [hat(q_j) G - Q, -G]``, so that both matrices follow from two 6x3 sums
``H_G = sum [I; hat(p1)] A hat(q)`` and ``H_D = sum [I; hat(p1)] A``:
``K = [H_G G - H_D Q, -H_D G]`` and ``K_c = [H_D, -H_G]``. It uses the model's force law
(:meth:`JointModel._string_forces`) and :class:`~tensegrity_stiffness.screw.ScrewKinematics`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.screw import ScrewKinematics, as_screws

if TYPE_CHECKING:
    from tensegrity_stiffness.joint import JointModel, JointState

FloatArray = NDArray[np.float64]

#: Screws per chunk of the batched reference evaluation.
BATCH_CHUNK = 1024

# Y = X @ _Y_MAP = [-(p1 x u); u] for X = [u; p1 x u] (row-wise).
_Y_MAP = np.block([[np.zeros((3, 3)), np.eye(3)], [-np.eye(3), np.zeros((3, 3))]])
# K_c = H @ _KC_MAP = [H_D, -H_G].
_KC_MAP = np.block([[np.zeros((3, 3)), -np.eye(3)], [np.eye(3), np.zeros((3, 3))]])
_ROW_SIGN = np.array([1.0, 1.0, 1.0, -1.0, -1.0, -1.0])[:, None]


def _hat(w: FloatArray) -> FloatArray:
    """hat3 for (..., 3) arrays."""
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -w[..., 2], w[..., 1]
    out[..., 1, 0], out[..., 1, 2] = w[..., 2], -w[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -w[..., 1], w[..., 0]
    return out


def _beta_map(Z: FloatArray) -> FloatArray:
    """Matrix C (4n, 36) with ``sum_j beta_j [Z_j hat(q_j), Z_j] = (g @ C).reshape(6, 6)``.

    ``g = [beta_1 q_1, beta_1, ..., beta_n q_n, beta_n]`` (homogeneous q scaled by beta);
    ``hat(q)[b, c] = -eps[b, c, d] q_d``.
    """
    n = Z.shape[0]
    eps = np.zeros((3, 3, 3))
    eps[0, 1, 2] = eps[1, 2, 0] = eps[2, 0, 1] = 1.0
    eps[0, 2, 1] = eps[2, 1, 0] = eps[1, 0, 2] = -1.0
    C = np.zeros((n, 4, 6, 6))
    C[:, :3, :, :3] = -np.einsum('jab,bcd->jdac', Z, eps)
    C[:, 3, :, 3:] = Z
    return C.reshape(4 * n, 36)


class _Maps:
    """Per-model constants of the reference evaluation."""

    __slots__ = ('BETA_MAP', 'BETA_MAP_SOA', 'Z', 'p1', 'p2h')

    def __init__(self, model: JointModel) -> None:
        n = model.n_strings
        self.p1 = model.link1_nodes[model.connections[:, 0]]
        p2 = model.link2_nodes[model.connections[:, 1]]
        self.p2h = np.hstack([p2, np.ones((n, 1))])
        self.Z = np.concatenate([np.broadcast_to(np.eye(3), (n, 3, 3)), _hat(self.p1)], axis=1)
        self.BETA_MAP = _beta_map(self.Z)
        # The same map for g laid out component-major ((4, n) instead of (n, 4)).
        self.BETA_MAP_SOA = self.BETA_MAP.reshape(n, 4, 36).transpose(1, 0, 2).reshape(-1, 36)


def _maps(model: JointModel) -> _Maps:
    maps = model.__dict__.get('_reference_maps')
    if maps is None:
        maps = model.__dict__['_reference_maps'] = _Maps(model)
    return maps


def evaluate(model: JointModel, xi: ArrayLike, rest_lengths: ArrayLike | None = None
             ) -> JointState:
    """All quantities at screw ``xi`` (6,) or a batch (N, 6); rest lengths (n,) or (N, n):
    the same contract as :meth:`JointModel.evaluate`."""
    from tensegrity_stiffness.joint import JointState

    xi = as_screws(xi)
    rest = model.validate_rest_lengths(rest_lengths)
    if rest.ndim == 2 and (xi.ndim != 2 or xi.shape[0] != rest.shape[0]):
        raise ValueError(f'batched rest_lengths {rest.shape} need screws of shape '
                         f'({rest.shape[0]}, 6), got {xi.shape}')
    if xi.ndim == 2:
        return evaluate_batch(model, xi, rest)
    maps = _maps(model)
    kin = ScrewKinematics(xi)
    # Homogeneous link-2 string ends in {1}: [q_j, 1] = T [p2_j, 1].
    qh = maps.p2h @ kin.T.T  # (n, 4)
    q = qh[:, :3]
    s = maps.p1 - q
    lengths = np.sqrt((s * s).sum(1))
    check_lengths(lengths)
    u = s / lengths[:, None]
    phi, dphi, slack, saturated = model._string_forces(lengths, rest)
    beta = phi / lengths
    alpha = dphi - beta
    # X_j = Z_j u_j = [u_j; p1_j x u_j] with Z_j = [I; hat(p1_j)]: F = sum phi_j X_j (eq. 9).
    X = (maps.Z @ u[:, :, None])[:, :, 0]  # (n, 6)
    wrench = phi @ X
    # H = sum Z A [hat(q), I] with A = alpha u u^T + beta I (eq. 10 with df/ds of every
    # region). Alpha part: sum alpha X Y^T, Y = [u x q; u] = [-(p1 x u); u] (u parallel s).
    # Beta part: sum beta [Z hat(q), Z], linear in (beta q, beta): one precomputed matrix.
    H = (X * alpha[:, None]).T @ (X @ _Y_MAP)
    H += ((qh * beta[:, None]).ravel() @ maps.BETA_MAP).reshape(6, 6)
    # K = [H_G G - H_D Q, -H_D G] = H diag(I, -I) J (J the SE(3) left Jacobian);
    # K_c = [H_D, -H_G].
    K = H @ (kin.J * _ROW_SIGN)
    Kc = H @ _KC_MAP
    return JointState(xi, kin.T, s, lengths, phi, slack, saturated, wrench, K, Kc)


def check_lengths(lengths: FloatArray) -> None:
    """ValueError naming the strings shorter than ``MIN_STRING_LENGTH``."""
    from tensegrity_stiffness.joint import MIN_STRING_LENGTH

    if lengths.min() < MIN_STRING_LENGTH:
        bad = np.unique(np.nonzero(lengths < MIN_STRING_LENGTH)[-1]).tolist()
        raise ValueError(f'strings {bad} have zero length at this screw')


def evaluate_batch(model: JointModel, xi: FloatArray, rest: FloatArray,
                   wrench_only: bool = False) -> JointState:
    """The same computation as the single path for (N, 6) screws, in chunks of
    ``BATCH_CHUNK`` and with strings on the last axis ((N, 3, n) component layout), so that
    every step is one array operation or one GEMM over the chunk. With ``wrench_only`` the
    stiffness matrices are left out (they are NaN)."""
    from tensegrity_stiffness.joint import JointState

    maps = _maps(model)
    N, n = xi.shape[0], model.n_strings
    T = np.empty((N, 4, 4))
    s_out = np.empty((N, n, 3))
    lengths = np.empty((N, n))
    phi = np.empty((N, n))
    slack = np.empty((N, n), dtype=bool)
    saturated = np.empty((N, n), dtype=bool)
    wrench = np.empty((N, 6))
    K = np.full((N, 6, 6), np.nan)
    Kc = np.full((N, 6, 6), np.nan)
    px, py, pz = maps.p1.T
    for start in range(0, N, BATCH_CHUNK):
        sl = slice(start, min(start + BATCH_CHUNK, N))
        m = sl.stop - sl.start
        r = rest if rest.ndim == 1 else rest[sl]
        kin = ScrewKinematics(xi[sl])
        T[sl] = kin.T
        qh = (kin.T.reshape(-1, 4) @ maps.p2h.T).reshape(m, 4, n)
        s = maps.p1.T - qh[:, :3]
        s_out[sl] = np.swapaxes(s, 1, 2)
        ln = np.sqrt(np.einsum('mkj,mkj->mj', s, s))
        check_lengths(ln)
        lengths[sl] = ln
        u = s / ln[:, None]
        ph, dph, slack[sl], saturated[sl] = model._string_forces(ln, r)
        phi[sl] = ph
        X = np.empty((m, 6, n))
        X[:, :3] = u
        X[:, 3] = py * u[:, 2] - pz * u[:, 1]
        X[:, 4] = pz * u[:, 0] - px * u[:, 2]
        X[:, 5] = px * u[:, 1] - py * u[:, 0]
        wrench[sl] = (X @ ph[:, :, None])[:, :, 0]
        if wrench_only:
            continue
        beta = ph / ln
        alpha = dph - beta
        H = (X * alpha[:, None]) @ (np.swapaxes(X, 1, 2) @ _Y_MAP)
        H += ((qh * beta[:, None]).reshape(m, -1) @ maps.BETA_MAP_SOA).reshape(m, 6, 6)
        K[sl] = H @ (kin.J * _ROW_SIGN)
        Kc[sl] = (H.reshape(-1, 6) @ _KC_MAP).reshape(m, 6, 6)
    return JointState(xi, T, s_out, lengths, phi, slack, saturated, wrench, K, Kc)
