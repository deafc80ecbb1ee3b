"""What the joint node does with each input, without ROS: the checks of a screw or a pose, and
the outputs of one configuration. ``stiffness_node`` and the bag command both call these, so they
reject the same inputs with the same words and publish the same numbers.

Decoding a message into numbers (length, NaN and size checks, quaternions) is
:mod:`msg_tools`' part; this module takes the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.interpretation import interpretation_vector
from tensegrity_stiffness.joint import JointModel, JointState
from tensegrity_stiffness.screw import check_in_chart, log_se3

FloatArray = NDArray[np.float64]


def screw_input(values: FloatArray) -> FloatArray:
    """The screw of a ``~/screw`` message's six finite values; ValueError outside the chart
    ``|omega| < 2 pi``."""
    check_in_chart(values, 'screw')
    return values


def pose_input(frame_id: str, transform: ArrayLike, link1_frame: str,
               reference: ArrayLike) -> FloatArray:
    """The screw of a pose of link 2 in link 1 (``~/pose``): the log map on the rotation branch
    nearest ``reference`` (the last screw). ValueError when ``frame_id`` is set and is not
    ``link1_frame``."""
    if frame_id and frame_id != link1_frame:
        raise ValueError(f"header.frame_id '{frame_id}' is not link 1's frame '{link1_frame}'")
    return log_se3(transform, reference=reference)


@dataclass(frozen=True)
class JointOutputs:
    """Everything the joint node publishes for one configuration: the joint ``state`` (wrench,
    K, K_c, tensions, ...) and the 16-value ``interpretation`` of K (eqs. 19-20)."""

    screw: FloatArray
    state: JointState
    interpretation: FloatArray


def joint_outputs(model: JointModel, screw: FloatArray) -> JointOutputs:
    """The outputs at ``screw`` (6,). Overflow far out shows as non-finite values, which the
    publishers' checks reject; no floating-point warning is raised."""
    with np.errstate(all='ignore'):
        state = model.evaluate(screw)
        interpretation = interpretation_vector(state.stiffness)
    return JointOutputs(screw, state, interpretation)
