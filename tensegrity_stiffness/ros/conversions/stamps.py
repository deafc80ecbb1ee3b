"""``builtin_interfaces/Time`` stamps <-> integer nanoseconds / float seconds.

In a node, prefer ``node.get_clock().now().to_msg()``; these helpers cover pure code and tests
(and stamps carried over from another source) without rclpy.
"""

from __future__ import annotations

import math

from builtin_interfaces.msg import Time

from tensegrity_stiffness.nodes.messages import (
    NANOSECONDS_PER_SECOND,
    stamp_nanoseconds,
    stamp_parts,
)

__all__ = [
    'NANOSECONDS_PER_SECOND',
    'stamp_from_nanoseconds',
    'stamp_from_seconds',
    'stamp_to_nanoseconds',
    'stamp_to_seconds',
]


def stamp_from_nanoseconds(nanoseconds: int) -> Time:
    """``Time`` of a non-negative integer count of nanoseconds (e.g. ``time.time_ns()``).

    Raises
    ------
    ValueError
        If negative or beyond the int32 seconds range of ``Time.sec``
        (:func:`tensegrity_stiffness.nodes.messages.stamp_parts`).
    """
    sec, nanosec = stamp_parts(nanoseconds)
    return Time(sec=sec, nanosec=nanosec)


def stamp_from_seconds(seconds: float) -> Time:
    """``Time`` of a non-negative finite float time in seconds (rounded to the nanosecond)."""
    t = float(seconds)
    if not math.isfinite(t):
        raise ValueError(f'stamp must be finite, got {t}')
    return stamp_from_nanoseconds(round(t * NANOSECONDS_PER_SECOND))


def stamp_to_nanoseconds(stamp: Time) -> int:
    """Integer nanoseconds of a ``Time`` (exact)."""
    return stamp_nanoseconds(stamp)


def stamp_to_seconds(stamp: Time) -> float:
    """Float seconds of a ``Time`` (nanosecond resolution is lost beyond ~2**53 ns)."""
    return int(stamp.sec) + int(stamp.nanosec) / NANOSECONDS_PER_SECOND
