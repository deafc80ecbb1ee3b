"""Recordings of a structure for
:func:`~tensegrity_stiffness.estimation.structure_calibration.calibrate_structure`: the still
instants of a rosbag2 or CSV recording of the string lengths, load cells and motor encoders, as
calibration samples (no rclpy).

The reading is the joint's (:mod:`tensegrity_stiffness.recordings.calibration_recording`: the
same CSV columns, the same bag reader and alignment) with the structure twin's topics
(:data:`DEFAULT_TOPICS`, ``structure_sim_node``'s ``~/measured_rest_lengths``,
``~/measured_tensions``, ``~/measured_lengths``); the encoders take the place of the joint's
commanded rest lengths (``rest_length_j`` in a CSV). Every string needs its three readings.

Still rule (:func:`still_indices`): an instant is still when the instants of the ``window``
seconds centred on it (half before, half after: a recording is read whole) span at least half of
it and each of their lengths and encoders lies within ``max_speed * window`` (m) of the
instant's. Centred, so that an instant where the motors have just started (the encoders and
lengths within the tolerance still) is not still: the readings of a bag are aligned to the
latest of each topic, and there an encoder one message old would be a reading of the move.
One sample per hold: the last still instant of it (two still instants are of one hold when the
later's lengths and encoders lie within that tolerance of the earlier's), as the joint's rule
picks them.
"""

from __future__ import annotations

import math

import numpy as np

from tensegrity_stiffness.estimation.structure_calibration import StructureCalibrationSample
from tensegrity_stiffness.recordings.calibration_recording import (
    DEFAULT_MAX_SPEED,
    DEFAULT_WINDOW,
    Recording,
    RecordingError,
)

__all__ = ['DEFAULT_TOPICS', 'REQUIRED', 'samples', 'still_indices']

#: The structure twin's topics by signal (no pose or wrench: a structure's calibration does not
#: use them).
DEFAULT_TOPICS: dict[str, str | None] = {
    'pose': None,
    'wrench': None,
    'rest_lengths': '/structure_sim_node/measured_rest_lengths',
    'tensions': '/structure_sim_node/measured_tensions',
    'lengths': '/structure_sim_node/measured_lengths',
}
#: The signals a structure's recording must have besides the encoders (the rest lengths).
REQUIRED = ('tensions', 'lengths')


def _readings(recording: Recording) -> np.ndarray:
    """(M, 2n) the lengths and encoders of every instant (NaN where a length is missing)."""
    return np.concatenate([recording.lengths, recording.rest], axis=1)


def still_indices(recording: Recording, window: float = DEFAULT_WINDOW,
                  max_speed: float = DEFAULT_MAX_SPEED) -> list[int]:
    """Indices of the still instants with every reading, one per hold (module docstring)."""
    for name, value in (('window', window), ('max_speed', max_speed)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f'{name} must be finite and > 0, got {value}')
    t = recording.times
    z = _readings(recording)
    complete = np.isfinite(z).all(axis=1) & np.isfinite(recording.tensions).all(axis=1)
    tolerance = max_speed * window
    picked: list[int] = []
    for i in np.flatnonzero(complete):
        lo = int(np.searchsorted(t, t[i] - 0.5 * window, 'left'))
        hi = int(np.searchsorted(t, t[i] + 0.5 * window, 'right'))
        inside = np.arange(lo, hi)[complete[lo:hi]]
        if inside.size < 2 or t[inside[-1]] - t[inside[0]] < 0.5 * window:
            continue
        if np.max(np.abs(z[inside] - z[i])) > tolerance:
            continue
        if picked and np.max(np.abs(z[i] - z[picked[-1]])) <= tolerance:
            picked[-1] = int(i)
        else:
            picked.append(int(i))
    return picked


def samples(recording: Recording, window: float = DEFAULT_WINDOW,
            max_speed: float = DEFAULT_MAX_SPEED
            ) -> tuple[list[int], list[StructureCalibrationSample]]:
    """Indices and samples of the still instants (:func:`still_indices`); RecordingError when a
    string lacks a reading throughout or no instant is still."""
    for signal, values in (('lengths', recording.lengths), ('tensions', recording.tensions)):
        never = np.flatnonzero(~np.isfinite(values).any(axis=0)) if len(recording) else []
        if len(never):
            raise RecordingError(f'{recording.source}: no {signal} reading of string '
                                 f'{int(never[0])} (a structure is calibrated from every '
                                 "string's length, load cell and encoder)")
    indices = still_indices(recording, window, max_speed)
    if not indices:
        raise RecordingError(f'{recording.source}: no still instants among {len(recording)} '
                             '(every reading present and the lengths and encoders still for the '
                             'window; see --window, --max-speed)')
    return indices, [StructureCalibrationSample(recording.lengths[i].copy(),
                                                recording.tensions[i].copy(),
                                                recording.rest[i].copy()) for i in indices]
