"""Builders of ``diagnostic_msgs/DiagnosticStatus`` and ``DiagnosticArray``."""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from std_msgs.msg import Header

__all__ = [
    'FLOAT_DIGITS',
    'LEVELS',
    'diagnostic_array',
    'diagnostic_status',
    'format_value',
]

#: Level names accepted by :func:`diagnostic_status` and their ``DiagnosticStatus`` byte values.
LEVELS: dict[str, bytes] = {
    'OK': DiagnosticStatus.OK,
    'WARN': DiagnosticStatus.WARN,
    'ERROR': DiagnosticStatus.ERROR,
    'STALE': DiagnosticStatus.STALE,
}
_LEVEL_VALUES = {v: k for k, v in LEVELS.items()}

#: Significant digits of floats in diagnostic values.
FLOAT_DIGITS = 6


def _level_byte(level: str | int | bytes) -> bytes:
    if isinstance(level, bytes):
        if level not in _LEVEL_VALUES:
            raise ValueError(f'invalid diagnostic level {level!r}')
        return level
    if isinstance(level, str):
        try:
            return LEVELS[level.upper()]
        except KeyError:
            raise ValueError(
                f'invalid diagnostic level {level!r}, expected one of {sorted(LEVELS)}'
            ) from None
    if isinstance(level, (int, np.integer)) and not isinstance(level, bool):
        if not 0 <= int(level) <= 3:
            raise ValueError(f'invalid diagnostic level {int(level)}, expected 0..3')
        return bytes([int(level)])
    raise ValueError(f'invalid diagnostic level {level!r}')


def format_value(value: Any) -> str:
    """String form of a diagnostic value: floats with 6 significant digits, bools lower-case,
    arrays as space-separated lists in brackets, anything else through ``str``."""
    if isinstance(value, (bool, np.bool_)):
        return 'true' if value else 'false'
    if isinstance(value, (float, np.floating)):
        v = float(value)
        return str(v) if not math.isfinite(v) else f'{v:.{FLOAT_DIGITS}g}'
    if isinstance(value, np.ndarray) or (isinstance(value, Sequence)
                                         and not isinstance(value, (str, bytes))):
        return '[' + ' '.join(format_value(v) for v in value) + ']'
    return str(value)


def diagnostic_status(name: str, level: str | int | bytes, message: str,
                      values: Mapping[str, Any] | Iterable[tuple[str, Any]] = (),
                      hardware_id: str = '') -> DiagnosticStatus:
    """``DiagnosticStatus`` with key/value pairs formatted by :func:`format_value`.

    Parameters
    ----------
    name : status name, e.g. ``'tensegrity_stiffness: equilibrium'``.
    level : ``'OK' | 'WARN' | 'ERROR' | 'STALE'`` (any case), 0..3, or the message's byte value.
    message : one-line human-readable summary.
    values : mapping or (key, value) pairs, kept in the given order.
    hardware_id : optional hardware identifier.

    Raises
    ------
    ValueError
        On an unknown level.
    """
    items = values.items() if isinstance(values, Mapping) else values
    return DiagnosticStatus(
        level=_level_byte(level), name=str(name), message=str(message),
        hardware_id=str(hardware_id),
        values=[KeyValue(key=str(k), value=format_value(v)) for k, v in items])


def diagnostic_array(statuses: Iterable[DiagnosticStatus], stamp: Time,
                     frame_id: str = '') -> DiagnosticArray:
    """``DiagnosticArray`` (for ``/diagnostics``) holding ``statuses`` with the given stamp."""
    return DiagnosticArray(header=Header(stamp=stamp, frame_id=frame_id), status=list(statuses))
