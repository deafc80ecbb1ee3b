"""Workspaces, singularity curves and stiffness maps of the planar mechanism (Figs. 2-3, 7-8).

Curves are returned as ``dict[name, (N, 2) float array]`` with NaN rows between segments (so
that ``plt.plot(c[:, 0], c[:, 1])`` draws them directly). Actuator curves have columns
``(theta1, L3)`` (rad, m; the axes of Fig. 2); Cartesian curves ``(x, y)`` (m, Fig. 3). Names
follow the paper: ``'i'`` L3 = 0 (eq. 26), ``'ii'`` sin(theta1) = 0 (eq. 27), ``'iii'`` eta1 = 0
(eq. 28), ``'iv'`` theta1 = theta2 mod pi (eq. 33), ``'v'`` the fold det J / L3 = 0 (eq. 30, in
closed form: a circle in the D1 plane and one in the D3 plane), ``'vi'`` L3 = L3_max (eq. 31).
Only the parts inside the actuator ranges are kept (a curve can be empty: with theta1 in [0, pi]
curve v always is). Cartesian curves are the exact images of the actuator curves under
:meth:`PlanarMechanism.forward_grid` (stable branch). Stiffness maps are vectorised (Figs. 7-8).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.planar import SQRT3, wrap_angles

if TYPE_CHECKING:
    from tensegrity_stiffness.mechanics.planar import PlanarMechanism

FloatArray = NDArray[np.float64]

#: Default number of samples along each curve.
DEFAULT_CURVE_SAMPLES = 400

_NAN_ROW = np.full((1, 2), np.nan)


def _segments(columns: tuple[FloatArray, FloatArray], keep: NDArray[np.bool_]) -> FloatArray:
    """(N, 2) array of the two columns with NaN where ``keep`` is False; empty if nothing kept."""
    if not np.any(keep):
        return np.empty((0, 2))
    out = np.column_stack(columns).astype(np.float64)
    out[~keep] = np.nan
    return out


def _join(parts: list[FloatArray]) -> FloatArray:
    """Concatenate segments with a NaN row between them (empty parts dropped)."""
    parts = [p for p in parts if len(p)]
    if not parts:
        return np.empty((0, 2))
    out = [parts[0]]
    for p in parts[1:]:
        out += [_NAN_ROW, p]
    return np.vstack(out)


def _in_L3_range(mech: PlanarMechanism, L3: FloatArray) -> NDArray[np.bool_]:
    tol = mech.range_tol
    with np.errstate(invalid='ignore'):
        return (L3 >= mech.L3_min - tol) & (L3 <= mech.L3_max + tol)


def actuator_workspace_curves(mech: PlanarMechanism,
                              n: int = DEFAULT_CURVE_SAMPLES) -> dict[str, FloatArray]:
    """Boundary and singularity curves of the actuator workspace (Fig. 2), columns (theta1, L3).

    ``'i'`` (eq. 26), ``'ii'`` (eq. 27, at each multiple of pi in the theta1 range), ``'iii'``
    (eq. 28: ``L3 = -2 sqrt3 K2 L / ((K1 + 2 K2) sin theta1 - sqrt3 K1 cos theta1)``), ``'iv'``
    (eq. 33: ``L3 = 2 L (sqrt3 K2 cos theta1 - (2 K1 - K2) sin theta1) / (sqrt3 K1)``), ``'v'``
    (eq. 30: circle ``|L c0 + m D1| = L (K1/2 + K2)``), ``'vi'`` (eq. 31, ``L3 = L3_max``).
    """
    if n < 2:
        raise ValueError(f'n must be >= 2, got {n}')
    L, K1, K2 = mech.L, mech.K1, mech.K2
    t1 = np.linspace(mech.theta1_min, mech.theta1_max, n)
    L3 = np.linspace(mech.L3_min, mech.L3_max, n)
    c1, s1 = np.cos(t1), np.sin(t1)
    curves: dict[str, FloatArray] = {}
    curves['i'] = (np.column_stack([t1, np.zeros(n)]) if mech.L3_min <= mech.range_tol
                   else np.empty((0, 2)))
    k_lo = math.ceil((mech.theta1_min - mech.range_tol) / math.pi)
    k_hi = math.floor((mech.theta1_max + mech.range_tol) / math.pi)
    curves['ii'] = _join([np.column_stack([np.full(n, k * math.pi), L3])
                          for k in range(k_lo, k_hi + 1)])
    with np.errstate(divide='ignore', invalid='ignore'):
        L3_iii = -2.0 * SQRT3 * K2 * L / ((K1 + 2.0 * K2) * s1 - SQRT3 * K1 * c1)
    curves['iii'] = _segments((t1, L3_iii), _in_L3_range(mech, L3_iii))
    L3_iv = 2.0 * L * (SQRT3 * K2 * c1 - (2.0 * K1 - K2) * s1) / (SQRT3 * K1)
    curves['iv'] = _segments((t1, L3_iv), _in_L3_range(mech, L3_iv))
    curves['v'] = _fold_actuator(mech, 4 * n)
    curves['vi'] = np.column_stack([t1, np.full(n, mech.L3_max)])
    return curves


def _fold_actuator(mech: PlanarMechanism, n: int) -> FloatArray:
    """Curve v sampled on its circle in the D1 plane, as (theta1, L3) within the ranges."""
    cx, cy, r = mech.fold_circle_actuator()
    phi = np.linspace(0.0, 2.0 * math.pi, n)
    u, v = cx + r * np.cos(phi), cy + r * np.sin(phi)
    L3 = np.hypot(u, v)
    t1, ok = wrap_angles(np.arctan2(v, u), mech.theta1_min, mech.theta1_max, mech.range_tol)
    keep = ok & _in_L3_range(mech, L3)
    out = _segments((t1, L3), keep)
    if len(out):
        jump = np.abs(np.diff(t1)) > math.pi  # theta1 wraps: break the polyline there
        out[1:][jump] = np.nan
    return out


def actuator_workspace_boundary(mech: PlanarMechanism,
                                n: int = DEFAULT_CURVE_SAMPLES) -> FloatArray:
    """Closed outline (4n + 1, 2) of the actuator ranges, columns (theta1, L3)."""
    t1 = np.linspace(mech.theta1_min, mech.theta1_max, n)
    L3 = np.linspace(mech.L3_min, mech.L3_max, n)
    return np.vstack([
        np.column_stack([t1, np.full(n, mech.L3_min)]),
        np.column_stack([np.full(n, mech.theta1_max), L3]),
        np.column_stack([t1[::-1], np.full(n, mech.L3_max)]),
        np.column_stack([np.full(n, mech.theta1_min), L3[::-1]]),
        [[mech.theta1_min, mech.L3_min]],
    ])


def to_cartesian(mech: PlanarMechanism, curve: FloatArray) -> FloatArray:
    """Map an (N, 2) actuator curve (theta1, L3) to D3 positions (x, y) by forward kinematics
    (stable branch); NaN rows stay NaN."""
    curve = np.asarray(curve, dtype=np.float64).reshape(-1, 2)
    out = np.full_like(curve, np.nan)
    ok = np.all(np.isfinite(curve), axis=1)
    if np.any(ok):
        g = mech.forward_grid(curve[ok, 1], curve[ok, 0])
        out[ok, 0], out[ok, 1] = g.x, g.y
    return out


def cartesian_workspace_curves(mech: PlanarMechanism,
                               n: int = DEFAULT_CURVE_SAMPLES) -> dict[str, FloatArray]:
    """Images of :func:`actuator_workspace_curves` in the D3 plane (Fig. 3), columns (x, y).

    On the stable branch: ``'i'`` is a single point (D3 does not depend on theta1 when
    L3 = 0); each point of ``'ii'`` satisfies eq. (35) (``(x - L3 cos theta1)^2 + y^2 = L^2``);
    ``'iii'`` lies on ``sqrt3 K1 x - (K1 + 2 K2) y = sqrt3 L (K1 cos theta2 + 2 K2)`` (theta2 = 0
    or pi; not the printed eq. 36); ``'iv'`` has ``|D3| = L3 +- L`` (eq. 37 only where L3 = 2L
    and theta2 = theta1); ``'v'`` lies on the circle :meth:`PlanarMechanism.fold_circle_cartesian`.
    """
    return {name: to_cartesian(mech, c) for name, c in actuator_workspace_curves(mech, n).items()}


def cartesian_workspace_boundary(mech: PlanarMechanism,
                                 n: int = DEFAULT_CURVE_SAMPLES) -> FloatArray:
    """Image (x, y) of :func:`actuator_workspace_boundary`: it contains the boundary of the
    Cartesian workspace (the fold, where the image could also fold, never lies in the default
    ranges; see curve ``'v'``)."""
    return to_cartesian(mech, actuator_workspace_boundary(mech, n))


def actuator_stiffness_map(mech: PlanarMechanism, L3: ArrayLike, theta1: ArrayLike, *,
                           outside: float = math.nan) -> FloatArray:
    """Stiffness at the stable equilibrium over broadcast ``L3``, ``theta1`` (Fig. 7), N m/rad.

    Closed form ``L/2 sqrt(eta1^2 + eta2^2)`` (eq. 47 on the stable branch); points outside the
    actuator ranges get the value ``outside`` (NaN by default).
    """
    L3 = finite_array('L3', L3)
    theta1 = finite_array('theta1', theta1)
    K = mech.stiffness_closed_form(L3, theta1)
    return np.where(mech.in_actuator_workspace(L3, theta1), K, outside)


def cartesian_stiffness_map(mech: PlanarMechanism, x: ArrayLike, y: ArrayLike) -> FloatArray:
    """Stiffness (N m/rad) of the stable in-range inverse solutions over broadcast ``x, y``
    (Fig. 8), shape ``S + (2,)``: slot 0 the stiffer solution, slot 1 the other; NaN where that
    solution does not exist or is outside the actuator ranges. ``np.nanmax(..., axis=-1)`` gives
    the stiffest reachable configuration."""
    g = mech.inverse_grid(x, y)
    return np.where(g.valid, g.stiffness, np.nan)
