"""Planar tensegrity parallel mechanism (Ji, Li & Lin): kinematics, singularities, stiffness.

Model (eqs. 1-7, with the corrections of ``docs/errata.md``)
--------------------------------------------------------
Base triangle ``C1 C2 C3`` (side ``2L``, ``C1`` at the origin, ``C2 = (-L, -sqrt3 L)``,
``C3 = (L, -sqrt3 L)``), mobile triangle ``D1 D2 D3`` (side ``L``). The prismatic actuator
``C1 D1`` has length ``L3`` (m) at angle ``theta1`` (rad); the strut ``D1 D3`` makes the angle
``theta2`` with X. Two zero-free-length springs: ``K1`` (N/m) joins ``C2``-``D2`` and ``K2`` joins
``C3``-``D3`` -- the only assignment whose energy equals eq. (4) (checked in the tests).

Writing ``D1 = z = L3 exp(i theta1)`` as a complex number, eq. (4) is
``U = U0 + A cos(theta2) + B sin(theta2)`` with ``A + iB = L (L c0 + m z)``,
``m = K1/2 + K2 - i sqrt3/2 K1`` and ``c0 = 2 K1 - K2 + i sqrt3 K2``; eqs. (6)-(7) are
``eta1 = 2B/L``, ``eta2 = 2A/L``. Hence (eqs. 5, 41, 42):

* equilibria: ``tan(theta2) = eta1 / eta2`` has two roots a half turn apart. The stable one
  (energy minimum) is ``theta2 = atan2(-eta1, -eta2)``, the unstable one ``atan2(eta1, eta2)``.
  The paper's rule "the root in [0, pi]" picks the stable root only where ``eta1 < 0``.
* stiffness at the stable root ``K = d2U/dtheta2^2 = sqrt(A^2 + B^2) = L/2 sqrt(eta1^2 + eta2^2)``
  (eq. 47 with the corrected eq. 46), ``-K`` at the unstable root. ``K`` is in N m/rad.
* Jacobian ``d(x, y)/d(L3, theta1)`` (eqs. 17-22) and ``det J = L3 (1 - L^2 (K1/2 + K2) / K)``
  (eq. 23 with the corrected eq. 24, simplified on the stable branch).
* inverse kinematics in closed form: with ``w = x + iy`` and ``p = L c0 + m w`` (``2p = delta2 +
  i delta1``, eqs. 50-51), the stable equilibria that put D3 at ``w`` have
  ``K / L = s = L Re(m) +- sqrt(|p|^2 - L^2 Im(m)^2)`` (``s > 0``),
  ``exp(i theta2) = p / (m L - s)`` and ``D1 = w - L exp(i theta2)``: at most two, none inside
  the fold circle ``|p| < L |Im m|`` (this is eqs. 48-52 solved exactly; the paper's eqs. 9-16
  give the same points, see the tests).

Singular conditions (eqs. 26-30), reported by name (``SINGULARITY_NAMES``) with a dimensionless
residual compared to ``singularity_tol``; the meaning of each on the stable branch:

* ``'i'``   eq. (26) ``L3 = 0``: D1 on C1; theta1 no longer moves anything (det J = 0).
  Residual ``L3 / L``.
* ``'ii'``  eq. (27) ``sin(theta1) = 0``: D1 on the X axis, the edge of the convention
  ``0 <= theta1 <= pi``. Residual ``sin(theta1)``.
* ``'iii'`` eq. (28) ``eta1 = 0``: ``sin(theta2) = 0``, strut D1D3 parallel to X; the edge of the
  convention ``0 <= theta2 <= pi`` where the paper's root switches branch (det J is finite here on
  the stable branch, not infinite as the paper says). Residual ``eta1 / sqrt(eta1^2 + eta2^2)``.
* ``'iv'``  eq. (29)/(33) ``theta1 = theta2`` (mod pi): D3 on the line C1D1. Not a zero or pole of
  det J. Residual ``sin(theta2 - theta1)``.
* ``'v'``   eq. (30) ``Phi1 = 0``: ``det J / L3 = 0``, the fold of the equilibrium set, where the
  two inverse solutions merge. It is the circle ``|L c0 + m D1| = L (K1/2 + K2)`` in the D1 plane,
  which for every K1, K2 > 0 lies below the X axis (outside ``0 <= theta1 <= pi``).
  Residual ``det J / L3 = 1 - L^2 (K1/2 + K2) / K``.
* ``'neutral'`` (extra, not in the paper): ``eta1 = eta2 = 0``, every theta2 is an equilibrium
  (one point ``D1 = -L c0 / m``, below the X axis). Forward results are NaN there.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from types import ModuleType

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.validation import finite_array, finite_scalar

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

SQRT3 = math.sqrt(3.0)
TWO_PI = 2.0 * math.pi

#: Node order of :meth:`PlanarMechanism.node_positions`.
NODE_NAMES = ('C1', 'C2', 'C3', 'D1', 'D2', 'D3')
#: Nodes joined by spring 1 (stiffness K1) and spring 2 (stiffness K2); see the module docstring.
SPRINGS = (('C2', 'D2'), ('C3', 'D3'))
#: Singular conditions of Section 4.2, in the paper's numbering.
SINGULARITY_NAMES = ('i', 'ii', 'iii', 'iv', 'v')
#: One-line meaning of each singular condition on the stable branch.
SINGULARITY_DESCRIPTIONS = {
    'i': 'eq. 26, L3 = 0: D1 on C1, theta1 has no effect (det J = 0)',
    'ii': 'eq. 27, sin(theta1) = 0: D1 on the X axis (edge of 0 <= theta1 <= pi)',
    'iii': 'eq. 28, eta1 = 0: sin(theta2) = 0, edge of 0 <= theta2 <= pi (paper branch switch)',
    'iv': 'eq. 29/33, theta1 = theta2 (mod pi): D3 on the line C1D1',
    'v': 'eq. 30, Phi1 = 0: det J / L3 = 0, the fold where two inverse solutions merge',
    'neutral': 'eta1 = eta2 = 0: every theta2 is an equilibrium (not in the paper)',
}

#: Default tolerance on the dimensionless residual of each singular condition.
DEFAULT_SINGULARITY_TOL = 1e-6
#: Default slack (m for L3, rad for angles) when testing the actuator and theta2 ranges.
DEFAULT_RANGE_TOL = 1e-9
#: K / (L (K1 + K2) (L + L3)) below this: neutral equilibrium (eta1 = eta2 = 0).
NEUTRAL_TOL = 1e-12
#: Inverse kinematics: a discriminant ``|p|^2 - L^2 Im(m)^2`` within ``+-FOLD_TOL L^2 Im(m)^2``
#: is rounding on the fold (curve v) and counts as zero (one double solution).
FOLD_TOL = 1e-12


def _wrap_scalar(theta: float, lo: float, hi: float, tol: float) -> tuple[float, bool]:
    """``theta`` shifted by 2 pi k into ``[lo - tol, lo + 2 pi - tol)``, and whether it is in
    ``[lo - tol, hi + tol]``."""
    t = lo + (theta - lo) % TWO_PI
    if t > hi + tol and t - TWO_PI >= lo - tol:
        t -= TWO_PI
    return t, lo - tol <= t <= hi + tol


def wrap_angles(theta: FloatArray, lo: float, hi: float,
                tol: float) -> tuple[FloatArray, BoolArray]:
    """Vectorised :func:`_wrap_scalar` (NaN stays NaN and is out of range)."""
    t = lo + np.mod(theta - lo, TWO_PI)
    t = np.where((t > hi + tol) & (t - TWO_PI >= lo - tol), t - TWO_PI, t)
    return t, (t >= lo - tol) & (t <= hi + tol)


@dataclass(frozen=True, slots=True, eq=False)
class PlanarForwardResult:
    """Forward kinematics at ``(L3, theta1)`` (m, rad), from :meth:`PlanarMechanism.forward`.

    ``L3``, ``theta1``: the input as given. ``x, y`` (m): node D3 at the stable equilibrium
    ``theta2`` (rad, written in
    ``[theta2_min, theta2_min + 2 pi)``); ``stiffness`` = d2U/dtheta2^2 there (eq. 42, N m/rad);
    ``energy`` U (eq. 4, J); ``stable`` is False only at the neutral point; ``theta2_in_range``
    and ``actuator_in_range`` (L3 and theta1 within the mechanism's ranges) are flags, nothing is
    discarded. ``*_unstable``: the other root of eq. (5) (stiffness ``-stiffness``).
    ``jacobian`` (2, 2, read-only) = d(x, y)/d(L3, theta1) (eqs. 17-22),
    ``jacobian_determinant`` (m);
    ``singularities``: names from ``SINGULARITY_NAMES`` (or ``'neutral'``) that hold.
    """

    L3: float
    theta1: float
    x: float
    y: float
    theta2: float
    stiffness: float
    energy: float
    stable: bool
    theta2_in_range: bool
    actuator_in_range: bool
    theta2_unstable: float
    x_unstable: float
    y_unstable: float
    stiffness_unstable: float
    energy_unstable: float
    jacobian: FloatArray
    jacobian_determinant: float
    singularities: tuple[str, ...]


@dataclass(frozen=True, slots=True)
class PlanarInverseSolution:
    """One actuator state that puts D3 at the requested point in equilibrium.

    ``L3`` (m), ``theta1`` (rad, written in ``[theta1_min, theta1_min + 2 pi)``), ``theta2``
    (rad, written in ``[theta2_min, theta2_min + 2 pi)``), ``stiffness`` (eq. 42, N m/rad),
    ``energy`` (J), ``stable`` (K > 0), ``theta2_in_range``, ``jacobian_determinant`` (m, of the
    branch the solution is on), ``singularities`` of the actuator state as in
    :class:`PlanarForwardResult` (i.e. evaluated on the stable branch).
    """

    L3: float
    theta1: float
    theta2: float
    stiffness: float
    energy: float
    stable: bool
    theta2_in_range: bool
    jacobian_determinant: float
    singularities: tuple[str, ...]


class PlanarInverseResult(list):
    """The list of :class:`PlanarInverseSolution` returned by :meth:`PlanarMechanism.inverse`.

    A plain ``list`` (iterate, ``len``, index, compare with ``[]``) ordered by decreasing
    stiffness, with three read-only extras: ``x``, ``y`` (the request, m) and ``reason``: ``''``
    when there are solutions, otherwise why there are none (no equilibrium at all, or none within
    the ranges).
    """

    __slots__ = ('_reason', '_x', '_y')

    def __init__(self, solutions: list[PlanarInverseSolution], x: float, y: float,
                 reason: str = '') -> None:
        super().__init__(solutions)
        self._x = x
        self._y = y
        self._reason = reason

    @property
    def reason(self) -> str:
        """Why the list is empty ('' when it is not)."""
        return self._reason

    @property
    def x(self) -> float:
        """Requested x of D3 (m)."""
        return self._x

    @property
    def y(self) -> float:
        """Requested y of D3 (m)."""
        return self._y


@dataclass(frozen=True, eq=False)
class PlanarForwardGrid:
    """Vectorised forward kinematics (every array has the broadcast shape ``S`` of the inputs).

    Fields as in :class:`PlanarForwardResult` (stable branch); ``jacobian`` has shape
    ``S + (2, 2)``; ``singular`` maps each name of ``SINGULARITY_NAMES`` to a boolean array.
    """

    L3: FloatArray
    theta1: FloatArray
    x: FloatArray
    y: FloatArray
    theta2: FloatArray
    stiffness: FloatArray
    energy: FloatArray
    stable: BoolArray
    theta2_in_range: BoolArray
    actuator_in_range: BoolArray
    jacobian: FloatArray
    jacobian_determinant: FloatArray
    singular: dict[str, BoolArray]


@dataclass(frozen=True, eq=False)
class PlanarInverseGrid:
    """Vectorised inverse kinematics: arrays of shape ``S + (2,)`` for inputs of shape ``S``.

    Slot 0 is the stiffer stable equilibrium (``s = L Re m + sqrt(...)``), slot 1 the other root
    (stable only when ``stiffness > 0``). ``valid``: a stable equilibrium with L3 and theta1 within
    the actuator ranges (the theta2 range is reported in ``theta2_in_range``, not applied).
    Entries with no equilibrium are NaN. ``count`` (shape ``S``) = number of valid solutions.
    """

    x: FloatArray
    y: FloatArray
    L3: FloatArray
    theta1: FloatArray
    theta2: FloatArray
    stiffness: FloatArray
    valid: BoolArray
    theta2_in_range: BoolArray
    count: NDArray[np.int64]


@dataclass(frozen=True)
class PlanarMechanism:
    """Planar tensegrity parallel mechanism of Ji, Li & Lin (see the module docstring).

    ``L`` (m) mobile side (base side 2L), ``K1``, ``K2`` (N/m) spring stiffnesses, all > 0.
    Ranges (eq. 31 and Section 2): ``L3_min <= L3 <= L3_max`` (default 0 .. 2L),
    ``theta1_min <= theta1 <= theta1_max`` and ``theta2_min <= theta2 <= theta2_max``
    (default 0 .. pi, rad, at most 2 pi wide). ``singularity_tol``: dimensionless tolerance of
    the singular conditions; ``range_tol``: slack of the range tests (m or rad).
    Bad values raise ValueError naming the field.
    """

    L: float
    K1: float
    K2: float
    L3_min: float = 0.0
    L3_max: float | None = None
    theta1_min: float = 0.0
    theta1_max: float = math.pi
    theta2_min: float = 0.0
    theta2_max: float = math.pi
    singularity_tol: float = DEFAULT_SINGULARITY_TOL
    range_tol: float = DEFAULT_RANGE_TOL

    def __post_init__(self) -> None:
        L = finite_scalar('L', self.L)
        K1 = finite_scalar('K1', self.K1)
        K2 = finite_scalar('K2', self.K2)
        for name, value in (('L', L), ('K1', K1), ('K2', K2)):
            if value <= 0.0:
                raise ValueError(f'{name} must be > 0, got {value}')
        L3_min = finite_scalar('L3_min', self.L3_min)
        L3_max = 2.0 * L if self.L3_max is None else finite_scalar('L3_max', self.L3_max)
        if L3_min < 0.0:
            raise ValueError(f'L3_min must be >= 0, got {L3_min}')
        if L3_max <= L3_min:
            raise ValueError(f'L3_max must be > L3_min = {L3_min}, got {L3_max}')
        ranges = {}
        for name in ('theta1', 'theta2'):
            lo = finite_scalar(f'{name}_min', getattr(self, f'{name}_min'))
            hi = finite_scalar(f'{name}_max', getattr(self, f'{name}_max'))
            if hi <= lo:
                raise ValueError(f'{name}_max must be > {name}_min = {lo}, got {hi}')
            if hi - lo > TWO_PI + 1e-12:
                raise ValueError(f'{name}_max - {name}_min must be <= 2 pi, got {hi - lo}')
            ranges[name] = (lo, hi)
        for name in ('singularity_tol', 'range_tol'):
            tol = finite_scalar(name, getattr(self, name))
            if tol <= 0.0:
                raise ValueError(f'{name} must be > 0, got {tol}')
            object.__setattr__(self, name, tol)
        for name, value in (('L', L), ('K1', K1), ('K2', K2), ('L3_min', L3_min),
                            ('L3_max', L3_max), ('theta1_min', ranges['theta1'][0]),
                            ('theta1_max', ranges['theta1'][1]),
                            ('theta2_min', ranges['theta2'][0]),
                            ('theta2_max', ranges['theta2'][1])):
            object.__setattr__(self, name, value)

    # ------------------------------------------------------------------ coefficients
    @property
    def m_real(self) -> float:
        """``Re m = K1/2 + K2`` (N/m)."""
        return 0.5 * self.K1 + self.K2

    @property
    def m_imag(self) -> float:
        """``Im m = -sqrt3/2 K1`` (N/m)."""
        return -0.5 * SQRT3 * self.K1

    @property
    def neutral_point(self) -> tuple[float, float]:
        """D1 (m) where eta1 = eta2 = 0 (every theta2 an equilibrium): ``-L c0 / m``."""
        z = -self.L * complex(2.0 * self.K1 - self.K2, SQRT3 * self.K2) / complex(
            self.m_real, self.m_imag)
        return z.real, z.imag

    def fold_circle_actuator(self) -> tuple[float, float, float]:
        """Curve v in the D1 plane: centre (m, m) and radius (m) of ``|L c0 + m D1| = L Re m``."""
        cx, cy = self.neutral_point
        return cx, cy, self.L * self.m_real / abs(complex(self.m_real, self.m_imag))

    def fold_circle_cartesian(self) -> tuple[float, float, float]:
        """Curve v in the D3 plane: centre and radius (m); inside it no equilibrium exists."""
        cx, cy = self.neutral_point
        return cx, cy, self.L * abs(self.m_imag) / abs(complex(self.m_real, self.m_imag))

    def _AB(self, L3: FloatArray, c1: FloatArray, s1: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Coefficients of cos(theta2) and sin(theta2) in eq. (4) (J)."""
        L, K1, K2 = self.L, self.K1, self.K2
        a, b = 0.5 * K1 + K2, 0.5 * SQRT3 * K1
        u, v = L3 * c1, L3 * s1
        A = (2.0 * K1 - K2) * L * L + L * (a * u + b * v)
        B = SQRT3 * K2 * L * L + L * (a * v - b * u)
        return A, B

    def _U0(self, L3: FloatArray, c1: FloatArray, s1: FloatArray) -> FloatArray:
        """theta2-independent part of eq. (4) (J)."""
        L, K1, K2 = self.L, self.K1, self.K2
        return (0.5 * (K1 + K2) * (5.0 * L * L + L3 * L3 + 2.0 * SQRT3 * L * L3 * s1)
                + (K1 - K2) * L * L3 * c1)

    def _energy_terms(self, L3: FloatArray, theta1: FloatArray, trig: ModuleType
                      ) -> tuple[FloatArray, ...]:
        """``cos theta1, sin theta1``, ``u, v`` (m, node D1 at ``L3 (cos, sin) theta1``), the
        coefficients ``A, B, U0`` of eq. (4) (J) and ``R = hypot(A, B)`` (eq. 42 at the stable
        root), with ``trig`` ``math`` for scalars (:meth:`forward`) or ``numpy`` for arrays."""
        c1, s1 = trig.cos(theta1), trig.sin(theta1)
        A, B = self._AB(L3, c1, s1)
        return c1, s1, L3 * c1, L3 * s1, A, B, self._U0(L3, c1, s1), trig.hypot(A, B)

    def _jacobian_entries(self, L3: FloatArray, c1: FloatArray, s1: FloatArray,
                          c2: FloatArray, s2: FloatArray, K: FloatArray
                          ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """``J = d(x, y)/d(L3, theta1)`` entries ``j00, j01, j10, j11`` (eqs. 18-21) at the
        equilibrium ``theta2`` (cos ``c2``, sin ``s2``) of stiffness ``K`` (eq. 42), with
        ``dtheta2`` by implicit differentiation of dU/dtheta2 = 0 (eq. 22; = cos^2 theta2
        d(tan theta2)); scalars or arrays alike."""
        L = self.L
        u, v = L3 * c1, L3 * s1
        a, b = self.m_real, 0.5 * SQRT3 * self.K1
        A_L3, B_L3 = L * (a * c1 + b * s1), L * (a * s1 - b * c1)
        dt2_dL3 = (A_L3 * s2 - B_L3 * c2) / K
        dt2_dt1 = (-L3 * B_L3 * s2 - L3 * A_L3 * c2) / K
        return (c1 - L * s2 * dt2_dL3, -v - L * s2 * dt2_dt1, s1 + L * c2 * dt2_dL3,
                u + L * c2 * dt2_dt1)

    # ------------------------------------------------------------------ model (vectorised)
    def node_positions(self, L3: ArrayLike, theta1: ArrayLike, theta2: ArrayLike) -> FloatArray:
        """Eq. (1) and D3 (eqs. 2-3): shape ``S + (6, 2)`` in the order ``NODE_NAMES`` (m)."""
        L3, t1, t2 = np.broadcast_arrays(*(finite_array(n, v) for n, v in (
            ('L3', L3), ('theta1', theta1), ('theta2', theta2))))
        L = self.L
        out = np.zeros(L3.shape + (6, 2))
        out[..., 1, :] = (-L, -SQRT3 * L)
        out[..., 2, :] = (L, -SQRT3 * L)
        d1 = np.stack([L3 * np.cos(t1), L3 * np.sin(t1)], axis=-1)
        out[..., 3, :] = d1
        out[..., 4, :] = d1 + L * np.stack([np.cos(t2 + math.pi / 3), np.sin(t2 + math.pi / 3)],
                                           axis=-1)
        out[..., 5, :] = d1 + L * np.stack([np.cos(t2), np.sin(t2)], axis=-1)
        return out

    def spring_lengths(self, L3: ArrayLike, theta1: ArrayLike, theta2: ArrayLike) -> FloatArray:
        """Lengths of spring 1 (C2-D2) and spring 2 (C3-D3), shape ``S + (2,)`` (m)."""
        p = self.node_positions(L3, theta1, theta2)
        i = {n: k for k, n in enumerate(NODE_NAMES)}
        return np.stack([np.linalg.norm(p[..., i[b], :] - p[..., i[a], :], axis=-1)
                         for a, b in SPRINGS], axis=-1)

    def geometric_energy(self, L3: ArrayLike, theta1: ArrayLike, theta2: ArrayLike) -> FloatArray:
        """``K1 l1^2 / 2 + K2 l2^2 / 2`` from the node positions (zero free length, J)."""
        lengths = self.spring_lengths(L3, theta1, theta2)
        return 0.5 * (self.K1 * lengths[..., 0] ** 2 + self.K2 * lengths[..., 1] ** 2)

    def energy(self, L3: ArrayLike, theta1: ArrayLike, theta2: ArrayLike) -> FloatArray:
        """Potential energy U, eq. (4) (J)."""
        L3, t1, t2 = (finite_array(n, v) for n, v in (
            ('L3', L3), ('theta1', theta1), ('theta2', theta2)))
        c1, s1 = np.cos(t1), np.sin(t1)
        A, B = self._AB(L3, c1, s1)
        return self._U0(L3, c1, s1) + A * np.cos(t2) + B * np.sin(t2)

    def torque(self, L3: ArrayLike, theta1: ArrayLike, theta2: ArrayLike) -> FloatArray:
        """``tau = dU/dtheta2``, eq. (41) (N m): the torque that holds the platform at theta2."""
        L3, t1, t2 = (finite_array(n, v) for n, v in (
            ('L3', L3), ('theta1', theta1), ('theta2', theta2)))
        A, B = self._AB(L3, np.cos(t1), np.sin(t1))
        return -A * np.sin(t2) + B * np.cos(t2)

    def stiffness(self, L3: ArrayLike, theta1: ArrayLike, theta2: ArrayLike) -> FloatArray:
        """``K = d2U/dtheta2^2``, eq. (42) (N m/rad), at any theta2 (actuators locked)."""
        L3, t1, t2 = (finite_array(n, v) for n, v in (
            ('L3', L3), ('theta1', theta1), ('theta2', theta2)))
        A, B = self._AB(L3, np.cos(t1), np.sin(t1))
        return -A * np.cos(t2) - B * np.sin(t2)

    def eta(self, L3: ArrayLike, theta1: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """``(eta1, eta2)`` of eqs. (6)-(7) (N/m times m = N)."""
        L3, t1 = finite_array('L3', L3), finite_array('theta1', theta1)
        A, B = self._AB(L3, np.cos(t1), np.sin(t1))
        return 2.0 * B / self.L, 2.0 * A / self.L

    def equilibrium_angles(self, L3: ArrayLike,
                           theta1: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Both roots of eq. (5) (rad, in (-pi, pi]): ``(stable, unstable)``.

        Stable = ``atan2(-eta1, -eta2)`` (energy minimum), unstable = ``atan2(eta1, eta2)``.
        """
        e1, e2 = self.eta(L3, theta1)
        return np.arctan2(-e1, -e2), np.arctan2(e1, e2)

    def stiffness_closed_form(self, L3: ArrayLike, theta1: ArrayLike) -> FloatArray:
        """Stiffness at the stable equilibrium, ``L/2 sqrt(eta1^2 + eta2^2)`` (N m/rad).

        This is eq. (47) (with eq. (46) corrected) evaluated on the stable root; the printed
        eq. (47) is the value at the root in [0, pi], i.e. ``-sign(eta1)`` times this
        (see :meth:`stiffness_eq47`).
        """
        e1, e2 = self.eta(L3, theta1)
        return 0.5 * self.L * np.hypot(e1, e2)

    def stiffness_eq47(self, L3: ArrayLike, theta1: ArrayLike) -> FloatArray:
        """Eq. (47) as printed (with eq. (46) corrected), N m/rad: eq. (42) at the root of eq. (5)
        with ``sin(theta2) >= 0`` (the paper's branch; stable only where ``eta1 < 0``).
        NaN where ``eta1 = 0``."""
        L3, t1 = finite_array('L3', L3), finite_array('theta1', theta1)
        A, B = self._AB(L3, np.cos(t1), np.sin(t1))
        e1, e2 = 2.0 * B / self.L, 2.0 * A / self.L
        with np.errstate(divide='ignore', invalid='ignore'):
            return -np.sqrt(e1 ** 2 / (e1 ** 2 + e2 ** 2)) * (A * e2 / e1 + B)

    def jacobian_determinant_eq23(self, L3: ArrayLike, theta1: ArrayLike,
                                  theta2: ArrayLike) -> FloatArray:
        """``det J = L3 Phi1 / Phi2``, eqs. (23)-(25), with eq. (24) corrected
        (``4 L sin(theta2)``, not ``4 L3 L sin(theta2)``). Valid on either branch for the theta2
        of that branch; undefined (NaN) where ``Phi2 = 0`` (``eta1 = 0``). Units m."""
        L3, t1, t2 = (finite_array(n, v) for n, v in (
            ('L3', L3), ('theta1', theta1), ('theta2', theta2)))
        L, K1, K2 = self.L, self.K1, self.K2
        c1, s1 = np.cos(t1), np.sin(t1)
        e1 = (K1 + 2 * K2) * L3 * s1 - SQRT3 * K1 * L3 * c1 + 2 * SQRT3 * K2 * L
        e2 = 2 * (2 * K1 - K2) * L + (K1 + 2 * K2) * L3 * c1 + SQRT3 * K1 * L3 * s1
        q = (4 * L * L * (K1 ** 2 + K2 ** 2 - K1 * K2)
             + L3 ** 2 * (K1 ** 2 + K2 ** 2 + K1 * K2)
             + 2 * L3 * L * c1 * (K1 ** 2 - K2 ** 2)
             + 2 * SQRT3 * L3 * L * s1 * (K1 ** 2 + K2 ** 2))
        phi2 = e1 * (e1 ** 2 + e2 ** 2)
        phi1 = phi2 + 4 * L * np.sin(t2) * (K1 + 2 * K2) * q
        with np.errstate(divide='ignore', invalid='ignore'):
            return np.where(phi2 != 0.0, L3 * phi1 / np.where(phi2 != 0.0, phi2, 1.0), np.nan)

    def stiffness_from_position(self, x: ArrayLike, y: ArrayLike) -> FloatArray:
        """Eq. (42) at the two equilibria that put D3 at (x, y), eqs. (48)-(52) solved exactly.

        ``K = (K1/2 + K2) L^2 +- L/2 sqrt(delta1^2 + delta2^2 - 3 K1^2 L^2)`` (N m/rad), shape
        ``S + (2,)``: slot 0 (``+``) always > 0 (stable), slot 1 stable iff > 0 (otherwise it is
        the unstable equilibrium). NaN inside the fold circle (no equilibrium). No actuator ranges.
        """
        x, y = finite_array('x', x), finite_array('y', y)
        L, K1, K2 = self.L, self.K1, self.K2
        d1 = (K1 + 2 * K2) * y - SQRT3 * K1 * x + 2 * SQRT3 * K2 * L
        d2 = 2 * (2 * K1 - K2) * L + (K1 + 2 * K2) * x + SQRT3 * K1 * y
        disc = d1 ** 2 + d2 ** 2 - 3.0 * (K1 * L) ** 2
        root = 0.5 * L * np.sqrt(np.where(disc >= 0.0, disc, np.nan))
        base = (0.5 * K1 + K2) * L * L
        return np.stack([base + root, base - root], axis=-1)

    # ------------------------------------------------------------------ singularities
    def singularity_residuals(self, L3: ArrayLike, theta1: ArrayLike) -> dict[str, FloatArray]:
        """Dimensionless residual of each singular condition on the stable branch (0 on the curve).

        ``'i'``: L3/L; ``'ii'``: sin(theta1); ``'iii'``: eta1/|eta|; ``'iv'``: sin(theta2 -
        theta1); ``'v'``: det J / L3 = 1 - L^2 (K1/2 + K2)/K. See the module docstring.
        """
        L3, t1 = np.broadcast_arrays(finite_array('L3', L3), finite_array('theta1', theta1))
        c1, s1 = np.cos(t1), np.sin(t1)
        A, B = self._AB(L3, c1, s1)
        R = np.hypot(A, B)
        with np.errstate(divide='ignore', invalid='ignore'):
            c2, s2 = -A / R, -B / R
            return {
                'i': L3 / self.L,
                'ii': s1,
                'iii': -s2,
                'iv': s2 * c1 - c2 * s1,
                'v': 1.0 - self.L * self.L * self.m_real / R,
            }

    def singularities(self, L3: float, theta1: float) -> tuple[str, ...]:
        """Names of the singular conditions holding at ``(L3, theta1)`` (``singularity_tol``)."""
        L3 = finite_scalar('L3', L3)
        theta1 = finite_scalar('theta1', theta1)
        c1, s1 = math.cos(theta1), math.sin(theta1)
        A, B = self._AB(L3, c1, s1)
        R = math.hypot(A, B)
        if R <= NEUTRAL_TOL * self.L * (self.K1 + self.K2) * (self.L + L3):
            return self._singular_names(L3, c1, s1, math.nan, math.nan, math.nan)
        return self._singular_names(L3, c1, s1, -A / R, -B / R, R)

    def _singular_names(self, L3: float, c1: float, s1: float, c2: float, s2: float,
                        R: float) -> tuple[str, ...]:
        """Scalar core of :meth:`singularities` (c2, s2 of the stable root; NaN when neutral)."""
        tol = self.singularity_tol
        names = []
        if abs(L3) <= tol * self.L:
            names.append('i')
        if abs(s1) <= tol:
            names.append('ii')
        if math.isnan(R):
            names.append('neutral')
            return tuple(names)
        if abs(s2) <= tol:
            names.append('iii')
        if abs(s2 * c1 - c2 * s1) <= tol:
            names.append('iv')
        if abs(1.0 - self.L * self.L * self.m_real / R) <= tol:
            names.append('v')
        return tuple(names)

    # ------------------------------------------------------------------ forward kinematics
    def forward(self, L3: float, theta1: float) -> PlanarForwardResult:
        """Forward kinematics (eqs. 2-7), stiffness (42), energy (4), Jacobian (17-22), det J (23)
        and singular conditions (26-30) at the stable equilibrium for actuator ``(L3, theta1)``.

        ``L3`` (m, >= 0) and ``theta1`` (rad) must be finite; values outside the actuator ranges
        are evaluated and flagged (``actuator_in_range``), not rejected.
        """
        L3 = finite_scalar('L3', L3)
        theta1 = finite_scalar('theta1', theta1)
        if L3 < 0.0:
            raise ValueError(f'L3 must be >= 0, got {L3}')
        L = self.L
        rtol = self.range_tol
        c1, s1, u, v, A, B, U0, R = self._energy_terms(L3, theta1, math)
        _, t1_ok = _wrap_scalar(theta1, self.theta1_min, self.theta1_max, rtol)
        act_ok = t1_ok and self.L3_min - rtol <= L3 <= self.L3_max + rtol
        if R <= NEUTRAL_TOL * L * (self.K1 + self.K2) * (L + L3):
            nan = math.nan
            return PlanarForwardResult(
                L3, theta1, nan, nan, nan, 0.0, U0, False, False, act_ok, nan, nan, nan, 0.0, U0,
                np.full((2, 2), nan), nan, self._singular_names(L3, c1, s1, nan, nan, nan))
        c2, s2 = -A / R, -B / R
        theta2, t2_ok = _wrap_scalar(math.atan2(s2, c2), self.theta2_min, self.theta2_max, rtol)
        theta2_u, _ = _wrap_scalar(theta2 + math.pi, self.theta2_min, self.theta2_max, rtol)
        K = -A * c2 - B * s2  # eq. (42) at the stable root (= R)
        j00, j01, j10, j11 = self._jacobian_entries(L3, c1, s1, c2, s2, K)
        jac = np.array([[j00, j01], [j10, j11]])
        jac.flags.writeable = False
        return PlanarForwardResult(
            L3, theta1, u + L * c2, v + L * s2, theta2, K, U0 - R, True, t2_ok, act_ok,
            theta2_u, u - L * c2, v - L * s2, -K, U0 + R, jac, j00 * j11 - j01 * j10,
            self._singular_names(L3, c1, s1, c2, s2, R))

    def forward_grid(self, L3: ArrayLike, theta1: ArrayLike) -> PlanarForwardGrid:
        """Vectorised :meth:`forward` (stable branch) over broadcast arrays ``L3``, ``theta1``."""
        L3, t1 = np.broadcast_arrays(finite_array('L3', L3), finite_array('theta1', theta1))
        if np.any(L3 < 0.0):
            raise ValueError(f'L3 must be >= 0, got {L3[L3 < 0.0].ravel()[0]}')
        L = self.L
        rtol = self.range_tol
        c1, s1, u, v, A, B, U0, R = self._energy_terms(L3, t1, np)
        neutral = R <= NEUTRAL_TOL * L * (self.K1 + self.K2) * (L + L3)
        Rs = np.where(neutral, np.nan, R)
        c2, s2 = -A / Rs, -B / Rs
        theta2, t2_ok = wrap_angles(np.arctan2(s2, c2), self.theta2_min, self.theta2_max, rtol)
        _, t1_ok = wrap_angles(t1, self.theta1_min, self.theta1_max, rtol)
        act_ok = t1_ok & (L3 >= self.L3_min - rtol) & (L3 <= self.L3_max + rtol)
        jac = np.empty(L3.shape + (2, 2))
        (jac[..., 0, 0], jac[..., 0, 1], jac[..., 1, 0],
         jac[..., 1, 1]) = self._jacobian_entries(L3, c1, s1, c2, s2, Rs)
        det = jac[..., 0, 0] * jac[..., 1, 1] - jac[..., 0, 1] * jac[..., 1, 0]
        tol = self.singularity_tol
        singular = {
            'i': np.abs(L3) <= tol * L,
            'ii': np.abs(s1) <= tol,
            'iii': np.abs(s2) <= tol,
            'iv': np.abs(s2 * c1 - c2 * s1) <= tol,
            'v': np.abs(1.0 - L * L * self.m_real / Rs) <= tol,
        }
        return PlanarForwardGrid(
            L3=L3, theta1=t1, x=u + L * c2, y=v + L * s2, theta2=theta2,
            stiffness=np.where(neutral, 0.0, R), energy=U0 - R, stable=~neutral,
            theta2_in_range=t2_ok, actuator_in_range=act_ok, jacobian=jac,
            jacobian_determinant=det, singular=singular)

    # ------------------------------------------------------------------ inverse kinematics
    def inverse(self, x: float, y: float, *, include_unstable: bool = False,
                require_theta2_in_range: bool = False) -> PlanarInverseResult:
        """Every actuator state ``(L3, theta1)`` within the actuator ranges that holds D3 at
        ``(x, y)`` (m) in stable equilibrium (eqs. 8-16 and 48-52, solved in closed form, see the
        module docstring): at most two, ordered by decreasing stiffness.

        ``include_unstable`` also returns unstable equilibria (``stable=False``, negative
        stiffness); ``require_theta2_in_range`` drops solutions whose theta2 is outside
        ``[theta2_min, theta2_max]`` (by default they are kept and flagged). An unreachable point
        gives an empty list with a ``reason``; non-finite input raises ValueError.
        """
        x = finite_scalar('x', x)
        y = finite_scalar('y', y)
        L, K1, K2 = self.L, self.K1, self.K2
        a, b = self.m_real, 0.5 * SQRT3 * K1
        pr = (2.0 * K1 - K2) * L + a * x + b * y  # delta2 / 2
        pi_ = SQRT3 * K2 * L + a * y - b * x  # delta1 / 2
        p2 = pr * pr + pi_ * pi_
        disc = p2 - (L * b) ** 2
        if disc < -FOLD_TOL * (L * b) ** 2:
            cx, cy, r = self.fold_circle_cartesian()
            return PlanarInverseResult([], x, y, (
                f'no equilibrium puts D3 at ({x:.6g}, {y:.6g}): the point is inside the fold '
                f'circle (singular curve v) of centre ({cx:.6g}, {cy:.6g}) and radius {r:.6g}'))
        root = math.sqrt(disc) if disc > FOLD_TOL * (L * b) ** 2 else 0.0
        s_plus = L * a + root
        candidates = [(s_plus, 1.0)]
        if root > 0.0:
            s_minus = ((a * a + b * b) * L * L - p2) / s_plus  # = L a - root, without cancellation
            if s_minus > 0.0:
                candidates.append((s_minus, 1.0))
            elif include_unstable:
                candidates.append((-s_minus, -1.0))
        solutions: list[PlanarInverseSolution] = []
        rejected: list[str] = []
        rtol = self.range_tol
        for s, sign in candidates:
            # q = L c0 + m D1 = -sign s e, e = exp(i theta2): p = (m L - sign s) e
            dr, di = a * L - sign * s, -b * L
            er, ei = pr * dr + pi_ * di, pi_ * dr - pr * di  # p * conj(d)
            n = math.hypot(er, ei)
            c2, s2 = er / n, ei / n
            u, v = x - L * c2, y - L * s2
            L3 = math.hypot(u, v)
            theta1, t1_ok = _wrap_scalar(math.atan2(v, u), self.theta1_min, self.theta1_max, rtol)
            theta2, t2_ok = _wrap_scalar(math.atan2(s2, c2), self.theta2_min, self.theta2_max,
                                         rtol)
            if not (t1_ok and self.L3_min - rtol <= L3 <= self.L3_max + rtol):
                rejected.append(f'(L3={L3:.6g}, theta1={theta1:.6g})')
                continue
            if require_theta2_in_range and not t2_ok:
                rejected.append(f'(L3={L3:.6g}, theta1={theta1:.6g}, theta2={theta2:.6g})')
                continue
            c1, s1 = (u / L3, v / L3) if L3 > 0.0 else (1.0, 0.0)
            A, B = self._AB(L3, c1, s1)
            K = -A * c2 - B * s2  # eq. (42); equals sign * L * s
            R = math.hypot(A, B)
            solutions.append(PlanarInverseSolution(
                L3, theta1, theta2, K, self._U0(L3, c1, s1) + A * c2 + B * s2, sign > 0.0, t2_ok,
                L3 * (1.0 - L * L * a / (sign * R)),
                self._singular_names(L3, c1, s1, -A / R, -B / R, R)))
        if solutions:
            return PlanarInverseResult(solutions, x, y)
        what = 'the theta2 range' if require_theta2_in_range else 'the actuator ranges'
        return PlanarInverseResult([], x, y, (
            f'the equilibria that put D3 at ({x:.6g}, {y:.6g}) need {", ".join(rejected)}, '
            f'outside {what} L3 in [{self.L3_min:.6g}, {self.L3_max:.6g}], theta1 in '
            f'[{self.theta1_min:.6g}, {self.theta1_max:.6g}], theta2 in '
            f'[{self.theta2_min:.6g}, {self.theta2_max:.6g}]'))

    def inverse_grid(self, x: ArrayLike, y: ArrayLike) -> PlanarInverseGrid:
        """Vectorised :meth:`inverse` (both roots of eq. 48) over broadcast arrays ``x``, ``y``."""
        x, y = np.broadcast_arrays(finite_array('x', x), finite_array('y', y))
        L, K1, K2 = self.L, self.K1, self.K2
        a, b = self.m_real, 0.5 * SQRT3 * K1
        pr = (2.0 * K1 - K2) * L + a * x + b * y
        pi_ = SQRT3 * K2 * L + a * y - b * x
        p2 = pr * pr + pi_ * pi_
        disc = p2 - (L * b) ** 2
        tol = FOLD_TOL * (L * b) ** 2
        root = np.sqrt(np.where(disc >= -tol, np.where(disc > tol, disc, 0.0), np.nan))
        s_plus = L * a + root
        s_minus = ((a * a + b * b) * L * L - p2) / s_plus
        s = np.stack([s_plus, s_minus], axis=-1)  # signed: K = L s
        dr = a * L - s  # p = (m L - s) e with s signed (s < 0: unstable)
        di = -b * L
        er = pr[..., None] * dr + pi_[..., None] * di
        ei = pi_[..., None] * dr - pr[..., None] * di
        n = np.hypot(er, ei)
        c2, s2 = er / n, ei / n
        u, v = x[..., None] - L * c2, y[..., None] - L * s2
        L3 = np.hypot(u, v)
        rtol = self.range_tol
        theta1, t1_ok = wrap_angles(np.arctan2(v, u), self.theta1_min, self.theta1_max, rtol)
        theta2, t2_ok = wrap_angles(np.arctan2(s2, c2), self.theta2_min, self.theta2_max, rtol)
        valid = (t1_ok & (L3 >= self.L3_min - rtol) & (L3 <= self.L3_max + rtol) & (s > 0.0))
        valid[..., 1] &= root > 0.0  # a double root is one solution
        return PlanarInverseGrid(x=x, y=y, L3=L3, theta1=theta1, theta2=theta2,
                                 stiffness=L * s, valid=valid, theta2_in_range=t2_ok,
                                 count=valid.sum(axis=-1))

    # ------------------------------------------------------------------ workspaces
    def in_actuator_workspace(self, L3: ArrayLike, theta1: ArrayLike) -> BoolArray:
        """Whether ``(L3, theta1)`` lies in the actuator ranges (eq. 31, Section 2), broadcast."""
        L3, t1 = finite_array('L3', L3), finite_array('theta1', theta1)
        _, ok = wrap_angles(t1, self.theta1_min, self.theta1_max, self.range_tol)
        return ok & (L3 >= self.L3_min - self.range_tol) & (L3 <= self.L3_max + self.range_tol)

    def in_cartesian_workspace(self, x: ArrayLike, y: ArrayLike, *,
                               require_theta2_in_range: bool = False) -> BoolArray:
        """Whether some stable equilibrium within the actuator ranges puts D3 at ``(x, y)``."""
        g = self.inverse_grid(x, y)
        ok = g.valid & g.theta2_in_range if require_theta2_in_range else g.valid
        return np.any(ok, axis=-1)
