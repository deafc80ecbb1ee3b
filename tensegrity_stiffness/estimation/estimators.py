"""Pose, load and stiffness of a tensegrity joint (or a spine) estimated from what robots
measure, with their uncertainty (no rclpy).

Measurements (:class:`Measurements`, models and Jacobians in :mod:`~tensegrity_stiffness.
sensor_models`): string tensions (load cells), string lengths (stretch sensors), a pose (motion
capture), the direction of gravity in link 2 (an accelerometer at rest) and the external wrench
(known, e.g. zero, or measured by a force-torque sensor; ``None`` = unknown). Rest lengths
(motor encoders) are known inputs of the model.

Method: weighted nonlinear least squares over the screw ``xi`` (Gauss-Newton with Levenberg-
Marquardt damping, analytic Jacobians), warm-started. Each measurement ``z`` with covariance
``S`` contributes the whitened residual ``L^-1 (h(xi) - z)`` (``S = L L^T``). A known or measured
load ``W_m`` enters as the quasi-static residual ``F(xi) + W_m`` with the load's covariance (at
the truth ``F + W = 0``, Section VI). An unknown load is a free unknown of the equilibrium
``F(xi) + W = 0``, which then carries no information on ``xi``: it is eliminated exactly and
recovered as ``W = -F(xi)`` with covariance ``K C K^T`` (``K = dF/dxi``, eq. 10).

Uncertainty: the screw covariance is the inverse of the weighted normal matrix ``C = (J^T J)^-1``
at the estimate (the Cramer-Rao bound of the linearised problem); the pose covariance follows the
ROS ``PoseWithCovariance`` convention (``[dp; dtheta]`` in {1}, ``p -> p + dp``,
``R -> exp(hat(dtheta)) R``): ``P C P^T`` with ``P`` = :func:`~tensegrity_stiffness.
sensor_models.pose_jacobian`. ``K_c``'s std is the first-order propagation of ``C`` through
central differences of ``K_c(xi)``.

Observability: the rank and condition number of the whitened Jacobian with the translation
columns scaled by the mean rest length (so that radians and metres weigh alike). A set that
cannot determine the pose (fewer than 6 independent measured degrees of freedom, e.g. 3 tensions
and an unknown load, or gravity alone) gets ``success=False, observable=False`` and a message
naming what is missing; it never gets a number.

Trust (``docs/estimation.md#trust``): every estimate says ``consistent`` (the chi-square test of
its whitened residual at :data:`CONSISTENCY_PROBABILITY`; None without redundancy), its
``redundancy`` and the ``outliers`` left out by name: impossible readings
(:data:`IMPOSSIBLE_STD`) before the fit, then, while the estimate is inconsistent and redundancy
remains, the reading the others contradict (:func:`suspect_reading`). A warm start that loses
track (inconsistent or failed) is restarted from a cold start.
"""

from __future__ import annotations

import copy
import functools
import math
import weakref
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg import lapack
from scipy.special import chdtri

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.geometry.screw import (
    ScrewKinematics,
    as_screws,
    check_in_chart,
    hat3,
    log_se3,
)
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import (
    finite_array,
    finite_array_of_shape,
    per_string,
)
from tensegrity_stiffness.mechanics.chain import ChainState, JointChain
from tensegrity_stiffness.mechanics.equilibrium import (
    MAX_ROTATION_STEP,
    MAX_TRANSLATION_STEP,
    solve_equilibrium,
)
from tensegrity_stiffness.mechanics.joint import JointModel, JointState

__all__ = [
    'CHAIN_EQUILIBRIUM_TOLERANCE',
    'CONSISTENCY_PROBABILITY',
    'DAMPING_GROWTH',
    'DECREMENT_TOLERANCE',
    'IMPOSSIBLE_STD',
    'INITIAL_DAMPING',
    'MAX_DAMPING',
    'MAX_ITERATIONS',
    'MAX_RESTORATION_STEPS',
    'MIN_LENGTH_SCALE',
    'POSE_AXES',
    'RANK_TOLERANCE',
    'STALL_TOLERANCE',
    'STIFFNESS_JACOBIAN_REUSE',
    'STIFFNESS_STEP',
    'ChainEstimate',
    'JointEstimate',
    'Measurements',
    'PreparedMeasurements',
    'cartesian_stiffness_jacobian',
    'consistency_threshold',
    'entry_std',
    'estimate_chain_state',
    'estimate_joint_state',
    'missing_message',
    'stiffness_jacobian_near',
    'suspect_reading',
    'tip_pose_jacobian',
    'tip_stiffness_std',
    'wilson_hilferty',
]

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
#: Why a Gauss-Newton fit stopped when its normal matrix could not be solved.
SINGULAR_NORMAL_MATRIX = 'singular normal matrix'
#: Damping factor of the first rejected step and the factor it grows by.
INITIAL_DAMPING = 1e-4
DAMPING_GROWTH = 10.0
#: An accepted step that lowers the cost by less than this fraction of it ends the iteration:
#: the iterate creeps along a kink of the cost (a string at its slack or saturation boundary).
STALL_TOLERANCE = 1e-9
#: Beyond this damping (a step a 1e-10 fraction of the gradient step) the iterate is a minimum.
MAX_DAMPING = 1e10
#: Central-difference step (rad, m) of dK_c/dxi for the std of K_c.
STIFFNESS_STEP = 1e-6
#: The chain's equilibria count as met when every residual is below this (N, N m).
CHAIN_EQUILIBRIUM_TOLERANCE = 1e-9
#: Newton corrections onto the chain's equilibria after each step.
MAX_RESTORATION_STEPS = 8
#: Names of the pose coordinates in the PoseWithCovariance order.
POSE_AXES = ('x', 'y', 'z', 'rx', 'ry', 'rz')
#: Probability of the consistency test (the one home of its default, read by the nodes'
#: ``estimation.consistency_probability``): an estimate is inconsistent when its chi2 exceeds
#: the ``1 - p`` quantile of chi-square(redundancy), which a set of sound readings does once in
#: ``1 / p`` estimates.
CONSISTENCY_PROBABILITY = 1e-3
#: A reading more than this many of its std outside its physical range is impossible: a tension
#: below ``-IMPOSSIBLE_STD`` std or above what the string can carry (its tension at its maximum
#: length) plus as many, a length above the string's maximum length plus as many; for a string
#: without a maximum length, a tension or length more than ``IMPOSSIBLE_STD ** 6`` (15,625) std.
IMPOSSIBLE_STD = 5.0
#: The length (m) that scales translations against rotations is at least this: rest lengths of
#: denormal size (a hostile ``~/rest_lengths``) would make it zero.
MIN_LENGTH_SCALE = 1e-6
#: Two suspects whose normalized residuals (Wilson-Hilferty z) are within this fraction of each
#: other cannot be told apart (with a redundancy of 1 every reading's is the same): none is left
#: out.
AMBIGUITY = 0.02
#: The most readings one estimate leaves out as contradicted. Left out only when the rest then
#: passes the chi-square test: a set that stays inconsistent after as many (the joint moving,
#: so that the static model fits no subset; a wrong model) keeps every reading and is reported
#: inconsistent, instead of a fit to whichever readings happened to agree.
MAX_CONTRADICTED = 2


def consistency_threshold(redundancy: int, probability: float = CONSISTENCY_PROBABILITY
                          ) -> float:
    """The chi2 above which an estimate with ``redundancy`` degrees of freedom is inconsistent
    (the ``1 - probability`` quantile of chi-square(redundancy)); inf without redundancy."""
    if redundancy <= 0:
        return math.inf
    if not 0.0 < probability < 1.0:
        raise ValueError(f'consistency_probability must be in (0, 1), got {probability}')
    return _chi2_quantile(redundancy, probability)


@functools.lru_cache(maxsize=256)
def _chi2_quantile(dof: int, probability: float) -> float:
    """The upper ``probability`` quantile of chi-square(dof) (a tracker asks for a few)."""
    return float(chdtri(dof, probability))


def _length_scale(rest: FloatArray) -> float:
    """The mean rest length (m), at least :data:`MIN_LENGTH_SCALE`."""
    return max(float(np.add.reduce(rest)) / rest.size, MIN_LENGTH_SCALE)  # sum(), less wrapping


# ---------------------------------------------------------------------------------- inputs
def _std(name: str, value: Any, size: int) -> FloatArray:
    """A std given as a scalar or one per entry: (size,) array, finite and > 0."""
    if value is None:
        raise ValueError(f'{name} is required with its measurement')
    if isinstance(value, float) and math.isfinite(value) and value > 0.0:
        return np.full(size, value)
    arr = finite_array(name, value).ravel()
    if arr.size == 1:
        arr = np.full(size, arr[0])
    if arr.size != size:
        raise ValueError(f'{name} must be a scalar or have {size} entries, got {arr.size}')
    if np.any(arr <= 0.0):
        raise ValueError(f'{name} must be > 0, got minimum {arr.min()}')
    return arr


#: Checked covariances and their whiteners by content: a tracker's covariances come from its
#: settings (or a sensor's fixed covariance) and repeat every estimate. A few are kept.
_COVARIANCES: dict[bytes, tuple[FloatArray, FloatArray]] = {}
_COVARIANCES_KEPT = 16


def _covariance(name: str, value: Any, size: int) -> tuple[FloatArray, FloatArray]:
    """A symmetric positive definite (size, size) covariance and its whitener ``L^-1`` with
    ``covariance = L L^T`` (whitened residual ``L^-1 r``; one Cholesky factorisation checks
    and whitens; both read-only, reused for a covariance seen before); ValueError naming
    ``name``."""
    if value is None:
        raise ValueError(f'{name} is required with its measurement')
    arr = finite_array(name, value)
    if arr.shape != (size, size):
        raise ValueError(f'{name} must have shape ({size}, {size}), got {arr.shape}')
    key = arr.tobytes()
    known = _COVARIANCES.get(key)
    if known is not None:
        return known
    if not np.allclose(arr, arr.T, rtol=1e-9, atol=0.0):
        raise ValueError(f'{name} must be symmetric')
    covariance = 0.5 * (arr + arr.T)
    try:
        factor = np.linalg.cholesky(covariance)
    except np.linalg.LinAlgError:
        raise ValueError(f'{name} must be positive definite') from None
    whitener = np.linalg.inv(factor)
    covariance.flags.writeable = whitener.flags.writeable = False
    if len(_COVARIANCES) >= _COVARIANCES_KEPT:
        _COVARIANCES.pop(next(iter(_COVARIANCES), None), None)
    _COVARIANCES[key] = (covariance, whitener)
    return covariance, whitener


_NOT_MEASURED = (np.empty(0, dtype=np.intp), np.empty(0), np.empty(0))
for _empty in _NOT_MEASURED:
    _empty.flags.writeable = False


def _string_readings(name: str, value: Any, std_name: str, std: Any, n: int
                     ) -> tuple[NDArray[np.intp], FloatArray, FloatArray]:
    """(indices of the measured strings, their values, their weights 1/std) of a per-string
    reading (NaN = not measured; None: no string measured, std not needed)."""
    if value is None:
        return _NOT_MEASURED
    values = per_string(name, value, n, not_measured=True)
    index = np.flatnonzero(~np.isnan(values))
    if not index.size:
        return _NOT_MEASURED
    if isinstance(std, float) and math.isfinite(std) and std > 0.0:  # the common scalar
        weight = np.full(index.size, 1.0 / std)
    else:
        weight = 1.0 / _std(std_name, std, n)[index]
    return index, values[index], weight


@dataclass
class Measurements:
    """One instant's sensor readings (see the module docstring).

    ``tensions`` (n,) N and ``lengths`` (n,) m in the config's string order, NaN where a string
    is not measured; ``tension_std`` / ``length_std`` a scalar or one per string. ``pose`` the
    measured pose of {2} in {1} ((4, 4) or ``[x y z qx qy qz qw]``) with ``pose_covariance``
    (6, 6) in the PoseWithCovariance convention. ``gravity`` (3,) the direction of gravity
    measured in link 2's frame by an accelerometer at rest (normalised here), ``gravity_std`` a
    scalar or (3,) std of its unit-vector components, ``gravity_base`` (3,) its known direction
    in {1}. ``external_wrench`` (6,) [N; N m] on link 2 in {1} about its origin with
    ``wrench_covariance`` (6, 6): a known (zeros with a small covariance for "unloaded") or
    measured (force-torque) load; ``None`` for an unknown load.

    For the recursive filter (:class:`~tensegrity_stiffness.estimation.joint_filter.
    JointFilter`; the static estimator does not read them): ``specific_force`` (3,) m/s^2 the
    accelerometer's raw specific force in {2} (acceleration minus gravity, modelled with the
    link's acceleration) with ``specific_force_std`` (m/s^2, a scalar or (3,)), and
    ``angular_velocity`` (3,) rad/s a gyro's reading of link 2's angular velocity in {2} with
    ``angular_velocity_std`` (rad/s, a scalar or (3,)).
    """

    tensions: ArrayLike | None = None
    tension_std: ArrayLike | float | None = None
    lengths: ArrayLike | None = None
    length_std: ArrayLike | float | None = None
    pose: ArrayLike | None = None
    pose_covariance: ArrayLike | None = None
    gravity: ArrayLike | None = None
    gravity_std: ArrayLike | float | None = None
    gravity_base: ArrayLike | None = None
    external_wrench: ArrayLike | None = None
    wrench_covariance: ArrayLike | None = None
    specific_force: ArrayLike | None = None
    specific_force_std: ArrayLike | float | None = None
    angular_velocity: ArrayLike | None = None
    angular_velocity_std: ArrayLike | float | None = None

    def prepared(self, n_strings: int) -> PreparedMeasurements:
        """Validated and whitened for a joint with ``n_strings`` strings; bad input raises
        ValueError naming the field."""
        return PreparedMeasurements(self, n_strings)


@dataclass
class _StringLimits:
    """A joint's string limits at rest lengths ``rest``: ``lmax`` the maximum lengths and
    ``top`` the tensions there (the most each string can carry), (n,), inf without a maximum
    length; ``ranges`` the physical ranges of readings already asked for (:meth:`range`)."""

    rest: FloatArray
    lmax: FloatArray
    top: FloatArray
    ranges: dict[tuple[str, bytes, bytes], tuple[FloatArray, FloatArray, FloatArray]] = field(
        default_factory=dict)

    def range(self, label: str, index: NDArray[np.intp], weight: FloatArray
              ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(physical limit, low, high) of the possible ``label`` (``tension`` or ``length``)
        readings of the strings ``index`` with weights ``weight`` (1/std): the limit is ``top``
        or ``lmax`` of those strings, the bounds :data:`IMPOSSIBLE_STD` std outside the range.
        A tracker's readings share their strings and stds: a few are kept."""
        key = (label, index.tobytes(), weight.tobytes())
        known = self.ranges.get(key)
        if known is not None:
            return known
        std = 1.0 / weight
        bound = (self.top if label == 'tension' else self.lmax)[index]
        low = -IMPOSSIBLE_STD * std if label == 'tension' else np.zeros(index.size)
        high = np.where(np.isfinite(bound), bound + IMPOSSIBLE_STD * std,
                        IMPOSSIBLE_STD ** 6 * std)
        if len(self.ranges) >= _RANGES_KEPT:
            self.ranges.pop(next(iter(self.ranges)))
        self.ranges[key] = bound, low, high
        return bound, low, high


_RANGES_KEPT = 16
_STRING_LIMITS: weakref.WeakKeyDictionary[JointModel, _StringLimits] = \
    weakref.WeakKeyDictionary()


def _string_limits(model: JointModel, rest: FloatArray) -> _StringLimits:
    """The string limits of ``model`` at rest lengths ``rest``; the last per model is kept."""
    cached = _STRING_LIMITS.get(model)
    if cached is not None and (rest is cached.rest or np.array_equal(rest, cached.rest)):
        return cached
    lmax = rest + model.max_stretch
    limited = np.isfinite(lmax)
    top = np.where(limited, model.string_forces(np.where(limited, lmax, rest), rest)[0],
                   np.inf)
    # the model's own rest lengths are kept by identity (never mutated), others copied
    limits = _StringLimits(rest if rest is model.rest_lengths else rest.copy(), lmax, top)
    _STRING_LIMITS[model] = limits
    return limits


def _impossible_reasons(label: str, values: FloatArray, low: FloatArray, bound: FloatArray,
                        bad: NDArray[np.intp]) -> list[tuple[int, str]]:
    """(position, why) of each impossible ``label`` reading ``values[bad]`` (below ``low``, or
    above its physical limit ``bound`` by more than :data:`IMPOSSIBLE_STD` std)."""
    unit = 'N' if label == 'tension' else 'm'
    out = []
    for k in bad.tolist():
        value, limit = float(values[k]), float(bound[k])
        if value < low[k]:
            why = f'{value:.6g} {unit} is below {low[k]:.3g} {unit}'
        elif math.isfinite(limit):
            what = (f'the most the string can carry ({limit:.4g} N)' if
                    label == 'tension' else f'its maximum length ({limit:.4g} m)')
            why = f'{value:.6g} {unit} exceeds {what} by more than {IMPOSSIBLE_STD:g} std'
        else:
            why = f'{value:.6g} {unit} is more than {IMPOSSIBLE_STD ** 6:g} std'
        out.append((k, f'impossible: {why}'))
    return out


#: :meth:`PreparedMeasurements.describe`'s texts by sensor pattern (a tracker's pattern rarely
#: changes, its measurements are prepared anew for every estimate). A few are kept.
_DESCRIPTIONS: dict[tuple, str] = {}
_DESCRIPTIONS_KEPT = 64


class PreparedMeasurements:
    """:class:`Measurements` validated for one joint, with their whitening (reusable)."""

    def __init__(self, m: Measurements, n: int) -> None:
        self.n_strings = n
        self.tension_index, self.tensions, self.tension_weight = _string_readings(
            'tensions', m.tensions, 'tension_std', m.tension_std, n)
        self.length_index, self.lengths, self.length_weight = _string_readings(
            'lengths', m.lengths, 'length_std', m.length_std, n)
        if self.lengths.size and self.lengths.min() <= 0.0:
            raise ValueError('lengths must be > 0 where measured')
        self.pose = None
        if m.pose is not None:
            self.pose = rigid_transform(m.pose, 'pose')
            _, self.pose_whitener = _covariance('pose_covariance', m.pose_covariance, 6)
        self.gravity = None
        if m.gravity is not None:
            self.gravity = sm.unit_vector(m.gravity, 'gravity')
            if m.gravity_base is None:
                raise ValueError('gravity_base (the direction of gravity in {1}) is required '
                                 'with gravity')
            self.gravity_base = sm.unit_vector(m.gravity_base, 'gravity_base')
            self.gravity_weight = 1.0 / _std('gravity_std', m.gravity_std, 3)
        self.wrench = None
        if m.external_wrench is not None:
            W = finite_array('external_wrench', m.external_wrench)
            if W.shape != (6,):
                raise ValueError(f'external_wrench must have shape (6,), got {W.shape}')
            self.wrench = W
            self.wrench_covariance, self.wrench_whitener = _covariance(
                'wrench_covariance', m.wrench_covariance, 6)
        # the filter's IMU readings (not counted in rows / dof: the static estimator ignores
        # them)
        self.specific_force = None
        if m.specific_force is not None:
            self.specific_force = finite_array_of_shape('specific_force', m.specific_force,
                                                        (3,))
            self.specific_force_weight = 1.0 / _std('specific_force_std',
                                                    m.specific_force_std, 3)
        self.angular_velocity = None
        if m.angular_velocity is not None:
            self.angular_velocity = finite_array_of_shape('angular_velocity',
                                                          m.angular_velocity, (3,))
            self.angular_velocity_weight = 1.0 / _std('angular_velocity_std',
                                                      m.angular_velocity_std, 3)
        self._count()

    def recount(self) -> None:
        """Count the rows and degrees of freedom again after readings were set on a copy
        (the filter hands the static estimator a specific force as a gravity direction)."""
        self._count()

    def _count(self) -> None:
        """The whitened rows and the measured degrees of freedom of the readings."""
        nt, nl = self.tension_index.size, self.length_index.size
        self.rows = nt + nl + (6 if self.pose is not None else 0) + (
            3 if self.gravity is not None else 0) + (6 if self.wrench is not None else 0)
        #: Independent measured degrees of freedom (a gravity direction counts 2).
        self.dof = nt + nl + (6 if self.pose is not None else 0) + (
            sm.GRAVITY_DOF if self.gravity is not None else 0) + (
            6 if self.wrench is not None else 0)

    def readings(self, string_names: Sequence[str]
                 ) -> list[tuple[str, NDArray[np.intp], int]]:
        """Every reading that can be left out: (name, its whitened rows, its degrees of
        freedom), in row order; names ``tension[<string>]``, ``length[<string>]``, ``pose``,
        ``gravity``, ``wrench``."""
        out: list[tuple[str, NDArray[np.intp], int]] = []
        row = 0
        for label, index in (('tension', self.tension_index), ('length', self.length_index)):
            for i in index.tolist():
                out.append((f'{label}[{string_names[i]}]', np.array([row]), 1))
                row += 1
        for name, rows, dof in (('pose', 6, 6), ('gravity', 3, sm.GRAVITY_DOF),
                                ('wrench', 6, 6)):
            if getattr(self, name) is not None:
                out.append((name, np.arange(row, row + rows), dof))
                row += rows
        return out

    def without(self, names: Sequence[str], string_names: Sequence[str]
                ) -> PreparedMeasurements:
        """A copy without the readings named as :meth:`readings` names them."""
        out = copy.copy(self)
        drop = set(names)
        for label in ('tension', 'length'):
            index = getattr(self, f'{label}_index')
            keep = np.array([f'{label}[{string_names[i]}]' not in drop for i in index.tolist()],
                            dtype=bool)
            if not keep.all():
                setattr(out, f'{label}_index', index[keep])
                setattr(out, f'{label}s', getattr(self, f'{label}s')[keep])
                setattr(out, f'{label}_weight', getattr(self, f'{label}_weight')[keep])
        for name in ('pose', 'gravity', 'wrench'):
            if name in drop:
                setattr(out, name, None)
        out._count()
        return out

    def impossible(self, model: JointModel, rest: FloatArray) -> list[tuple[str, str]]:
        """The string readings outside their physical range (:data:`IMPOSSIBLE_STD`): (name,
        why) each, in the names of :meth:`readings` (one comparison per kind of reading
        against its cached range; the reasons are written for the impossible ones alone)."""
        out: list[tuple[str, str]] = []
        if not (self.tension_index.size or self.length_index.size):
            return out
        limits = _string_limits(model, rest)
        for label, index, values, weight in (
                ('tension', self.tension_index, self.tensions, self.tension_weight),
                ('length', self.length_index, self.lengths, self.length_weight)):
            if not index.size:
                continue
            bound, low, high = limits.range(label, index, weight)
            outside = values < low
            outside |= values > high
            if not np.count_nonzero(outside):
                continue
            out += [(f'{label}[{model.string_names[int(index[k])]}]', why)
                    for k, why in _impossible_reasons(label, values, low, bound,
                                                      np.flatnonzero(outside))]
        return out

    @property
    def needs_strings(self) -> bool:
        return bool(self.tension_index.size or self.length_index.size)

    def describe(self, string_names: Sequence[str], load: bool = True) -> str:
        """The inputs in words, e.g. ``'3 tensions (a, b, c), unknown load'`` (without the load
        when not ``load``); one text per sensor pattern and names, kept across estimates."""
        key = (self.tension_index.tobytes(), self.length_index.tobytes(),
               self.pose is not None, self.gravity is not None, self.wrench is not None, load,
               tuple(string_names))
        text = _DESCRIPTIONS.get(key)
        if text is None:
            text = self._describe(string_names, load)
            if len(_DESCRIPTIONS) >= _DESCRIPTIONS_KEPT:
                _DESCRIPTIONS.pop(next(iter(_DESCRIPTIONS), None), None)
            _DESCRIPTIONS[key] = text
        return text

    def _describe(self, string_names: Sequence[str], load: bool) -> str:
        parts = []
        for label, index in (('tension', self.tension_index), ('length', self.length_index)):
            if index.size:
                names = ', '.join(string_names[i] for i in index)
                parts.append(f'{index.size} {label}{"s" if index.size > 1 else ""} ({names})')
        if self.pose is not None:
            parts.append('a pose')
        if self.gravity is not None:
            parts.append('gravity')
        if load:
            parts.append('a known load' if self.wrench is not None else 'unknown load')
        return ', '.join(parts)


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


def _nan(*shape: int) -> FloatArray:
    out = np.empty(shape)
    out.fill(np.nan)
    return out


def _outlier_fields(dropped: Sequence[tuple[str, str]]
                    ) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """An estimate's ``outliers`` and ``outlier_reasons`` from the (name, why) left out."""
    if not dropped:
        return (), ()
    return tuple(name for name, _ in dropped), tuple(f'{name}: {why}' for name, why in dropped)


class _JointProblem:
    """The whitened residual and Jacobian of one joint's measurements at a screw."""

    def __init__(self, model: JointModel, prep: PreparedMeasurements, rest: FloatArray) -> None:
        self.model = model
        self.prep = prep
        self.rest = rest
        self.length_scale = _length_scale(rest)

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


def _describe_direction(pose_change: FloatArray, length_scale: float) -> str:
    """A pose change [dp; dtheta] in words: the translation or rotation that dominates."""
    dp, dth = pose_change[:3], pose_change[3:]
    if np.linalg.norm(dth) * length_scale >= np.linalg.norm(dp):
        axis = dth / np.linalg.norm(dth)
        kind = 'rotation about'
    else:
        axis = dp / np.linalg.norm(dp)
        kind = 'translation along'
    return f'{kind} ({axis[0]:.2f}, {axis[1]:.2f}, {axis[2]:.2f})'


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


def _observability(problem: _JointProblem, J: FloatArray, state: JointState,
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
    words = [_describe_direction(P @ v, problem.length_scale) for v in null]
    slack = [problem.model.string_names[i] for i in prep.tension_index if state.slack[i]]
    return rank, cond, s, missing_message(prep, problem.model.string_names, rank, words,
                                                slack)


def _clip(step: FloatArray, length_scale: float) -> FloatArray:
    """The step scaled into the equilibrium solver's trust radius (rotation, translation)."""
    wx, wy, wz, vx, vy, vz = step.tolist()
    worst = max(math.sqrt(wx * wx + wy * wy + wz * wz) / MAX_ROTATION_STEP,
                math.sqrt(vx * vx + vy * vy + vz * vz) / (MAX_TRANSLATION_STEP * length_scale),
                1.0)
    return step if worst == 1.0 else step / worst


def _normal_solve(A: FloatArray, g: FloatArray) -> FloatArray | None:
    """The Gauss-Newton step ``-A^-1 g`` for a symmetric positive definite normal matrix ``A``
    (LAPACK's Cholesky solver ``dposv``); None when ``A`` is not positive definite."""
    _, x, info = lapack.dposv(A, g)
    return -x if info == 0 else None


class _InitialPointError(ValueError):
    """The starting point of :func:`_gauss_newton` cannot be evaluated."""


def _gauss_newton(evaluate: Any, x0: FloatArray, length_scale: float, max_iterations: int,
                  tolerance: float) -> tuple[FloatArray, Any, int, bool, str]:
    """Levenberg-Marquardt on the whitened residual of ``evaluate(x, jacobian) -> (r, J,
    state, kinematics)``.

    Trial points are evaluated without their Jacobian (the cost decides); at an accepted point
    the decrement is first taken with the Jacobian it was stepped from (a chord step), and only
    when that is not below ``tolerance`` is the Jacobian evaluated there. So a warm start near
    the optimum costs one evaluation with the Jacobian and one without, and the covariance is
    linearised at the last point where the Jacobian was evaluated (within ``tolerance`` of the
    optimum in units of its own std). The damping scales the normal matrix's diagonal
    (Marquardt); it is zero while steps reduce the cost. Returns (x, (r, J, A, state,
    kinematics) with J of the linearisation point and ``A = J^T J`` its normal matrix, r, state
    and the kinematics of x (None when ``evaluate`` gave none there), iterations, converged,
    message).
    """
    x = x0.copy()
    try:
        r, J, state, kin = evaluate(x)
    except ValueError as exc:  # the trial steps below catch theirs: this one is the caller's
        raise _InitialPointError(str(exc)) from None
    cost = float(r @ r)
    damping = 0.0
    for it in range(1, max_iterations + 1):
        A = J.T @ J
        g = J.T @ r
        full_step = _normal_solve(A, g)
        if full_step is None:
            return x, (r, J, A, state, kin), it - 1, False, SINGULAR_NORMAL_MATRIX
        if float(-g @ full_step) < tolerance:
            return x, (r, J, A, state, kin), it - 1, True, ''
        while True:
            if damping == 0.0:
                step = full_step
            else:
                step = _normal_solve(A + damping * np.diag(np.diag(A)), g)
                if step is None:
                    return x, (r, J, A, state, kin), it, False, SINGULAR_NORMAL_MATRIX
            trial = x + _clip(step, length_scale)
            try:
                trial_r, _, trial_state, trial_kin = evaluate(trial, False)
            except ValueError:  # a string of zero length, outside the chart: step too long
                trial_r = None
            if trial_r is not None:
                trial_cost = float(trial_r @ trial_r)
                if trial_cost <= cost:
                    stalled = cost - trial_cost <= STALL_TOLERANCE * max(cost, 1.0)
                    x, r, state, kin, cost = trial, trial_r, trial_state, trial_kin, trial_cost
                    if stalled:  # creeping along a kink (a string at its slack boundary)
                        return x, (r, J, A, state, kin), it, True, ''
                    damping = 0.0 if damping <= INITIAL_DAMPING else damping / DAMPING_GROWTH
                    break
            damping = INITIAL_DAMPING if damping == 0.0 else damping * DAMPING_GROWTH
            if damping > MAX_DAMPING:
                # Not even a short gradient step lowers the cost: a minimum, where the cost has
                # a kink (a string at its slack or saturation boundary) or is flat to rounding.
                return x, (r, J, A, state, kin), it, True, ''
        chord_g = J.T @ r
        chord = _normal_solve(A, chord_g)
        if chord is not None and float(-chord_g @ chord) < tolerance:
            return x, (r, J, A, state, kin), it, True, ''
        r, J, state, kin = evaluate(x)
    return x, (r, J, J.T @ J, state, kin), max_iterations, False, (
        f'not converged in {max_iterations} iterations')


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
        length = _length_scale(rest)
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
    return JointEstimate(False, message, _nan(6), _nan(4, 4), _nan(6, 6), _nan(6, 6), _nan(6),
                         _nan(6, 6), None, _nan(6, 6), math.nan,
                         0 if prep is None else prep.dof - 6, observable, rank, cond,
                         iterations, '' if prep is None else prep.describe(names),
                         np.empty(0) if s is None else s, None,
                         0 if prep is None else prep.dof - 6, *_outlier_fields(dropped))


def _initial_screw(model: JointModel, prep: PreparedMeasurements, rest: FloatArray,
                   initial_screw: ArrayLike | None) -> FloatArray:
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
        res = solve_equilibrium(model, prep.wrench, rest)
        if res.success:
            return res.screw
    return model.initial_screw.copy()


def wilson_hilferty(value: float, dof: int) -> float:
    """The standard normal quantile of a chi-square(dof) ``value`` (Wilson-Hilferty): readings
    of different degrees of freedom compared on one scale."""
    a = 2.0 / (9.0 * dof)
    return ((value / dof) ** (1.0 / 3.0) - (1.0 - a)) / math.sqrt(a)


def suspect_reading(r: FloatArray, J: FloatArray, C: FloatArray,
                    readings: Sequence[tuple[str, NDArray[np.intp], int]], redundancy: int
                    ) -> tuple[str, str] | None:
    """The reading the others contradict most, as robust estimators find it (Baarda's data
    snooping): for each reading's rows ``g`` of the whitened residual ``r`` (Jacobian ``J``,
    covariance ``C = (J^T J)^-1`` of the unknowns), ``r_g^T S_gg^+ r_g`` with
    ``S = I - J C J^T`` the residual's covariance, which is the drop of chi2 when the reading
    is left out (chi-square with its degrees of freedom for a sound reading). Returns (name, why)
    of the largest (Wilson-Hilferty z) among the readings that can be left out (no more degrees
    of freedom than ``redundancy``, checked by the others), or None when there is none or the
    two largest cannot be told apart (:data:`AMBIGUITY`)."""
    S = np.eye(r.size) - J @ C @ J.T
    scored: list[tuple[float, float, str]] = []
    for name, rows, dof in readings:
        if dof > redundancy:
            continue
        w, V = np.linalg.eigh(S[np.ix_(rows, rows)])
        checked = w > 1e-6
        if not checked.any():
            continue
        proj = V[:, checked].T @ r[rows]
        statistic = float(np.sum(proj * proj / w[checked]))
        k = min(dof, int(checked.sum()))
        scored.append((wilson_hilferty(statistic, k), statistic, name))
    if not scored:
        return None
    scored.sort(reverse=True)
    z, statistic, name = scored[0]
    if len(scored) > 1 and scored[1][0] >= z - AMBIGUITY * abs(z):
        return None
    return name, (f'contradicted by the others: leaving it out lowers chi2 by '
                  f'{statistic:.4g} (normalized residual z = {z:.3g})')


class _Fit:
    """What the trust rules ask of a fit, a joint's (:class:`_JointFit`) or a spine's
    (:class:`_ChainFit`): its whitened residual ``r``, Jacobian ``J`` and covariance ``C``, chi2
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
        return self.chi2 <= _chi2_quantile(redundancy, probability)

    def on_track(self, probability: float) -> bool:
        """Whether the fit succeeded and passes the chi-square test (or has no redundancy)."""
        return self.ok and self.consistent(probability) is not False


_F = TypeVar('_F', bound=_Fit)


@dataclass
class _JointFit(_Fit):
    """One Gauss-Newton fit of a joint's readings and its information (``chi2`` computed
    once: the trust rules ask for it several times)."""

    problem: _JointProblem
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
               x0: FloatArray, tolerance: float, max_iterations: int, rank_tolerance: float
               ) -> _JointFit:
    """Gauss-Newton from ``x0`` and the covariance, rank and condition at the optimum;
    :class:`_InitialPointError` when ``x0`` cannot be evaluated."""
    problem = _JointProblem(model, prep, rest)
    x, ev, iterations, converged, why = _gauss_newton(
        problem.evaluate, x0, problem.length_scale, max_iterations, tolerance)
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


def _better(cold: _Fit, warm: _Fit) -> bool:
    """Whether the cold start's fit beats a warm start's (it succeeded where the warm one did
    not, or reached a lower chi2)."""
    return cold.ok and (not warm.ok or cold.chi2 < warm.chi2)


def _tracked_fit(model: JointModel, prep: PreparedMeasurements, rest: FloatArray,
                 warm: FloatArray | None, probability: float, options: tuple[float, int, float]
                 ) -> tuple[_JointFit, bool]:
    """The fit from the warm start ``warm`` (a tracker's last estimate) and whether it was
    restarted: a warm start that cannot be evaluated, fails or is inconsistent has lost track
    and is fitted again from a cold start (:func:`_initial_screw` without it), whose fit is
    kept when better. Without ``warm``, the cold start's fit (ValueError when its starting
    point cannot be evaluated). The cold start (with a known load, an equilibrium solve) is
    computed only when it is used."""
    if warm is not None:
        try:
            fit = _fit_joint(model, prep, rest, warm, *options)
        except _InitialPointError:
            fit = None
        if fit is not None and fit.on_track(probability):
            return fit, False
        try:
            cold = _fit_joint(model, prep, rest, _initial_screw(model, prep, rest, None),
                              *options)
        except _InitialPointError:
            cold = None
        if fit is None:
            if cold is None:
                raise ValueError('initial_screw: neither the warm nor the cold start can be '
                                 'evaluated')
            return cold, True
        return (cold, True) if cold is not None and _better(cold, fit) else (fit, False)
    try:
        return _fit_joint(model, prep, rest, _initial_screw(model, prep, rest, None),
                          *options), False
    except _InitialPointError as exc:
        raise ValueError(f'initial_screw: {exc}') from None


def _joint_refit_without(model: JointModel, rest: FloatArray, probability: float,
                         options: tuple[float, int, float], fit: _JointFit, name: str
                         ) -> tuple[_JointFit, bool] | None:
    """The joint's readings of ``fit`` without the reading ``name``, fitted again from the fit's
    estimate (:func:`_tracked_fit`); None when no start can be evaluated."""
    reduced = fit.problem.prep.without([name], model.string_names)
    try:
        return _tracked_fit(model, reduced, rest, fit.x, probability, options)
    except ValueError:
        return None


def _reject_contradicted(fit: _F, restarted: bool, dropped: list[tuple[str, str]],
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


def estimate_joint_state(model: JointModel, measurements: Measurements | PreparedMeasurements,
                         rest_lengths: ArrayLike | None = None,
                         initial_screw: ArrayLike | None = None, *,
                         tolerance: float = DECREMENT_TOLERANCE,
                         max_iterations: int = MAX_ITERATIONS,
                         rank_tolerance: float = RANK_TOLERANCE,
                         stiffness_std: bool = True,
                         consistency_probability: float = CONSISTENCY_PROBABILITY,
                         reject_outliers: bool = True) -> JointEstimate:
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
    """
    prep = (measurements if isinstance(measurements, PreparedMeasurements)
            else Measurements.prepared(measurements, model.n_strings))
    if prep.n_strings != model.n_strings:
        raise ValueError(f'measurements were prepared for {prep.n_strings} strings, the model '
                         f'has {model.n_strings}')
    consistency_threshold(1, consistency_probability)  # checks the probability
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
    options = (tolerance, max_iterations, rank_tolerance)
    warm = None if initial_screw is None else _initial_screw(model, prep, rest, initial_screw)
    fit, restarted = _tracked_fit(model, prep, rest, warm, consistency_probability, options)
    consistent = fit.consistent(consistency_probability)
    if reject_outliers and consistent is False:  # the search runs on an inconsistent fit alone
        fit, restarted = _reject_contradicted(
            fit, restarted, dropped, consistency_probability,
            lambda current: current.problem.prep.readings(names),
            functools.partial(_joint_refit_without, model, rest, consistency_probability,
                              options))
        prep = fit.problem.prep
        consistent = fit.consistent(consistency_probability)
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
    x, C, state = fit.x, fit.C, fit.state
    P = sm.pose_jacobian(x, fit.kin)  # at the estimate
    pose_cov = P @ C @ P.T
    K = state.stiffness
    Kc_std = (entry_std(stiffness_jacobian_near(model, x, rest), C) if stiffness_std
              else _nan(6, 6))
    return JointEstimate(True, 'ok', x, state.transform.copy(), 0.5 * (pose_cov + pose_cov.T), C,
                         -state.wrench, K @ C @ K.T, state, Kc_std, fit.chi2, prep.dof - 6,
                         True, fit.rank, fit.cond, fit.iterations, prep.describe(names), fit.s,
                         consistent, prep.dof - 6, *_outlier_fields(dropped), restarted)


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
        return _nan(6, 6), s
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


# ---------------------------------------------------------------------------------- spine
@dataclass
class ChainEstimate:
    """Outcome of :func:`estimate_chain_state` (N joints).

    ``screws`` (N, 6) with ``screw_covariance`` (6N, 6N) (joint-major); ``joint_covariances``
    (N, 6, 6) each joint's pose covariance in its own {1}_i (PoseWithCovariance convention);
    ``tip_wrench`` (6,) in the base about its origin with ``tip_wrench_covariance``;
    ``tip_transform`` (4, 4) with ``tip_pose_covariance`` (6, 6) in the base;
    ``tip_stiffness`` (6, 6) the exact tip stiffness under the estimated load (base frame, rows
    [f; m], columns [dv; dw]) with ``tip_stiffness_std`` (first order, central differences);
    ``chi2``, ``dof``, ``observable``, ``rank`` (of 6N + 6), ``condition_number``,
    ``iterations``; ``state`` the :class:`ChainState` at the estimate; ``consistent``,
    ``redundancy``, ``outliers``, ``outlier_reasons`` and ``restarted`` as
    :class:`JointEstimate`'s (a joint's readings named ``joint <i> tension[<string>]``,
    ``joint <i> length[<string>]``, ``joint <i> pose``; the tip's ``pose`` and ``wrench``).
    ``screw_rates`` (N, 6) and ``screw_rate_covariance`` (6N, 6N): the chain filter's
    (:class:`~tensegrity_stiffness.estimation.chain_filter.ChainFilter`); empty from the static
    estimator, which assumes rest.
    """

    success: bool
    message: str
    screws: FloatArray
    screw_covariance: FloatArray
    joint_covariances: FloatArray
    tip_wrench: FloatArray
    tip_wrench_covariance: FloatArray
    tip_transform: FloatArray
    tip_pose_covariance: FloatArray
    tip_stiffness: FloatArray
    tip_stiffness_std: FloatArray
    chi2: float
    dof: int
    observable: bool
    rank: int
    condition_number: float
    iterations: int
    state: ChainState | None = field(default=None, repr=False)
    consistent: bool | None = None
    redundancy: int = 0
    outliers: tuple[str, ...] = ()
    outlier_reasons: tuple[str, ...] = ()
    restarted: bool = False
    screw_rates: FloatArray = field(default_factory=lambda: np.zeros((0, 6)))
    screw_rate_covariance: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))


class _ChainProblem:
    """Unknowns ``z = [xi_1 .. xi_N, W]``. Measurement residuals (whitened): each joint's
    tensions, lengths and pose, the tip pose, the tip load when it is known; constraints: each
    joint's equilibrium ``c_i = F_i + Ad_{P_i}^T B_i = 0`` (exact, Jacobian from
    :meth:`JointChain.residual_jacobian`'s blocks and ``dc_i/dW = Ad_{P_i}^T``)."""

    def __init__(self, chain: JointChain, preps: list[PreparedMeasurements | None],
                 rest: list[FloatArray | None], gravity: FloatArray,
                 tip_pose: FloatArray | None, tip_pose_whitener: FloatArray | None,
                 tip_wrench: FloatArray | None, tip_wrench_whitener: FloatArray | None) -> None:
        self.chain = chain
        self.n = chain.n_joints
        self.rest = rest
        self.gravity = gravity
        self.tip_pose = tip_pose
        self.tip_pose_whitener = tip_pose_whitener
        self.tip_wrench = tip_wrench
        self.tip_wrench_whitener = tip_wrench_whitener
        self.problems = [
            None if p is None or p.rows == 0
            else _JointProblem(model, p, model.validate_rest_lengths(r, False))
            for model, p, r in zip(chain.joints, preps, rest, strict=True)]
        self.length_scale = max(float(np.mean([np.mean(m.rest_lengths) for m in chain.joints])),
                                MIN_LENGTH_SCALE)
        size = 6 * self.n + 6
        #: Column scale of z for rank and clipping: radians, metres / length_scale, the load.
        self.scale = np.array(([1.0] * 3 + [self.length_scale] * 3) * self.n + [1.0] * 6)
        self.size = size

    def constraints(self, z: FloatArray) -> tuple[FloatArray, FloatArray, ChainState]:
        """(c (6N,), dc/dz (6N, size), chain state) at z."""
        n = self.n
        xi = z[:6 * n].reshape(n, 6)
        chain = self.chain
        state = chain.evaluate(xi, self.rest)
        c, D, AdT, _ = chain.equilibrium_system(state, z[6 * n:], self.gravity)
        Jc = np.empty((6 * n, self.size))
        Jc[:, :6 * n] = chain.residual_screw_jacobian(D, xi)
        Jc[:, 6 * n:] = AdT.reshape(6 * n, 6)
        return c.reshape(-1), Jc, state

    def measurements(self, z: FloatArray, state: ChainState) -> tuple[FloatArray, FloatArray]:
        """(r, dr/dz) whitened at z (``state`` the chain's at z)."""
        n, size = self.n, self.size
        xi = z[:6 * n].reshape(n, 6)
        W = z[6 * n:]
        rows_r: list[FloatArray] = []
        rows_J: list[FloatArray] = []
        for i, problem in enumerate(self.problems):
            if problem is None:
                continue
            r, J, _, _ = problem.evaluate(xi[i])
            block = np.zeros((r.size, size))
            block[:, 6 * i:6 * i + 6] = J
            rows_r.append(r)
            rows_J.append(block)
        if self.tip_pose is not None:
            T = state.tip_transform
            jac = np.zeros((6, size))
            jac[:, :6 * n] = tip_pose_jacobian(self.chain, xi, T)
            r, jac = sm.pose_residual_unchecked(T, self.tip_pose, jac)
            rows_r.append(self.tip_pose_whitener @ r)
            rows_J.append(self.tip_pose_whitener @ jac)
        if self.tip_wrench is not None:
            jac = np.zeros((6, size))
            jac[:, 6 * n:] = self.tip_wrench_whitener
            rows_r.append(self.tip_wrench_whitener @ (W - self.tip_wrench))
            rows_J.append(jac)
        r = np.concatenate(rows_r) if rows_r else np.empty(0)
        J = np.vstack(rows_J) if rows_J else np.empty((0, size))
        return r, J

    def restore(self, z: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, ChainState
                                               ] | None:
        """Newton's minimum-norm corrections onto the equilibria from z: (z, c, dc/dz, state)
        once every residual is below :data:`CHAIN_EQUILIBRIUM_TOLERANCE`; None when that fails
        (or a string collapses)."""
        z = z.copy()
        for _ in range(MAX_RESTORATION_STEPS):
            try:
                c, Jc, state = self.constraints(z)
            except ValueError:
                return None
            if not np.all(np.isfinite(c)):
                return None
            if np.max(np.abs(c)) < CHAIN_EQUILIBRIUM_TOLERANCE:
                return z, c, Jc, state
            try:
                Q1, _, R = _tangent(Jc)
                step = Q1 @ np.linalg.solve(R.T, -c)
            except np.linalg.LinAlgError:
                return None
            for i in range(self.n):
                step[6 * i:6 * i + 6] = _clip(step[6 * i:6 * i + 6], self.length_scale)
            z = z + step
        return None


def tip_pose_jacobian(chain: JointChain, xi: FloatArray, tip: FloatArray) -> FloatArray:
    """``d[dp; dtheta]/dxi`` (6, 6N) of the tip pose (PoseWithCovariance convention in the base)
    from the tip's spatial twist ``[dv; dw]`` (:meth:`JointChain.jacobian`):
    ``dp = dv + dw x p``, ``dtheta = dw``."""
    twist = chain.jacobian(xi)
    out = np.empty_like(twist)
    out[:3] = twist[:3] - hat3(tip[:3, 3]) @ twist[3:]
    out[3:] = twist[3:]
    return out


def _tangent(Jc: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Orthonormal bases of the range (Q1) and null space (Q2) of ``Jc^T`` and ``R`` with
    ``Jc^T = Q1 R`` (complete QR)."""
    m = Jc.shape[0]
    Q, R = np.linalg.qr(Jc.T, mode='complete')
    return Q[:, :m], Q[:, m:], R[:m]


def _constrained_gauss_newton(problem: _ChainProblem, z0: FloatArray, max_iterations: int,
                              tolerance: float) -> tuple[FloatArray, Any, int, bool, str]:
    """Levenberg-Marquardt on the measurements over the equilibria (a manifold of dimension 6):
    each step lies in the tangent (the null space of dc/dz) and is followed by Newton's
    restoration onto the equilibria (:meth:`_ChainProblem.restore`); a step is kept when the
    restored point lowers the cost. Converged when the decrement is below ``tolerance``.
    Returns (z, (r, J, c, dc/dz, state), iterations, converged, message)."""
    restored = problem.restore(z0)
    if restored is None:
        return z0, None, 0, False, ('no equilibrium of the chain near the initial screws and '
                                    'tip load')
    z, c, Jc, state = restored
    r, J = problem.measurements(z, state)
    cost = float(r @ r)
    damping = 0.0
    for it in range(1, max_iterations + 1):
        _, Q2, _ = _tangent(Jc)
        M = J @ Q2
        A = M.T @ M
        g = M.T @ r
        try:
            full = -np.linalg.solve(A, g)
        except np.linalg.LinAlgError:
            return z, (r, J, c, Jc, state), it - 1, False, SINGULAR_NORMAL_MATRIX
        if float(-g @ full) < tolerance:
            return z, (r, J, c, Jc, state), it - 1, True, ''
        while True:
            y = full if damping == 0.0 else -np.linalg.solve(A + damping * np.diag(np.diag(A)), g)
            step = Q2 @ y
            for i in range(problem.n):
                step[6 * i:6 * i + 6] = _clip(step[6 * i:6 * i + 6], problem.length_scale)
            trial = problem.restore(z + step)
            if trial is not None:
                trial_r, trial_J = problem.measurements(trial[0], trial[3])
                trial_cost = float(trial_r @ trial_r)
                if trial_cost <= cost:
                    stalled = cost - trial_cost <= STALL_TOLERANCE * max(cost, 1.0)
                    z, c, Jc, state = trial
                    r, J, cost = trial_r, trial_J, trial_cost
                    if stalled:  # see _gauss_newton
                        return z, (r, J, c, Jc, state), it, True, ''
                    damping = 0.0 if damping <= INITIAL_DAMPING else damping / DAMPING_GROWTH
                    break
            damping = INITIAL_DAMPING if damping == 0.0 else damping * DAMPING_GROWTH
            if damping > MAX_DAMPING:  # a minimum (see _gauss_newton)
                return z, (r, J, c, Jc, state), it, True, ''
    return z, (r, J, c, Jc, state), max_iterations, False, (
        f'not converged in {max_iterations} iterations')


def _chain_information(problem: _ChainProblem, J: FloatArray, Jc: FloatArray,
                       rank_tolerance: float) -> tuple[FloatArray, int, float, FloatArray]:
    """Covariance of z (size, size) on the equilibria, ``Q2 (M^T M)^-1 Q2^T`` with
    ``M = J Q2``, the rank (of 6: the equilibria leave 6 directions, those of the load), the
    condition number and the scaled null directions (rows, in z) when rank < 6."""
    scale = problem.scale
    _, Q2, _ = _tangent(Jc * scale)  # the tangent in scaled coordinates
    M = (J * scale) @ Q2
    k = Q2.shape[1]
    Ms = M if M.shape[0] >= k else np.vstack([M, np.zeros((k - M.shape[0], k))])
    _, s, Vt = np.linalg.svd(Ms)
    rank = int(np.sum(s > rank_tolerance * s[0])) if s.size and s[0] > 0 else 0
    cond = float(s[0] / s[-1]) if s.size and s[-1] > 0 else math.inf
    if rank < k:
        return _nan(problem.size, problem.size), rank, cond, (Q2 @ Vt[rank:].T).T * scale
    C = Q2 @ np.linalg.inv(M.T @ M) @ Q2.T
    C = C * np.outer(scale, scale)
    return 0.5 * (C + C.T), rank, cond, np.empty((0, problem.size))


def _chainmissing_message(null: FloatArray, n: int, inputs: str, rank: int) -> str:
    weight = np.zeros(n + 1)
    for v in null:
        weight += np.sqrt(np.sum(v.reshape(n + 1, 6) ** 2, axis=1))
    involved = [f'joint {i + 1}' for i in range(n) if weight[i] > 0.1 * weight.max()]
    if weight[n] > 0.1 * weight.max():
        involved.append('the tip load')
    return (f'{inputs}: with the equilibria they determine only {rank} of the 6 remaining '
            f'unknowns (the tip load, or the configuration it implies); undetermined: '
            f'{", ".join(involved)}. Add string tensions or lengths on those joints, a joint or '
            f'tip pose, or the tip load (tip_wrench)')


def estimate_chain_state(chain: JointChain,
                         joint_measurements: Sequence[Measurements | None],
                         tip_pose: ArrayLike | None = None,
                         tip_pose_covariance: ArrayLike | None = None,
                         tip_wrench: ArrayLike | None = None,
                         tip_wrench_covariance: ArrayLike | None = None,
                         gravity: ArrayLike | None = None, *,
                         rest_lengths: Any = None,
                         initial_screws: ArrayLike | None = None,
                         initial_tip_wrench: ArrayLike | None = None,
                         tolerance: float = DECREMENT_TOLERANCE,
                         max_iterations: int = MAX_ITERATIONS,
                         rank_tolerance: float = RANK_TOLERANCE,
                         stiffness_std: bool = True,
                         consistency_probability: float = CONSISTENCY_PROBABILITY,
                         reject_outliers: bool = True) -> ChainEstimate:
    """Every joint's screw, the tip load, the tip pose and the exact tip stiffness of a spine,
    each with its covariance.

    ``joint_measurements``: one :class:`Measurements` (or None) per joint with its strings'
    tensions / lengths and optionally the joint's own pose (of {2}_i in {1}_i). The load is the
    spine's: ``tip_wrench`` (6,) in the base about its origin with ``tip_wrench_covariance``, or
    None for an unknown tip load, shared by every joint's equilibrium (which is what makes a few
    load cells per vertebra enough). The equilibria ``F_i + Ad_{P_i}^T B_i = 0`` are exact
    constraints (null-space Gauss-Newton), so 6 unknowns remain whatever N: the tip load (or
    the configuration it implies). ``tip_pose`` (the tool frame in the base, (4, 4) or 7
    values) with ``tip_pose_covariance`` (6, 6, PoseWithCovariance convention). ``gravity``
    (3,) for the link weights (default ``chain.gravity``). ``initial_screws`` (N, 6) and
    ``initial_tip_wrench`` warm-start (default: the unloaded screws and the known load or
    zero). Trust as :func:`estimate_joint_state`'s: impossible readings left out, a lost warm
    start restarted cold, contradicted readings left out while redundancy remains.
    """
    inputs = _chain_inputs(chain, joint_measurements, tip_pose, tip_pose_covariance, tip_wrench,
                           tip_wrench_covariance, gravity, rest_lengths, initial_screws,
                           initial_tip_wrench, consistency_probability)
    dropped = inputs.dropped
    measured = _measured_dof(inputs.preps, inputs.tip)
    if measured < 6:
        return _failed_chain(
            f'{inputs.text}: {measured} measured degrees of freedom cannot determine the 6 '
            'unknowns left by the equilibria (the tip load). Add string tensions or lengths, a '
            'pose, or the tip load (tip_wrench)', chain.n_joints, measured, dropped, False,
            measured, math.inf)
    fitter = _ChainFitter(chain, inputs, tolerance, max_iterations, rank_tolerance,
                          consistency_probability)
    fit, restarted = fitter.tracked(inputs.preps, inputs.tip, inputs.z0,
                                    initial_screws is not None)
    if reject_outliers:
        fit, restarted = _reject_contradicted(fit, restarted, dropped, consistency_probability,
                                              fitter.readings, fitter.refit_without)
    return _chain_estimate(chain, inputs, fit, restarted, dropped, stiffness_std,
                           consistency_probability)


def _measured_dof(preps: list[PreparedMeasurements | None], tip: frozenset[str]) -> int:
    """The degrees of freedom measured by the joints' readings ``preps`` and the tip's ``tip``."""
    return sum(p.dof for p in preps if p is not None) + 6 * len(tip)


@dataclass
class _ChainInputs:
    """The checked inputs of :func:`estimate_chain_state`: each joint's prepared readings
    (impossible ones left out, named in ``dropped``), the gravity, the rest lengths, the tip's
    readings with their whiteners, the starting point ``z0 = [xi_1 .. xi_N, W]`` and ``text``
    naming the inputs for messages."""

    preps: list[PreparedMeasurements | None]
    dropped: list[tuple[str, str]]
    gravity: FloatArray
    rest: list[FloatArray | None]
    tip_pose: FloatArray | None
    tip_pose_whitener: FloatArray | None
    tip_wrench: FloatArray | None
    tip_wrench_whitener: FloatArray | None
    z0: FloatArray
    text: str

    @property
    def tip(self) -> frozenset[str]:
        """The tip's readings present (``pose``, ``wrench``)."""
        return frozenset(name for name, value in (('pose', self.tip_pose),
                                                  ('wrench', self.tip_wrench))
                         if value is not None)


def _chain_preps(chain: JointChain, joint_measurements: Sequence[Measurements | None]
                 ) -> list[PreparedMeasurements | None]:
    """Each joint's readings prepared (None: none); ValueError naming the joint's entry."""
    n = chain.n_joints
    if len(joint_measurements) != n:
        raise ValueError(f'joint_measurements must hold one entry per joint ({n}), '
                         f'got {len(joint_measurements)}')
    preps: list[PreparedMeasurements | None] = []
    for i, (model, m) in enumerate(zip(chain.joints, joint_measurements, strict=True)):
        if m is None:
            preps.append(None)
            continue
        if m.external_wrench is not None or m.gravity is not None:
            raise ValueError(f'joint_measurements[{i}]: a spine takes its load as tip_wrench '
                             'and gravity as gravity (per-joint external_wrench / gravity are '
                             'not supported)')
        try:
            preps.append(m.prepared(model.n_strings))
        except ValueError as exc:
            raise ValueError(f'joint_measurements[{i}].{exc}') from None
    return preps


def _drop_impossible(chain: JointChain, preps: list[PreparedMeasurements | None],
                     rest: list[FloatArray | None]) -> list[tuple[str, str]]:
    """Leaves the impossible readings out of ``preps`` (in place); returns them as
    (``joint <i> <reading>``, why)."""
    dropped: list[tuple[str, str]] = []
    for i, (model, p) in enumerate(zip(chain.joints, preps, strict=True)):
        if p is not None:
            bad = p.impossible(model, model.validate_rest_lengths(rest[i], False))
            if bad:
                preps[i] = p.without([name for name, _ in bad], model.string_names)
                dropped += [(f'joint {i + 1} {name}', why) for name, why in bad]
    return dropped


def _chain_inputs(chain: JointChain, joint_measurements: Sequence[Measurements | None],
                  tip_pose: ArrayLike | None, tip_pose_covariance: ArrayLike | None,
                  tip_wrench: ArrayLike | None, tip_wrench_covariance: ArrayLike | None,
                  gravity: ArrayLike | None, rest_lengths: Any,
                  initial_screws: ArrayLike | None, initial_tip_wrench: ArrayLike | None,
                  consistency_probability: float) -> _ChainInputs:
    """The arguments of :func:`estimate_chain_state` checked (ValueError naming the argument)
    and prepared, impossible readings left out."""
    preps = _chain_preps(chain, joint_measurements)
    consistency_threshold(1, consistency_probability)  # checks the probability
    g = chain.resolved_gravity(gravity)
    rest = chain.rest_lengths_per_joint(rest_lengths)
    dropped = _drop_impossible(chain, preps, rest)
    pose_T = pose_whitener = None
    if tip_pose is not None:
        pose_T = rigid_transform(tip_pose, 'tip_pose')
        _, pose_whitener = _covariance('tip_pose_covariance', tip_pose_covariance, 6)
    W_m = W_whitener = None
    if tip_wrench is not None:
        W_m = finite_array('tip_wrench', tip_wrench)
        if W_m.shape != (6,):
            raise ValueError(f'tip_wrench must have shape (6,), got {W_m.shape}')
        _, W_whitener = _covariance('tip_wrench_covariance', tip_wrench_covariance, 6)
    x0 = (chain.unloaded_screws(rest) if initial_screws is None
          else chain.validated_screws(initial_screws).copy())
    if initial_tip_wrench is None:
        W0 = W_m.copy() if W_m is not None else np.zeros(6)
    else:
        W0 = finite_array('initial_tip_wrench', initial_tip_wrench)
        if W0.shape != (6,):
            raise ValueError(f'initial_tip_wrench must have shape (6,), got {W0.shape}')
    names = [f'joint {i + 1}: {p.describe(model.string_names, load=False)}'
             for i, (model, p) in enumerate(zip(chain.joints, preps, strict=True))
             if p is not None and p.rows]
    if pose_T is not None:
        names.append('a tip pose')
    names.append('a known tip load' if W_m is not None else 'unknown tip load')
    return _ChainInputs(preps, dropped, g, rest, pose_T, pose_whitener, W_m, W_whitener,
                        np.concatenate([x0.reshape(-1), W0]), '; '.join(names))


@dataclass
class _ChainFit(_Fit):
    """One constrained fit of a spine's readings (``preps`` of the joints, ``tip`` of the tip)
    and its information (``C``, ``rank``, ``cond``, the null directions ``null``) when it
    reached the equilibria (``ev`` not None)."""

    problem: _ChainProblem
    preps: list[PreparedMeasurements | None]
    tip: frozenset[str]
    z: FloatArray
    ev: Any
    iterations: int
    converged: bool
    why: str
    rank: int = 0
    cond: float = math.inf
    C: FloatArray = field(default_factory=lambda: _nan(0, 0))
    null: FloatArray = field(default_factory=lambda: _nan(0, 0))

    @property
    def r(self) -> FloatArray:  # type: ignore[override]
        return self.ev[0]

    @property
    def J(self) -> FloatArray:  # type: ignore[override]
        return self.ev[1]

    @property
    def chi2(self) -> float:
        return math.inf if self.ev is None else float(self.ev[0] @ self.ev[0])

    @property
    def redundancy(self) -> int:
        return _measured_dof(self.preps, self.tip) - 6


@dataclass
class _ChainFitter:
    """A spine's fits with one set of inputs and solver settings: :meth:`fit` from a start,
    :meth:`tracked` (restarted cold when a warm start lost track), :meth:`readings` (the
    named rows of a fit's residual) and :meth:`refit_without` a reading."""

    chain: JointChain
    inputs: _ChainInputs
    tolerance: float
    max_iterations: int
    rank_tolerance: float
    probability: float

    def fit(self, preps: list[PreparedMeasurements | None], tip: frozenset[str],
            z0: FloatArray) -> _ChainFit:
        """The readings ``preps`` and ``tip`` fitted from ``z0``
        (:func:`_constrained_gauss_newton`)."""
        inputs = self.inputs
        problem = _ChainProblem(self.chain, preps, inputs.rest, inputs.gravity,
                                inputs.tip_pose if 'pose' in tip else None,
                                inputs.tip_pose_whitener,
                                inputs.tip_wrench if 'wrench' in tip else None,
                                inputs.tip_wrench_whitener)
        z, ev, iterations, converged, why = _constrained_gauss_newton(
            problem, z0, self.max_iterations, self.tolerance)
        out = _ChainFit(problem, preps, tip, z, ev, iterations, converged, why)
        if ev is not None:
            out.C, out.rank, out.cond, out.null = _chain_information(problem, ev[1], ev[3],
                                                                     self.rank_tolerance)
        return out

    def tracked(self, preps: list[PreparedMeasurements | None], tip: frozenset[str],
                z0: FloatArray, warm: bool) -> tuple[_ChainFit, bool]:
        """The fit from ``z0`` and whether it was restarted: a ``warm`` start that fails or is
        inconsistent is fitted again from the cold start (the unloaded screws, the known tip
        load or zero), kept when better."""
        first = self.fit(preps, tip, z0)
        if not warm or first.on_track(self.probability):
            return first, False
        inputs = self.inputs
        W_cold = inputs.tip_wrench.copy() if 'wrench' in tip else np.zeros(6)
        cold = self.fit(preps, tip, np.concatenate(
            [self.chain.unloaded_screws(inputs.rest).reshape(-1), W_cold]))
        return (cold, True) if _better(cold, first) else (first, False)

    def readings(self, fit: _ChainFit) -> list[tuple[str, NDArray[np.intp], int]]:
        """The readings of ``fit`` (name, rows of the residual, degrees of freedom): each
        joint's as ``joint <i> <reading>``, then the tip's ``pose`` and ``wrench``."""
        out: list[tuple[str, NDArray[np.intp], int]] = []
        row = 0
        for i, (model, p) in enumerate(zip(self.chain.joints, fit.preps, strict=True)):
            if p is None or not p.rows:
                continue
            out += [(f'joint {i + 1} {name}', rows + row, dof)
                    for name, rows, dof in p.readings(model.string_names)]
            row += p.rows
        for name in ('pose', 'wrench'):
            if name in fit.tip:
                out.append((name, np.arange(row, row + 6), 6))
                row += 6
        return out

    def refit_without(self, fit: _ChainFit, name: str) -> tuple[_ChainFit, bool]:
        """The readings of ``fit`` without ``name`` (of :meth:`readings`) fitted again from
        its estimate (a warm start): the tip pose, the tip load (which becomes unknown) or a
        joint's reading."""
        reduced, kept = list(fit.preps), fit.tip
        if name in kept:
            kept = kept - {name}
        else:
            joint, _, reading = name.partition(' ')[2].partition(' ')
            i = int(joint) - 1
            reduced[i] = reduced[i].without([reading], self.chain.joints[i].string_names)
        return self.tracked(reduced, kept, fit.z, True)


def _failed_chain(message: str, n: int, measured: int, dropped: Sequence[tuple[str, str]],
                  observable: bool, rank: int, cond: float, iterations: int = 0
                  ) -> ChainEstimate:
    return ChainEstimate(False, message, _nan(n, 6), _nan(6 * n, 6 * n), _nan(n, 6, 6),
                         _nan(6), _nan(6, 6), _nan(4, 4), _nan(6, 6), _nan(6, 6),
                         _nan(6, 6), math.nan, measured - 6, observable, rank, cond,
                         iterations, None, None, measured - 6,
                         *_outlier_fields(dropped))


def _chain_estimate(chain: JointChain, inputs: _ChainInputs, fit: _ChainFit, restarted: bool,
                    dropped: Sequence[tuple[str, str]], stiffness_std: bool,
                    probability: float) -> ChainEstimate:
    """The :class:`ChainEstimate` of the last fit: a failure naming what is missing or why it
    did not converge, else the screws, the tip load, pose and stiffness with covariances."""
    n = chain.n_joints
    measured = _measured_dof(fit.preps, fit.tip)
    z, ev, iterations = fit.z, fit.ev, fit.iterations
    if ev is None:
        return _failed_chain(f'{inputs.text}: {fit.why}', n, measured, dropped, True, 0,
                             math.inf, iterations)
    r, _, _, _, state = ev
    C, rank, cond = fit.C, fit.rank, fit.cond
    if rank < 6:
        return _failed_chain(_chainmissing_message(fit.null, n, inputs.text, rank), n,
                             measured, dropped, False, rank, cond, iterations)
    if not fit.converged:
        return _failed_chain(f'{inputs.text}: {fit.why}', n, measured, dropped, True, rank,
                             cond, iterations)
    g, rest = inputs.gravity, inputs.rest
    xi = z[:6 * n].reshape(n, 6)
    W = z[6 * n:]
    joint_cov = np.empty((n, 6, 6))
    for i in range(n):
        P = sm.pose_jacobian(xi[i])
        joint_cov[i] = P @ C[6 * i:6 * i + 6, 6 * i:6 * i + 6] @ P.T
    T_tip = state.tip_transform
    M = np.zeros((6, 6 * n + 6))
    M[:, :6 * n] = tip_pose_jacobian(chain, xi, T_tip)
    tip_cov = M @ C @ M.T
    K_tip = chain.tip_stiffness_from_state(state, W, g)
    K_tip_std = tip_stiffness_std(chain, z, C, g, rest) if stiffness_std else _nan(6, 6)
    return ChainEstimate(True, 'ok', xi.copy(), C[:6 * n, :6 * n], joint_cov, W.copy(),
                         C[6 * n:, 6 * n:], T_tip.copy(), 0.5 * (tip_cov + tip_cov.T), K_tip,
                         K_tip_std, float(r @ r), measured - 6, True, rank, cond, iterations,
                         state, fit.consistent(probability), measured - 6,
                         *_outlier_fields(dropped), restarted)


def tip_stiffness_std(chain: JointChain, z: FloatArray, C: FloatArray, g: FloatArray,
                       rest: Any) -> FloatArray:
    """First-order std (6, 6) of the exact tip stiffness: central differences of
    :meth:`JointChain.tip_stiffness` over ``z = [xi; W]`` propagated with ``C``."""
    n = chain.n_joints
    grads = np.empty((6, 6, z.size))
    for k in range(z.size):
        values = []
        for sign in (1.0, -1.0):
            zk = z.copy()
            zk[k] += sign * STIFFNESS_STEP
            values.append(chain.tip_stiffness(zk[:6 * n].reshape(n, 6), zk[6 * n:], g,
                                              rest_lengths=rest))
        grads[:, :, k] = (values[0] - values[1]) / (2.0 * STIFFNESS_STEP)
    return entry_std(grads, C)
