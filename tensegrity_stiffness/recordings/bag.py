"""Offline: what ``stiffness_node`` would publish, for a whole rosbag2 recording.

Reads ``<namespace>/screw``, ``<namespace>/pose`` and ``<namespace>/rest_lengths`` from a rosbag2
(mcap or sqlite3) with ``rosbags`` (pure Python, no ROS install: neither rclpy nor a ROS
message package is imported), in log-time order, and writes a
rosbag2 with the node's five array outputs (``wrench``, ``stiffness``, ``cartesian_stiffness``,
``string_tensions``, ``stiffness_interpretation``): the same message types, layouts, labels
(:mod:`tensegrity_stiffness.nodes.layouts`) and frame ids as the node, one of each per answered
input,
written at the log time of the input it answers.

The node's behaviour, input by input, with the node's functions: inputs are decoded with
:mod:`tensegrity_stiffness.nodes.messages` (the node's readers: they read messages by attribute, so
rosbags' messages do as well as rclpy's),
checked and computed with :mod:`tensegrity_stiffness.nodes.processing`, configured from the node's
parameter table (:mod:`tensegrity_stiffness.nodes.parameters`); a bad input is skipped and counted
by
kind, with the node's text as the example. A pose is turned into a screw on the branch nearest
the last answered screw (the config's initial screw before the first). New rest lengths apply
from their log time on and re-publish the last answer, written at the log time of the
rest-lengths message. Header stamps: a pose's stamp when it is non-zero; where the node stamps
the time of computation (screws, zero-stamped poses) the input's log time; a re-publish keeps
the stamp of the answer it repeats, as the node does.

Speed: answers are computed in chunks with one batched evaluation
(:func:`processing.joint_outputs_batch`, OpenBLAS on one thread); a screw of the plain layout
is decoded with its chunk in one ``frombuffer``; an output message is a serialized template
(the node's message of :func:`layouts.joint_output_layouts`, built and filled once with
rosbags' types by :mod:`tensegrity_stiffness.nodes.messages` and serialized by rosbags) whose
payload
bytes are replaced; a chunk's messages are written with rosbags' public ``Writer.write``
(:func:`write_blocks`).

``spine_node`` (``node='spine'``, :class:`SpineProcessor`): its inputs (``screws``, ``poses``,
``rest_lengths``) and per-input outputs (:data:`spine_processing.OUTPUT_NAMES`), one input at a
time with the node's functions (:mod:`tensegrity_stiffness.nodes.spine_processing`) and the node's
messages (:class:`messages.SpineOutputMessages`, filled as the node fills them, with rosbags'
types); the same stamp rules.
"""

from __future__ import annotations

import csv
import shutil
import time
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG
from tensegrity_stiffness.nodes import layouts, parameters, spine_processing
from tensegrity_stiffness.nodes.messages import (
    NANOSECONDS_PER_SECOND,
    MessageTypes,
    SpineOutputMessages,
    multiarray_to_array,
    new_message,
    output_writer,
    pose_message_to_transform,
    stamp_nanoseconds_or,
)
from tensegrity_stiffness.nodes.parameters import JointNodeSettings, SpineNodeSettings
from tensegrity_stiffness.nodes.processing import (
    JointOutputs,
    finite_rows,
    joint_outputs,
    joint_outputs_batch,
    pose_input,
    require_finite,
    screw_input,
    screw_inputs,
)

FloatArray = NDArray[np.float64]

FLOAT64_MULTIARRAY = layouts.FLOAT64_MULTIARRAY
POSE_STAMPED = layouts.POSE_STAMPED
POSE_ARRAY = 'geometry_msgs/msg/PoseArray'

DEFAULT_NAMESPACE = '/stiffness_node'
#: Output storages (rosbag2 storage identifiers).
STORAGES = ('mcap', 'sqlite3')
#: Answers computed per batched evaluation.
CHUNK_SIZE = 2048
#: Seconds between progress reports.
PROGRESS_PERIOD = 0.2


@dataclass(frozen=True)
class NodeTopics:
    """Input and output topics (names relative to the node, message types) of one node kind:
    ``stiffness`` is ``stiffness_node`` (:class:`StiffnessProcessor`), ``spine`` is
    ``spine_node`` (:class:`SpineProcessor`)."""

    inputs: Mapping[str, str]
    outputs: Mapping[str, str]


NODE_TOPICS: dict[str, NodeTopics] = {
    # The outputs' types (from the node's layouts) do not depend on the string names or the
    # joint count.
    'stiffness': NodeTopics(
        inputs={'screw': FLOAT64_MULTIARRAY, 'pose': POSE_STAMPED,
                'rest_lengths': FLOAT64_MULTIARRAY},
        outputs={name: layout.msgtype for name, layout in
                 layouts.joint_output_layouts(()).items()}),
    # spine_node's per-input outputs, in the order of spine_processing.OUTPUT_NAMES.
    'spine': NodeTopics(
        inputs={'screws': FLOAT64_MULTIARRAY, 'poses': POSE_ARRAY,
                'rest_lengths': FLOAT64_MULTIARRAY},
        outputs={name: layout.msgtype for name, layout in
                 layouts.spine_output_layouts(1).items()}),
}
OUTPUT_NAMES = tuple(NODE_TOPICS['stiffness'].outputs)
#: Default namespace (the node's name in the root namespace) of each node kind.
DEFAULT_NAMESPACES = {'stiffness': DEFAULT_NAMESPACE, 'spine': '/spine_node'}


class BagError(ValueError):
    """A problem with the command's files or options (the CLI's exit 2, one line)."""


# ------------------------------------------------------------------------------ configuration
def node_settings(path: str | Path | None = None) -> JointNodeSettings:
    """The settings ``stiffness_node`` runs with for ``--params-file path`` (model, frames,
    limits): the parameter table's defaults, overridden by the file's parameters
    (:func:`parameters.values_from_config`); BagError names the file and the field."""
    try:
        values = (parameters.defaults(parameters.STIFFNESS_NODE_PARAMETERS) if path is None
                  else parameters.values_from_config(path, parameters.STIFFNESS_NODE_PARAMETERS))
        return parameters.joint_node_settings(values)
    except ValueError as exc:
        text = str(exc)
        raise BagError(text if path is None or str(path) in text else f'config {path}: {text}'
                       ) from None


# ------------------------------------------------------------------------------ BLAS threads
#: (get, set) thread-count functions of the OpenBLAS builds numpy and scipy ship, by symbol.
_OPENBLAS_THREAD_SYMBOLS = (
    ('scipy_openblas_get_num_threads64_', 'scipy_openblas_set_num_threads64_'),
    ('scipy_openblas_get_num_threads', 'scipy_openblas_set_num_threads'),
    ('openblas_get_num_threads64_', 'openblas_set_num_threads64_'),
    ('openblas_get_num_threads', 'openblas_set_num_threads'),
)


def _loaded_openblas() -> list[tuple[Any, Any]]:
    """(get, set) thread-count functions of every OpenBLAS library loaded in this process
    (Linux: from /proc/self/maps; elsewhere none)."""
    import ctypes

    try:
        with open('/proc/self/maps', encoding='utf-8') as maps:
            paths = {line.split()[-1] for line in maps if 'openblas' in line.lower()}
    except OSError:
        return []
    found = []
    for path in sorted(p for p in paths if p.startswith('/')):
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for get_name, set_name in _OPENBLAS_THREAD_SYMBOLS:
            get, put = getattr(lib, get_name, None), getattr(lib, set_name, None)
            if get is not None and put is not None:
                get.restype, put.argtypes = ctypes.c_int, [ctypes.c_int]
                found.append((get, put))
                break
    return found


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """OpenBLAS on one thread inside the block (restored after). The batched evaluation's
    GEMMs (chunks of 512 rows) are large enough for OpenBLAS to start its threads, whose
    busy waiting on a shared two-core machine costs more than it saves; the bag command runs
    one process that is already busy. No effect without a loaded OpenBLAS."""
    libraries = _loaded_openblas()
    before = [get() for get, _ in libraries]
    for _, put in libraries:
        put(1)
    try:
        yield
    finally:
        for (_, put), n in zip(libraries, before, strict=True):
            put(n)


# ------------------------------------------------------------------------------ rejections
#: Kind of a rejection from the text of the node's ValueError (first match wins).
_REJECTION_KINDS = (
    ('too many elements', 'oversized array'),
    ('data_offset', 'bad data_offset'),
    ('expected ', 'wrong length'),
    ('outside the chart', 'outside the chart'),
    ('frame_id', 'wrong frame_id'),
    ('quaternion', 'bad quaternion'),
    ('rest_lengths', 'bad rest lengths'),
    ('nan or inf', 'NaN or inf'),
)


def rejection_kind(problem: str) -> str:
    """Short name of the kind of problem a ValueError's text describes."""
    text = problem.lower()
    for needle, kind in _REJECTION_KINDS:
        if needle in text:
            return kind
    return 'invalid'


# ------------------------------------------------------------------------------ screw CDR
#: Serialized ``Float64MultiArray`` of six values without layout dimensions, little-endian CDR:
#: encapsulation header, ``dim`` count 0, ``data_offset`` 0, ``data`` length 6, 4 padding bytes,
#: then the six float64 (the plain layout recorders write for a screw).
_PLAIN_SCREW_HEAD = b'\x00\x01\x00\x00' + bytes(8) + (6).to_bytes(4, 'little')
_PLAIN_SCREW_DATA = 20
PLAIN_SCREW_SIZE = _PLAIN_SCREW_DATA + 8 * 6


def plain_screw_values(raws: Sequence[bytes]) -> FloatArray:
    """(N, 6) values of serialized screws of the plain layout (:data:`PLAIN_SCREW_SIZE` bytes
    starting with ``_PLAIN_SCREW_HEAD``; the caller checks), read in one ``frombuffer``."""
    block = np.frombuffer(b''.join(raws), dtype=np.uint8).reshape(len(raws), PLAIN_SCREW_SIZE)
    return np.ascontiguousarray(block[:, _PLAIN_SCREW_DATA:]).view('<f8').astype(np.float64)


# ------------------------------------------------------------------------------ answers
@dataclass
class Answers:
    """A chunk of answers, row i answering the input logged at ``log_times[i]`` (ns).

    ``sources``: 'screw', 'pose' or 're-publish'; ``stamps`` (N,) ns of the wrench header;
    ``screws`` (N, 6); ``wrenches`` (N, 6); ``stiffness`` and ``cartesian_stiffness``
    (N, 6, 6); ``tensions`` (N, n); ``interpretation`` (N, 16)."""

    log_times: NDArray[np.int64]
    sources: list[str]
    stamps: NDArray[np.int64]
    screws: FloatArray
    wrenches: FloatArray
    stiffness: FloatArray
    cartesian_stiffness: FloatArray
    tensions: FloatArray
    interpretation: FloatArray

    def __len__(self) -> int:
        return len(self.sources)

    @classmethod
    def of(cls, outputs: JointOutputs, rows: slice | NDArray[np.int64], log_times: Any,
           sources: list[str], stamps: Any) -> Answers:
        """The answers of ``rows`` of a batch of :class:`JointOutputs`."""
        state = outputs.state
        return cls(np.asarray(log_times, dtype=np.int64), sources,
                   np.asarray(stamps, dtype=np.int64), outputs.screw[rows],
                   state.wrench[rows], state.stiffness[rows], state.cartesian_stiffness[rows],
                   state.tensions[rows], outputs.interpretation[rows])


class StiffnessProcessor:
    """The node's per-input behaviour (``_on_screw``, ``_on_pose``, ``_on_rest_lengths``,
    ``_compute_and_publish``) over a recording, answering in batches with the node's functions
    (:mod:`tensegrity_stiffness.nodes.processing`, :mod:`tensegrity_stiffness.nodes.messages`).

    Feed inputs in log-time order with :meth:`screw_raw` (serialized) or :meth:`screw`,
    :meth:`pose`, :meth:`rest_lengths`; answers go to ``emit`` in chunks (:class:`Answers`),
    rejections are counted in :attr:`rejected` by ``'<topic>: <kind>'`` with the node's text
    as the example. Call :meth:`finish` at the end.
    """

    def __init__(self, settings: JointNodeSettings, emit: Callable[[Answers], None],
                 chunk_size: int = CHUNK_SIZE,
                 deserialize: Callable[[bytes], Any] | None = None) -> None:
        self.settings = settings
        self.model = settings.model
        self.emit = emit
        self.chunk_size = chunk_size
        if deserialize is None:
            store = jazzy_typestore()

            def deserialize(raw: bytes) -> Any:
                return store.deserialize_cdr(raw, FLOAT64_MULTIARRAY)
        self.deserialize = deserialize
        self.rejected: Counter[str] = Counter()
        self.examples: dict[str, str] = {}
        self.answered: Counter[str] = Counter()
        # Plain-layout screws not decoded yet (raw bytes, log times).
        self._raw: list[bytes] = []
        self._raw_times: list[int] = []
        # Accepted inputs waiting for the next batched evaluation.
        self._sources: list[str] = []
        self._times: list[int] = []
        self._stamps: list[int | None] = []  # None: the stamp of the last answer (re-publish)
        self._screws: list[FloatArray] = []  # blocks (k, 6)
        self._count = 0
        self._transforms: dict[int, FloatArray] = {}  # pending index -> a pose's transform
        # The last answer (screw, wrench stamp ns), as the node keeps _last_screw/_last_stamp.
        self._last_screw: FloatArray | None = None
        self._last_stamp: int | None = None

    def reject(self, topic: str, problem: str, kind: str | None = None) -> None:
        key = f'{topic}: {kind or rejection_kind(problem)}'
        self.rejected[key] += 1
        self.examples.setdefault(key, problem)

    def _reference(self) -> FloatArray:
        """Branch reference of the next pose: the last accepted screw (answered or pending)."""
        if self._screws:
            return self._screws[-1][-1]
        return self._last_screw if self._last_screw is not None else self.model.initial_screw

    def _add(self, source: str, log_times: list[int], stamps: list[int | None],
             screws: FloatArray, transform: FloatArray | None = None) -> None:
        if transform is not None:
            self._transforms[self._count] = transform
        self._sources += [source] * len(log_times)
        self._times += log_times
        self._stamps += stamps
        self._screws.append(screws)
        self._count += len(log_times)
        if self._count >= self.chunk_size:
            self.flush()

    # -------------------------------------------------------------- inputs (node callbacks)
    def screw_raw(self, raw: bytes, log_time: int) -> None:
        """A serialized ``~/screw`` message: a plain six-value array is decoded later with the
        others (:meth:`_decode`); any other is deserialized and checked now."""
        if len(raw) == PLAIN_SCREW_SIZE and raw[:16] == _PLAIN_SCREW_HEAD:
            self._raw.append(raw)
            self._raw_times.append(log_time)
            if len(self._raw) >= self.chunk_size:
                self._decode()
            return
        msg = self._deserialize('screw', raw)
        if msg is not None:
            self.screw(msg, log_time)

    def _deserialize(self, topic: str, raw: bytes) -> Any:
        try:
            return self.deserialize(raw)
        except Exception as exc:  # rosbags raises several types on corrupt CDR
            self.reject(topic, f'cannot deserialize: {type(exc).__name__}: {exc}', 'undecodable')
            return None

    def _decode(self) -> None:
        """Check the pending plain screws as :meth:`screw` does, in one batch: the decoded
        values are exactly what ``messages.multiarray_to_array`` returns for them (no data
        offset, six values); a non-finite one goes through that function for its message."""
        if not self._raw:
            return
        raws, times = self._raw, self._raw_times
        self._raw, self._raw_times = [], []
        values = plain_screw_values(raws)
        finite = np.isfinite(values).all(axis=1)
        if not finite.all():
            max_length = self.settings.max_array_length
            for i in np.flatnonzero(~finite):
                try:  # raises the node's 'array contains NaN or inf'
                    multiarray_to_array(self.deserialize(raws[i]), expected_length=6,
                                        max_length=max_length)
                except ValueError as exc:
                    self.reject('screw', str(exc))
            values, times = values[finite], [t for t, ok in zip(times, finite.tolist(),
                                                                strict=True) if ok]
        accepted, problems = screw_inputs(values)
        for problem in problems.values():
            self.reject('screw', problem)
        if problems:
            values = values[accepted]
            times = [t for t, ok in zip(times, accepted.tolist(), strict=True) if ok]
        if len(times):
            self._add('screw', times, list(times), values)

    def screw(self, msg: Any, log_time: int) -> None:
        """A deserialized ``~/screw`` message (the node's ``_on_screw``)."""
        self._decode()
        try:
            xi = screw_input(multiarray_to_array(
                msg, expected_length=6, max_length=self.settings.max_array_length))
        except ValueError as exc:
            self.reject('screw', str(exc))
            return
        self._add('screw', [log_time], [log_time], xi[None])

    def pose(self, msg: Any, log_time: int) -> None:
        """A deserialized ``~/pose`` message (the node's ``_on_pose``)."""
        self._decode()
        try:
            T = pose_message_to_transform(msg.pose)
            xi = pose_input(msg.header.frame_id, T, self.settings.link1_frame,
                            self._reference())
        except ValueError as exc:
            self.reject('pose', str(exc))
            return
        self._add('pose', [log_time], [stamp_nanoseconds_or(msg.header.stamp, log_time)],
                  xi[None], T)

    def rest_lengths(self, msg: Any, log_time: int) -> None:
        """A deserialized ``~/rest_lengths`` message (the node's ``_on_rest_lengths``)."""
        self.flush()  # inputs logged before apply the old rest lengths
        try:
            rest = multiarray_to_array(msg, expected_length=self.model.n_strings,
                                       max_length=self.settings.max_array_length)
            self.model = self.model.with_rest_lengths(rest)
        except ValueError as exc:
            self.reject('rest_lengths', str(exc))
            return
        if self._last_screw is not None:  # the node's _republish_last
            self._add('re-publish', [log_time], [None], self._last_screw[None])
            self.flush()

    def finish(self) -> None:
        self.flush()

    # -------------------------------------------------------------- batched answers
    def flush(self) -> None:
        """Answer the pending inputs with one :func:`joint_outputs_batch`. The first row the
        node's publishers would refuse (a non-finite output) splits the chunk: the rows before
        it are answered, it goes through the node's single path (``joint_outputs`` and the
        finite check of ``JointOutputMessages.fill``, whose ValueError is the rejection), and the
        poses after it get their branch again from the last answer."""
        self._decode()
        while self._count:
            sources, times, stamps = self._sources, self._times, self._stamps
            screws = np.concatenate(self._screws)
            transforms = self._transforms
            self._sources, self._times, self._stamps, self._screws = [], [], [], []
            self._transforms, self._count = {}, 0
            if stamps[0] is None:
                stamps[0] = self._last_stamp
            outputs = joint_outputs_batch(self.model, screws)
            finite = finite_rows(outputs)
            bad = len(screws) if finite.all() else int(np.flatnonzero(~finite)[0])
            if bad:
                self._answer(Answers.of(outputs, slice(0, bad), times[:bad], sources[:bad],
                                        stamps[:bad]))
            if bad == len(screws):
                return
            self._single(sources[bad], times[bad], stamps[bad], screws[bad])
            for i in range(bad + 1, len(screws)):
                T = transforms.get(i)
                xi = screws[i] if T is None else pose_input(
                    '', T, self.settings.link1_frame, self._reference())
                self._add(sources[i], [times[i]], [stamps[i]], xi[None], T)

    def _single(self, source: str, log_time: int, stamp: int | None, xi: FloatArray) -> None:
        """One input through the node's own single-screw path."""
        outputs = joint_outputs(self.model, xi)
        try:  # the check of JointOutputMessages.fill (filling the joint's messages cannot fail)
            require_finite(outputs)
        except ValueError as exc:
            self.reject(source, str(exc), 'non-finite result')
            return
        state = outputs.state
        self._answer(Answers(
            np.array([log_time], dtype=np.int64), [source],
            np.array([self._last_stamp if stamp is None else stamp], dtype=np.int64),
            xi[None], state.wrench[None], state.stiffness[None],
            state.cartesian_stiffness[None], state.tensions[None],
            outputs.interpretation[None]))

    def _answer(self, answers: Answers) -> None:
        self._last_screw = answers.screws[-1].copy()
        self._last_stamp = int(answers.stamps[-1])
        self.answered.update(answers.sources)
        self.emit(answers)


# ------------------------------------------------------------------------------ spine
def spine_settings(path: str | Path | None = None) -> SpineNodeSettings:
    """The settings ``spine_node`` runs with for ``--params-file path`` (default: the packaged
    ``config/default_spine.yaml``): the parameter table of the file's ``chain.n_joints``,
    overridden by the file's parameters; BagError names the file and the field."""
    path = config.packaged_config_path(DEFAULT_SPINE_CONFIG) if path is None else path
    try:
        n = parameters.values_from_config(path, parameters.CHAIN_PARAMETERS)['chain.n_joints']
        values = parameters.values_from_config(path, parameters.spine_node_parameters(n))
        return parameters.spine_node_settings(values)
    except ValueError as exc:
        text = str(exc)
        raise BagError(text if str(path) in text else f'config {path}: {text}') from None


def rosbags_types(typestore: Any) -> MessageTypes:
    """rosbags' message classes of ``typestore`` for :mod:`tensegrity_stiffness.nodes.messages`
    (``float64[]`` fields as float64 arrays)."""
    return MessageTypes(classes=typestore.types,
                        payload=lambda values: np.array(values, dtype=np.float64).reshape(-1))


@dataclass
class SpineAnswer:
    """One answer of the spine node: the input's log time (ns), its source ('screws', 'poses'
    or 're-publish'), the stamp (ns) of ``tip_pose`` and ``tip_wrench``, the library's outputs
    and the node's filled messages (rosbags', in :class:`SpineOutputMessages` order)."""

    log_time: int
    source: str
    stamp: int
    outputs: spine_processing.SpineOutputs
    messages: tuple[Any, ...]


class SpineProcessor:
    """``spine_node``'s per-input behaviour (``_on_screws``, ``_on_poses``,
    ``_on_rest_lengths``, ``_compute_and_publish``) over a recording, one input at a time with
    the node's functions (:mod:`tensegrity_stiffness.nodes.spine_processing`,
    :mod:`tensegrity_stiffness.nodes.messages`; the node's ``SpineOutputMessages`` with rosbags'
    ``types``, default Jazzy's, for the messages). Each answer goes to ``emit``
    (:class:`SpineAnswer`, its messages reused by the next answer); rejections are counted in
    :attr:`rejected` by ``'<topic>: <kind>'`` with the node's text as the example."""

    def __init__(self, settings: SpineNodeSettings, emit: Callable[[SpineAnswer], None],
                 types: MessageTypes | None = None) -> None:
        self.settings = settings
        self.emit = emit
        self.types = rosbags_types(jazzy_typestore()) if types is None else types
        self.messages = SpineOutputMessages(settings.n_joints, self.types)
        self.rejected: Counter[str] = Counter()
        self.examples: dict[str, str] = {}
        self.answered: Counter[str] = Counter()
        self._last_screws: FloatArray | None = None
        self._last_stamp: int | None = None

    def reject(self, topic: str, problem: str, kind: str | None = None) -> None:
        key = f'{topic}: {kind or rejection_kind(problem)}'
        self.rejected[key] += 1
        self.examples.setdefault(key, problem)

    def screws(self, msg: Any, log_time: int) -> None:
        """A ``~/screws`` message (the node's ``_on_screws``); stamped with its log time, as the
        node stamps the time of computation."""
        settings = self.settings
        try:
            xi = spine_processing.screws_input(multiarray_to_array(
                msg, max_length=settings.max_array_length), settings.n_joints)
        except ValueError as exc:
            self.reject('screws', str(exc))
            return
        self._compute(xi, log_time, log_time, 'screws')

    def poses(self, msg: Any, log_time: int) -> None:
        """A ``~/poses`` message (the node's ``_on_poses``): the log map on the branch nearest
        the last answered screws (the models' initial screws before the first)."""
        settings = self.settings
        try:
            reference = self._last_screws if self._last_screws is not None else np.array(
                [model.initial_screw for model in settings.chain.joints])
            xi = spine_processing.poses_input(msg.header.frame_id, msg.poses,
                                              settings.base_frame, reference,
                                              pose_message_to_transform)
        except ValueError as exc:
            self.reject('poses', str(exc))
            return
        self._compute(xi, log_time, stamp_nanoseconds_or(msg.header.stamp, log_time), 'poses')

    def rest_lengths(self, msg: Any, log_time: int) -> None:
        """A ``~/rest_lengths`` message (the node's ``_on_rest_lengths``): in force from its log
        time on; the last answer is re-published under it, with that answer's stamp."""
        settings = self.settings
        try:
            rest = spine_processing.rest_lengths_input(multiarray_to_array(
                msg, max_length=settings.max_array_length), settings.chain)
        except ValueError as exc:
            self.reject('rest_lengths', str(exc))
            return
        self.settings = replace(settings, rest_lengths=rest,
                                generation=settings.generation + 1)
        if self._last_screws is not None and self._last_stamp is not None:
            self._compute(self._last_screws, log_time, self._last_stamp, 're-publish')

    def _compute(self, xi: FloatArray, log_time: int, stamp: int, source: str) -> None:
        settings = self.settings
        try:
            outputs = spine_processing.spine_outputs(settings.chain, xi, settings.rest_lengths)
            self.messages.fill(outputs, self.types.time(stamp), settings.base_frame)
        except ValueError as exc:
            text = str(exc)
            self.reject(source, text, 'singular tip stiffness' if 'singular' in text
                        else 'non-finite result')
            return
        self._last_screws, self._last_stamp = xi, stamp
        self.answered[source] += 1
        self.emit(SpineAnswer(log_time, source, stamp, outputs, self.messages.messages()))


class _SpineCsvSink:
    """One row per spine answer: log time, source, stamp, the joints' screws (joint-major),
    the tip wrench (base frame) and the tip stiffness (tool frame, row-major)."""

    def __init__(self, path: Path, n_joints: int) -> None:
        self._file = path.open('w', newline='')
        self._writer = csv.writer(self._file)
        w, s, t = layouts.WRENCH_NAMES, layouts.SCREW_NAMES, layouts.TWIST_NAMES
        self._writer.writerow(
            ['log_time_ns', 'source', 'stamp_ns',
             *(f'joint_{i}_{c}' for i in range(1, n_joints + 1) for c in s),
             *(f'tip_{c}' for c in w), *(f'Ktip_{r}_{c}' for r in w for c in t)])

    def write(self, a: SpineAnswer) -> None:
        o = a.outputs
        self._writer.writerow([a.log_time, a.source, a.stamp, *np.concatenate(
            [o.screws.ravel(), o.tip_wrench, o.tip_stiffness_tool.ravel()]).tolist()])

    def close(self) -> None:
        self._file.close()


def _run_spine(reader: Any, connections: list[Any], wanted: Mapping[str, tuple[str, str]],
               writer: Any, typestore: Any, settings: SpineNodeSettings, outputs: list[str],
               spec: NodeTopics, prefix: str, csv_sink: _SpineCsvSink | None,
               summary: BagSummary, total: int,
               progress: Callable[[int, int], None] | None) -> BagSummary:
    """The read - process - write loop of :func:`process_bag` for ``spine_node``: one input
    at a time, each answer's messages (rosbags') serialized."""
    names = spine_processing.OUTPUT_NAMES
    chosen = [names.index(name) for name in outputs]
    out_connections = [writer.add_connection(f'{prefix}/{names[k]}', spec.outputs[names[k]],
                                             typestore=typestore) for k in chosen]
    serialize = typestore.serialize_cdr

    def emit(a: SpineAnswer) -> None:
        for k, connection in zip(chosen, out_connections, strict=True):
            writer.write(connection, a.log_time,
                         bytes(serialize(a.messages[k], connection.msgtype)))
        if csv_sink is not None:
            csv_sink.write(a)

    processor = SpineProcessor(settings, emit, rosbags_types(typestore))
    handlers = {'screws': processor.screws, 'poses': processor.poses,
                'rest_lengths': processor.rest_lengths}
    inputs: Counter[str] = Counter()
    next_report = time.perf_counter() + PROGRESS_PERIOD
    done = 0
    for connection, log_time, raw in reader.messages(connections=connections):
        done += 1
        name, msgtype = wanted[connection.topic]
        inputs[name] += 1
        if connection.msgtype != msgtype:
            processor.reject(name, f'message type {connection.msgtype}, expected {msgtype}',
                             'wrong message type')
        else:
            try:
                msg = typestore.deserialize_cdr(raw, msgtype)
            except Exception as exc:  # rosbags raises several types on corrupt CDR
                processor.reject(name, f'cannot deserialize: {type(exc).__name__}: {exc}',
                                 'undecodable')
            else:
                handlers[name](msg, log_time)
        if progress is not None and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + PROGRESS_PERIOD
            progress(done, total)
    if progress is not None:
        progress(done, total)
    summary.inputs = {name: inputs[name] for name in spec.inputs if inputs[name]}
    summary.answered = dict(processor.answered)
    summary.written = {f'{prefix}/{name}': summary.answers for name in outputs}
    summary.rejected = dict(processor.rejected)
    summary.rejection_examples = dict(processor.examples)
    return summary


# ------------------------------------------------------------------------------ output messages
class _Template:
    """Serialized bytes of one output message of ``layout`` whose payload ends the message:
    ``layout.size`` float64 values (little-endian CDR, no padding after them), and for a
    ``WrenchStamped`` the header stamp (sec int32, nanosec uint32) right after the 4-byte
    encapsulation header. The message is built and filled as the node's
    (:func:`messages.new_message`, :func:`messages.output_writer`, rosbags' types) and
    serialized by rosbags; rows of a chunk are this template with those bytes replaced
    (checked against rosbags at build)."""

    _PROBE_STAMP = (1234567, 89)

    def __init__(self, typestore: Any, layout: layouts.OutputLayout, frame_id: str) -> None:
        types = rosbags_types(typestore)
        self.size = size = layout.size
        self.stamped = layout.msgtype == layouts.WRENCH_STAMPED
        if layout.msgtype not in (FLOAT64_MULTIARRAY, layouts.WRENCH_STAMPED):
            raise ValueError(f'{layout.msgtype}: no template')
        msg = new_message(layout, types)
        probe = np.arange(1.0, size + 1.0)
        sec, nanosec = self._PROBE_STAMP
        output_writer(layout, types)(msg, probe,
                                     types.time(sec * NANOSECONDS_PER_SECOND + nanosec),
                                     frame_id)
        raw = np.frombuffer(bytes(typestore.serialize_cdr(msg, layout.msgtype)), dtype=np.uint8)
        payload = raw[raw.size - 8 * size:].view('<f8')
        stamp_ok = not self.stamped or raw[4:12].view('<i4').tolist() == [sec, nanosec]
        if raw[:2].tolist() != [0, 1] or not np.array_equal(payload, probe) or not stamp_ok:
            raise RuntimeError(f'{layout.msgtype}: unexpected CDR layout')  # a rosbags change
        self.raw = raw

    def rows(self, values: FloatArray, stamps: NDArray[np.int64] | None = None
             ) -> NDArray[np.uint8]:
        """(N, bytes) serialized messages with payloads ``values`` (N, size)."""
        n = len(values)
        out = np.empty((n, self.raw.size), dtype=np.uint8)
        out[:] = self.raw
        out[:, self.raw.size - 8 * self.size:] = np.ascontiguousarray(
            values.reshape(n, self.size), dtype='<f8').view(np.uint8)
        if self.stamped:
            sec, nanosec = np.divmod(stamps, NANOSECONDS_PER_SECOND)
            stamp = np.empty((n, 2), dtype='<i4')
            stamp[:, 0] = sec
            stamp[:, 1] = nanosec.astype(np.uint32).view(np.int32)
            out[:, 4:12] = stamp.view(np.uint8)
        return out


# ------------------------------------------------------------------------------ files
def jazzy_typestore() -> Any:
    """rosbags' type store of ROS 2 Jazzy's messages (decodes and encodes recordings)."""
    from rosbags.typesys import Stores, get_typestore

    return get_typestore(Stores.ROS2_JAZZY)


def namespace_prefix(namespace: str) -> str:
    """``'/stiffness_node'`` for ``'stiffness_node'``, ``'/a/b/'`` ...; ``''`` for ``'/'``."""
    parts = [p for p in str(namespace).split('/') if p]
    return ''.join('/' + p for p in parts)


def _storage_of(path: Path) -> str:
    """Storage identifier of a rosbag2 folder (its metadata.yaml) or storage file."""
    if path.is_file():
        return {'.mcap': 'mcap', '.db3': 'sqlite3'}.get(path.suffix, path.suffix)
    try:
        info = config.load_yaml(path / 'metadata.yaml')['rosbag2_bagfile_information']
        return str(info['storage_identifier'])
    except (ValueError, KeyError, TypeError):
        return 'unknown'


def check_input(path: Path) -> None:
    """A rosbag2 folder or storage file to read; BagError naming what is wrong."""
    if not path.exists():
        raise BagError(f'{path}: no such rosbag2 folder')
    if path.is_dir() and not (path / 'metadata.yaml').is_file():
        raise BagError(f'{path}: not a rosbag2 (no metadata.yaml)')
    if path.is_file() and path.suffix not in ('.mcap', '.db3'):
        raise BagError(f'{path}: not a rosbag2 (a folder with metadata.yaml, or a .mcap or '
                       '.db3 file)')


def _clear_output(path: Path, overwrite: bool, what: str) -> None:
    """Make room for an output: an error if it exists unless ``overwrite``; only a rosbag2
    folder (or an empty folder) or a plain file is removed."""
    if not path.exists() and not path.is_symlink():
        return
    if not overwrite:
        raise BagError(f'{what} {path} exists (use --overwrite to replace it)')
    if path.is_dir() and not path.is_symlink():
        if any(path.iterdir()) and not (path / 'metadata.yaml').is_file():
            raise BagError(f'{what} {path} is a folder that is not a rosbag2; not replacing it')
        shutil.rmtree(path)
    elif path.is_dir():
        raise BagError(f'{what} {path} is a link to a folder; not replacing it')
    else:
        path.unlink()


@dataclass
class BagSummary:
    """What :func:`process_bag` read and wrote."""

    input: str
    output: str
    storage: str
    csv: str | None
    namespace: str
    inputs: dict[str, int] = field(default_factory=dict)
    answered: dict[str, int] = field(default_factory=dict)
    written: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    rejection_examples: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0

    @property
    def answers(self) -> int:
        return sum(self.answered.values())

    def to_dict(self) -> dict[str, Any]:
        inputs = sum(self.inputs.values())
        return {
            'input': self.input, 'output': self.output, 'storage': self.storage,
            'csv': self.csv, 'namespace': self.namespace or '/',
            'inputs': dict(self.inputs), 'answered': dict(self.answered),
            'answers': self.answers, 'written': dict(self.written),
            'rejected': dict(sorted(self.rejected.items())),
            'rejected_total': sum(self.rejected.values()),
            'rejection_examples': dict(sorted(self.rejection_examples.items())),
            'seconds': self.seconds,
            'inputs_per_second': inputs / self.seconds if self.seconds > 0 else None,
        }


class _CsvSink:
    """One row per answer: log time, source, stamp, screw, wrench, K, K_c, tensions."""

    def __init__(self, path: Path, string_names: Sequence[str]) -> None:
        self._file = path.open('w', newline='')
        self._writer = csv.writer(self._file)
        w, s, t = layouts.WRENCH_NAMES, layouts.SCREW_NAMES, layouts.TWIST_NAMES
        self._writer.writerow(
            ['log_time_ns', 'source', 'stamp_ns', *s, *w,
             *(f'K_{r}_{c}' for r in w for c in s), *(f'Kc_{r}_{c}' for r in w for c in t),
             *(f'tension_{name}' for name in string_names)])

    def write(self, a: Answers) -> None:
        n = len(a)
        values = np.hstack([a.screws, a.wrenches, a.stiffness.reshape(n, 36),
                            a.cartesian_stiffness.reshape(n, 36), a.tensions]).tolist()
        self._writer.writerows(
            [t, source, stamp, *row] for t, source, stamp, row in
            zip(a.log_times.tolist(), a.sources, a.stamps.tolist(), values, strict=True))

    def close(self) -> None:
        self._file.close()


def _output_topics(topics: Sequence[str] | None, prefix: str,
                   names: Sequence[str] = OUTPUT_NAMES) -> list[str]:
    """Output names (of ``names``, the node kind's outputs) selected by ``--topics``
    (relative or full)."""
    if not topics:
        return list(names)
    chosen = []
    for topic in topics:
        name = topic[len(prefix) + 1:] if prefix and topic.startswith(prefix + '/') else topic
        name = name.lstrip('/') if not prefix else name
        if name not in names:
            raise BagError(f"--topics: unknown output '{topic}' (outputs: "
                           f"{', '.join(names)})")
        if name not in chosen:
            chosen.append(name)
    return [name for name in names if name in chosen]


def process_bag(input_path: str | Path, output_path: str | Path, *,
                config_path: str | Path | None = None,
                namespace: str | None = None, storage: str | None = None,
                csv_path: str | Path | None = None, topics: Sequence[str] | None = None,
                overwrite: bool = False, node: str = 'stiffness',
                progress: Callable[[int, int], None] | None = None,
                chunk_size: int = CHUNK_SIZE) -> BagSummary:
    """Read the node's inputs from the rosbag2 ``input_path`` and write what the node would
    publish to the rosbag2 ``output_path`` (and ``csv_path``); see the module docstring.

    ``node``: 'stiffness' (``stiffness_node``) or 'spine' (``spine_node``: its inputs and
    per-input outputs, config ``config/default_spine.yaml`` unless ``config_path``);
    ``namespace``: the topics' prefix (default :data:`DEFAULT_NAMESPACES` of the node);
    ``storage``: 'mcap' or 'sqlite3' (default: the input's); ``topics``: the outputs to write
    (default all); ``progress(done, total)``: inputs read so far of all.
    Raises :class:`BagError` (a ValueError) for the files and options, and when no input
    was answered.
    """
    from rosbags.rosbag2 import Reader, StoragePlugin, Writer
    from rosbags.rosbag2.errors import ReaderError, WriterError

    started = time.perf_counter()
    if node not in NODE_TOPICS:
        raise BagError(f"--node: unknown node '{node}' (known: {', '.join(NODE_TOPICS)})")
    spec = NODE_TOPICS[node]
    src, out = Path(input_path), Path(output_path)
    csv_file = Path(csv_path) if csv_path is not None else None
    check_input(src)
    if storage is not None and storage not in STORAGES:
        raise BagError(f"unknown storage '{storage}' (mcap or sqlite3)")
    prefix = namespace_prefix(DEFAULT_NAMESPACES[node] if namespace is None else namespace)
    outputs = _output_topics(topics, prefix, tuple(spec.outputs))
    spine = node == 'spine'
    settings = spine_settings(config_path) if spine else node_settings(config_path)
    if out.resolve() == src.resolve():
        raise BagError(f'{out}: the output must not be the input')

    try:
        reader = Reader(src)
        reader.open()
    except (ReaderError, OSError, KeyError, ValueError) as exc:
        raise BagError(f'{src}: not a readable rosbag2: {exc}') from None
    try:
        in_storage = _storage_of(src)
        out_storage = storage or (in_storage if in_storage in STORAGES else 'mcap')
        wanted = {f'{prefix}/{name}': (name, msgtype) for name, msgtype in spec.inputs.items()}
        present = {c.topic: c.msgtype for c in reader.connections}
        if not set(wanted) & set(present):
            have = ', '.join(f'{t} ({m})' for t, m in sorted(present.items())) or 'none'
            raise BagError(f"{src}: none of the topics {', '.join(wanted)} is in the bag; "
                           f'its topics: {have}')
        connections = [c for c in reader.connections if c.topic in wanted]
        total = sum(c.msgcount for c in connections)
        summary = BagSummary(input=str(src), output=str(out), storage=out_storage,
                             csv=str(csv_file) if csv_file else None, namespace=prefix)
        _clear_output(out, overwrite, 'output')
        if csv_file is not None:
            _clear_output(csv_file, overwrite, 'csv file')
        typestore = jazzy_typestore()
        summary.written = dict.fromkeys(f'{prefix}/{name}' for name in outputs)
        try:
            writer = Writer(out, version=9,
                            storage_plugin=StoragePlugin[out_storage.upper()])
            writer.open()
        except (WriterError, OSError) as exc:
            raise BagError(f'{out}: cannot write: {exc}') from None
        csv_sink = None
        try:
            if spine:
                csv_sink = _SpineCsvSink(csv_file, settings.n_joints) if csv_file else None
                summary = _run_spine(reader, connections, wanted, writer, typestore, settings,
                                     outputs, spec, prefix, csv_sink, summary, total, progress)
            else:
                csv_sink = _CsvSink(csv_file, settings.model.string_names) if csv_file else None
                with single_threaded_blas():
                    summary = _run(reader, connections, wanted, writer, typestore, settings,
                                   outputs, spec, prefix, csv_sink, summary, total, progress,
                                   chunk_size)
        finally:
            writer.close()
            if csv_sink is not None:
                csv_sink.close()
    finally:
        reader.close()
    summary.seconds = time.perf_counter() - started
    if summary.answers == 0:
        shutil.rmtree(out, ignore_errors=True)
        if csv_file is not None:
            csv_file.unlink(missing_ok=True)
        bad = ', '.join(f'{k} {v}' for k, v in sorted(summary.rejected.items())) or 'no inputs'
        raise BagError(f'{src}: no input could be answered ({bad}); nothing written')
    return summary


def write_blocks(writer: Any, connections: Sequence[Any], log_times: NDArray[np.int64],
                 rows: Sequence[NDArray[np.uint8]]) -> None:
    """Write a block of messages through rosbags' public ``Writer.write``: ``rows[k]``
    (N, bytes) on ``connections[k]``, the messages of input i at ``log_times[i]`` in
    connection order (the order the node publishes them)."""
    write = writer.write
    columns = []
    for block in rows:
        data, width = np.ascontiguousarray(block).tobytes(), block.shape[1]
        columns.append([data[at:at + width] for at in range(0, len(data), width)])
    for t, *datas in zip(log_times.tolist(), *columns, strict=True):
        for connection, data in zip(connections, datas, strict=True):
            write(connection, t, data)


def _run(reader: Any, connections: list[Any], wanted: Mapping[str, tuple[str, str]],
         writer: Any, typestore: Any, settings: JointNodeSettings, outputs: list[str],
         spec: NodeTopics, prefix: str, csv_sink: _CsvSink | None, summary: BagSummary,
         total: int, progress: Callable[[int, int], None] | None,
         chunk_size: int) -> BagSummary:
    """The read - process - write loop of :func:`process_bag`."""
    output_layouts = layouts.joint_output_layouts(settings.model.string_names)
    templates = {name: _Template(typestore, output_layouts[name], settings.link1_frame)
                 for name in outputs}
    out_connections = [writer.add_connection(f'{prefix}/{name}', spec.outputs[name],
                                             typestore=typestore) for name in outputs]
    written = Counter()

    def emit(a: Answers) -> None:
        payloads = dict(zip(layouts.JOINT_OUTPUTS, (
            a.wrenches, a.stiffness, a.cartesian_stiffness, a.tensions, a.interpretation),
            strict=True))
        write_blocks(writer, out_connections, a.log_times, [templates[name].rows(
            payloads[name], a.stamps if name == 'wrench' else None) for name in outputs])
        for name in outputs:
            written[name] += len(a)
        if csv_sink is not None:
            csv_sink.write(a)

    deserialize = typestore.deserialize_cdr
    processor = StiffnessProcessor(settings, emit, chunk_size=chunk_size,
                                   deserialize=lambda raw: deserialize(raw, FLOAT64_MULTIARRAY))
    handlers = {'pose': processor.pose, 'rest_lengths': processor.rest_lengths}
    inputs: Counter[str] = Counter()
    next_report = time.perf_counter() + PROGRESS_PERIOD
    done = 0
    screw_raw = processor.screw_raw
    screw_topic = f'{prefix}/screw'
    # rosbags yields each storage file in log-time order; the files of a split bag follow
    # each other in time.
    for connection, log_time, raw in reader.messages(connections=connections):
        done += 1
        topic = connection.topic
        if topic == screw_topic and connection.msgtype == FLOAT64_MULTIARRAY:
            screw_raw(raw, log_time)
        else:
            name, msgtype = wanted[topic]
            inputs[name] += 1
            if connection.msgtype != msgtype:
                processor.reject(name, f'message type {connection.msgtype}, expected '
                                 f'{msgtype}', 'wrong message type')
            else:
                try:
                    msg = deserialize(raw, msgtype)
                except Exception as exc:  # rosbags raises several types on corrupt CDR
                    processor.reject(name, f'cannot deserialize: {type(exc).__name__}: {exc}',
                                     'undecodable')
                else:
                    handlers[name](msg, log_time)
        if progress is not None and not done & 1023 and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + PROGRESS_PERIOD
            progress(done, total)
    processor.finish()
    if progress is not None:
        progress(done, total)
    inputs['screw'] += done - sum(inputs.values())
    summary.inputs = {name: inputs[name] for name in spec.inputs if inputs[name]}
    summary.answered = dict(processor.answered)
    summary.written = {f'{prefix}/{name}': written[name] for name in outputs}
    summary.rejected = dict(processor.rejected)
    summary.rejection_examples = dict(processor.examples)
    return summary

