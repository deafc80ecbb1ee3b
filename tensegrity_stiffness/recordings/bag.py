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
:mod:`tensegrity_stiffness.nodes.stiffness_node` (:mod:`~tensegrity_stiffness.nodes.spine_node`
for the spine), configured from the node's parameter table
(:mod:`tensegrity_stiffness.nodes.registry`). A bad input is
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
are written by the node kind's writer and the CSV sink; :data:`NODE_KINDS` holds what differs.

``stiffness_node`` is answered in chunks with one batched evaluation
(:func:`~tensegrity_stiffness.nodes.stiffness_node.joint_outputs_batch`, BLAS on one thread
through ``threadpoolctl``); a screw of the plain layout is decoded with its chunk in one
``frombuffer``; an output message is
a serialized template (the node's message of :func:`layouts.joint_output_layouts`, built and
filled once with rosbags' types by :mod:`tensegrity_stiffness.nodes.messages` and serialized by
rosbags) whose payload bytes are replaced; a chunk's messages are written with rosbags' public
``Writer.write`` (:func:`write_blocks`). ``spine_node`` is answered one input at a time, with
the node's messages (:class:`messages.SpineOutputMessages`, filled as the node fills them, with
rosbags' types) serialized by rosbags.
"""

from __future__ import annotations

import shutil
import time
from collections import Counter
from collections.abc import Callable, Iterable, Mapping, Sequence
from contextlib import nullcontext
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.nodes import layouts
from tensegrity_stiffness.nodes.registry import node_tables
from tensegrity_stiffness.recordings.bag_processors import (  # noqa: F401 (public here)
    Answers,
    Processor,
    SpineAnswer,
    SpineProcessor,
    StiffnessProcessor,
    StructureAnswer,
    StructureProcessor,
)
from tensegrity_stiffness.recordings.bag_topics import (  # noqa: F401 (public here)
    CHUNK_SIZE,
    DEFAULT_NAMESPACE,
    DEFAULT_NAMESPACES,
    NODE_TOPICS,
    OUTPUT_NAMES,
    POSE_ARRAY,
    POSE_STAMPED,
    PROGRESS_PERIOD,
    STORAGES,
    BagError,
    DamagedBagError,
    MessageReading,
    NodeTopics,
    jazzy_typestore,
    node_settings,
    rosbags_types,
    single_threaded_blas,
    spine_settings,
    structure_settings,
)
from tensegrity_stiffness.recordings.bag_writers import (  # noqa: F401 (public here)
    NODE_KINDS,
    CsvSink,
    NodeKind,
    write_blocks,
)
from tensegrity_stiffness.recordings.screw_cdr import (  # noqa: F401 (public here)
    PLAIN_SCREW_SIZE,
    plain_screw_values,
)

FloatArray = NDArray[np.float64]

FLOAT64_MULTIARRAY = layouts.FLOAT64_MULTIARRAY


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
    others = {table.node for table in node_tables()} - {own}
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
    spec, kind = NODE_TOPICS[node], NODE_KINDS[node]
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
    kind: NodeKind
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
            csv_sink = CsvSink(job.csv_file, kind.csv_columns(job.settings))
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


def _and_csv(write: Callable[[Any], None], sink: CsvSink,
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
