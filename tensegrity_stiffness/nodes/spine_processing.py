"""What the spine node does with each input, without ROS: the checks of the joints' screws,
poses and rest lengths, and the outputs of one configuration of a
:class:`~tensegrity_stiffness.mechanics.chain.JointChain` (conventions in
:mod:`tensegrity_stiffness.mechanics.chain`).

Decoding a message into numbers (length, NaN and size checks, quaternions) is
:mod:`tensegrity_stiffness.ros.conversions`'
part; this module takes the numbers. Every check names the joint (1-based) it rejects.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import (
    SingularStiffnessError,
    WrongLengthError,
    in_context,
)
from tensegrity_stiffness.geometry.screw import CHART_LIMIT, check_in_chart, log_se3
from tensegrity_stiffness.geometry.validation import require_all_finite, require_frame
from tensegrity_stiffness.mechanics.chain import ChainState, JointChain
from tensegrity_stiffness.mechanics.equilibrium import stability_margin
from tensegrity_stiffness.nodes.health import JointHealth
from tensegrity_stiffness.nodes.layouts import SPINE_OUTPUTS

FloatArray = NDArray[np.float64]


def screws_input(values: FloatArray, n_joints: int) -> FloatArray:
    """The (N, 6) screws of a ``~/screws`` message's 6N finite values (joint-major);
    ValueError on another length or a screw outside the chart ``|omega| < 2 pi``."""
    if values.shape != (6 * n_joints,):
        raise WrongLengthError(f'expected 6 N = {6 * n_joints} values (one screw per joint), got '
                         f'{values.size}')
    xi = values.reshape(n_joints, 6)
    try:
        check_in_chart(xi, 'screws')
    except ValueError:  # name the first joint outside
        for i, screw in enumerate(xi):
            check_in_chart(screw, f'joint {i + 1} screw')
    return xi


def poses_input(frame_id: str, poses: Sequence[Any], base_frame: str, reference: FloatArray,
                to_transform: Callable[[Any], ArrayLike] = np.asarray) -> FloatArray:
    """The (N, 6) screws of the poses of every link 2 in its link 1 (``~/poses``; each pose
    made a (4, 4) transform by ``to_transform``, after the count is checked): the log map of
    each on the rotation branch nearest the joint's ``reference`` screw (the last screws).
    ValueError when ``frame_id`` is set and is not the base frame, or the pose count is not N."""
    require_frame(frame_id, base_frame, 'the base frame')
    n = reference.shape[0]
    if len(poses) != n:
        raise WrongLengthError(f'expected N = {n} poses (one per joint), got {len(poses)}')
    out = np.empty((n, 6))
    for i, (pose, ref) in enumerate(zip(poses, reference, strict=True)):
        try:
            out[i] = log_se3(to_transform(pose), reference=ref)
        except ValueError as exc:
            raise in_context(exc, f'joint {i + 1} pose') from None
    return out


def rest_lengths_input(values: FloatArray, chain: JointChain) -> tuple[FloatArray, ...]:
    """Per-joint rest lengths of a ``~/rest_lengths`` message (one value per string of every
    joint, joint-major); ValueError naming the joint."""
    counts = [model.n_strings for model in chain.joints]
    if values.shape != (sum(counts),):
        raise WrongLengthError(f'expected {sum(counts)} values (the strings of every joint, '
                         f'joint-major), got {values.size}')
    out = []
    for i, (model, part) in enumerate(zip(chain.joints, np.split(values, np.cumsum(counts)[:-1]),
                                          strict=True)):
        try:
            out.append(model.validate_rest_lengths(part, batched=False))
        except ValueError as exc:
            raise in_context(exc, f'joint {i + 1}') from None
    return tuple(out)


@dataclass(frozen=True)
class SpineOutputs:
    """Everything the spine node publishes for one configuration: the chain ``state``, the tip
    wrench the configuration implies (base frame) and the tip stiffness at that load in the tool
    and base frames."""

    screws: FloatArray
    state: ChainState
    tip_wrench: FloatArray
    tip_stiffness_tool: FloatArray
    tip_stiffness_base: FloatArray


def spine_outputs(chain: JointChain, screws: FloatArray,
                  rest_lengths: Sequence[ArrayLike] | None = None) -> SpineOutputs:
    """The outputs at ``screws`` (N, 6): the implied tip wrench ``W`` (minus the last joint's
    string wrench moved into the base, less the weight of link N), and the exact tip stiffness
    under ``W`` and the link weights (``chain.gravity``). ``SingularStiffnessError`` (a ValueError)
    where the tip stiffness is singular; overflow far out shows as non-finite values, which the
    publishers' checks reject."""
    with np.errstate(all='ignore'):
        state = chain.evaluate(screws, None if rest_lengths is None else list(rest_lengths))
        try:
            W, base, tool = chain.tip_outputs_from_state(state)
        except np.linalg.LinAlgError:
            raise SingularStiffnessError('the tip stiffness is singular at this configuration'
                                    ) from None
    return SpineOutputs(screws, state, W, tool, base)


def output_arrays(outputs: SpineOutputs) -> tuple[FloatArray, ...]:
    """The published arrays of ``outputs``, in the order of :data:`OUTPUT_NAMES`."""
    state = outputs.state
    return (state.wrenches, state.stiffness, state.cartesian_stiffness, state.tip_transform,
            outputs.tip_wrench, outputs.tip_stiffness_tool, outputs.tip_stiffness_base)


#: Names of :func:`output_arrays` (the topics they are published on).
OUTPUT_NAMES = SPINE_OUTPUTS


def require_finite(outputs: SpineOutputs) -> None:
    """ValueError naming the first published array of ``outputs`` that is not finite (an input
    gets all of its outputs or none). One sum per array on the common, finite path."""
    require_all_finite(OUTPUT_NAMES, output_arrays(outputs))


def joint_health_in_chain(state: ChainState, i: int, string_names: Sequence[str]) -> JointHealth:
    """The health of joint ``i`` (0-based) of an evaluated chain (as
    :func:`~tensegrity_stiffness.nodes.health.joint_health` of that joint alone)."""
    names = np.array(list(string_names))
    slack, saturated = np.asarray(state.slack[i]), np.asarray(state.saturated[i])
    return JointHealth(
        slack=names[slack].tolist(), saturated=names[saturated].tolist(),
        chart_margin=CHART_LIMIT - float(np.linalg.norm(state.screws[i, :3])),
        stability_margin=stability_margin(state.cartesian_stiffness[i]),
        condition_number=float(np.linalg.cond(state.stiffness[i])))
