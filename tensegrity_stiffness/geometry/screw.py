"""Screw algebra on SE(3) in the paper's [omega; v] ordering (Monke & Vikas, eqs. 1-5, 12-18).

Conventions
-----------
* A screw is ``xi = [omega; v]`` (rotation first), ``theta = |omega|`` in radians, ``v`` in metres.
* ``T(xi) = exp(hat(xi))`` maps coordinates in link 2's frame {2} into link 1's frame {1}.
* Every function accepts one screw of shape ``(6,)`` or a batch of shape ``(N, 6)`` and returns
  arrays with the same leading shape.

The closed-form derivative ``dT/dxi`` uses the SO(3) left Jacobian ``G`` (eq. 4, 14) and the
derivative of ``G v`` with respect to ``omega`` (eqs. 15-17). Every coefficient that is a ratio of
vanishing quantities at ``theta -> 0`` has a Taylor branch below ``SERIES_THRESHOLD``; the closed
forms are used above it, where they keep at least 13 significant digits.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import OutsideChartError
from tensegrity_stiffness.geometry.validation import finite_array

FloatArray = NDArray[np.float64]

#: Below this rotation angle (rad) the Taylor series of the coefficients are used.
SERIES_THRESHOLD = 0.5
#: Number of Taylor terms (in theta**2) kept; the remainder at theta = 0.5 is below 1e-30.
_SERIES_TERMS = 12
#: Below this angle (rad) the inverse left Jacobian uses its series.
_INVERSE_SERIES_THRESHOLD = 0.5
#: |theta - pi| below which log_so3 takes the rotation axis from the symmetric part of R.
_LOG_SYMMETRIC_BRANCH = 0.5 * math.pi
#: Batches of at most this many screws (a spine's joints) take the plain-float chart check.
SCALAR_KINEMATICS_ROWS = 16
#: The chart of screw coordinates: |omega| < CHART_LIMIT (the left Jacobian G, eq. 4, is singular
#: at 2 pi, so neither dT/dxi nor K can be inverted there).
CHART_LIMIT = 2.0 * math.pi
#: The swap of the 3-blocks of a 6-vector: ``[omega; v] <-> [v; omega]`` (index array, its own
#: inverse; ``Pi`` of the chain's and the dynamics' equations).
BLOCK_SWAP = np.array([3, 4, 5, 0, 1, 2])
BLOCK_SWAP.flags.writeable = False


def check_in_chart(xi: ArrayLike, name: str = 'screw') -> None:
    """:class:`~.errors.OutsideChartError` (a ValueError) naming ``name`` unless every screw
    of ``xi`` (shape (6,) or (N, 6)) has |omega| < :data:`CHART_LIMIT`."""
    arr = np.asarray(xi, dtype=np.float64)
    if arr.ndim == 1:  # one screw (the node's per-message path): plain floats
        wx, wy, wz = arr[:3].tolist()
        theta = math.sqrt(wx * wx + wy * wy + wz * wz)
        if theta < CHART_LIMIT:
            return
        worst = theta if not math.isnan(theta) else math.inf
    elif arr.ndim == 2 and arr.shape[0] <= SCALAR_KINEMATICS_ROWS:  # a spine's joints
        thetas = [math.sqrt(wx * wx + wy * wy + wz * wz)
                  for wx, wy, wz in arr[:, :3].tolist()]
        if all(theta < CHART_LIMIT for theta in thetas):
            return
        worst = max(math.inf if math.isnan(theta) else theta for theta in thetas)
    else:
        omega = arr[..., :3]
        thetas = np.sqrt(np.sum(omega * omega, axis=-1))
        if np.all(thetas < CHART_LIMIT):
            return
        worst = float(np.max(np.where(np.isnan(thetas), np.inf, thetas)))
    raise OutsideChartError(f'{name}: |omega| = {worst:.6g} rad is outside the chart '
                     f'(must be < 2 pi)')


def _series(offset: int, derivative: bool) -> FloatArray:
    """Taylor coefficients (in theta**2) of sum_k (-1)^k theta^2k / (2k + offset)!.

    With ``derivative`` the coefficients of (1/theta) d/dtheta of that series.
    """
    coeffs = np.array(
        [(-1.0) ** k / math.factorial(2 * k + offset) for k in range(_SERIES_TERMS + 1)]
    )
    if derivative:
        coeffs = np.array([2.0 * k * coeffs[k] for k in range(1, _SERIES_TERMS + 1)])
    else:
        coeffs = coeffs[:_SERIES_TERMS]
    return coeffs[::-1].copy()  # highest power first, for np.polyval


# a = sin t / t, b = (1 - cos t) / t^2, c = (t - sin t) / t^3 and b1 = b'/t, c1 = c'/t.
_A_SERIES = _series(1, False)
_B_SERIES = _series(2, False)
_C_SERIES = _series(3, False)
_B1_SERIES = _series(2, True)
_C1_SERIES = _series(3, True)
#: The Taylor tables of the rotation coefficients a, b, c, b1, c1, in that order (the compiled
#: kernel's copy is generated from these).
ROTATION_SERIES = (_A_SERIES, _B_SERIES, _C_SERIES, _B1_SERIES, _C1_SERIES)
# e = (1 - t sin t / (2 (1 - cos t))) / t^2, the omega^2 coefficient of the inverse left Jacobian.
_E_SERIES = np.array([691.0 / 1307674368000.0, 1.0 / 47900160.0, 1.0 / 1209600.0,
                      1.0 / 30240.0, 1.0 / 720.0, 1.0 / 12.0])
_E_SERIES_FLOATS = tuple(_E_SERIES.tolist())
_TINY = float(np.finfo(float).tiny)


def rotation_coefficients(theta: ArrayLike) -> tuple[FloatArray, ...]:
    """Coefficients ``a, b, c, b1, c1`` of Rodrigues' formula and the left Jacobian.

    ``a = sin t / t``, ``b = (1 - cos t) / t^2``, ``c = (t - sin t) / t^3`` (eqs. 3, 4, 14) and
    ``b1 = (db/dt) / t = (t sin t + 2 cos t - 2) / t^4``,
    ``c1 = (dc/dt) / t = (3 sin t - t cos t - 2 t) / t^5`` (eq. 16 divided by t, so that
    ``d b / d omega_i = b1 * omega_i``). Accurate for every ``t >= 0`` including 0.
    """
    t = np.asarray(theta, dtype=np.float64)
    t2 = t * t
    small = t < SERIES_THRESHOLD
    # Without small angles only the closed forms are needed; otherwise they are evaluated at 1
    # where the series is taken (no 0/0 in the discarded branch).
    ts = t if t.ndim and not small.any() else np.where(small, 1.0, t)
    s, c = np.sin(ts), np.cos(ts)
    closed = (
        s / ts,
        (1.0 - c) / ts**2,
        (ts - s) / ts**3,
        (ts * s + 2.0 * c - 2.0) / ts**4,
        (3.0 * s - ts * c - 2.0 * ts) / ts**5,
    )
    if ts is t:
        return closed
    series = (_A_SERIES, _B_SERIES, _C_SERIES, _B1_SERIES, _C1_SERIES)
    return tuple(
        np.where(small, np.polyval(p, t2), value) for p, value in zip(series, closed, strict=True)
    )


def _coefficients_scalar(theta: float) -> tuple[float, float, float, float, float]:
    """Scalar fast path of :func:`rotation_coefficients` (math module, no array overhead)."""
    if theta < SERIES_THRESHOLD:
        t2 = theta * theta
        out = []
        for p in (_A_SERIES, _B_SERIES, _C_SERIES, _B1_SERIES, _C1_SERIES):
            acc = 0.0
            for coeff in p:
                acc = acc * t2 + coeff
            out.append(acc)
        return out[0], out[1], out[2], out[3], out[4]
    s, c = math.sin(theta), math.cos(theta)
    t2 = theta * theta
    return (
        s / theta,
        (1.0 - c) / t2,
        (theta - s) / (t2 * theta),
        (theta * s + 2.0 * c - 2.0) / (t2 * t2),
        (3.0 * s - theta * c - 2.0 * theta) / (t2 * t2 * theta),
    )


def as_screws(xi: ArrayLike, name: str = 'xi') -> FloatArray:
    """Validate screws: shape ``(6,)`` or ``(N, 6)``, finite; returns a float64 array."""
    arr = np.asarray(xi, dtype=np.float64)
    if arr.ndim not in (1, 2) or arr.shape[-1] != 6:
        raise ValueError(f'{name} must have shape (6,) or (N, 6), got {arr.shape}')
    if not np.isfinite(arr).all():
        raise ValueError(f'{name} must be finite, got {arr}')
    return arr


def single_screw(xi: ArrayLike, name: str = 'screw', in_chart: bool = True) -> FloatArray:
    """One screw ``[omega; v]`` (6,) as float64: ValueError naming ``name`` when it is not six
    finite numbers and, when ``in_chart``, :class:`~.errors.OutsideChartError` when
    ``|omega| >= CHART_LIMIT``. The one check of a single screw."""
    x = finite_array(name, xi)
    if x.shape != (6,):
        raise ValueError(f'{name} must have 6 values [wx wy wz vx vy vz], got shape {x.shape}')
    if in_chart:
        check_in_chart(x, name)
    return x


def hat3(w: ArrayLike) -> FloatArray:
    """so(3) hat: ``(..., 3) -> (..., 3, 3)`` with ``hat3(a) @ b == cross(a, b)``."""
    w = np.asarray(w, dtype=np.float64)
    out = np.zeros(w.shape[:-1] + (3, 3))
    out[..., 0, 1] = -w[..., 2]
    out[..., 0, 2] = w[..., 1]
    out[..., 1, 0] = w[..., 2]
    out[..., 1, 2] = -w[..., 0]
    out[..., 2, 0] = -w[..., 1]
    out[..., 2, 1] = w[..., 0]
    return out


def vee3(W: ArrayLike) -> FloatArray:
    """Inverse of :func:`hat3` (uses the skew-symmetric part)."""
    W = np.asarray(W, dtype=np.float64)
    return 0.5 * np.stack(
        [W[..., 2, 1] - W[..., 1, 2], W[..., 0, 2] - W[..., 2, 0], W[..., 1, 0] - W[..., 0, 1]],
        axis=-1,
    )


def hat(xi: ArrayLike) -> FloatArray:
    """se(3) hat (eq. 1): ``(..., 6) -> (..., 4, 4)``, ``xi = [omega; v]``."""
    xi = np.asarray(xi, dtype=np.float64)
    out = np.zeros(xi.shape[:-1] + (4, 4))
    out[..., :3, :3] = hat3(xi[..., :3])
    out[..., :3, 3] = xi[..., 3:]
    return out


def small_adjoint(V: ArrayLike) -> FloatArray:
    """``ad_V = [[hat(w), 0], [hat(v), hat(w)]]`` (6, 6) of a twist ``V = [w; v]`` (6,) in the
    screws' order: ``hat(ad_V U) = [hat(V), hat(U)]``."""
    V = np.asarray(V, dtype=np.float64)
    out = np.zeros((6, 6))
    hw = hat3(V[:3])
    out[:3, :3] = hw
    out[3:, 3:] = hw
    out[3:, :3] = hat3(V[3:])
    return out


def vee(X: ArrayLike) -> FloatArray:
    """Inverse of :func:`hat`: ``(..., 4, 4) -> (..., 6)`` as ``[omega; v]``."""
    X = np.asarray(X, dtype=np.float64)
    return np.concatenate([vee3(X[..., :3, :3]), X[..., :3, 3]], axis=-1)


def _rotation_and_jacobian(
    omega: FloatArray, coeffs: tuple[FloatArray, ...]
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """R = exp(hat omega) (eq. 3), G (eq. 4), W = hat(omega), W @ W for batched omega."""
    a, b, c = coeffs[0], coeffs[1], coeffs[2]
    W = hat3(omega)
    W2 = W @ W
    eye = np.eye(3)
    R = eye + a[..., None, None] * W + b[..., None, None] * W2
    G = eye + b[..., None, None] * W + c[..., None, None] * W2
    return R, G, W, W2


def exp_so3(omega: ArrayLike) -> FloatArray:
    """Rodrigues' formula (eq. 3): ``(..., 3) -> (..., 3, 3)``."""
    omega = np.asarray(omega, dtype=np.float64)
    coeffs = rotation_coefficients(np.linalg.norm(omega, axis=-1))
    return _rotation_and_jacobian(omega, coeffs)[0]


def left_jacobian_so3(omega: ArrayLike) -> FloatArray:
    """SO(3) left Jacobian ``G = I + b W + c W^2`` (eqs. 4, 14)."""
    omega = np.asarray(omega, dtype=np.float64)
    coeffs = rotation_coefficients(np.linalg.norm(omega, axis=-1))
    return _rotation_and_jacobian(omega, coeffs)[1]


def left_jacobian_so3_inverse(omega: ArrayLike) -> FloatArray:
    """``G^-1 = I - W/2 + e W^2``, ``e = (1 - t sin t / (2 (1 - cos t))) / t^2``.

    Singular at ``|omega| = 2 pi`` (where ``G`` is not invertible).
    """
    omega = np.asarray(omega, dtype=np.float64)
    t = np.linalg.norm(omega, axis=-1)
    small = t < _INVERSE_SERIES_THRESHOLD
    ts = np.where(small, 1.0, t)
    closed = (1.0 - ts * np.sin(ts) / (2.0 * (1.0 - np.cos(ts)))) / ts**2
    e = np.where(small, np.polyval(_E_SERIES, t * t), closed)
    W = hat3(omega)
    return np.eye(3) - 0.5 * W + e[..., None, None] * (W @ W)


def _kinematics_entries(xi6: list, coeffs: tuple, zero: Any, one: Any) -> tuple[list, list]:
    """Entries of T (4x4) and J (6x6) as nested lists, for floats or (N,) arrays.

    ``W^2 = w w^T - theta^2 I`` gives R (eq. 3) and G (eq. 4); ``t = G v``;
    ``D = -b hat(v) + c (w v^T + (w.v) I - 2 v w^T) + e w^T`` with ``e = b1 W v + c1 W^2 v``
    (eqs. 15-17 applied to v); ``Q = D + hat(t) G``; ``J = [[G, 0], [Q, G]]``.
    """
    wx, wy, wz, vx, vy, vz = xi6
    a, b, c, b1, c1 = coeffs
    xx, yy, zz, xy, xz, yz = wx * wx, wy * wy, wz * wz, wx * wy, wx * wz, wy * wz
    t2 = xx + yy + zz
    g00, g01, g02 = 1.0 + c * (xx - t2), -b * wz + c * xy, b * wy + c * xz
    g10, g11, g12 = b * wz + c * xy, 1.0 + c * (yy - t2), -b * wx + c * yz
    g20, g21, g22 = -b * wy + c * xz, b * wx + c * yz, 1.0 + c * (zz - t2)
    tx = g00 * vx + g01 * vy + g02 * vz
    ty = g10 * vx + g11 * vy + g12 * vz
    tz = g20 * vx + g21 * vy + g22 * vz
    T = [[1.0 + b * (xx - t2), -a * wz + b * xy, a * wy + b * xz, tx],
         [a * wz + b * xy, 1.0 + b * (yy - t2), -a * wx + b * yz, ty],
         [-a * wy + b * xz, a * wx + b * yz, 1.0 + b * (zz - t2), tz],
         [zero, zero, zero, one]]
    wv = wx * vx + wy * vy + wz * vz
    ex = b1 * (wy * vz - wz * vy) + c1 * (wx * wv - t2 * vx)
    ey = b1 * (wz * vx - wx * vz) + c1 * (wy * wv - t2 * vy)
    ez = b1 * (wx * vy - wy * vx) + c1 * (wz * wv - t2 * vz)
    d = [[c * (wv - wx * vx) + ex * wx, b * vz + c * (wx * vy - 2.0 * vx * wy) + ex * wy,
          -b * vy + c * (wx * vz - 2.0 * vx * wz) + ex * wz],
         [-b * vz + c * (wy * vx - 2.0 * vy * wx) + ey * wx, c * (wv - wy * vy) + ey * wy,
          b * vx + c * (wy * vz - 2.0 * vy * wz) + ey * wz],
         [b * vy + c * (wz * vx - 2.0 * vz * wx) + ez * wx,
          -b * vx + c * (wz * vy - 2.0 * vz * wy) + ez * wy, c * (wv - wz * vz) + ez * wz]]
    q = [[d[0][0] - tz * g10 + ty * g20, d[0][1] - tz * g11 + ty * g21,
          d[0][2] - tz * g12 + ty * g22],
         [d[1][0] + tz * g00 - tx * g20, d[1][1] + tz * g01 - tx * g21,
          d[1][2] + tz * g02 - tx * g22],
         [d[2][0] - ty * g00 + tx * g10, d[2][1] - ty * g01 + tx * g11,
          d[2][2] - ty * g02 + tx * g12]]
    J = [[g00, g01, g02, zero, zero, zero], [g10, g11, g12, zero, zero, zero],
         [g20, g21, g22, zero, zero, zero], q[0] + [g00, g01, g02], q[1] + [g10, g11, g12],
         q[2] + [g20, g21, g22]]
    return T, J


class ScrewKinematics:
    """Everything derived from one screw (or a batch) that the joint model needs.

    Attributes (leading batch shape ``B`` = ``()`` or ``(N,)``):
    ``T`` (B, 4, 4) = exp(hat(xi)) with ``R`` (B, 3, 3) and ``t`` (B, 3) as views;
    ``J`` (B, 6, 6) = [[G, 0], [Q, G]] the SE(3) left Jacobian in [omega; v] order, with views
    ``G`` (the SO(3) left Jacobian, eq. 4) and ``Q = D + hat(t) G`` where ``D = d t / d omega``
    (eqs. 15-17; :attr:`D` recovers it). One set of entry formulas serves both paths: plain
    floats for a single screw (about 10x faster than arrays at this size), (N,) arrays for a batch.
    """

    __slots__ = ('G', 'J', 'Q', 'R', 'T', 't', 'theta')

    def __init__(self, xi: ArrayLike) -> None:
        xi = np.asarray(xi, dtype=np.float64)
        if xi.ndim == 1:
            values = xi.tolist()
            self.theta = math.sqrt(values[0] ** 2 + values[1] ** 2 + values[2] ** 2)
            T, J = _kinematics_entries(values, _coefficients_scalar(self.theta), 0.0, 1.0)
            self.T, self.J = np.array(T), np.array(J)
        else:
            n = xi.shape[0]
            self.theta = np.sqrt(np.einsum('ij,ij->i', xi[:, :3], xi[:, :3]))
            T, J = _kinematics_entries(list(xi.T), rotation_coefficients(self.theta),
                                       np.zeros(n), np.ones(n))
            self.T = np.moveaxis(np.array(T), -1, 0)
            self.J = np.moveaxis(np.array(J), -1, 0)
        self.R = self.T[..., :3, :3]
        self.t = self.T[..., :3, 3]
        self.G = self.J[..., :3, :3]
        self.Q = self.J[..., 3:, :3]

    @classmethod
    def from_matrices(cls, theta: float, T: FloatArray, J: FloatArray) -> ScrewKinematics:
        """The kinematics of one screw whose ``T`` (4, 4) and ``J`` (6, 6) were computed
        elsewhere (the compiled kernel's twin of these formulas), with its angle ``theta``."""
        kin = cls.__new__(cls)
        kin.theta, kin.T, kin.J = theta, T, J
        kin.R = T[:3, :3]
        kin.t = T[:3, 3]
        kin.G = J[:3, :3]
        kin.Q = J[3:, :3]
        return kin

    @property
    def D(self) -> FloatArray:
        """``d t / d omega`` (eqs. 15-17), (B, 3, 3): column i is d(G v)/d omega_i."""
        return self.Q - hat3(self.t) @ self.G


def exp_se3(xi: ArrayLike) -> FloatArray:
    """``T = exp(hat(xi))`` (eq. 2): ``(6,) -> (4, 4)`` or ``(N, 6) -> (N, 4, 4)``."""
    return ScrewKinematics(as_screws(xi)).T


def left_jacobian_se3(xi: ArrayLike) -> FloatArray:
    """SE(3) left Jacobian in [omega; v] order: ``[[G, 0], [Q, G]]``, ``(..., 6, 6)``.

    Defined by ``exp(hat(xi + d)) = exp(hat(J d)) exp(hat(xi)) + O(|d|^2)``: it maps a change of
    screw coordinates to the spatial twist (in {1}, [omega; v]) that produces it.
    """
    return ScrewKinematics(as_screws(xi)).J


def dexp_se3(xi: ArrayLike) -> FloatArray:
    """Closed-form ``dT/dxi`` (eqs. 12-18): ``(6,) -> (4, 4, 6)``, ``[:, :, i] = dT/dxi_i``.

    Rotation block: ``dR/d omega_i = hat(G e_i) R``, equal to Gallego and Yezzi's eq. (13) read
    as a sum of three terms (docs/errata.md; checked in the tests). Translation column:
    ``d(G v)/d omega_i = D e_i`` (eqs. 15-17), ``dT/dv_i = [0, G e_i]`` (eq. 18). Batched input
    ``(N, 6)`` gives ``(N, 4, 4, 6)``. Exact at ``theta = 0`` (series branch).
    """
    xi = as_screws(xi)
    kin = ScrewKinematics(xi)
    out = np.zeros(xi.shape[:-1] + (4, 4, 6))
    # hat(G e_i) R for i = 0, 1, 2: move the column index of G to the front.
    Gcols = np.moveaxis(kin.G, -1, -2)  # (..., 3 (i), 3)
    dR = hat3(Gcols) @ kin.R[..., None, :, :]  # (..., 3 (i), 3, 3)
    out[..., :3, :3, :3] = np.moveaxis(dR, -3, -1)
    out[..., :3, 3, :3] = kin.D
    out[..., :3, 3, 3:] = kin.G
    return out


def log_so3(R: ArrayLike, reference: ArrayLike | None = None) -> FloatArray:
    """Rotation vector of ``R`` (``|omega| < 2 pi``) on the branch nearest to ``reference``.

    The candidates are ``theta u`` and ``(theta - 2 pi) u`` with ``theta`` in ``[0, pi]``; without
    a reference the principal one (``|omega| <= pi``) is returned. Robust at ``theta = 0`` and at
    ``theta = pi`` (axis from the symmetric part of R, sign from the skew part).
    """
    R = np.asarray(R, dtype=np.float64)
    if R.shape != (3, 3):
        raise ValueError(f'R must have shape (3, 3), got {R.shape}')
    ref = None if reference is None else np.asarray(reference, dtype=np.float64).tolist()
    return np.array(_log_so3_floats(R.tolist(), ref))


def _log_so3_floats(R: list, reference: list | None) -> list[float]:
    """:func:`log_so3` on plain floats (a 3x3 nested list; one rotation costs a few us, where
    numpy's small-array calls cost some 50 us)."""
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R
    sx, sy, sz = 0.5 * (r21 - r12), 0.5 * (r02 - r20), 0.5 * (r10 - r01)  # sin(theta) u
    sin_t = math.sqrt(sx * sx + sy * sy + sz * sz)
    cos_t = 0.5 * (r00 + r11 + r22 - 1.0)
    theta = math.atan2(sin_t, cos_t)
    if theta < _LOG_SYMMETRIC_BRANCH:
        # theta / sin(theta) with its series near 0.
        t2 = theta * theta
        ratio = 1.0 + t2 / 6.0 + 7.0 * t2 * t2 / 360.0 if theta < 1e-4 else theta / sin_t
        omega = [ratio * sx, ratio * sy, ratio * sz]
    else:
        # u u^T = (sym(R) - cos t I) / (1 - cos t); take the best-conditioned column.
        d = 1.0 - cos_t
        uu = [[(r00 - cos_t) / d, 0.5 * (r01 + r10) / d, 0.5 * (r02 + r20) / d],
              [0.5 * (r01 + r10) / d, (r11 - cos_t) / d, 0.5 * (r12 + r21) / d],
              [0.5 * (r02 + r20) / d, 0.5 * (r12 + r21) / d, (r22 - cos_t) / d]]
        k = max(range(3), key=lambda i: uu[i][i])
        scale = 1.0 / math.sqrt(max(uu[k][k], _TINY))
        u = [uu[0][k] * scale, uu[1][k] * scale, uu[2][k] * scale]
        norm = math.sqrt(u[0] * u[0] + u[1] * u[1] + u[2] * u[2])
        sign = -1.0 if u[0] * sx + u[1] * sy + u[2] * sz < 0.0 else 1.0
        omega = [sign * theta * c / norm for c in u]
    if reference is None or theta == 0.0:
        return omega
    norm = math.sqrt(omega[0] ** 2 + omega[1] ** 2 + omega[2] ** 2)
    factor = (norm - 2.0 * math.pi) / norm
    other = [c * factor for c in omega]
    if math.dist(other, reference) < math.dist(omega, reference):
        return other
    return omega


def log_so3_batch(R: ArrayLike) -> FloatArray:
    """Rotation vectors (N, 3) of rotations (N, 3, 3), principal branch (``|phi| <= pi``): the
    batched :func:`log_so3` (the same two branches: ``theta /
    sin(theta)`` times the skew part below pi/2, the axis from the symmetric part above)."""
    R = np.asarray(R, dtype=np.float64)
    v = vee3(R)  # sin(theta) u
    sin_t = np.linalg.norm(v, axis=-1)
    cos_t = 0.5 * (np.trace(R, axis1=-2, axis2=-1) - 1.0)
    theta = np.arctan2(sin_t, cos_t)
    small = theta < 1e-4
    with np.errstate(invalid='ignore', divide='ignore'):
        ratio = np.where(small, 1.0 + theta * theta / 6.0, theta / np.where(small, 1.0, sin_t))
    out = ratio[:, None] * v
    large = np.flatnonzero(theta >= 0.5 * math.pi)
    if large.size:
        Rl, cl = R[large], cos_t[large]
        uu = (0.5 * (Rl + np.swapaxes(Rl, -1, -2)) - cl[:, None, None] * np.eye(3)) / \
            (1.0 - cl)[:, None, None]
        rows = np.arange(large.size)
        k = np.argmax(np.diagonal(uu, axis1=-2, axis2=-1), axis=1)
        u = uu[rows, :, k] / np.sqrt(np.maximum(uu[rows, k, k], np.finfo(float).tiny))[:, None]
        u /= np.linalg.norm(u, axis=1)[:, None]
        u *= np.where(np.einsum('ij,ij->i', u, v[large]) < 0.0, -1.0, 1.0)[:, None]
        out[large] = theta[large, None] * u
    return out


def log_se3_sequence(poses: ArrayLike, reference: ArrayLike) -> FloatArray:
    """Screws (N, 6) of poses (N, 4, 4), each on the rotation branch nearest the previous one
    (the first nearest ``reference``), as a tracker takes them: :func:`log_se3` in a batch."""
    poses = np.asarray(poses, dtype=np.float64)
    omega = log_so3_batch(poses[:, :3, :3])
    previous = np.asarray(reference, dtype=np.float64)[:3]
    for i, w in enumerate(omega):
        norm = math.sqrt(float(w @ w))
        if norm > 0.0:
            other = w * ((norm - 2.0 * math.pi) / norm)
            if np.linalg.norm(other - previous) < np.linalg.norm(w - previous):
                omega[i] = other
        previous = omega[i]
    v = (left_jacobian_so3_inverse(omega) @ poses[:, :3, 3, None])[:, :, 0]
    return np.concatenate([omega, v], axis=1)


def _inverse_jacobian_coefficient(t: float) -> float:
    """``e`` of :func:`left_jacobian_so3_inverse` at one angle ``t`` (its series below
    ``_INVERSE_SERIES_THRESHOLD``)."""
    if t < _INVERSE_SERIES_THRESHOLD:
        e = 0.0
        for coefficient in _E_SERIES_FLOATS:  # Horner in t^2, as np.polyval
            e = e * t * t + coefficient
        return e
    return (1.0 - t * math.sin(t) / (2.0 * (1.0 - math.cos(t)))) / (t * t)


def log_se3(T: ArrayLike, reference: ArrayLike | None = None) -> FloatArray:
    """Screw ``xi = [omega; v]`` with ``exp(hat(xi)) = T`` (inverse of eq. 2).

    ``reference`` (a screw, shape (6,)) selects the rotation branch nearest to its omega, which
    matters at ``theta = pi`` where ``pi u`` and ``-pi u`` give the same rotation. ``T`` must be a
    rigid transform (orthonormal R with det +1 to 1e-6). ``v = G^-1 p`` with
    ``G^-1 = I - W/2 + e W^2`` (:func:`left_jacobian_so3_inverse`), on plain floats.
    """
    T = np.asarray(T, dtype=np.float64)
    if T.shape != (4, 4):
        raise ValueError(f'T must have shape (4, 4), got {T.shape}')
    rows = T.tolist()
    if not all(math.isfinite(x) for row in rows for x in row):
        raise ValueError('T must be finite')
    R = [row[:3] for row in rows[:3]]
    columns = list(zip(*R, strict=True))
    gram_error = max(abs(sum(a * b for a, b in zip(columns[i], columns[j], strict=True))
                         - (1.0 if i == j else 0.0)) for i in range(3) for j in range(3))
    (r00, r01, r02), (r10, r11, r12), (r20, r21, r22) = R
    det = (r00 * (r11 * r22 - r12 * r21) - r01 * (r10 * r22 - r12 * r20)
           + r02 * (r10 * r21 - r11 * r20))
    if gram_error > 1e-6 or det < 0.0:
        raise ValueError('T[:3, :3] must be a rotation matrix (orthonormal, det +1)')
    ref_omega = None
    if reference is not None:
        ref = as_screws(reference, 'reference')
        if ref.shape != (6,):
            raise ValueError(f'reference must have shape (6,), got {ref.shape}')
        ref_omega = ref[:3].tolist()
    wx, wy, wz = _log_so3_floats(R, ref_omega)
    px, py, pz = rows[0][3], rows[1][3], rows[2][3]
    e = _inverse_jacobian_coefficient(math.sqrt(wx * wx + wy * wy + wz * wz))
    # w x p and w x (w x p): W p and W^2 p
    cx, cy, cz = wy * pz - wz * py, wz * px - wx * pz, wx * py - wy * px
    ccx, ccy, ccz = wy * cz - wz * cy, wz * cx - wx * cz, wx * cy - wy * cx
    return np.array([wx, wy, wz, px - 0.5 * cx + e * ccx, py - 0.5 * cy + e * ccy,
                     pz - 0.5 * cz + e * ccz])
