"""The bag command's processors: each node's ROS-free processing of one block of recorded
messages (:class:`StiffnessProcessor`, :class:`SpineProcessor`, :class:`StructureProcessor`),
the same as the node's, into its answers (:class:`Answers`, :class:`SpineAnswer`,
:class:`StructureAnswer`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.geometry.errors import INVALID, SingularStiffnessError, error_kind
from tensegrity_stiffness.nodes import spine_node, structure_node
from tensegrity_stiffness.nodes.layouts import FLOAT64_MULTIARRAY
from tensegrity_stiffness.nodes.messages import (
    SpineOutputMessages,
    multiarray_to_array,
    pose_message_to_transform,
    stamp_nanoseconds_or,
)
from tensegrity_stiffness.nodes.spine_node import SpineNodeSettings
from tensegrity_stiffness.nodes.stiffness_node import (
    JointNodeSettings,
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
from tensegrity_stiffness.recordings.bag_topics import CHUNK_SIZE, jazzy_typestore, rosbags_types
from tensegrity_stiffness.recordings.screw_cdr import (
    PLAIN_SCREW_HEAD,
    PLAIN_SCREW_SIZE,
    plain_screw_values,
)

FloatArray = NDArray[np.float64]

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
        if len(raw) == PLAIN_SCREW_SIZE and raw[:16] == PLAIN_SCREW_HEAD:
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
    outputs: spine_node.SpineOutputs
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
            xi = spine_node.screws_input(multiarray_to_array(
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
            xi = spine_node.poses_input(msg.header.frame_id, msg.poses,
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
            rest = spine_node.rest_lengths_input(multiarray_to_array(
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
            outputs = spine_node.spine_outputs(settings.chain, xi, settings.rest_lengths)
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
