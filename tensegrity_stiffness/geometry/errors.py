"""Typed input errors: ValueError subclasses whose ``kind`` names the kind of problem.

Raised where a problem is found (array checks, the chart, frames, quaternions, rest lengths)
and read by whoever counts rejections by kind (the bag command); every ``except ValueError``
catches them. The message is the same text a plain ValueError had. Free of imports, so every
layer may raise them.
"""

from __future__ import annotations

from typing import ClassVar

#: Kind of a ValueError that is not an :class:`InputError`.
INVALID = 'invalid'


class InputError(ValueError):
    """A rejected input; ``kind`` names its kind (the subclass's)."""

    kind: ClassVar[str] = INVALID


class OversizedArrayError(InputError):
    """An array message with more elements than allowed."""

    kind = 'oversized array'


class BadDataOffsetError(InputError):
    """An array message whose ``layout.data_offset`` is past its data."""

    kind = 'bad data_offset'


class WrongLengthError(InputError):
    """An array or a list with another number of values than expected."""

    kind = 'wrong length'


class OutsideChartError(InputError):
    """A screw with ``|omega| >= 2 pi`` (outside the chart of screw coordinates)."""

    kind = 'outside the chart'


class WrongFrameError(InputError):
    """A ``header.frame_id`` that is not the expected frame."""

    kind = 'wrong frame_id'


class BadQuaternionError(InputError):
    """A quaternion that is not finite, zero or not of unit norm."""

    kind = 'bad quaternion'


class BadRestLengthsError(InputError):
    """Rest lengths that are not finite, positive or of the right shape."""

    kind = 'bad rest lengths'


class NotFiniteError(InputError):
    """An array containing NaN or inf."""

    kind = 'NaN or inf'


class SingularStiffnessError(InputError):
    """A stiffness matrix that cannot be inverted at the configuration."""

    kind = 'singular tip stiffness'


def error_kind(exc: BaseException) -> str:
    """``exc.kind`` of an :class:`InputError`, :data:`INVALID` for any other exception."""
    return exc.kind if isinstance(exc, InputError) else INVALID


def in_context(exc: ValueError, prefix: str) -> ValueError:
    """A ValueError of ``exc``'s kind whose text is ``'<prefix>: <exc>'`` (to raise ``from
    None`` where a check names the part it rejects, e.g. a joint)."""
    cls = type(exc) if isinstance(exc, InputError) else ValueError
    return cls(f'{prefix}: {exc}')
