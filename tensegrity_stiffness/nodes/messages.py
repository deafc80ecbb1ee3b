"""The nodes' messages, read and written by attribute, for any ROS 2 message implementation.

rclpy's generated classes (:mod:`tensegrity_stiffness.ros.conversions`, the nodes) and rosbags'
types (the bag command,
which runs without a ROS install) have the same fields. This module reads the inputs and builds
and refills the outputs through those fields only, so it imports neither: a
:class:`MessageTypes` names the implementation (its classes by ROS type name, and how it holds a
float64 payload).

Inputs: :func:`multiarray_to_array` (the validated payload of a ``Float64MultiArray``) and
:func:`pose_message_to_transform` (a ``Pose``). Outputs: :class:`OutputMessages`, preallocated
messages of :class:`~tensegrity_stiffness.nodes.layouts.OutputLayout` s refilled per input
(one writer per message type, :func:`output_writer`); the per-input outputs of
``stiffness_node`` and ``spine_node``, :class:`JointOutputMessages` and
:class:`SpineOutputMessages` (one finite check of every output, then each message gets its
array without a second check), and the per-estimate outputs of the estimators,
:class:`EstimatorOutputMessages` and :class:`SpineEstimatorOutputMessages` (checked by their
processing), each filled from its node's output table.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import (
    BadDataOffsetError,
    OversizedArrayError,
    WrongLengthError,
)
from tensegrity_stiffness.geometry.quaternion import (
    QUATERNION_UNIT_TOLERANCE,
    ROTATION_TOLERANCE,
    quaternion_to_rotation,
    rotation_to_quaternion,
    rotation_to_quaternion_unchecked,
)
from tensegrity_stiffness.geometry.validation import finite_array_of_shape, require_all_finite
from tensegrity_stiffness.nodes.layouts import (
    ESTIMATOR_OUTPUT_TABLE,
    FLOAT64_MULTIARRAY,
    JOINT_OUTPUT_TABLE,
    JOINT_OUTPUTS,
    POSE_STAMPED,
    POSE_WITH_COVARIANCE_STAMPED,
    SPINE_ESTIMATOR_OUTPUT_TABLE,
    SPINE_OUTPUT_TABLE,
    SPINE_OUTPUTS,
    STAMPED_MATRIX,
    WRENCH_STAMPED,
    OutputLayout,
    estimator_output_layouts,
    joint_output_layouts,
    spine_estimator_output_layouts,
    spine_output_layouts,
    table_arrays,
)

if TYPE_CHECKING:  # the outputs' types (the node modules are not loaded for them)
    from tensegrity_stiffness.nodes.estimator_node import EstimatorOutputs
    from tensegrity_stiffness.nodes.spine_estimator_node import SpineEstimatorOutputs
    from tensegrity_stiffness.nodes.spine_node import SpineOutputs
    from tensegrity_stiffness.nodes.stiffness_node import JointOutputs

FloatArray = NDArray[np.float64]

#: Largest element count accepted from an incoming message unless the caller says otherwise.
DEFAULT_MAX_LENGTH = 4096
NANOSECONDS_PER_SECOND = 1_000_000_000
_MAX_SECONDS = 2**31 - 1  # builtin_interfaces/Time.sec is int32


# ------------------------------------------------------------------------------ inputs
def multiarray_to_array(msg: Any, expected_length: int | None = None,
                        max_length: int = DEFAULT_MAX_LENGTH) -> FloatArray:
    """Validated flat copy of the payload of a ``Float64MultiArray``, shape (n,).

    ``layout.data_offset`` is honoured (elements before it are skipped). Checks, in order:
    the payload length against ``max_length`` (before any conversion, so an oversized message
    costs nothing), the data offset, the length against ``expected_length``, then NaN / inf.

    Raises
    ------
    ValueError
        ``'too many elements'``, ``'data_offset'``, ``'expected N values'`` or ``'NaN or inf'``
        (:mod:`~tensegrity_stiffness.geometry.errors`: ``OversizedArrayError``,
        ``BadDataOffsetError``, ``WrongLengthError``, ``NotFiniteError``).
    """
    values = multiarray_payload(msg, max_length)
    if expected_length is not None and values.size != expected_length:
        raise WrongLengthError(f'expected {expected_length} values, got {values.size}')
    return finite_array_of_shape('array', values, None)


def multiarray_payload(msg: Any, max_length: int = DEFAULT_MAX_LENGTH) -> FloatArray:
    """The payload of a ``Float64MultiArray`` from ``layout.data_offset`` on, as float64, NaN and
    inf kept (measured arrays use NaN for "not measured"); ValueError when it has more than
    ``max_length`` elements (checked before any conversion) or a bad data offset."""
    n_total = len(msg.data)
    if n_total > max_length:
        raise OversizedArrayError(f'too many elements: {n_total} > max_length {max_length}')
    offset = int(msg.layout.data_offset)
    if offset > n_total:
        raise BadDataOffsetError(f'data_offset {offset} exceeds the {n_total} data elements')
    return np.array(msg.data, dtype=np.float64)[offset:]


def pose_message_to_transform(pose: Any,
                      unit_tolerance: float = QUATERNION_UNIT_TOLERANCE) -> FloatArray:
    """(4, 4) homogeneous transform of a ``geometry_msgs/Pose`` (position in m).

    The orientation is validated as in :func:`quaternion_to_rotation` (finite, non-zero, unit
    norm within ``unit_tolerance``; renormalised within it).

    Raises
    ------
    ValueError
        Non-finite position, or an invalid orientation quaternion.
    """
    p = finite_array_of_shape('pose position',
                              [pose.position.x, pose.position.y, pose.position.z], None)
    o = pose.orientation
    T = np.eye(4)
    T[:3, :3] = quaternion_to_rotation([o.x, o.y, o.z, o.w], unit_tolerance=unit_tolerance)
    T[:3, 3] = p
    return T


# ------------------------------------------------------------------------------ output fields
def pose_values(transform: ArrayLike, tolerance: float = ROTATION_TOLERANCE
                ) -> tuple[list[float], list[float]]:
    """Position ``[x y z]`` and quaternion ``[x y z w]`` (``w >= 0``) of a (4, 4) homogeneous
    transform, as a ``geometry_msgs/Pose`` holds them.

    Raises
    ------
    ValueError
        If T is not finite (4, 4), its last row is not [0 0 0 1] within ``tolerance``, or its
        rotation block is not a rotation (see :func:`rotation_to_quaternion`).
    """
    T = finite_array_of_shape('transform', transform, (4, 4))
    if float(np.max(np.abs(T[3] - np.array([0.0, 0.0, 0.0, 1.0])))) > tolerance:
        raise ValueError(f'transform last row must be [0 0 0 1], got {T[3].tolist()}')
    q = rotation_to_quaternion(T[:3, :3], tolerance=tolerance)
    return T[:3, 3].tolist(), np.asarray(q, dtype=np.float64).tolist()


def write_pose(msg: Any, transform: ArrayLike) -> Any:
    """Write the pose of a (4, 4) transform into an existing ``Pose`` (:func:`pose_values`'
    checks; nothing is written if they fail)."""
    (px, py, pz), (qx, qy, qz, qw) = pose_values(transform)
    p, o = msg.position, msg.orientation
    p.x, p.y, p.z = px, py, pz
    o.x, o.y, o.z, o.w = qx, qy, qz, qw
    return msg


def write_wrench(msg: Any, wrench: FloatArray) -> Any:
    """Write a (6,) array ``[fx fy fz mx my mz]`` already checked finite into an existing
    ``Wrench``."""
    f, t = msg.force, msg.torque
    f.x, f.y, f.z, t.x, t.y, t.z = wrench.tolist()
    return msg


def stamp_nanoseconds(stamp: Any) -> int:
    """Integer nanoseconds of a ``builtin_interfaces/Time`` of any message implementation
    (exact)."""
    return int(stamp.sec) * NANOSECONDS_PER_SECOND + int(stamp.nanosec)


def stamp_is_set(stamp: Any) -> bool:
    """False for a zero stamp, which every input reader takes to mean "now": the node's clock
    at arrival, or the log time of a recorded message (the nodes and the bag command alike)."""
    return bool(stamp.sec or stamp.nanosec)


def stamp_nanoseconds_or(stamp: Any, now_ns: int) -> int:
    """:func:`stamp_nanoseconds`, or ``now_ns`` for a zero stamp (:func:`stamp_is_set`)."""
    return stamp_nanoseconds(stamp) if stamp_is_set(stamp) else now_ns


def stamp_parts(nanoseconds: int) -> tuple[int, int]:
    """``(sec, nanosec)`` of a ``builtin_interfaces/Time`` for a non-negative integer count of
    nanoseconds.

    Raises
    ------
    ValueError
        If negative or beyond the int32 seconds range of ``Time.sec``.
    """
    ns = int(nanoseconds)
    if ns < 0:
        raise ValueError(f'stamp must be non-negative, got {ns} ns')
    sec, nanosec = divmod(ns, NANOSECONDS_PER_SECOND)
    if sec > _MAX_SECONDS:
        raise ValueError(f'stamp {sec} s exceeds the int32 range of Time.sec')
    return sec, nanosec


# ------------------------------------------------------------------------------ implementations
@dataclass(frozen=True)
class MessageTypes:
    """A message implementation: ``classes[name]`` builds the message ``name``
    (``'std_msgs/msg/Header'`` ...) from keyword fields; ``payload(values)`` is what its
    ``float64[]`` fields hold for a float64 array (row-major, flattened)."""

    classes: Mapping[str, Callable[..., Any]]
    payload: Callable[[FloatArray], Any]

    def time(self, nanoseconds: int) -> Any:
        """A ``builtin_interfaces/Time`` (:func:`stamp_parts`' checks)."""
        sec, nanosec = stamp_parts(nanoseconds)
        return self.classes['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)


#: The ROS type names :func:`new_message` builds with (every field given, as rosbags needs).
MESSAGE_CLASS_NAMES = (
    'builtin_interfaces/msg/Time', 'std_msgs/msg/Header', 'std_msgs/msg/MultiArrayDimension',
    'std_msgs/msg/MultiArrayLayout', FLOAT64_MULTIARRAY, 'geometry_msgs/msg/Vector3',
    'geometry_msgs/msg/Wrench', WRENCH_STAMPED, 'geometry_msgs/msg/Point',
    'geometry_msgs/msg/Quaternion', 'geometry_msgs/msg/Pose', POSE_STAMPED, STAMPED_MATRIX,
    'geometry_msgs/msg/PoseWithCovariance', POSE_WITH_COVARIANCE_STAMPED)


def multiarray(dims: Sequence[tuple[str, int, int]], values: FloatArray,
               types: MessageTypes) -> Any:
    """A ``Float64MultiArray`` with the layout ``dims`` ((label, size, stride) each, e.g.
    :func:`~tensegrity_stiffness.nodes.layouts.matrix_dims`) and the payload ``values`` (checked
    by the caller)."""
    c = types.classes
    dim = c['std_msgs/msg/MultiArrayDimension']
    return c[FLOAT64_MULTIARRAY](
        layout=c['std_msgs/msg/MultiArrayLayout'](
            dim=[dim(label=label, size=size, stride=stride) for label, size, stride in dims],
            data_offset=0),
        data=types.payload(values))


def new_message(layout: OutputLayout, types: MessageTypes) -> Any:
    """A message of ``layout`` with every field set: a ``Float64MultiArray`` with the layout's
    dimensions and a zero payload, or a stamped wrench / pose (with covariance) of zeros
    (identity orientation) with a zero stamp and an empty frame id."""
    c = types.classes
    if layout.msgtype == FLOAT64_MULTIARRAY:
        return multiarray(layout.dims, np.zeros(layout.size), types)
    header = c['std_msgs/msg/Header'](stamp=types.time(0), frame_id='')
    if layout.msgtype == STAMPED_MATRIX:
        (row_label, rows, _), (column_label, cols, _) = layout.dims
        return c[STAMPED_MATRIX](header=header, row_label=row_label, column_label=column_label,
                                 rows=rows, cols=cols, data=types.payload(np.zeros(rows * cols)))
    if layout.msgtype == WRENCH_STAMPED:
        vector3 = c['geometry_msgs/msg/Vector3']
        return c[WRENCH_STAMPED](header=header, wrench=c['geometry_msgs/msg/Wrench'](
            force=vector3(x=0.0, y=0.0, z=0.0), torque=vector3(x=0.0, y=0.0, z=0.0)))
    pose = c['geometry_msgs/msg/Pose'](
        position=c['geometry_msgs/msg/Point'](x=0.0, y=0.0, z=0.0),
        orientation=c['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0))
    if layout.msgtype == POSE_STAMPED:
        return c[POSE_STAMPED](header=header, pose=pose)
    if layout.msgtype == POSE_WITH_COVARIANCE_STAMPED:
        # a float64[36] field: a numpy array, as both implementations hold it
        return c[POSE_WITH_COVARIANCE_STAMPED](header=header, pose=c[
            'geometry_msgs/msg/PoseWithCovariance'](pose=pose, covariance=np.zeros(36)))
    raise ValueError(f'no output message of type {layout.msgtype}')


#: Writes one checked array into its message: ``writer(msg, values, stamp, frame_id)``.
Writer = Callable[[Any, FloatArray, Any, str], None]


def write_wrench_stamped(msg: Any, values: FloatArray, stamp: Any, frame_id: str) -> None:
    """A WrenchStamped's header and ``[fx fy fz mx my mz]``."""
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    write_wrench(msg.wrench, values)


def write_pose_stamped(msg: Any, values: FloatArray, stamp: Any, frame_id: str) -> None:
    """A PoseStamped's pose of a (4, 4) transform and its header (ValueError, and nothing
    written, if the rotation block is not a rotation)."""
    write_pose(msg.pose, values)
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id


def write_pose_with_covariance_stamped(msg: Any, values: tuple[FloatArray, FloatArray],
                                       stamp: Any, frame_id: str) -> None:
    """A PoseWithCovarianceStamped's header, pose of a (4, 4) transform and (6, 6) covariance
    (row-major), ``values = (transform, covariance)``. The transform is an estimate's (a
    rotation by construction, checked finite): its rotation is not checked again."""
    transform, covariance = values
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    pose = msg.pose.pose
    pose.position.x, pose.position.y, pose.position.z = transform[:3, 3].tolist()
    o = pose.orientation
    o.x, o.y, o.z, o.w = rotation_to_quaternion_unchecked(transform[:3, :3]).tolist()
    # A float64[36] field takes a numpy array of 36 as it is (rclpy checks any other sequence
    # value by value): a copy, as the message keeps it.
    msg.pose.covariance = np.array(covariance, dtype=np.float64).reshape(36)


def stamped_matrix_writer(types: MessageTypes) -> Writer:
    """The :data:`Writer` of a ``StampedMatrix``: its header and data (labels and counts,
    set once, stay)."""
    payload = types.payload

    def write_stamped_matrix(msg: Any, values: FloatArray, stamp: Any, frame_id: str) -> None:
        msg.header.stamp = stamp
        msg.header.frame_id = frame_id
        msg.data = payload(values)

    return write_stamped_matrix


def output_writer(layout: OutputLayout, types: MessageTypes) -> Writer:
    """The :data:`Writer` of a message of ``layout``: a ``Float64MultiArray``'s data (its
    layout, labelled once, stays), or a stamped message's header and fields."""
    if layout.msgtype == WRENCH_STAMPED:
        return write_wrench_stamped
    if layout.msgtype == POSE_STAMPED:
        return write_pose_stamped
    if layout.msgtype == POSE_WITH_COVARIANCE_STAMPED:
        return write_pose_with_covariance_stamped
    if layout.msgtype == STAMPED_MATRIX:
        return stamped_matrix_writer(types)
    return payload_writer(types)


def payload_writer(types: MessageTypes) -> Writer:
    """The :data:`Writer` of a ``Float64MultiArray``'s data in ``types``' payload form (its
    layout, labelled once, stays; stamp and frame are not used)."""
    payload = types.payload

    def write_payload(msg: Any, values: FloatArray, stamp: Any, frame_id: str) -> None:
        msg.data = payload(values)

    return write_payload


def fill_outputs(messages: Sequence[Any], arrays: Sequence[FloatArray],
                 writers: Sequence[Writer], stamp: Any, frame_id: str,
                 wanted: Sequence[bool] | None = None) -> None:
    """Write ``arrays[k]`` into ``messages[k]`` with ``writers[k]`` for every ``k`` flagged in
    ``wanted`` (default all)."""
    for k, (msg, values, write) in enumerate(zip(messages, arrays, writers, strict=True)):
        if wanted is None or wanted[k]:
            write(msg, values, stamp, frame_id)


# ------------------------------------------------------------------------------ node outputs
class OutputMessages:
    """One preallocated message per output of ``layouts`` (topic -> layout, in publishing
    order), refilled per input by :meth:`fill_arrays`: the outputs with their own array first,
    then those that carry another's (:attr:`OutputLayout.source`, the stamped matrices)."""

    def __init__(self, layouts: Mapping[str, OutputLayout], types: MessageTypes) -> None:
        self.layouts = dict(layouts)
        self.types = types
        self._messages = tuple(new_message(layout, types) for layout in self.layouts.values())
        self.writers = tuple(output_writer(layout, types) for layout in self.layouts.values())
        names = list(self.layouts)
        #: For each message, the index of its array among the outputs with their own.
        self.array_index = tuple(names.index(layout.source or name)
                                 for name, layout in self.layouts.items())

    def messages(self) -> tuple[Any, ...]:
        """The messages in the order of :attr:`layouts`."""
        return self._messages

    def fill_arrays(self, arrays: Sequence[FloatArray], stamp: Any, frame_id: str,
                    wanted: Sequence[bool] | None = None) -> None:
        """Write ``arrays`` (checked finite, one per output with its own array, in
        :meth:`messages` order) into the messages flagged in ``wanted`` (default all), each
        stamped matrix the array it carries; the stamped ones get ``stamp`` and ``frame_id``."""
        fill_outputs(self._messages, [arrays[k] for k in self.array_index], self.writers,
                     stamp, frame_id, wanted)


class JointOutputMessages(OutputMessages):
    """``stiffness_node``'s seven per-input output messages (five arrays, two stamped matrices)
    (:func:`~tensegrity_stiffness.nodes.layouts.joint_output_layouts`), refilled by
    :meth:`fill`."""

    def __init__(self, string_names: Sequence[str], types: MessageTypes) -> None:
        self.string_names = tuple(string_names)
        super().__init__(joint_output_layouts(self.string_names), types)
        (self.wrench, self.stiffness, self.cartesian_stiffness, self.tensions,
         self.interpretation, self.stiffness_stamped,
         self.cartesian_stiffness_stamped) = self._messages

    def fill(self, outputs: JointOutputs, stamp: Any, frame_id: str,
             wanted: Sequence[bool] | None = None) -> None:
        """Set the messages from ``outputs`` (those flagged in ``wanted``, in :meth:`messages`
        order; default all); ValueError if any output is not finite (then none is set)."""
        arrays = table_arrays(JOINT_OUTPUT_TABLE, outputs)
        require_all_finite(JOINT_OUTPUTS, arrays)
        self.fill_arrays(arrays, stamp, frame_id, wanted)


class SpineOutputMessages(OutputMessages):
    """``spine_node``'s nine per-input output messages (seven arrays and stamped messages,
    two stamped matrices) of a spine of ``n_joints``
    (:func:`~tensegrity_stiffness.nodes.layouts.spine_output_layouts`), refilled by
    :meth:`fill`."""

    def __init__(self, n_joints: int, types: MessageTypes, tool_frame: str = '') -> None:
        self.n_joints = n_joints
        #: The frame id of the stamped tip stiffness in the tool frame (the others: the base).
        self.tool_frame = tool_frame
        super().__init__(spine_output_layouts(n_joints), types)
        (self.joint_wrenches, self.joint_stiffness, self.joint_cartesian_stiffness,
         self.tip_pose, self.tip_wrench, self.tip_stiffness, self.tip_stiffness_base,
         self.tip_stiffness_stamped, self.tip_stiffness_base_stamped) = self._messages

    def fill(self, outputs: SpineOutputs, stamp: Any, base_frame: str,
             wanted: Sequence[bool] | None = None) -> None:
        """Set the messages from ``outputs`` (those flagged in ``wanted``, in :meth:`messages`
        order; default all); ValueError if any output is not finite (then none is set), or if
        the tip transform's rotation block is not a rotation. The stamped matrices carry
        ``base_frame``, the tool-frame tip stiffness :attr:`tool_frame`."""
        arrays = table_arrays(SPINE_OUTPUT_TABLE, outputs)
        require_all_finite(SPINE_OUTPUTS, arrays)
        self.fill_arrays(arrays, stamp, base_frame, wanted)
        self.tip_stiffness_stamped.header.frame_id = self.tool_frame


class EstimatorOutputMessages(OutputMessages):
    """``estimator_node``'s nine per-estimate output messages (seven of
    :data:`~tensegrity_stiffness.nodes.layouts.ESTIMATOR_OUTPUT_TABLE`, two stamped matrices)
    (:func:`~tensegrity_stiffness.nodes.layouts.estimator_output_layouts`), refilled by
    :meth:`fill`."""

    def __init__(self, string_names: Sequence[str], types: MessageTypes) -> None:
        self.string_names = tuple(string_names)
        super().__init__(estimator_output_layouts(self.string_names), types)

    def fill(self, outputs: EstimatorOutputs, stamp: Any, frame_id: str,
             wanted: Sequence[bool] | None = None) -> None:
        """Set the messages flagged in ``wanted`` (default all, :meth:`messages` order) from
        ``outputs``, whose arrays the processing checked finite (the std of K_c only when it
        was computed: else it is NaN and not wanted)."""
        self.fill_arrays(table_arrays(ESTIMATOR_OUTPUT_TABLE, outputs), stamp, frame_id, wanted)


class SpineEstimatorOutputMessages(OutputMessages):
    """``spine_estimator_node``'s six per-estimate output messages (five of
    :data:`~tensegrity_stiffness.nodes.layouts.SPINE_ESTIMATOR_OUTPUT_TABLE`, the stamped tip
    stiffness) of a spine of ``n_joints``
    (:func:`~tensegrity_stiffness.nodes.layouts.spine_estimator_output_layouts`), refilled by
    :meth:`fill`."""

    def __init__(self, n_joints: int, types: MessageTypes) -> None:
        self.n_joints = n_joints
        super().__init__(spine_estimator_output_layouts(n_joints), types)

    def fill(self, outputs: SpineEstimatorOutputs, stamp: Any, frame_id: str,
             wanted: Sequence[bool] | None = None) -> None:
        """As :meth:`EstimatorOutputMessages.fill` (the std of the tip stiffness likewise)."""
        self.fill_arrays(table_arrays(SPINE_ESTIMATOR_OUTPUT_TABLE, outputs), stamp, frame_id,
                         wanted)
