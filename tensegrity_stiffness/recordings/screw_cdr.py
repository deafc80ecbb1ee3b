"""The CDR fast path of the bag command: the screws of plain ``Float64MultiArray`` messages read
straight from their serialized bytes (:func:`plain_screw_values`), without deserialising
each message.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]

# ------------------------------------------------------------------------------ screw CDR
#: Serialized ``Float64MultiArray`` of six values without layout dimensions, little-endian CDR:
#: encapsulation header, ``dim`` count 0, ``data_offset`` 0, ``data`` length 6, 4 padding bytes,
#: then the six float64 (the plain layout recorders write for a screw).
PLAIN_SCREW_HEAD = b'\x00\x01\x00\x00' + bytes(8) + (6).to_bytes(4, 'little')
_PLAIN_SCREW_DATA = 20
PLAIN_SCREW_SIZE = _PLAIN_SCREW_DATA + 8 * 6


def plain_screw_values(raws: Sequence[bytes]) -> FloatArray:
    """(N, 6) values of serialized screws of the plain layout (:data:`PLAIN_SCREW_SIZE` bytes
    starting with ``PLAIN_SCREW_HEAD``; the caller checks), read in one ``frombuffer``."""
    block = np.frombuffer(b''.join(raws), dtype=np.uint8).reshape(len(raws), PLAIN_SCREW_SIZE)
    return np.ascontiguousarray(block[:, _PLAIN_SCREW_DATA:]).view('<f8').astype(np.float64)
