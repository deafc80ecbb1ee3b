"""What one estimate reads (:class:`Measurements`) and the same readings checked once and made
ready for the fits (:class:`PreparedMeasurements`): the std and covariance of each reading, the
per-string readings, and the readings outside their physical range (:data:`IMPOSSIBLE_STD`).
The estimators' method is in :mod:`~tensegrity_stiffness.estimation.estimators`.
"""

from __future__ import annotations

import copy
import math
import weakref
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import (
    finite_array,
    finite_array_of_shape,
    per_string,
)
from tensegrity_stiffness.mechanics.joint import JointModel

FloatArray = NDArray[np.float64]

#: A reading more than this many of its std outside its physical range is impossible: a tension
#: below ``-IMPOSSIBLE_STD`` std or above what the string can carry (its tension at its maximum
#: length) plus as many, a length above the string's maximum length plus as many; for a string
#: without a maximum length, a tension or length more than ``IMPOSSIBLE_STD ** 6`` (15,625) std.
IMPOSSIBLE_STD = 5.0


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


def reading_covariance(name: str, value: Any, size: int) -> tuple[FloatArray, FloatArray]:
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

    For the recursive filter (:class:`~tensegrity_stiffness.estimation.joint_filter.JointFilter`;
    the static estimator does not read them): ``specific_force`` (3,) m/s^2 the accelerometer's raw
    specific force in {2} (acceleration minus gravity, modelled with the link's acceleration) with
    ``specific_force_std`` (m/s^2, a scalar or (3,)), and ``angular_velocity`` (3,) rad/s a gyro's
    reading of link 2's angular velocity in {2} with ``angular_velocity_std`` (rad/s, a scalar or
    (3,)).
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
            _, self.pose_whitener = reading_covariance('pose_covariance', m.pose_covariance, 6)
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
            self.wrench_covariance, self.wrench_whitener = reading_covariance(
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
