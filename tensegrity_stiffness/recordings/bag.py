"""Offline: what ``stiffness_node``, ``spine_node`` or ``structure_node`` would publish, for a
whole rosbag2 recording.

Reads the node's inputs (``stiffness_node``: ``<namespace>/screw``, ``pose``, ``rest_lengths``;
``spine_node``: ``screws``, ``poses``, ``rest_lengths``; ``structure_node``: ``poses``,
``pose_values``, ``rest_lengths``) from a rosbag2 (mcap or sqlite3) with
``rosbags`` (pure Python, no ROS install: neither rclpy nor a ROS message package is imported),
in log-time order, and writes a rosbag2 with the node's per-input outputs
(:data:`NODE_TOPICS`): the same message types, layouts, labels
(:mod:`tensegrity_stiffness.nodes.layouts`) and frame ids as the node, one of each per answered
input, written at the log time of the input it answers.

The node's behaviour, input by input, with the node's functions: inputs are decoded with
:mod:`tensegrity_stiffness.nodes.messages` (the node's readers: they read messages by attribute,
so rosbags' messages do as well as rclpy's), checked and computed with
:mod:`tensegrity_stiffness.nodes.processing` (``spine_processing`` for the spine), configured
from the node's parameter table (:mod:`tensegrity_stiffness.nodes.parameters`). A bad input is
skipped and counted by kind (the ``kind`` of the node's typed ValueError,
:mod:`tensegrity_stiffness.geometry.errors`), with the node's text as the example. A pose is
turned into a screw on the branch nearest the last answered screw (the config's initial screw
before the first). New rest lengths apply from their log time on and re-publish the last
answer, written at the log time of the rest-lengths message. Header stamps: a pose's stamp when
it is non-zero; where the node stamps the time of computation (screws, zero-stamped poses) the
input's log time; a re-publish keeps the stamp of the answer it repeats, as the node does.

One loop for both nodes (:func:`process_bag`): the messages are read, checked for type,
deserialized and handed to the node kind's processor (:class:`StiffnessProcessor`,
:class:`SpineProcessor`, sharing the rejection counting of :class:`Processor`), whose answers
are written by the node kind's writer and the CSV sink; :data:`_NODE_KINDS` holds what differs.

``stiffness_node`` is answered in chunks with one batched evaluation
(:func:`processing.joint_outputs_batch`, BLAS on one thread through ``threadpoolctl``); a
screw of the plain layout is decoded with its chunk in one ``frombuffer``; an output message is
a serialized template (the node's message of :func:`layouts.joint_output_layouts`, built and
filled once with rosbags' types by :mod:`tensegrity_stiffness.nodes.messages` and serialized by
rosbags) whose payload bytes are replaced; a chunk's messages are written with rosbags' public
``Writer.write`` (:func:`write_blocks`). ``spine_node`` is answered one input at a time, with
the node's messages (:class:`messages.SpineOutputMessages`, filled as the node fills them, with
rosbags' types) serialized by rosbags.
"""

from __future__ import annotations

import csv
import shutil
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.errors import INVALID, SingularStiffnessError, error_kind
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG
from tensegrity_stiffness.nodes import layouts, parameters, spine_processing, structure_node
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
    with_rest_lengths,
)
from tensegrity_stiffness.structures.schema import is_structure_document

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
    # structure_node's, in the order of structure_node.STRUCTURE_OUTPUTS (contact_forces only
    # for a structure with a ground: the structure kind's writer skips it otherwise).
    'structure': NodeTopics(
        inputs={'poses': POSE_ARRAY, 'pose_values': FLOAT64_MULTIARRAY,
                'rest_lengths': FLOAT64_MULTIARRAY},
        outputs=dict.fromkeys(structure_node.STRUCTURE_OUTPUTS, FLOAT64_MULTIARRAY)),
}
OUTPUT_NAMES = tuple(NODE_TOPICS['stiffness'].outputs)
#: Default namespace (the node's name in the root namespace) of each node kind.
DEFAULT_NAMESPACES = {'stiffness': DEFAULT_NAMESPACE, 'spine': '/spine_node',
                      'structure': '/structure_node'}


class BagError(ValueError):
    """A problem with the command's files or options (the CLI's exit 2, one line)."""


class DamagedBagError(BagError):
    """A recording whose storage stops being readable part way (flipped bytes, a truncated
    file): what was read is said; the reader that raises it takes ``allow_damaged`` to go on
    with what was read."""


@dataclass
class MessageReading:
    """The messages of a rosbag2 reader with damage caught: :meth:`messages` yields
    ``reader.messages(connections=...)`` until the storage ends or stops being readable, then
    ``damage`` says why (empty: read to the end) and ``read`` how many of ``total`` came."""

    total: int
    read: int = 0
    damage: str = ''

    def messages(self, reader: Any, connections: Sequence[Any]) -> Iterable[Any]:
        """``(connection, log_time, raw)`` of ``connections`` in log-time order."""
        stream = iter(reader.messages(connections=connections))
        while True:
            try:
                item = next(stream)
            except StopIteration:
                return
            except Exception as exc:  # rosbags raises many types on corrupt storage
                self.damage = f'{type(exc).__name__}: {exc}'
                return
            self.read += 1
            yield item

    def check(self, source: Any, allow_damaged: bool) -> None:
        """:class:`DamagedBagError` saying how much was read, unless ``allow_damaged`` or the
        storage was read to its end."""
        if self.damage and not allow_damaged:
            raise DamagedBagError(f'{source}: {self.summary()}; nothing kept (allow damaged '
                                  'input to go on with what was read: --allow-damaged)')

    def summary(self) -> str:
        """``damaged: 271 of 600 messages read (OverflowError: ...)``, or empty when whole."""
        if not self.damage:
            return ''
        return f'damaged: {self.read} of {self.total} messages read ({self.damage})'


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


def structure_settings(path: str | Path | None = None) -> structure_node.StructureNodeSettings:
    """The settings ``structure_node`` runs with for ``--params-file path`` (default: the
    parameter table's defaults, the packaged 6-bar); a structure file itself (a ``structure``
    section with ``bodies``) is taken as ``structure.config``. BagError names the file and the
    field."""
    table = structure_node.STRUCTURE_NODE_PARAMETERS
    try:
        if path is None:
            return structure_node.structure_node_settings(parameters.defaults(table))
        if is_structure_document(config.load_yaml(path)):  # the structure itself
            values = {**parameters.defaults(table), 'structure.config': str(path)}
        else:
            values = parameters.values_from_config(path, table)
        return structure_node.structure_node_settings(values)
    except ValueError as exc:
        text = str(exc)
        raise BagError(text if path is None or str(path) in text else f'config {path}: {text}'
                       ) from None


def single_threaded_blas() -> Any:
    """A context manager holding BLAS to one thread inside its block (restored after):
    ``threadpoolctl.threadpool_limits(limits=1, user_api='blas')``. The batched evaluation's
    GEMMs are large enough for OpenBLAS to start its threads, whose busy waiting on a shared
    machine costs more than it saves; the bag command runs one process that is already busy."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api='blas')


def jazzy_typestore() -> Any:
    """rosbags' type store of ROS 2 Jazzy's messages (decodes and encodes recordings), with
    the package's own ``StampedMatrix`` registered from its definition (``msg/``)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    definition = config.packaged_path(layouts.STAMPED_MATRIX_DEFINITION).read_text('utf-8')
    typestore.register(get_types_from_msg(definition, layouts.STAMPED_MATRIX))
    return typestore


def rosbags_types(typestore: Any) -> MessageTypes:
    """rosbags' message classes of ``typestore`` for :mod:`tensegrity_stiffness.nodes.messages`
    (``float64[]`` fields as float64 arrays)."""
    return MessageTypes(classes=typestore.types,
                        payload=lambda values: np.array(values, dtype=np.float64).reshape(-1))


# ------------------------------------------------------------------------------ processors
class Processor:
    """What both node kinds' processors share: deserializing a message of the recording
    (rosbags' ``typestore``, default Jazzy's) and counting rejections in :attr:`rejected` by
    ``'<topic>: <kind>'``, the first problem's text in :attr:`examples`; answers by source in
    :attr:`answered`. A subclass names its input handlers (:meth:`handlers`, deserialized
    messages) and may take some inputs serialized (:meth:`raw_handlers`)."""

    def __init__(self, typestore: Any | None = None) -> None:
        self.typestore = jazzy_typestore() if typestore is None else typestore
        self.rejected: Counter[str] = Counter()
        self.examples: dict[str, str] = {}
        self.answered: Counter[str] = Counter()

    def handlers(self) -> dict[str, Callable[[Any, int], None]]:
        """The handler ``(msg, log_time)`` of each input (name relative to the node)."""
        raise NotImplementedError

    def raw_handlers(self) -> dict[str, Callable[[bytes, int], None]]:
        """Handlers ``(raw, log_time)`` of inputs taken serialized (deserialized by the
        processor as it needs); none by default."""
        return {}

    def finish(self) -> None:
        """Answer what is pending at the end of the recording."""

    def reject(self, topic: str, problem: Exception | str, kind: str | None = None) -> None:
        """Count a rejected input of ``topic``: of ``kind``, else of the problem's kind
        (:func:`~tensegrity_stiffness.geometry.errors.error_kind`)."""
        if kind is None:
            kind = INVALID if isinstance(problem, str) else error_kind(problem)
        key = f'{topic}: {kind}'
        self.rejected[key] += 1
        self.examples.setdefault(key, str(problem))

    def decode(self, topic: str, raw: bytes, msgtype: str) -> Any:
        """The deserialized message, or None (rejected as undecodable)."""
        try:
            return self.typestore.deserialize_cdr(raw, msgtype)
        except Exception as exc:  # rosbags raises several types on corrupt CDR
            self.reject(topic, f'cannot deserialize: {type(exc).__name__}: {exc}', 'undecodable')
            return None


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


class StiffnessProcessor(Processor):
    """The node's per-input behaviour (``_on_screw``, ``_on_pose``, ``_on_rest_lengths``,
    ``_compute_and_publish``) over a recording, answering in batches with the node's functions
    (:mod:`tensegrity_stiffness.nodes.processing`, :mod:`tensegrity_stiffness.nodes.messages`).

    Feed inputs in log-time order with :meth:`screw_raw` (serialized) or :meth:`screw`,
    :meth:`pose`, :meth:`rest_lengths`; answers go to ``emit`` in chunks (:class:`Answers`),
    rejections are counted as :class:`Processor` counts them. Call :meth:`finish` at the end.
    """

    def __init__(self, settings: JointNodeSettings, emit: Callable[[Answers], None],
                 chunk_size: int = CHUNK_SIZE, typestore: Any | None = None) -> None:
        super().__init__(typestore)
        self.settings = settings
        self.model = settings.model
        self.emit = emit
        self.chunk_size = chunk_size
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

    def handlers(self) -> dict[str, Callable[[Any, int], None]]:
        return {'screw': self.screw, 'pose': self.pose, 'rest_lengths': self.rest_lengths}

    def raw_handlers(self) -> dict[str, Callable[[bytes, int], None]]:
        return {'screw': self.screw_raw}

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
        msg = self.decode('screw', raw, FLOAT64_MULTIARRAY)
        if msg is not None:
            self.screw(msg, log_time)

    def _decode(self) -> None:
        """Check the pending plain screws as :meth:`screw` does, in one batch: the decoded
        values are exactly what ``messages.multiarray_to_array`` returns for them (no data
        offset, six values); a non-finite one goes through that function for its error."""
        if not self._raw:
            return
        raws, times = self._raw, self._raw_times
        self._raw, self._raw_times = [], []
        values = plain_screw_values(raws)
        finite = np.isfinite(values).all(axis=1)
        if not finite.all():
            max_length = self.settings.max_array_length
            deserialize = self.typestore.deserialize_cdr
            for i in np.flatnonzero(~finite):
                try:  # raises the node's 'array contains NaN or inf'
                    multiarray_to_array(deserialize(raws[i], FLOAT64_MULTIARRAY),
                                        expected_length=6, max_length=max_length)
                except ValueError as exc:
                    self.reject('screw', exc)
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
            self.reject('screw', exc)
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
            self.reject('pose', exc)
            return
        self._add('pose', [log_time], [stamp_nanoseconds_or(msg.header.stamp, log_time)],
                  xi[None], T)

    def rest_lengths(self, msg: Any, log_time: int) -> None:
        """A deserialized ``~/rest_lengths`` message (the node's ``_on_rest_lengths``)."""
        self.flush()  # inputs logged before apply the old rest lengths
        try:
            rest = multiarray_to_array(msg, expected_length=self.model.n_strings,
                                       max_length=self.settings.max_array_length)
            self.model = with_rest_lengths(self.model, rest)
        except ValueError as exc:
            self.reject('rest_lengths', exc)
            return
        if self._last_screw is not None:  # the node's _republish_last
            self._add('re-publish', [log_time], [None], self._last_screw[None])
            self.flush()

    def finish(self) -> None:
        self.flush()

    # -------------------------------------------------------------- batched answers
    def flush(self) -> None:
        """Answer the pending inputs with one :func:`joint_outputs_batch`. The first row the
        node would refuse (a non-finite output, a screw the model refuses) splits the chunk:
        the rows before it are answered, it goes through the node's single path
        (``joint_outputs`` and the finite check of ``JointOutputMessages.fill``, whose
        ValueError is the rejection), and the poses after it get their branch again from the
        last answer."""
        self._decode()
        while self._count:
            sources, times, stamps = self._sources, self._times, self._stamps
            screws = np.concatenate(self._screws)
            transforms = self._transforms
            self._sources, self._times, self._stamps, self._screws = [], [], [], []
            self._transforms, self._count = {}, 0
            if stamps[0] is None:
                stamps[0] = self._last_stamp
            outputs, bad = self._batch(screws)
            if bad and outputs is not None:
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

    def _batch(self, screws: FloatArray) -> tuple[JointOutputs | None, int]:
        """The batched outputs of ``screws`` and the index of the first row the node would not
        answer (``len(screws)``: none): a non-finite output, or a screw the model refuses (a
        ValueError of the batch, e.g. a string of zero length; the rows before it are
        evaluated again without it)."""
        try:
            outputs = joint_outputs_batch(self.model, screws)
        except ValueError:
            first = next((i for i, xi in enumerate(screws) if not self._answerable(xi)),
                         len(screws))
            return (joint_outputs_batch(self.model, screws[:first]) if first else None), first
        finite = finite_rows(outputs)
        return outputs, len(screws) if finite.all() else int(np.flatnonzero(~finite)[0])

    def _answerable(self, xi: FloatArray) -> bool:
        try:
            require_finite(joint_outputs(self.model, xi))
        except ValueError:
            return False
        return True

    def _single(self, source: str, log_time: int, stamp: int | None, xi: FloatArray) -> None:
        """One input through the node's own single-screw path."""
        try:
            outputs = joint_outputs(self.model, xi)
        except ValueError as exc:  # the model refuses the screw (the node's _outputs)
            self.reject(source, exc)
            return
        try:  # the check of JointOutputMessages.fill (filling the joint's messages cannot fail)
            require_finite(outputs)
        except ValueError as exc:
            self.reject(source, exc, 'non-finite result')
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


class SpineProcessor(Processor):
    """``spine_node``'s per-input behaviour (``_on_screws``, ``_on_poses``,
    ``_on_rest_lengths``, ``_compute_and_publish``) over a recording, one input at a time with
    the node's functions (:mod:`tensegrity_stiffness.nodes.spine_processing`,
    :mod:`tensegrity_stiffness.nodes.messages`; the node's ``SpineOutputMessages`` with rosbags'
    types of ``typestore``, default Jazzy's, for the messages). Each answer goes to ``emit``
    (:class:`SpineAnswer`, its messages reused by the next answer); rejections are counted as
    :class:`Processor` counts them."""

    def __init__(self, settings: SpineNodeSettings, emit: Callable[[SpineAnswer], None],
                 typestore: Any | None = None) -> None:
        super().__init__(typestore)
        self.settings = settings
        self.emit = emit
        self.types = rosbags_types(self.typestore)
        self.messages = SpineOutputMessages(settings.n_joints, self.types, settings.tool_frame)
        self._last_screws: FloatArray | None = None
        self._last_stamp: int | None = None

    def handlers(self) -> dict[str, Callable[[Any, int], None]]:
        return {'screws': self.screws, 'poses': self.poses, 'rest_lengths': self.rest_lengths}

    def screws(self, msg: Any, log_time: int) -> None:
        """A ``~/screws`` message (the node's ``_on_screws``); stamped with its log time, as the
        node stamps the time of computation."""
        settings = self.settings
        try:
            xi = spine_processing.screws_input(multiarray_to_array(
                msg, max_length=settings.max_array_length), settings.n_joints)
        except ValueError as exc:
            self.reject('screws', exc)
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
            self.reject('poses', exc)
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
            self.reject('rest_lengths', exc)
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
            self.reject(source, exc, exc.kind if isinstance(exc, SingularStiffnessError)
                        else 'non-finite result')
            return
        self._last_screws, self._last_stamp = xi, stamp
        self.answered[source] += 1
        self.emit(SpineAnswer(log_time, source, stamp, outputs, self.messages.messages()))


# ------------------------------------------------------------------------------ structure
@dataclass
class StructureAnswer:
    """One answer of the structure node: the input's log time (ns), its source ('poses',
    'pose_values' or 're-publish'), the library's outputs and the node's filled messages
    (rosbags', in :func:`structure_node.structure_output_layouts` order)."""

    log_time: int
    source: str
    outputs: structure_node.StructureOutputs
    messages: tuple[Any, ...]


class StructureProcessor(Processor):
    """``structure_node``'s per-input behaviour (``_on_poses``, ``_on_pose_values``,
    ``_on_rest_lengths``, ``_compute_and_publish``) over a recording, one input at a time with
    the node's functions (:mod:`tensegrity_stiffness.nodes.structure_node`: its inputs, outputs
    and ``StructureOutputMessages`` with rosbags' types). Each answer goes to ``emit``
    (:class:`StructureAnswer`, its messages reused by the next answer)."""

    def __init__(self, settings: structure_node.StructureNodeSettings,
                 emit: Callable[[StructureAnswer], None], typestore: Any | None = None
                 ) -> None:
        super().__init__(typestore)
        self.settings = settings
        self.emit = emit
        self.types = rosbags_types(self.typestore)
        self.messages = structure_node.StructureOutputMessages(settings.structure, self.types)
        self._last: FloatArray | None = None

    def handlers(self) -> dict[str, Callable[[Any, int], None]]:
        return {'poses': self.poses, 'pose_values': self.pose_values,
                'rest_lengths': self.rest_lengths}

    def poses(self, msg: Any, log_time: int) -> None:
        """A ``~/poses`` message (the node's ``_on_poses``)."""
        settings = self.settings
        try:
            T = structure_node.poses_input(msg.header.frame_id, msg.poses, settings.world_frame,
                                           settings.n_bodies, pose_message_to_transform)
        except ValueError as exc:
            self.reject('poses', exc)
            return
        self._compute(T, log_time, 'poses')

    def pose_values(self, msg: Any, log_time: int) -> None:
        """A ``~/pose_values`` message (the node's ``_on_pose_values``)."""
        settings = self.settings
        try:
            T = structure_node.pose_values_input(multiarray_to_array(
                msg, max_length=settings.max_array_length), settings.structure)
        except ValueError as exc:
            self.reject('pose_values', exc)
            return
        self._compute(T, log_time, 'pose_values')

    def rest_lengths(self, msg: Any, log_time: int) -> None:
        """A ``~/rest_lengths`` message (the node's ``_on_rest_lengths``): in force from its log
        time on; the last answer is re-published under it."""
        try:
            self.settings = structure_node.with_commanded_rest_lengths(
                self.settings, multiarray_to_array(
                    msg, max_length=self.settings.max_array_length))
        except ValueError as exc:
            self.reject('rest_lengths', exc)
            return
        if self._last is not None:
            self._compute(self._last, log_time, 're-publish')

    def _compute(self, T: FloatArray, log_time: int, source: str) -> None:
        settings = self.settings
        try:
            outputs = structure_node.structure_outputs(settings, T)
            self.messages.fill(outputs, self.types.time(log_time), settings.world_frame)
        except ValueError as exc:
            self.reject(source, exc, 'non-finite result')
            return
        self._last = T
        self.answered[source] += 1
        self.emit(StructureAnswer(log_time, source, outputs, self.messages.messages()))


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
        self.stamped = layout.stamped
        if layout.msgtype not in (FLOAT64_MULTIARRAY, layouts.WRENCH_STAMPED,
                                  layouts.STAMPED_MATRIX):
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


# ------------------------------------------------------------------------------ writing
class _CsvSink:
    """One CSV row per answer: log time, source, stamp, then the node kind's columns."""

    def __init__(self, path: Path, columns: Sequence[str]) -> None:
        self._file = path.open('w', newline='')
        self._writer = csv.writer(self._file)
        self._writer.writerow(['log_time_ns', 'source', 'stamp_ns', *columns])

    def write(self, rows: Iterable[Sequence[Any]]) -> None:
        self._writer.writerows(rows)

    def close(self) -> None:
        self._file.close()


def _joint_csv_columns(settings: JointNodeSettings) -> list[str]:
    """The screw, wrench, K, K_c and the tension of each string."""
    w, s, t = layouts.WRENCH_NAMES, layouts.SCREW_NAMES, layouts.TWIST_NAMES
    return [*s, *w, *(f'K_{r}_{c}' for r in w for c in s), *(f'Kc_{r}_{c}' for r in w for c in t),
            *(f'tension_{name}' for name in settings.model.string_names)]


def _joint_csv_rows(a: Answers) -> Iterable[list[Any]]:
    n = len(a)
    values = np.hstack([a.screws, a.wrenches, a.stiffness.reshape(n, 36),
                        a.cartesian_stiffness.reshape(n, 36), a.tensions]).tolist()
    return ([t, source, stamp, *row] for t, source, stamp, row in
            zip(a.log_times.tolist(), a.sources, a.stamps.tolist(), values, strict=True))


def _spine_csv_columns(settings: SpineNodeSettings) -> list[str]:
    """The joints' screws (joint-major), the tip wrench (base frame) and the tip stiffness
    (tool frame, row-major)."""
    w, s, t = layouts.WRENCH_NAMES, layouts.SCREW_NAMES, layouts.TWIST_NAMES
    return [*(f'joint_{i}_{c}' for i in range(1, settings.n_joints + 1) for c in s),
            *(f'tip_{c}' for c in w), *(f'Ktip_{r}_{c}' for r in w for c in t)]


def _spine_csv_rows(a: SpineAnswer) -> Iterable[list[Any]]:
    o = a.outputs
    return [[a.log_time, a.source, a.stamp, *np.concatenate(
        [o.screws.ravel(), o.tip_wrench, o.tip_stiffness_tool.ravel()]).tolist()]]


def _joint_writer(writer: Any, typestore: Any, connections: Sequence[Any],
                  outputs: Sequence[str], settings: JointNodeSettings
                  ) -> Callable[[Answers], None]:
    """Writes a chunk's answers on ``connections`` (of ``outputs``): the templates' rows."""
    output_layouts = layouts.joint_output_layouts(settings.model.string_names)
    templates = [_Template(typestore, output_layouts[name], settings.link1_frame)
                 for name in outputs]

    def write(a: Answers) -> None:
        payloads = dict(zip(layouts.JOINT_OUTPUTS, (
            a.wrenches, a.stiffness, a.cartesian_stiffness, a.tensions, a.interpretation),
            strict=True))
        write_blocks(writer, connections, a.log_times, [template.rows(
            payloads[output_layouts[name].source or name],
            a.stamps if template.stamped else None)
            for name, template in zip(outputs, templates, strict=True)])

    return write


def _spine_writer(writer: Any, typestore: Any, connections: Sequence[Any],
                  outputs: Sequence[str], settings: SpineNodeSettings
                  ) -> Callable[[SpineAnswer], None]:
    """Writes an answer's messages on ``connections`` (of ``outputs``), serialized by
    rosbags."""
    names = list(layouts.spine_output_layouts(settings.n_joints))  # the messages' order
    chosen = [names.index(name) for name in outputs]
    serialize = typestore.serialize_cdr

    def write(a: SpineAnswer) -> None:
        for k, connection in zip(chosen, connections, strict=True):
            writer.write(connection, a.log_time,
                         bytes(serialize(a.messages[k], connection.msgtype)))

    return write


def _structure_csv_columns(settings: structure_node.StructureNodeSettings) -> list[str]:
    """The bodies' wrenches, the tensions and the bar forces."""
    s = settings.structure
    return [*(f'{b}_{c}' for b in s.body_names for c in layouts.WRENCH_NAMES),
            *(f'tension_{name}' for name in s.string_names),
            *(f'bar_{name}' for name in s.bar_names)]


def _structure_csv_rows(a: StructureAnswer) -> Iterable[list[Any]]:
    state = a.outputs.state
    return [[a.log_time, a.source, a.log_time, *np.concatenate(
        [state.wrenches.ravel(), state.tensions, state.bar_forces]).tolist()]]


def _structure_writer(writer: Any, typestore: Any, connections: Sequence[Any],
                      outputs: Sequence[str], settings: structure_node.StructureNodeSettings
                      ) -> Callable[[StructureAnswer], None]:
    """Writes an answer's messages on ``connections`` (of ``outputs``; ``contact_forces`` only
    with a ground), serialized by rosbags."""
    names = list(structure_node.structure_output_layouts(settings.structure))
    chosen = [(names.index(name), c) for name, c in zip(outputs, connections, strict=True)
              if name in names]
    serialize = typestore.serialize_cdr

    def write(a: StructureAnswer) -> None:
        for k, connection in chosen:
            writer.write(connection, a.log_time,
                         bytes(serialize(a.messages[k], connection.msgtype)))

    return write


@dataclass(frozen=True)
class _NodeKind:
    """What :func:`process_bag` does differently for one node kind: its settings from
    ``--config``, its CSV columns and rows, the writer of its answers, its processor
    ``(settings, emit, typestore, chunk_size)``; ``batched``: BLAS on one thread meanwhile
    and the clock read every 1024 inputs (else every input) for the progress reports."""

    settings: Callable[[str | Path | None], Any]
    csv_columns: Callable[[Any], list[str]]
    csv_rows: Callable[[Any], Iterable[Sequence[Any]]]
    writer: Callable[[Any, Any, Sequence[Any], Sequence[str], Any], Callable[[Any], None]]
    processor: Callable[[Any, Callable[[Any], None], Any, int], Processor]
    batched: bool


_NODE_KINDS = {
    'stiffness': _NodeKind(
        node_settings, _joint_csv_columns, _joint_csv_rows, _joint_writer,
        lambda settings, emit, typestore, chunk_size: StiffnessProcessor(
            settings, emit, chunk_size, typestore), batched=True),
    'spine': _NodeKind(
        spine_settings, _spine_csv_columns, _spine_csv_rows, _spine_writer,
        lambda settings, emit, typestore, _: SpineProcessor(settings, emit, typestore),
        batched=False),
    'structure': _NodeKind(
        structure_settings, _structure_csv_columns, _structure_csv_rows, _structure_writer,
        lambda settings, emit, typestore, _: StructureProcessor(settings, emit, typestore),
        batched=False),
}


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


# ------------------------------------------------------------------------------ files
def namespace_prefix(namespace: str) -> str:
    """``'/stiffness_node'`` for ``'stiffness_node'``, ``'/a/b/'`` ...; ``''`` for ``'/'``."""
    parts = [p for p in str(namespace).split('/') if p]
    return ''.join('/' + p for p in parts)


def publisher_prefix(prefix: str, node: str) -> str:
    """The namespace of the node of kind ``node`` that would publish the outputs of inputs read
    under ``prefix``: ``prefix`` itself, unless its last part is the name of another of the
    package's nodes (``/twin/sim_node``: the twin publishes the inputs), which is then replaced
    by the node's own name (``/twin/stiffness_node``)."""
    head, _, last = prefix.rpartition('/')
    own = DEFAULT_NAMESPACES[node].strip('/')
    others = {table.node for table in parameters.node_tables()} - {own}
    return f'{head}/{own}' if last in others else prefix


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


def clear_output(path: Path, overwrite: bool, what: str) -> None:
    """Make room for an output (of the bag command and ``record``): a :class:`BagError` if it
    exists unless ``overwrite``; only a rosbag2 folder (or an empty folder) or a plain file is
    removed."""
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
    #: The namespace of the outputs (:func:`publisher_prefix`, or ``output_namespace``).
    output_namespace: str = ''
    inputs: dict[str, int] = field(default_factory=dict)
    answered: dict[str, int] = field(default_factory=dict)
    written: dict[str, int] = field(default_factory=dict)
    rejected: dict[str, int] = field(default_factory=dict)
    rejection_examples: dict[str, str] = field(default_factory=dict)
    seconds: float = 0.0
    #: Messages of the input topics in the bag's index, read, and why the rest was unreadable
    #: (empty: read whole; :class:`MessageReading`).
    messages_total: int = 0
    messages_read: int = 0
    damage: str = ''

    @property
    def answers(self) -> int:
        return sum(self.answered.values())

    def to_dict(self) -> dict[str, Any]:
        inputs = sum(self.inputs.values())
        return {
            'input': self.input, 'output': self.output, 'storage': self.storage,
            'csv': self.csv, 'namespace': self.namespace or '/',
            'output_namespace': self.output_namespace or '/',
            'inputs': dict(self.inputs), 'answered': dict(self.answered),
            'answers': self.answers, 'written': dict(self.written),
            'rejected': dict(sorted(self.rejected.items())),
            'rejected_total': sum(self.rejected.values()),
            'rejection_examples': dict(sorted(self.rejection_examples.items())),
            'seconds': self.seconds,
            'inputs_per_second': inputs / self.seconds if self.seconds > 0 else None,
            'messages_total': self.messages_total, 'messages_read': self.messages_read,
            'damage': self.damage,
        }


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
                namespace: str | None = None, output_namespace: str | None = None,
                storage: str | None = None, csv_path: str | Path | None = None,
                topics: Sequence[str] | None = None,
                overwrite: bool = False, node: str = 'stiffness',
                progress: Callable[[int, int], None] | None = None,
                chunk_size: int = CHUNK_SIZE, allow_damaged: bool = False) -> BagSummary:
    """Read the node's inputs from the rosbag2 ``input_path`` and write what the node would
    publish to the rosbag2 ``output_path`` (and ``csv_path``); see the module docstring.

    ``node``: 'stiffness' (``stiffness_node``), 'spine' (``spine_node``: its inputs and
    per-input outputs, config ``config/default_spine.yaml`` unless ``config_path``) or
    'structure' (``structure_node``: config its parameter file or a structure file; default the
    packaged 6-bar);
    ``namespace``: the input topics' prefix (default :data:`DEFAULT_NAMESPACES` of the node);
    ``output_namespace``: the outputs' (default: the node that would publish them,
    :func:`publisher_prefix` of ``namespace``);
    ``storage``: 'mcap' or 'sqlite3' (default: the input's); ``topics``: the outputs to write
    (default all); ``progress(done, total)``: inputs read so far of all.
    Raises :class:`BagError` (a ValueError) for the files and options, and when no input
    was answered.
    """
    from rosbags.rosbag2 import Reader
    from rosbags.rosbag2.errors import ReaderError

    started = time.perf_counter()
    if node not in NODE_TOPICS:
        raise BagError(f"--node: unknown node '{node}' (known: {', '.join(NODE_TOPICS)})")
    spec, kind = NODE_TOPICS[node], _NODE_KINDS[node]
    src, out = Path(input_path), Path(output_path)
    csv_file = Path(csv_path) if csv_path is not None else None
    check_input(src)
    if storage is not None and storage not in STORAGES:
        raise BagError(f"unknown storage '{storage}' (mcap or sqlite3)")
    prefix = namespace_prefix(DEFAULT_NAMESPACES[node] if namespace is None else namespace)
    out_prefix = (publisher_prefix(prefix, node) if output_namespace is None
                  else namespace_prefix(output_namespace))
    outputs = _output_topics(topics, out_prefix, tuple(spec.outputs))
    settings = kind.settings(config_path)
    if out.resolve() == src.resolve():
        raise BagError(f'{out}: the output must not be the input')

    try:
        reader = Reader(src)
        reader.open()
    except (ReaderError, OSError, KeyError, ValueError) as exc:
        raise BagError(f'{src}: not a readable rosbag2: {exc}') from None
    try:
        summary = _process(reader, _Job(src, out, csv_file, storage, prefix, out_prefix,
                                        outputs, spec, kind, settings, overwrite, chunk_size),
                           progress)
    finally:
        reader.close()
    summary.seconds = time.perf_counter() - started
    if summary.damage and not allow_damaged:
        _remove_outputs(out, csv_file)
    reading = MessageReading(summary.messages_total, summary.messages_read, summary.damage)
    reading.check(src, allow_damaged)
    if summary.answers == 0:
        _remove_outputs(out, csv_file)
        bad = ', '.join(f'{k} {v}' for k, v in sorted(summary.rejected.items())) or 'no inputs'
        raise BagError(f'{src}: no input could be answered ({bad}); nothing written')
    return summary


def _remove_outputs(out: Path, csv_file: Path | None) -> None:
    shutil.rmtree(out, ignore_errors=True)
    if csv_file is not None:
        csv_file.unlink(missing_ok=True)


@dataclass(frozen=True)
class _Job:
    """The checked options of one :func:`process_bag`."""

    src: Path
    out: Path
    csv_file: Path | None
    storage: str | None
    prefix: str
    out_prefix: str
    outputs: list[str]
    spec: NodeTopics
    kind: _NodeKind
    settings: Any
    overwrite: bool
    chunk_size: int


def _process(reader: Any, job: _Job, progress: Callable[[int, int], None] | None
             ) -> BagSummary:
    """Open the outputs of :func:`process_bag`, run the node kind's processor over the
    recording (:func:`_read`) and sum up."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.errors import WriterError

    src, out, prefix, kind = job.src, job.out, job.prefix, job.kind
    in_storage = _storage_of(src)
    out_storage = job.storage or (in_storage if in_storage in STORAGES else 'mcap')
    wanted = {f'{prefix}/{name}': (name, msgtype) for name, msgtype in job.spec.inputs.items()}
    present = {c.topic: c.msgtype for c in reader.connections}
    if not set(wanted) & set(present):
        have = ', '.join(f'{t} ({m})' for t, m in sorted(present.items())) or 'none'
        raise BagError(f"{src}: none of the topics {', '.join(wanted)} is in the bag; "
                       f'its topics: {have}')
    connections = [c for c in reader.connections if c.topic in wanted]
    summary = BagSummary(input=str(src), output=str(out), storage=out_storage,
                         csv=str(job.csv_file) if job.csv_file else None, namespace=prefix,
                         output_namespace=job.out_prefix)
    clear_output(out, job.overwrite, 'output')
    if job.csv_file is not None:
        clear_output(job.csv_file, job.overwrite, 'csv file')
    typestore = jazzy_typestore()
    try:
        writer = Writer(out, version=9, storage_plugin=StoragePlugin[out_storage.upper()])
        writer.open()
    except (WriterError, OSError) as exc:
        raise BagError(f'{out}: cannot write: {exc}') from None
    csv_sink = None
    try:
        if job.csv_file is not None:
            csv_sink = _CsvSink(job.csv_file, kind.csv_columns(job.settings))
        emit = kind.writer(writer, typestore, [
            writer.add_connection(f'{job.out_prefix}/{name}', job.spec.outputs[name],
                                  typestore=typestore) for name in job.outputs],
            job.outputs, job.settings)
        if csv_sink is not None:
            emit = _and_csv(emit, csv_sink, kind.csv_rows)
        processor = kind.processor(job.settings, emit, typestore, job.chunk_size)
        with single_threaded_blas() if kind.batched else nullcontext():
            inputs, reading = _read(reader, connections, wanted, processor,
                                    1023 if kind.batched else 0, progress)
    finally:
        writer.close()
        if csv_sink is not None:
            csv_sink.close()
    summary.inputs = {name: inputs[name] for name in job.spec.inputs if inputs[name]}
    summary.answered = dict(processor.answered)
    summary.written = {f'{job.out_prefix}/{name}': summary.answers for name in job.outputs}
    summary.rejected = dict(processor.rejected)
    summary.rejection_examples = dict(processor.examples)
    summary.messages_total, summary.messages_read = reading.total, reading.read
    summary.damage = reading.damage
    return summary


def _and_csv(write: Callable[[Any], None], sink: _CsvSink,
             rows: Callable[[Any], Iterable[Sequence[Any]]]) -> Callable[[Any], None]:
    """``write`` an answer, then its CSV ``rows`` to ``sink``."""
    def emit(answer: Any) -> None:
        write(answer)
        sink.write(rows(answer))

    return emit


def _read(reader: Any, connections: list[Any], wanted: Mapping[str, tuple[str, str]],
          processor: Processor, clock_mask: int,
          progress: Callable[[int, int], None] | None
          ) -> tuple[Counter[str], MessageReading]:
    """The read loop of :func:`process_bag`: each message of ``connections`` (log-time order)
    of its expected type to the processor's handler of its input (serialized to a raw
    handler, else deserialized), one of another type rejected; ``progress`` reported at most
    every :data:`PROGRESS_PERIOD` (the clock read when ``done & clock_mask`` is 0). The inputs
    read, by name, and the :class:`MessageReading` (how much of the storage was readable)."""
    handlers, raw_handlers = processor.handlers(), processor.raw_handlers()
    routes = {topic: (name, msgtype, raw_handlers.get(name))
              for topic, (name, msgtype) in wanted.items()}
    total = sum(c.msgcount for c in connections)
    reading = MessageReading(total)
    inputs: Counter[str] = Counter()
    next_report = time.perf_counter() + PROGRESS_PERIOD
    done = 0
    # rosbags yields each storage file in log-time order; the files of a split bag follow
    # each other in time.
    for connection, log_time, raw in reading.messages(reader, connections):
        done += 1
        name, msgtype, raw_handler = routes[connection.topic]
        inputs[name] += 1
        if connection.msgtype != msgtype:
            processor.reject(name, f'message type {connection.msgtype}, expected {msgtype}',
                             'wrong message type')
        elif raw_handler is not None:
            raw_handler(raw, log_time)
        else:
            msg = processor.decode(name, raw, msgtype)
            if msg is not None:
                handlers[name](msg, log_time)
        if progress is not None and not done & clock_mask and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + PROGRESS_PERIOD
            progress(done, total)
    processor.finish()
    if progress is not None:
        progress(done, total)
    return inputs, reading
