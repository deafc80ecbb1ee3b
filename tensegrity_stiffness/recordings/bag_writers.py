"""The bag command's writers: each node's answers as the node's output messages in the output
bag (:func:`write_blocks`) and as CSV rows, for every node kind (:data:`NODE_KINDS`).
"""

from __future__ import annotations

import csv
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.nodes import layouts, structure_node
from tensegrity_stiffness.nodes.layouts import FLOAT64_MULTIARRAY
from tensegrity_stiffness.nodes.messages import (
    NANOSECONDS_PER_SECOND,
    new_message,
    output_writer,
)
from tensegrity_stiffness.nodes.spine_node import SpineNodeSettings
from tensegrity_stiffness.nodes.stiffness_node import JointNodeSettings
from tensegrity_stiffness.recordings.bag_processors import (
    Answers,
    Processor,
    SpineAnswer,
    SpineProcessor,
    StiffnessProcessor,
    StructureAnswer,
    StructureProcessor,
)
from tensegrity_stiffness.recordings.bag_topics import (
    node_settings,
    rosbags_types,
    spine_settings,
    structure_settings,
)

FloatArray = NDArray[np.float64]

# ------------------------------------------------------------------------------ output messages
class OutputTemplate:
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
class CsvSink:
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
    templates = [OutputTemplate(typestore, output_layouts[name], settings.link1_frame)
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
class NodeKind:
    """What :func:`~.bag.process_bag` does differently for one node kind: its settings from
    ``--config``, its CSV columns and rows, the writer of its answers, its processor
    ``(settings, emit, typestore, chunk_size)``; ``batched``: BLAS on one thread meanwhile
    and the clock read every 1024 inputs (else every input) for the progress reports."""

    settings: Callable[[str | Path | None], Any]
    csv_columns: Callable[[Any], list[str]]
    csv_rows: Callable[[Any], Iterable[Sequence[Any]]]
    writer: Callable[[Any, Any, Sequence[Any], Sequence[str], Any], Callable[[Any], None]]
    processor: Callable[[Any, Callable[[Any], None], Any, int], Processor]
    batched: bool


#: The node kinds the bag command replays (its ``--node``), by name.
NODE_KINDS = {
    'stiffness': NodeKind(
        node_settings, _joint_csv_columns, _joint_csv_rows, _joint_writer,
        lambda settings, emit, typestore, chunk_size: StiffnessProcessor(
            settings, emit, chunk_size, typestore), batched=True),
    'spine': NodeKind(
        spine_settings, _spine_csv_columns, _spine_csv_rows, _spine_writer,
        lambda settings, emit, typestore, _: SpineProcessor(settings, emit, typestore),
        batched=False),
    'structure': NodeKind(
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
