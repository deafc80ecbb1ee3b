"""Recordings for :mod:`tensegrity_stiffness.estimation.calibration`: reading a rosbag2 or a CSV
file into time series, and picking the quasi-static instants that become calibration samples.

No rclpy and no ROS message package: rosbag2 files (mcap or sqlite3) are read with ``rosbags``
(its own message types for ROS 2 Jazzy, read by attribute) with the bag command's input checks
and typestore (:mod:`tensegrity_stiffness.recordings.bag`) and the nodes' pose reader
(:func:`tensegrity_stiffness.nodes.messages.pose_message_to_transform`).

Bag topics (each optional except the rest lengths; a bag needs a pose, a wrench or tensions):

* pose: ``geometry_msgs/PoseStamped`` or ``PoseWithCovarianceStamped`` (link 2 in {1});
* rest lengths: ``std_msgs/Float64MultiArray`` (n commanded values, the node's
  ``~/rest_lengths``), held from their time on;
* tensions: ``std_msgs/Float64MultiArray`` (n values, NaN for a string without a load cell);
* wrench: ``geometry_msgs/WrenchStamped`` (on link 2, in {1} about its origin, [N; N m]);
* lengths: ``std_msgs/Float64MultiArray`` (n measured string lengths, m, NaN where none).

Times: a message's header stamp when it has a non-zero one, else its log time.

CSV columns (a header row; one row per instant; :data:`CSV_TIME` in seconds):
``time``; ``rest_length_0 .. rest_length_{n-1}`` (m, required); the pose ``x y z qx qy qz qw``
(m; optional); the wrench ``fx fy fz mx my mz`` (N, N m; optional, empty = unknown);
``tension_0 ..`` (N) and ``length_0 ..`` (m) (optional, empty or NaN = not measured). A
string's index is its position in the config.

Quasi-static rule (:func:`quasi_static_indices`): an instant with a pose is quasi-static when the
rest lengths have not changed for at least ``window`` seconds before it and every pose of that
window lies within ``max_speed * window`` (m) and ``max_angular_speed * window`` (rad) of the
instant's pose (the poses of the window must span at least half of it); without poses, when the
rest lengths have been held for ``window`` seconds. One sample per hold: the last quasi-static
instant of the hold (the most settled; one per hold, so that the samples' noise is independent).
A hold ends where the rest lengths change or link 2 moves: two quasi-static instants belong to
the same hold when the rest lengths did not change between them and the later pose lies within
``max_speed * window`` and ``max_angular_speed * window`` of the earlier (the tolerance of the
rule), whatever lies between them (a gap in the poses or a glitch only interrupts a run of
quasi-static instants, it does not start a new hold).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.estimation.calibration_samples import (
    RECORDED_ROTATION_TOLERANCE,
    CalibrationSample,
)
from tensegrity_stiffness.geometry.screw import log_so3_batch
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.nodes.estimator_node import measured_array
from tensegrity_stiffness.nodes.messages import (
    DEFAULT_MAX_LENGTH,
    multiarray_payload,
    multiarray_to_array,
    pose_message_to_transform,
    stamp_nanoseconds_or,
)
from tensegrity_stiffness.recordings.bag import check_input as check_bag_input
from tensegrity_stiffness.recordings.bag_topics import MessageReading, jazzy_typestore

FloatArray = NDArray[np.float64]

#: Default window (s) and speed limits of the quasi-static rule.
DEFAULT_WINDOW = 0.5
DEFAULT_MAX_SPEED = 2e-3            # m/s
DEFAULT_MAX_ANGULAR_SPEED = math.radians(2.0)  # rad/s
#: Rest lengths that differ by at most this (m) count as held.
REST_TOLERANCE = 1e-9
#: Default topics: the stiffness node's inputs and the measured signals in its namespace.
DEFAULT_TOPICS = {
    'pose': '/stiffness_node/pose',
    'rest_lengths': '/stiffness_node/rest_lengths',
    'tensions': '/stiffness_node/measured_tensions',
    'wrench': '/stiffness_node/measured_wrench',
    'lengths': '/stiffness_node/measured_lengths',
}
POSE_TYPES = ('geometry_msgs/msg/PoseStamped', 'geometry_msgs/msg/PoseWithCovarianceStamped')
ARRAY_TYPE = 'std_msgs/msg/Float64MultiArray'
WRENCH_TYPE = 'geometry_msgs/msg/WrenchStamped'
#: CSV column names.
CSV_TIME = 'time'
CSV_POSE = ('x', 'y', 'z', 'qx', 'qy', 'qz', 'qw')
CSV_WRENCH = ('fx', 'fy', 'fz', 'mx', 'my', 'mz')
CSV_REST = 'rest_length_{j}'
CSV_TENSION = 'tension_{j}'
CSV_LENGTH = 'length_{j}'


class RecordingError(ValueError):
    """A recording that cannot give calibration samples (the command's exit 2, one line)."""


@dataclass
class Recording:
    """Time series on a common clock (M instants, n strings): ``times`` (M,) s; ``rest`` (M, n)
    commanded rest lengths in force; ``poses`` (M, 4, 4), NaN where none; ``wrench`` (M, 6),
    NaN where unknown; ``tensions`` and ``lengths`` (M, n), NaN where not measured. ``source``
    names what was read; ``absent`` the signals whose (default) topic the bag does not have, or
    has no message on, by signal (``{'wrench': '/stiffness_node/measured_wrench'}``)."""

    times: FloatArray
    rest: FloatArray
    poses: FloatArray
    wrench: FloatArray
    tensions: FloatArray
    lengths: FloatArray
    source: str = ''
    absent: dict[str, str] = field(default_factory=dict)

    def __len__(self) -> int:
        return self.times.shape[0]

    def samples(self, indices: Sequence[int]) -> list[CalibrationSample]:
        """The instants ``indices`` as :class:`CalibrationSample`."""
        out = []
        for i in indices:
            pose = self.poses[i] if np.isfinite(self.poses[i]).all() else None
            tensions = self.tensions[i] if np.isfinite(self.tensions[i]).any() else None
            lengths = self.lengths[i] if np.isfinite(self.lengths[i]).any() else None
            wrench = self.wrench[i] if np.isfinite(self.wrench[i]).all() else None
            out.append(CalibrationSample(self.rest[i].copy(), pose=pose, tensions=tensions,
                                         lengths=lengths, external_wrench=wrench))
        return out


# ------------------------------------------------------------------------------ quasi-static
def quasi_static_indices(recording: Recording, window: float = DEFAULT_WINDOW,
                         max_speed: float = DEFAULT_MAX_SPEED,
                         max_angular_speed: float = DEFAULT_MAX_ANGULAR_SPEED) -> list[int]:
    """Indices of the quasi-static instants, one per hold (see the module docstring)."""
    for name, value in (('window', window), ('max_speed', max_speed),
                        ('max_angular_speed', max_angular_speed)):
        if not (math.isfinite(value) and value > 0.0):
            raise ValueError(f'{name} must be finite and > 0, got {value}')
    t = recording.times
    M = len(recording)
    if M == 0:
        return []
    changed = np.ones(M, bool)
    changed[1:] = np.max(np.abs(np.diff(recording.rest, axis=0)), axis=1) > REST_TOLERANCE
    last_change = t[np.maximum.accumulate(np.where(changed, np.arange(M), 0))]
    held = t - last_change >= window
    has_pose = np.isfinite(recording.poses).all(axis=(1, 2))
    quiet = held.copy()
    if has_pose.any():
        pose_idx = np.flatnonzero(has_pose)
        pose_t = t[pose_idx]
        quiet &= has_pose
        for i in np.flatnonzero(quiet):
            lo = int(np.searchsorted(pose_t, t[i] - window, 'left'))
            hi = int(np.searchsorted(pose_t, t[i], 'right'))
            inside = pose_idx[lo:hi]
            if inside.size < 2 or t[i] - t[inside[0]] < 0.5 * window:
                quiet[i] = False
                continue
            P = recording.poses[inside]
            B = recording.poses[i]
            drift = np.max(np.linalg.norm(P[:, :3, 3] - B[:3, 3], axis=1))
            turn = np.max(np.linalg.norm(log_so3_batch(P[:, :3, :3] @ B[:3, :3].T),
                                         axis=1))
            quiet[i] = drift <= max_speed * window and turn <= max_angular_speed * window
    # The last quiet instant of each hold (module docstring).
    picked: list[int] = []
    for i in np.flatnonzero(quiet):
        if picked and _same_hold(recording, changed, picked[-1], int(i), max_speed * window,
                                 max_angular_speed * window):
            picked[-1] = int(i)
        else:
            picked.append(int(i))
    return picked


def _same_hold(recording: Recording, changed: NDArray[np.bool_], a: int, b: int, distance: float,
               angle: float) -> bool:
    """Whether the quiet instants ``a < b`` are of one hold: no rest-length change after ``a``
    up to ``b``, and (with poses) link 2 within ``distance`` (m) and ``angle`` (rad) of where it
    was at ``a``."""
    if changed[a + 1:b + 1].any():
        return False
    A, B = recording.poses[a], recording.poses[b]
    if not (np.isfinite(A).all() and np.isfinite(B).all()):
        return True
    turn = float(np.linalg.norm(log_so3_batch((B[:3, :3] @ A[:3, :3].T)[None])[0]))
    return float(np.linalg.norm(B[:3, 3] - A[:3, 3])) <= distance and turn <= angle


# ------------------------------------------------------------------------------ CSV
def _csv_float(text: str, where: str) -> float:
    text = text.strip()
    if text == '' or text.lower() == 'nan':
        return math.nan
    try:
        return float(text)
    except ValueError:
        raise RecordingError(f'{where}: not a number: {text!r}') from None


def read_csv(path: str | Path, n_strings: int) -> Recording:
    """A :class:`Recording` from a CSV file with the documented columns (module docstring)."""
    path = Path(path)
    try:
        with path.open(newline='', encoding='utf-8') as handle:
            rows = list(csv.reader(handle))
    except OSError as exc:
        raise RecordingError(f'{path}: cannot read: {exc.strerror}') from None
    if not rows:
        raise RecordingError(f'{path}: empty file (expected a header row)')
    header = [h.strip() for h in rows[0]]
    column = {name: i for i, name in enumerate(header)}
    rest_cols = [CSV_REST.format(j=j) for j in range(n_strings)]
    missing = [c for c in [CSV_TIME, *rest_cols] if c not in column]
    if missing:
        raise RecordingError(f'{path}: missing columns {missing} (the config has {n_strings} '
                             'strings; see the documented columns)')
    has_pose = all(c in column for c in CSV_POSE)
    has_wrench = all(c in column for c in CSV_WRENCH)
    partial = [group for group, names in (('pose', CSV_POSE), ('wrench', CSV_WRENCH))
               if any(c in column for c in names) and not all(c in column for c in names)]
    if partial:
        raise RecordingError(f'{path}: incomplete {partial[0]} columns (need all of '
                             f'{CSV_POSE if partial[0] == "pose" else CSV_WRENCH})')
    data = rows[1:]
    M = len(data)
    rec = _empty(M, n_strings, str(path))
    for r, row in enumerate(data):
        where = f'{path}: row {r + 2}'
        if len(row) != len(header):
            raise RecordingError(f'{where}: {len(row)} fields, the header has {len(header)}')

        def get(name: str) -> float:
            return _csv_float(row[column[name]], f'{where}, column {name}')  # noqa: B023

        rec.times[r] = get(CSV_TIME)
        rec.rest[r] = [get(c) for c in rest_cols]
        if has_pose:
            values = np.array([get(c) for c in CSV_POSE])
            if np.isfinite(values).all():
                try:
                    rec.poses[r] = rigid_transform(values, f'{where}, pose',
                                                   RECORDED_ROTATION_TOLERANCE)
                except ValueError as exc:
                    raise RecordingError(str(exc)) from None
        if has_wrench:
            rec.wrench[r] = [get(c) for c in CSV_WRENCH]
        for j in range(n_strings):
            if CSV_TENSION.format(j=j) in column:
                rec.tensions[r, j] = get(CSV_TENSION.format(j=j))
            if CSV_LENGTH.format(j=j) in column:
                rec.lengths[r, j] = get(CSV_LENGTH.format(j=j))
    _check_times_and_rest(rec, str(path))
    return rec


def write_csv(path: str | Path, recording: Recording) -> None:
    """Write a :class:`Recording` in the documented CSV columns (a round trip of
    :func:`read_csv`)."""
    n = recording.rest.shape[1]
    header = [CSV_TIME, *(CSV_REST.format(j=j) for j in range(n)), *CSV_POSE, *CSV_WRENCH,
              *(CSV_TENSION.format(j=j) for j in range(n)),
              *(CSV_LENGTH.format(j=j) for j in range(n))]
    from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion

    with Path(path).open('w', newline='', encoding='utf-8') as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for i in range(len(recording)):
            T = recording.poses[i]
            pose = ([*T[:3, 3], *rotation_to_quaternion(T[:3, :3])] if np.isfinite(T).all()
                    else [math.nan] * 7)
            values = [recording.times[i], *recording.rest[i], *pose, *recording.wrench[i],
                      *recording.tensions[i], *recording.lengths[i]]
            writer.writerow(['' if not math.isfinite(v) else repr(float(v)) for v in values])


def _empty(M: int, n: int, source: str) -> Recording:
    return Recording(np.zeros(M), np.zeros((M, n)), np.full((M, 4, 4), np.nan),
                     np.full((M, 6), np.nan), np.full((M, n), np.nan), np.full((M, n), np.nan),
                     source)


def _check_times_and_rest(rec: Recording, source: str) -> None:
    if not np.isfinite(rec.times).all():
        raise RecordingError(f'{source}: every instant needs a finite time')
    if np.any(np.diff(rec.times) < 0.0):
        raise RecordingError(f'{source}: times must not decrease')
    bad = ~np.isfinite(rec.rest).all(axis=1) | np.any(rec.rest <= 0.0, axis=1)
    if bad.any():
        raise RecordingError(f'{source}: instant {int(np.flatnonzero(bad)[0])} has no valid '
                             'rest lengths (finite, > 0, one per string)')


# ------------------------------------------------------------------------------ rosbag2
def _stamp_seconds(msg: Any, log_time: int) -> float:
    header = getattr(msg, 'header', None)
    ns = log_time if header is None else stamp_nanoseconds_or(header.stamp, log_time)
    return ns * 1e-9


def _wrench_of(msg: Any) -> FloatArray:
    f, m = msg.wrench.force, msg.wrench.torque
    values = np.array([f.x, f.y, f.z, m.x, m.y, m.z], dtype=np.float64)
    if not np.isfinite(values).all():
        raise ValueError('wrench is not finite')
    return values


def read_bag(path: str | Path, n_strings: int, topics: dict[str, str | None] | None = None,
             required: Sequence[str] = (), max_age: float = 0.1,
             progress: Callable[[int, int], None] | None = None,
             allow_damaged: bool = False) -> Recording:
    """A :class:`Recording` from a rosbag2 (mcap or sqlite3) folder or file: one instant per
    pose message (else per tensions, wrench or lengths message), with the rest lengths in
    force then and the latest tensions, wrench and lengths no older than ``max_age`` s.

    ``topics`` maps ``pose``, ``rest_lengths``, ``tensions``, ``wrench``, ``lengths`` to topic
    names (default :data:`DEFAULT_TOPICS`; None leaves a signal out); ``required``: the signals
    whose topic must be in the bag (else :class:`RecordingError` naming it); the rest lengths
    always are. Messages that cannot be decoded or have the wrong size are skipped and counted
    (``recording.source`` says how many). A bag whose storage stops being readable part way
    raises :class:`~tensegrity_stiffness.recordings.bag.DamagedBagError` saying how much was
    read, unless ``allow_damaged`` (then ``recording.source`` says it).
    """
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError


    path = Path(path)
    check_bag_input(path)
    wanted = dict(DEFAULT_TOPICS)
    wanted.update(topics or {})
    try:
        reader = Reader(path)
        reader.open()
    except (ReaderError, OSError, KeyError, ValueError) as exc:
        raise RecordingError(f'{path}: not a readable rosbag2: {exc}') from None
    deserialize = jazzy_typestore().deserialize_cdr
    try:
        use, absent = _bag_topics(path, {c.topic: c.msgtype for c in reader.connections},
                                  wanted, required)
        series, skipped, reading = _read_series(reader, deserialize, use, n_strings, progress)
    finally:
        reader.close()
    reading.check(path, allow_damaged)
    return _bag_recording(path, series, use, absent, required, skipped, n_strings, max_age,
                          reading.summary())


#: The message types a signal's topic may have.
_SIGNAL_TYPES = {'pose': POSE_TYPES, 'rest_lengths': (ARRAY_TYPE,), 'tensions': (ARRAY_TYPE,),
                 'wrench': (WRENCH_TYPE,), 'lengths': (ARRAY_TYPE,)}


def _needed(signal: str, required: Sequence[str]) -> bool:
    """Whether a bag without ``signal`` is refused (the rest lengths always are needed)."""
    return signal in required or signal == 'rest_lengths'


def _bag_topics(path: Path, present: dict[str, str], wanted: dict[str, str | None],
                required: Sequence[str]) -> tuple[dict[str, str], dict[str, str]]:
    """The topics to read per signal (``wanted`` among the bag's ``present`` topic: type) and
    the absent ones; :class:`RecordingError` for a missing needed topic, a topic of the wrong
    type, or none to fit to."""
    use: dict[str, str] = {}
    absent: dict[str, str] = {}
    for signal, topic in wanted.items():
        if topic is None:
            continue
        if topic not in present:
            if _needed(signal, required):
                have = ', '.join(f'{t} ({m})' for t, m in sorted(present.items())) or 'none'
                raise RecordingError(f'{path}: no {signal} topic {topic} in the bag; its '
                                     f'topics: {have}')
            absent[signal] = topic
            continue
        if present[topic] not in _SIGNAL_TYPES[signal]:
            raise RecordingError(f'{path}: topic {topic} has type {present[topic]}, '
                                 f'expected {" or ".join(_SIGNAL_TYPES[signal])} for {signal}')
        use[signal] = topic
    if not {'pose', 'tensions', 'wrench', 'lengths'} & set(use):
        raise RecordingError(f'{path}: none of the pose, tensions, wrench topics '
                             f'({wanted["pose"]}, {wanted["tensions"]}, '
                             f'{wanted["wrench"]}) is in the bag: nothing to fit to')
    return use, absent


def _message_value(signal: str, msg: Any, msgtype: str, n_strings: int) -> Any:
    """The value of a ``signal``'s message (ValueError when it has the wrong size or, for rest
    lengths, is not positive)."""
    if signal == 'pose':
        return pose_message_to_transform(msg.pose.pose if msgtype == POSE_TYPES[1] else msg.pose)
    if signal == 'wrench':
        return _wrench_of(msg)
    if signal == 'rest_lengths':
        value = multiarray_to_array(msg, n_strings)
        if np.any(value <= 0.0):
            raise ValueError('rest lengths must be > 0')
        return value
    # NaN: not measured, so the payload with NaN kept
    return measured_array(multiarray_payload(msg, max(n_strings, DEFAULT_MAX_LENGTH)),
                          n_strings, signal, require_any=False)


def _read_series(reader: Any, deserialize: Callable[[bytes, str], Any], use: dict[str, str],
                 n_strings: int, progress: Callable[[int, int], None] | None
                 ) -> tuple[dict[str, list[tuple[float, Any]]], int, MessageReading]:
    """Every message of the ``use`` topics as (time, value) per signal, how many could not
    be decoded or had the wrong size (skipped), and how much of the storage was readable;
    ``progress(done, total)`` every 1000."""
    signal_of = {topic: signal for signal, topic in use.items()}
    connections = [c for c in reader.connections if c.topic in signal_of]
    total = sum(c.msgcount for c in connections)
    reading = MessageReading(total)
    series: dict[str, list[tuple[float, Any]]] = {s: [] for s in use}
    skipped = 0
    for done, (connection, log_time, raw) in enumerate(
            reading.messages(reader, connections), start=1):
        signal = signal_of[connection.topic]
        try:
            msg = deserialize(raw, connection.msgtype)
            t = _stamp_seconds(msg, log_time)
            value = _message_value(signal, msg, connection.msgtype, n_strings)
        except Exception:  # rosbags raises several types on corrupt CDR
            skipped += 1
            continue
        series[signal].append((t, value))
        if progress is not None and not done % 1000:
            progress(done, total)
    if progress is not None:
        progress(total, total)
    return series, skipped, reading


def _bag_recording(path: Path, series: dict[str, list[tuple[float, Any]]], use: dict[str, str],
                   absent: dict[str, str], required: Sequence[str], skipped: int,
                   n_strings: int, max_age: float, damage: str = '') -> Recording:
    """The instants of the read ``series`` (:func:`_align`); a topic without a valid message is
    absent, or a :class:`RecordingError` when it is needed (saying how much of a damaged bag
    was read: ``damage``)."""
    for signal, items in series.items():
        if not items:  # the topic is there, without a (valid) message
            if _needed(signal, required):
                raise RecordingError(f'{path}: no valid message on the {signal} topic '
                                     f'{use[signal]} in the bag'
                                     + (f' ({skipped} bad messages skipped)' if skipped else '')
                                     + (f' ({damage})' if damage else ''))
            absent[signal] = use[signal]
    recording = _align(series, n_strings, max_age,
                       f'{path} ({", ".join(f"{s} {len(v)}" for s, v in series.items())}'
                       + (f', {skipped} bad messages skipped' if skipped else '')
                       + (f', {damage}' if damage else '') + ')')
    recording.absent = absent
    return recording


def _align(series: dict[str, list[tuple[float, Any]]], n: int, max_age: float,
           source: str) -> Recording:
    """Instants at the pose times (else at the tensions' or the wrench's), each with the latest
    value of every other signal (rest lengths: held; others: no older than ``max_age``)."""
    for signal in series:
        series[signal].sort(key=lambda item: item[0])
    rests = series.get('rest_lengths', [])
    if not rests:
        raise RecordingError(f'{source}: no rest lengths recorded')
    clock = next((s for s in ('pose', 'tensions', 'wrench', 'lengths') if series.get(s)), None)
    if clock is None:
        raise RecordingError(f'{source}: no pose, tensions, wrench or lengths message recorded')
    times = np.array([t for t, _ in series[clock]])
    rest_t = np.array([t for t, _ in rests])
    k = np.searchsorted(rest_t, times, 'right') - 1
    keep = k >= 0  # instants before the first rest lengths have none
    times = times[keep]
    rec = _empty(times.size, n, source)
    rec.times = times
    rec.rest = np.array([rests[i][1] for i in k[keep]]).reshape(-1, n)
    clock_values = [v for (_, v), ok in zip(series[clock], keep, strict=True) if ok]
    for signal, target in (('pose', rec.poses), ('wrench', rec.wrench),
                           ('tensions', rec.tensions), ('lengths', rec.lengths)):
        items = series.get(signal)
        if not items:
            continue
        if signal == clock:
            target[:] = np.array(clock_values)
            continue
        st = np.array([t for t, _ in items])
        idx = np.searchsorted(st, times, 'right') - 1
        for r, i in enumerate(idx):
            if i >= 0 and times[r] - st[i] <= max_age:
                target[r] = items[i][1]
    return rec
