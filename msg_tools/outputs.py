"""Refilling a node's preallocated output messages per input (``JointOutputMessages``,
``SpineOutputMessages``): after one finite check of every output by the caller, each wanted
message gets its array without a second check (the node's per-message path)."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from builtin_interfaces.msg import Time

from msg_tools.arrays import FloatArray, payload
from msg_tools.geometry import transform_to_pose, write_wrench

#: Writes one checked array into its message: ``writer(msg, values, stamp, frame_id)``.
Writer = Callable[[Any, FloatArray, Time, str], None]


def write_payload(msg: Any, values: FloatArray, stamp: Time, frame_id: str) -> None:
    """A Float64MultiArray's data (its layout, labelled once, stays)."""
    msg.data = payload(values)


def write_wrench_stamped(msg: Any, values: FloatArray, stamp: Time, frame_id: str) -> None:
    """A WrenchStamped's header and ``[fx fy fz mx my mz]``."""
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id
    write_wrench(msg.wrench, values)


def write_pose_stamped(msg: Any, values: FloatArray, stamp: Time, frame_id: str) -> None:
    """A PoseStamped's header and the pose of a (4, 4) transform (ValueError if its rotation
    block is not a rotation)."""
    msg.pose = transform_to_pose(values)
    msg.header.stamp = stamp
    msg.header.frame_id = frame_id


def fill_outputs(messages: Sequence[Any], arrays: Sequence[FloatArray],
                 writers: Sequence[Writer], stamp: Time, frame_id: str,
                 wanted: Sequence[bool] | None = None) -> None:
    """Write ``arrays[k]`` into ``messages[k]`` with ``writers[k]`` for every ``k`` flagged in
    ``wanted`` (default all)."""
    for k, (msg, values, write) in enumerate(zip(messages, arrays, writers, strict=True)):
        if wanted is None or wanted[k]:
            write(msg, values, stamp, frame_id)
