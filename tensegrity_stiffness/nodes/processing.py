"""What the joint node does with each input, without ROS: the checks of a screw or a pose, and
the outputs of one configuration. ``stiffness_node`` and the bag command both call these, so they
reject the same inputs with the same words and publish the same numbers.

Decoding a message into numbers (length, NaN and size checks, quaternions) is
:mod:`tensegrity_stiffness.ros.conversions`' part; this module takes the numbers.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.geometry.screw import check_in_chart, log_se3
from tensegrity_stiffness.geometry.validation import require_all_finite, require_frame
from tensegrity_stiffness.mechanics.dynamics import JointModes
from tensegrity_stiffness.mechanics.interpretation import interpretation_vector
from tensegrity_stiffness.mechanics.joint import JointModel, JointState
from tensegrity_stiffness.mechanics.plausibility import check_screw, check_translation
from tensegrity_stiffness.nodes.layouts import JOINT_OUTPUTS, natural_frequencies_label

FloatArray = NDArray[np.float64]


def screw_input(values: FloatArray, model: JointModel | None = None) -> FloatArray:
    """The screw of a ``~/screw`` message's six finite values; ValueError outside the chart
    ``|omega| < 2 pi`` or, given the ``model``, out of its reach
    (:func:`~tensegrity_stiffness.mechanics.plausibility.check_screw`: a norm when within)."""
    check_in_chart(values, 'screw')
    if model is not None:
        check_screw(model, values, 'screw')
    return values


def pose_input(frame_id: str, transform: ArrayLike, link1_frame: str,
               reference: ArrayLike, model: JointModel | None = None) -> FloatArray:
    """The screw of a pose of link 2 in link 1 (``~/pose``): the log map on the rotation branch
    nearest ``reference`` (the last screw). ValueError when ``frame_id`` is set and is not
    ``link1_frame`` or, given the ``model``, when the pose is out of its reach
    (:func:`~tensegrity_stiffness.mechanics.plausibility.check_translation`)."""
    require_frame(frame_id, link1_frame, "link 1's frame")
    if model is not None:
        check_translation(model, np.asarray(transform, dtype=np.float64)[:3, 3], 'pose')
    return log_se3(transform, reference=reference)


def with_rest_lengths(model: JointModel, rest_lengths: FloatArray) -> JointModel:
    """``model`` with the rest lengths of a ``~/rest_lengths`` message's finite values;
    :class:`~tensegrity_stiffness.geometry.errors.BadRestLengthsError` (the model's text) when
    the model refuses them (not positive, or no room for the maximum stretch)."""
    try:
        return model.with_rest_lengths(rest_lengths)
    except BadRestLengthsError:
        raise
    except ValueError as exc:
        raise BadRestLengthsError(str(exc)) from None


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


#: The published arrays of :class:`JointOutputs` by topic, in :func:`output_arrays` order.
OUTPUT_NAMES = JOINT_OUTPUTS


def output_arrays(outputs: JointOutputs) -> tuple[FloatArray, ...]:
    """The published arrays of ``outputs`` in :data:`OUTPUT_NAMES` order."""
    state = outputs.state
    return (state.wrench, state.stiffness, state.cartesian_stiffness, state.tensions,
            outputs.interpretation)


def require_finite(outputs: JointOutputs) -> None:
    """ValueError naming the first published array of ``outputs`` that is not finite (an input
    gets all of its outputs or none). One sum per array on the common, finite path."""
    require_all_finite(OUTPUT_NAMES, output_arrays(outputs))


def screw_inputs(values: FloatArray) -> tuple[NDArray[np.bool_], dict[int, ValueError]]:
    """:func:`screw_input` over the rows of ``values`` (N, 6) of finite screws: which rows are
    accepted, and for each rejected row its ValueError (the node's words and kind)."""
    values = np.asarray(values, dtype=np.float64).reshape(-1, 6)
    try:
        check_in_chart(values, 'screw')
    except ValueError:
        pass
    else:
        return np.ones(len(values), dtype=bool), {}
    accepted = np.ones(len(values), dtype=bool)
    problems: dict[int, ValueError] = {}
    for i, row in enumerate(values):
        try:
            screw_input(row)
        except ValueError as exc:
            accepted[i] = False
            problems[i] = exc
    return accepted, problems


def joint_outputs_batch(model: JointModel, screws: FloatArray) -> JointOutputs:
    """:func:`joint_outputs` of many screws (N, 6) in one batched evaluation: every field with a
    leading axis N (``state`` from :meth:`JointModel.evaluate`, ``interpretation`` (N, 16)).
    Rows agree with :func:`joint_outputs` of each screw to rounding."""
    screws = np.asarray(screws, dtype=np.float64).reshape(-1, 6)
    with np.errstate(all='ignore'):
        state = model.evaluate(screws)
        interpretation = interpretation_vector(state.stiffness)
    return JointOutputs(screws, state, interpretation)


def finite_rows(outputs: JointOutputs) -> NDArray[np.bool_]:
    """(N,) mask of the rows of a :func:`joint_outputs_batch` whose published arrays (wrench,
    K, K_c, tensions, interpretation) are all finite: the rows :func:`require_finite` accepts."""
    n = len(outputs.screw)
    mask = np.ones(n, dtype=bool)
    for array in output_arrays(outputs):
        mask &= np.isfinite(array.reshape(n, -1)).all(axis=1)
    return mask


def frequency_report(modes: JointModes) -> tuple[FloatArray, str]:
    """``~/natural_frequencies``' payload and label of ``modes``: the frequencies (Hz), an
    overdamped mode's (a pair of real eigenvalues, :attr:`JointModes.overdamped`) as 0 Hz, and
    the label saying whether the pose is stable and which modes are overdamped
    (:func:`~tensegrity_stiffness.nodes.layouts.natural_frequencies_label`)."""
    overdamped = modes.overdamped
    values = np.where(overdamped, 0.0, modes.frequencies)
    return values, natural_frequencies_label(modes.stable,
                                             np.flatnonzero(overdamped).tolist())
