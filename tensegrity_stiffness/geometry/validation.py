"""Input validation shared by the library: ValueError messages that name the field (typed
:mod:`.errors` where the kind of problem is known)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import NotFiniteError, WrongFrameError


def finite_scalar(name: str, value: float) -> float:
    """``float(value)``, or ValueError naming ``name`` when it is not a finite number."""
    try:
        v = float(value)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{name} must be a finite number: {exc}') from None
    if not math.isfinite(v):
        raise NotFiniteError(f'{name} must be finite, got {v}')
    return v


def positive_number(name: str, value: Any, allow_zero: bool = False,
                    allow_inf: bool = False) -> None:
    """ValueError naming ``name`` unless ``value`` is a real number (not a bool) > 0 (>= 0 with
    ``allow_zero``), finite or, with ``allow_inf``, inf: an option of the twins."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and \
        (math.isfinite(value) or (allow_inf and value == math.inf)) and \
        (value >= 0.0 if allow_zero else value > 0.0)
    if not ok:
        bound = ('>= 0' if allow_zero else '> 0') + (' or inf' if allow_inf else '')
        raise ValueError(f'{name} must be a finite number {bound}, got {value!r}')


def positive_interval(name: str, value: ArrayLike) -> tuple[float, float]:
    """``(min, max)`` of ``value`` with 0 < min < max; ValueError naming ``name`` otherwise (a
    range of the twins' rest lengths, m)."""
    bounds = finite_array(name, value)
    if bounds.shape != (2,) or not 0.0 < bounds[0] < bounds[1]:
        raise ValueError(f'{name} must be (min, max) with 0 < min < max (m), got {value!r}')
    return float(bounds[0]), float(bounds[1])


def _as_float_array(name: str, value: ArrayLike) -> NDArray[np.float64]:
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ValueError(f'{name} must be numeric: {exc}') from None


def finite_array(name: str, value: ArrayLike) -> NDArray[np.float64]:
    """``np.asarray(value, float64)``; ValueError naming ``name`` if an entry is not finite."""
    a = _as_float_array(name, value)
    if not np.isfinite(a).all():
        raise NotFiniteError(f'{name} must be finite, got {a[~np.isfinite(a)].ravel()[0]}')
    return a


def finite_array_of_shape(name: str, value: ArrayLike, shape: tuple[int, ...] | None
                          ) -> NDArray[np.float64]:
    """``np.asarray(value, float64)`` of exactly ``shape`` (None: any shape); ValueError naming
    ``name`` when it is not numeric, has another shape or contains NaN or inf."""
    arr = _as_float_array(name, value)
    if shape is not None and arr.shape != shape:
        raise ValueError(f'{name} must have shape {shape}, got {arr.shape}')
    if not np.isfinite(arr).all():
        raise NotFiniteError(f'{name} contains NaN or inf')
    return arr


def per_string(name: str, value: ArrayLike | None, n: int | None, *, repeat_one: bool = False,
               not_measured: bool = False, finite: bool = True) -> NDArray[np.float64]:
    """One value per string: ``n`` finite values (flattened, float64), or ValueError naming
    ``name``. The one check of per-string arrays (rest lengths, stiffnesses, limits, readings).

    ``repeat_one``: a single value is given to every string. ``not_measured``: NaN marks a
    string that is not measured (inf is still refused) and None is every string unmeasured.
    ``n`` None: a scalar or one value per string of any count, kept as given (the caller
    checks the count once it knows it). ``finite`` False: the values are not looked at (the
    caller checks them, e.g. a config's ``max_lengths`` where inf is no limit)."""
    if value is None and not_measured and n is not None:
        return np.full(n, np.nan)
    arr = _as_float_array(name, value)
    if n is None:
        if arr.ndim > 1:
            raise ValueError(f'{name} must be a scalar or one value per string, got shape '
                             f'{arr.shape}')
        arr = arr.copy()
    else:
        arr = arr.ravel()
        if repeat_one and arr.size == 1:
            arr = np.full(n, arr[0])
        if arr.size != n:
            unmeasured = ', NaN = not measured' if not_measured else ''
            or_one = ' (or one value for all)' if repeat_one else ''
            raise ValueError(f'{name} must have {n} values (one per string{unmeasured}), '
                             f'got {arr.size}{or_one}')
    if not finite:
        return arr
    bad = np.isinf(arr) if not_measured else ~np.isfinite(arr)
    if bad.any():
        where = f' at string {int(np.flatnonzero(bad)[0])}' if arr.ndim else ''
        allowed = ' or NaN (not measured)' if not_measured else ''
        raise NotFiniteError(f'{name} must be finite{allowed}, got {arr[bad].ravel()[0]}{where}')
    return arr


def optional_vector(name: str, value: ArrayLike | None, size: int = 6) -> NDArray[np.float64]:
    """A finite ``(size,)`` array (a wrench, a screw rate), zeros when ``value`` is None;
    ValueError naming ``name`` when an entry is not finite or the shape is another."""
    if value is None:
        return np.zeros(size)
    arr = finite_array(name, value)
    if arr.shape != (size,):
        raise ValueError(f'{name} must have shape ({size},), got {arr.shape}')
    return arr


def require_all_finite(names: Sequence[str], arrays: Sequence[NDArray[np.float64]]) -> None:
    """ValueError ``'<name> contains NaN or inf'`` for the first of ``arrays`` that is not finite
    (an input gets all of its outputs or none). One sum over all of them on the common, finite
    path (a sum that overflows is looked at array by array)."""
    if not arrays:
        return
    with np.errstate(all='ignore'):
        total = float(np.concatenate([a.reshape(-1) for a in arrays]).sum())
    if math.isfinite(total):
        return
    for name, array in zip(names, arrays, strict=True):
        if not np.isfinite(array).all():
            raise NotFiniteError(f'{name} contains NaN or inf')


def require_frame(frame_id: str, expected: str, what: str) -> None:
    """An input's ``header.frame_id`` must be ``expected`` (``what`` names that frame, e.g.
    "the base frame"); empty means "in the expected frame". ValueError otherwise."""
    if frame_id and frame_id != expected:
        raise WrongFrameError(f"header.frame_id '{frame_id}' is not {what} '{expected}'")
