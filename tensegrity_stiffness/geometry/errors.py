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
    """A rejected input; ``kind`` names its kind (a subclass gives it in its class line:
    ``class WrongFrameError(InputError, kind='wrong frame_id')``)."""

    kind: ClassVar[str] = INVALID

    def __init_subclass__(cls, kind: str | None = None, **kwargs: object) -> None:
        super().__init_subclass__(**kwargs)
        if kind is not None:
            cls.kind = kind


class OversizedArrayError(InputError, kind='oversized array'):
    """An array message with more elements than allowed."""


class BadDataOffsetError(InputError, kind='bad data_offset'):
    """An array message whose ``layout.data_offset`` is past its data."""


class WrongLengthError(InputError, kind='wrong length'):
    """An array or a list with another number of values than expected."""


class OutsideChartError(InputError, kind='outside the chart'):
    """A screw with ``|omega| >= 2 pi`` (outside the chart of screw coordinates)."""


class WrongFrameError(InputError, kind='wrong frame_id'):
    """A ``header.frame_id`` that is not the expected frame."""


class BadQuaternionError(InputError, kind='bad quaternion'):
    """A quaternion that is not finite, zero or not of unit norm."""


class BadRestLengthsError(InputError, kind='bad rest lengths'):
    """Rest lengths that are not finite, positive or of the right shape."""


class NotFiniteError(InputError, kind='NaN or inf'):
    """An array containing NaN or inf."""


class SingularStiffnessError(InputError, kind='singular tip stiffness'):
    """A stiffness matrix that cannot be inverted at the configuration."""


def error_kind(exc: BaseException) -> str:
    """``exc.kind`` of an :class:`InputError`, :data:`INVALID` for any other exception."""
    return exc.kind if isinstance(exc, InputError) else INVALID


def in_context(exc: ValueError, prefix: str) -> ValueError:
    """A ValueError of ``exc``'s kind whose text is ``'<prefix>: <exc>'`` (to raise ``from
    None`` where a check names the part it rejects, e.g. a joint)."""
    cls = type(exc) if isinstance(exc, InputError) else ValueError
    return cls(f'{prefix}: {exc}')
