"""The frames the nodes broadcast on ``/tf`` (``tf.enabled``), without ROS: which parent and child
frame each transform joins and which pose of the library it is.

* A joint (``stiffness_node``, ``estimator_node``, ``sim_node``): ``frames.link1`` ->
  ``frames.link2``, the pose of {2} in {1}, ``T = exp(hat(xi))`` (eq. 2; ``JointState.transform``).
* A spine (``spine_node``, ``spine_estimator_node``, ``sim_node`` with ``sim.spine``):
  ``frames.base`` -> ``<frames.base>_link_<i>`` (i = 1..N) with ``L_i``, the pose of {2}_i in the
  base (``ChainState.link_transforms``), and, fixed in link N, ``<frames.base>_link_<N>`` ->
  ``frames.tool`` with ``O_tool`` (``JointChain.tool``; on ``/tf_static``), so that base -> tool
  composes to ``T_tip = L_N O_tool``.

A transform maps coordinates in the child frame to the parent frame, as a ``Pose`` of the child
in the parent does (``geometry_msgs/TransformStamped``: ``header.frame_id`` = parent,
``child_frame_id`` = child).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class FrameTransform:
    """The pose ``transform`` (4, 4) of frame ``child`` in frame ``parent``."""

    parent: str
    child: str
    transform: FloatArray


def spine_link_frame(base_frame: str, link: int) -> str:
    """The frame of link ``link`` (1..N; {2}_i, link 2 of joint i) of a spine whose base frame is
    ``base_frame``: ``<base_frame>_link_<link>``."""
    return f'{base_frame}_link_{link}'


def joint_frame_transforms(link1_frame: str, link2_frame: str, transform: ArrayLike
                           ) -> tuple[FrameTransform, ...]:
    """Link 1 -> link 2 at the pose ``transform`` of {2} in {1}."""
    return (FrameTransform(link1_frame, link2_frame, np.asarray(transform, dtype=np.float64)),)


def spine_frame_transforms(base_frame: str, link_transforms: ArrayLike
                           ) -> tuple[FrameTransform, ...]:
    """Base -> every link at the poses ``link_transforms`` (N, 4, 4) of {2}_i in the base."""
    poses = np.asarray(link_transforms, dtype=np.float64)
    return tuple(FrameTransform(base_frame, spine_link_frame(base_frame, i + 1), pose)
                 for i, pose in enumerate(poses))


def spine_tool_transform(base_frame: str, n_joints: int, tool_frame: str, tool: ArrayLike
                         ) -> FrameTransform:
    """Link N -> the tool frame, fixed in link N (``O_tool``, the chain's ``tool``)."""
    return FrameTransform(spine_link_frame(base_frame, n_joints), tool_frame,
                          np.asarray(tool, dtype=np.float64))
