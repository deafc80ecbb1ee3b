"""Offline: what ``stiffness_node`` would publish, for a whole rosbag2 recording.

Reads ``<namespace>/screw``, ``<namespace>/pose`` and ``<namespace>/rest_lengths`` from a rosbag2
(mcap or sqlite3) with ``rosbags`` (pure Python, no ROS install), in log-time order, and writes a
rosbag2 with the node's five array outputs (``wrench``, ``stiffness``, ``cartesian_stiffness``,
``string_tensions``, ``stiffness_interpretation``): the same message types, layouts, labels
(:mod:`tensegrity_stiffness.layouts`) and frame ids as the node, one of each per answered input,
written at the log time of the input it answers.

The node's behaviour, input by input: inputs are decoded with the node's :mod:`msg_tools`
functions (they read messages by attribute, so rosbags' messages do as well as rclpy's) and
validated as the node validates them; a bad input is skipped and counted by kind. A pose is
turned into a screw on the branch nearest the last answered screw (the config's initial screw
before the first). New rest lengths apply from their log time on and re-publish the last answer,
written at the log time of the rest-lengths message. Header stamps: a pose's stamp when it is
non-zero; where the node stamps the time of computation (screws, zero-stamped poses) the input's
log time; a re-publish keeps the stamp of the answer it repeats, as the node does.

Speed: answers are computed in chunks with one batched :meth:`JointModel.evaluate` call; an
output message is a serialized template (layout, labels, frame id; built once with rosbags)
whose payload bytes are replaced, so no message is serialized per answer.
"""

from __future__ import annotations

import csv
import shutil
import time
from collections import Counter
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

import msg_tools
from tensegrity_stiffness import config, layouts
from tensegrity_stiffness.interpretation import interpretation_vector
from tensegrity_stiffness.joint import JointModel
from tensegrity_stiffness.screw import check_in_chart, log_se3

FloatArray = NDArray[np.float64]

FLOAT64_MULTIARRAY = 'std_msgs/msg/Float64MultiArray'
POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
WRENCH_STAMPED = 'geometry_msgs/msg/WrenchStamped'

DEFAULT_NAMESPACE = '/stiffness_node'
#: Output storages (rosbag2 storage identifiers).
STORAGES = ('mcap', 'sqlite3')
#: Frame id of the outputs and largest accepted input array when the config has none (the
#: node's parameter defaults).
DEFAULT_LINK1_FRAME = 'tensegrity_link1'
DEFAULT_MAX_ARRAY_LENGTH = 1024
#: Answers computed per batched evaluation.
CHUNK_SIZE = 2048
#: Seconds between progress reports.
PROGRESS_PERIOD = 0.2


@dataclass(frozen=True)
class NodeTopics:
    """Input and output topics (names relative to the node, message types) of one node kind.
    ``stiffness`` is ``stiffness_node``; another node kind (the spine node) gets its own entry
    in :data:`NODE_TOPICS` and its own processor."""

    inputs: Mapping[str, str]
    outputs: Mapping[str, str]


NODE_TOPICS: dict[str, NodeTopics] = {
    'stiffness': NodeTopics(
        inputs={'screw': FLOAT64_MULTIARRAY, 'pose': POSE_STAMPED,
                'rest_lengths': FLOAT64_MULTIARRAY},
        outputs={'wrench': WRENCH_STAMPED, 'stiffness': FLOAT64_MULTIARRAY,
                 'cartesian_stiffness': FLOAT64_MULTIARRAY,
                 'string_tensions': FLOAT64_MULTIARRAY,
                 'stiffness_interpretation': FLOAT64_MULTIARRAY}),
}
OUTPUT_NAMES = tuple(NODE_TOPICS['stiffness'].outputs)


class BagError(ValueError):
    """A problem with the command's files or options (the CLI's exit 2, one line)."""


# ------------------------------------------------------------------------------ configuration
@dataclass(frozen=True)
class ProcessingConfig:
    """What the node's per-input path reads from its parameters."""

    model: JointModel
    link1_frame: str
    max_array_length: int

    @classmethod
    def from_file(cls, path: str | Path | None = None) -> ProcessingConfig:
        """The node's configuration for ``--params-file path``: each parameter of the file, the
        packaged config's value for the others (the node declares its parameters with the
        packaged values, then the file overrides those it has). ValueError names the field."""
        packaged = config.parameters(config.load_yaml(config.packaged_config_path()))
        sections: dict[str, dict[str, Any]] = {
            key: dict(packaged.get(key) or {}) for key in ('joint', 'frames', 'limits')}
        if path is not None:
            try:
                given = config.parameters(config.load_yaml(path))
            except ValueError as exc:
                raise BagError(f'config {path}: {exc}') from None
            for key in sections:
                value = given.get(key)
                if value is not None and not isinstance(value, Mapping):
                    raise BagError(f'config {path}: {key} must be a mapping')
                sections[key].update(value or {})
        model = JointModel.from_dict(sections['joint'])
        frame = str(sections['frames'].get('link1', DEFAULT_LINK1_FRAME))
        if not frame.strip():
            raise ValueError('frames.link1 must not be empty')
        max_length = int(sections['limits'].get('max_array_length', DEFAULT_MAX_ARRAY_LENGTH))
        if max_length < 6:
            raise ValueError(f'limits.max_array_length must be >= 6, got {max_length}')
        return cls(model=model, link1_frame=frame, max_array_length=max_length)


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


@dataclass
class _Pending:
    """An accepted input waiting for the next batched evaluation."""

    source: str
    log_time: int
    stamp: int | None       # ns; None: the log time (or, for a re-publish, the repeated stamp)
    screw: FloatArray
    transform: FloatArray | None = None   # a pose's transform (its screw depends on the branch)


class StiffnessProcessor:
    """The node's per-input behaviour (``_on_screw``, ``_on_pose``, ``_on_rest_lengths``,
    ``_compute_and_publish``) over a recording, answering in batches.

    Feed inputs in log-time order with :meth:`screw`, :meth:`pose`, :meth:`rest_lengths`;
    answers go to ``emit`` in chunks (:class:`Answers`), rejections are counted in
    :attr:`rejected` by ``'<topic>: <kind>'``. Call :meth:`finish` at the end.
    """

    def __init__(self, cfg: ProcessingConfig, emit: Callable[[Answers], None],
                 chunk_size: int = CHUNK_SIZE) -> None:
        self.cfg = cfg
        self.model = cfg.model
        self.emit = emit
        self.chunk_size = chunk_size
        self.rejected: Counter[str] = Counter()
        self.examples: dict[str, str] = {}
        self.answered: Counter[str] = Counter()
        self._pending: list[_Pending] = []
        # The last answer (screw, wrench stamp ns), as the node keeps _last_screw/_last_stamp.
        self._last_screw: FloatArray | None = None
        self._last_stamp: int | None = None
        self._evaluated: tuple[Any, FloatArray, NDArray[np.bool_]] | None = None

    def _reject(self, topic: str, problem: str, kind: str | None = None) -> None:
        key = f'{topic}: {kind or rejection_kind(problem)}'
        self.rejected[key] += 1
        self.examples.setdefault(key, problem)

    def _reference(self) -> FloatArray:
        """Branch reference of the next pose: the last accepted screw (answered or pending)."""
        if self._pending:
            return self._pending[-1].screw
        return self._last_screw if self._last_screw is not None else self.model.initial_screw

    # -------------------------------------------------------------- inputs (node callbacks)
    def screw(self, msg: Any, log_time: int) -> None:
        try:
            xi = msg_tools.multiarray_to_array(msg, expected_length=6,
                                               max_length=self.cfg.max_array_length)
        except ValueError as exc:
            self._reject('screw', str(exc))
            return
        # The chart is checked per chunk (check_in_chart); a screw outside it is rejected then.
        self._add(_Pending('screw', log_time, None, xi))

    def pose(self, msg: Any, log_time: int) -> None:
        try:
            frame = msg.header.frame_id
            if frame and frame != self.cfg.link1_frame:
                raise ValueError(f"header.frame_id '{frame}' is not link 1's frame "
                                 f"'{self.cfg.link1_frame}'")
            T = msg_tools.pose_to_transform(msg.pose)
            xi = log_se3(T, reference=self._reference())
        except ValueError as exc:
            self._reject('pose', str(exc))
            return
        stamp = msg.header.stamp
        ns = int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)
        self._add(_Pending('pose', log_time, ns if ns != 0 else None, xi, T))

    def rest_lengths(self, msg: Any, log_time: int) -> None:
        self.flush()  # inputs logged before apply the old rest lengths
        try:
            rest = msg_tools.multiarray_to_array(msg, expected_length=self.model.n_strings,
                                                 max_length=self.cfg.max_array_length)
            self.model = self.model.with_rest_lengths(rest)
        except ValueError as exc:
            self._reject('rest_lengths', str(exc))
            return
        if self._last_screw is not None:  # the node's _republish_last
            self._pending.append(_Pending('re-publish', log_time, self._last_stamp,
                                          self._last_screw))
            self.flush()

    def finish(self) -> None:
        self.flush()

    # -------------------------------------------------------------- batched answers
    def _add(self, item: _Pending) -> None:
        self._pending.append(item)
        if len(self._pending) >= self.chunk_size:
            self.flush()

    def flush(self) -> None:
        """Answer the pending inputs. The first one the node would reject (a screw outside the
        chart, a non-finite result) splits the chunk: the inputs before it are answered, the
        poses after it get their branch again from the last answer."""
        while self._pending:
            items, self._pending = self._pending, []
            screws = np.array([p.screw for p in items])
            bad = self._first_rejected(items, screws)
            if bad is None:
                self._answer(items, screws)
                return
            index, topic, problem, kind = bad
            if index:
                self._answer(items[:index], screws[:index])
            self._reject(topic, problem, kind)
            for item in items[index + 1:]:
                if item.transform is not None:
                    reference = self._reference()
                    item.screw = log_se3(item.transform, reference=reference)
                self._pending.append(item)

    def _first_rejected(self, items: list[_Pending], screws: FloatArray
                        ) -> tuple[int, str, str, str | None] | None:
        """(index, topic, problem, kind) of the first pending input the node would reject."""
        is_screw = np.array([p.source == 'screw' for p in items])
        first = len(items)
        found: tuple[int, str, str, str | None] | None = None
        try:
            check_in_chart(screws[is_screw])
        except ValueError:
            for i in np.flatnonzero(is_screw):
                try:
                    check_in_chart(screws[i])
                except ValueError as exc:
                    first = int(i)
                    found = (first, 'screw', str(exc), None)
                    break
        if first == 0:
            return found
        self._evaluated = self._evaluate(screws[:first])
        finite = self._evaluated[-1]
        if not finite.all():
            i = int(np.flatnonzero(~finite)[0])
            source = items[i].source
            return (i, source, 'an output is not finite (NaN or inf)', 'non-finite result')
        return found

    def _evaluate(self, screws: FloatArray) -> tuple[Any, FloatArray, NDArray[np.bool_]]:
        """Batched state, interpretation vectors and a per-row finite mask of every output."""
        with np.errstate(all='ignore'):
            state = self.model.evaluate(screws.reshape(-1, 6))
            interp = np.array([interpretation_vector(K) for K in state.stiffness]
                              ).reshape(-1, layouts.INTERPRETATION_SIZE)
        n = len(screws)
        finite = (np.isfinite(state.wrench).all(axis=1)
                  & np.isfinite(state.stiffness.reshape(n, -1)).all(axis=1)
                  & np.isfinite(state.cartesian_stiffness.reshape(n, -1)).all(axis=1)
                  & np.isfinite(state.tensions).all(axis=1)
                  & np.isfinite(interp).all(axis=1))
        return state, interp, finite

    def _answer(self, items: list[_Pending], screws: FloatArray) -> None:
        """Emit the answers of ``items`` (the first rows of the last evaluation)."""
        state, interp, _ = self._evaluated
        n = len(items)
        stamps = np.array([p.log_time if p.stamp is None else p.stamp for p in items],
                          dtype=np.int64)
        answers = Answers(
            log_times=np.array([p.log_time for p in items], dtype=np.int64),
            sources=[p.source for p in items], stamps=stamps, screws=screws,
            wrenches=state.wrench[:n], stiffness=state.stiffness[:n],
            cartesian_stiffness=state.cartesian_stiffness[:n], tensions=state.tensions[:n],
            interpretation=interp[:n])
        self._last_screw = screws[n - 1].copy()
        self._last_stamp = int(stamps[n - 1])
        self.answered.update(answers.sources)
        self.emit(answers)


# ------------------------------------------------------------------------------ output messages
def _multiarray(typestore: Any, dims: Sequence[tuple[str, int, int]], size: int) -> Any:
    """A rosbags ``Float64MultiArray`` with the layout ``dims`` and ``size`` zeros."""
    types = typestore.types
    dim_type = types['std_msgs/msg/MultiArrayDimension']
    layout = types['std_msgs/msg/MultiArrayLayout'](
        dim=[dim_type(label=label, size=n, stride=stride) for label, n, stride in dims],
        data_offset=0)
    return types[FLOAT64_MULTIARRAY](layout=layout, data=np.zeros(size))


def output_messages(typestore: Any, string_names: Sequence[str], link1_frame: str
                    ) -> dict[str, Any]:
    """The node's output messages (zero payload) as rosbags messages: layouts and labels of
    :mod:`tensegrity_stiffness.layouts`, the wrench in ``link1_frame``."""
    types = typestore.types
    vector3 = types['geometry_msgs/msg/Vector3']
    header = types['std_msgs/msg/Header'](
        stamp=types['builtin_interfaces/msg/Time'](sec=0, nanosec=0), frame_id=link1_frame)
    wrench = types[WRENCH_STAMPED](
        header=header, wrench=types['geometry_msgs/msg/Wrench'](
            force=vector3(x=0.0, y=0.0, z=0.0), torque=vector3(x=0.0, y=0.0, z=0.0)))
    n = len(string_names)
    return {
        'wrench': wrench,
        'stiffness': _multiarray(typestore, layouts.matrix_dims(
            6, 6, layouts.STIFFNESS_ROW_LABEL, layouts.STIFFNESS_COL_LABEL), 36),
        'cartesian_stiffness': _multiarray(typestore, layouts.matrix_dims(
            6, 6, layouts.STIFFNESS_ROW_LABEL, layouts.CARTESIAN_STIFFNESS_COL_LABEL), 36),
        'string_tensions': _multiarray(
            typestore, layouts.vector_dims(n, layouts.tensions_label(string_names)), n),
        'stiffness_interpretation': _multiarray(
            typestore, layouts.vector_dims(layouts.INTERPRETATION_SIZE,
                                           layouts.INTERPRETATION_LABEL),
            layouts.INTERPRETATION_SIZE),
    }


class _Template:
    """Serialized bytes of one output message whose payload ends the message: ``size`` float64
    values (little-endian CDR, no padding after them), and for a ``WrenchStamped`` the header
    stamp (sec int32, nanosec uint32) right after the 4-byte encapsulation header. Rows of a
    chunk are this template with those bytes replaced (checked against rosbags at build)."""

    def __init__(self, typestore: Any, msgtype: str, msg: Any, size: int,
                 stamped: bool) -> None:
        self.size, self.stamped = size, stamped
        probe = np.arange(1.0, size + 1.0)
        self._set(msg, probe)
        if stamped:
            msg.header.stamp.sec, msg.header.stamp.nanosec = 1234567, 89
        raw = np.frombuffer(bytes(typestore.serialize_cdr(msg, msgtype)), dtype=np.uint8)
        payload = raw[raw.size - 8 * size:].view('<f8')
        stamp_ok = not stamped or raw[4:12].view('<i4').tolist() == [1234567, 89]
        if raw[:2].tolist() != [0, 1] or not np.array_equal(payload, probe) or not stamp_ok:
            raise RuntimeError(f'{msgtype}: unexpected CDR layout')  # a rosbags change
        self.raw = raw

    @staticmethod
    def _set(msg: Any, values: FloatArray) -> None:
        if hasattr(msg, 'wrench'):
            f, t = msg.wrench.force, msg.wrench.torque
            f.x, f.y, f.z, t.x, t.y, t.z = (float(v) for v in values)
        else:
            msg.data = values.copy()

    def rows(self, values: FloatArray, stamps: NDArray[np.int64] | None = None
             ) -> NDArray[np.uint8]:
        """(N, bytes) serialized messages with payloads ``values`` (N, size)."""
        n = len(values)
        out = np.empty((n, self.raw.size), dtype=np.uint8)
        out[:] = self.raw
        out[:, self.raw.size - 8 * self.size:] = np.ascontiguousarray(
            values.reshape(n, self.size), dtype='<f8').view(np.uint8)
        if self.stamped:
            sec, nanosec = np.divmod(stamps, 1_000_000_000)
            stamp = np.empty((n, 2), dtype='<i4')
            stamp[:, 0] = sec
            stamp[:, 1] = nanosec.astype(np.uint32).view(np.int32)
            out[:, 4:12] = stamp.view(np.uint8)
        return out


# ------------------------------------------------------------------------------ files
def _typestore() -> Any:
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


def _check_input(path: Path) -> None:
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


def _output_topics(topics: Sequence[str] | None, prefix: str) -> list[str]:
    """Output names (of :data:`OUTPUT_NAMES`) selected by ``--topics`` (relative or full)."""
    if not topics:
        return list(OUTPUT_NAMES)
    chosen = []
    for topic in topics:
        name = topic[len(prefix) + 1:] if prefix and topic.startswith(prefix + '/') else topic
        name = name.lstrip('/') if not prefix else name
        if name not in OUTPUT_NAMES:
            raise BagError(f"--topics: unknown output '{topic}' (outputs: "
                           f"{', '.join(OUTPUT_NAMES)})")
        if name not in chosen:
            chosen.append(name)
    return [name for name in OUTPUT_NAMES if name in chosen]


def process_bag(input_path: str | Path, output_path: str | Path, *,
                config_path: str | Path | None = None,
                namespace: str = DEFAULT_NAMESPACE, storage: str | None = None,
                csv_path: str | Path | None = None, topics: Sequence[str] | None = None,
                overwrite: bool = False, node: str = 'stiffness',
                progress: Callable[[int, int], None] | None = None,
                chunk_size: int = CHUNK_SIZE) -> BagSummary:
    """Read the node's inputs from the rosbag2 ``input_path`` and write what the node would
    publish to the rosbag2 ``output_path`` (and ``csv_path``); see the module docstring.

    ``storage``: 'mcap' or 'sqlite3' (default: the input's); ``topics``: the outputs to write
    (default all five); ``progress(done, total)``: inputs read so far of all.
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
    _check_input(src)
    if storage is not None and storage not in STORAGES:
        raise BagError(f"unknown storage '{storage}' (mcap or sqlite3)")
    prefix = namespace_prefix(namespace)
    outputs = _output_topics(topics, prefix)
    cfg = ProcessingConfig.from_file(config_path)
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
        typestore = _typestore()
        summary.written = dict.fromkeys(f'{prefix}/{name}' for name in outputs)
        try:
            writer = Writer(out, version=9,
                            storage_plugin=StoragePlugin[out_storage.upper()])
            writer.open()
        except (WriterError, OSError) as exc:
            raise BagError(f'{out}: cannot write: {exc}') from None
        csv_sink = None
        try:
            csv_sink = _CsvSink(csv_file, cfg.model.string_names) if csv_file else None
            summary = _run(reader, connections, wanted, writer, typestore, cfg, outputs,
                           spec, prefix, csv_sink, summary, total, progress, chunk_size)
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


def _run(reader: Any, connections: list[Any], wanted: Mapping[str, tuple[str, str]],
         writer: Any, typestore: Any, cfg: ProcessingConfig, outputs: list[str],
         spec: NodeTopics, prefix: str, csv_sink: _CsvSink | None, summary: BagSummary,
         total: int, progress: Callable[[int, int], None] | None,
         chunk_size: int) -> BagSummary:
    """The read - process - write loop of :func:`process_bag`."""
    messages = output_messages(typestore, cfg.model.string_names, cfg.link1_frame)
    sizes = {'wrench': 6, 'stiffness': 36, 'cartesian_stiffness': 36,
             'string_tensions': cfg.model.n_strings,
             'stiffness_interpretation': layouts.INTERPRETATION_SIZE}
    templates = {name: _Template(typestore, spec.outputs[name], messages[name], sizes[name],
                                 name == 'wrench') for name in outputs}
    out_connections = {name: writer.add_connection(f'{prefix}/{name}', spec.outputs[name],
                                                   typestore=typestore) for name in outputs}
    written = Counter()

    def emit(a: Answers) -> None:
        payloads = {'wrench': a.wrenches, 'stiffness': a.stiffness,
                    'cartesian_stiffness': a.cartesian_stiffness,
                    'string_tensions': a.tensions,
                    'stiffness_interpretation': a.interpretation}
        blocks = [(out_connections[name], templates[name].rows(
            payloads[name], a.stamps if name == 'wrench' else None)) for name in outputs]
        write = writer.write
        for i, t in enumerate(a.log_times.tolist()):
            for connection, rows in blocks:
                write(connection, t, rows[i].tobytes())
        for name in outputs:
            written[name] += len(a)
        if csv_sink is not None:
            csv_sink.write(a)

    processor = StiffnessProcessor(cfg, emit, chunk_size=chunk_size)
    handlers = {'screw': processor.screw, 'pose': processor.pose,
                'rest_lengths': processor.rest_lengths}
    inputs: Counter[str] = Counter()
    deserialize = typestore.deserialize_cdr
    next_report = time.perf_counter() + PROGRESS_PERIOD
    done = 0
    for connection, log_time, raw in _messages(reader, connections):
        done += 1
        name, msgtype = wanted[connection.topic]
        inputs[name] += 1
        if connection.msgtype != msgtype:
            processor._reject(name, f'message type {connection.msgtype}, expected {msgtype}',
                              'wrong message type')
            continue
        try:
            msg = deserialize(raw, msgtype)
        except Exception as exc:  # rosbags raises several types on corrupt CDR
            processor._reject(name, f'cannot deserialize: {type(exc).__name__}: {exc}',
                              'undecodable')
            continue
        handlers[name](msg, log_time)
        if progress is not None and done % 256 == 0 and time.perf_counter() >= next_report:
            next_report = time.perf_counter() + PROGRESS_PERIOD
            progress(done, total)
    processor.finish()
    if progress is not None:
        progress(done, total)
    summary.inputs = {name: inputs[name] for name in spec.inputs if inputs[name]}
    summary.answered = dict(processor.answered)
    summary.written = {f'{prefix}/{name}': written[name] for name in outputs}
    summary.rejected = dict(processor.rejected)
    summary.rejection_examples = dict(processor.examples)
    return summary


def _messages(reader: Any, connections: list[Any]) -> Iterator[tuple[Any, int, bytes]]:
    """The messages of ``connections`` in log-time order (rosbags yields each storage file in
    log-time order; the files of a split bag follow each other in time)."""
    yield from reader.messages(connections=connections)
