"""``stiffness_node``'s behaviour without ROS
(:mod:`tensegrity_stiffness.ros.stiffness_node` converts, validates and publishes): its
parameter table (:data:`STIFFNESS_NODE_PARAMETERS`: the shared joint, frame and common sections,
the planar mechanism's and the joint's dynamics), its settings (:func:`joint_node_settings`),
the checks of a screw or a pose, and the outputs of one configuration. ``stiffness_node`` and the
bag command both call these, so they reject the same inputs with the same words and publish the
same numbers.

Decoding a message into numbers (length, NaN and size checks, quaternions) is
:mod:`tensegrity_stiffness.ros.conversions`' part; this module takes the numbers.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.geometry.screw import check_in_chart, log_se3
from tensegrity_stiffness.geometry.validation import require_all_finite, require_frame
from tensegrity_stiffness.mechanics.interpretation import interpretation_vector
from tensegrity_stiffness.mechanics.joint import JointModel, JointState
from tensegrity_stiffness.mechanics.joint_dynamics import JointDynamics
from tensegrity_stiffness.mechanics.modes import JointModes
from tensegrity_stiffness.mechanics.planar import PlanarMechanism
from tensegrity_stiffness.mechanics.plausibility import (
    check_dynamics,
    check_rest_lengths,
    check_screw,
    check_translation,
)
from tensegrity_stiffness.nodes.layouts import (
    JOINT_OUTPUT_TABLE,
    JOINT_OUTPUTS,
    natural_frequencies_label,
    table_arrays,
)
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.shared_parameters import (
    COMMON_PARAMETERS,
    DYNAMICS_PARAMETER_NAMES,
    FRAME_PARAMETERS,
    JOINT_DYNAMICS_PARAMETERS,
    JOINT_PARAMETERS,
    REST_LENGTH_OFFSET_PARAMETERS,
    TF_PARAMETERS,
    joint_from_values,
    link2_inertia_from_values,
    marker_period,
)

FloatArray = NDArray[np.float64]

_ANGLE_RANGE = (-2.0 * math.pi, 2.0 * math.pi)
PLANAR_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('planar.L', 'double', 1.0, 'mobile triangle side L (base side 2 L), m',
                  range=(1e-9, 1e9)),
    ParameterSpec('planar.K1', 'double', 100.0, 'stiffness K1 of the spring C2-D2, N/m',
                  range=(1e-12, 1e12)),
    ParameterSpec('planar.K2', 'double', 10.0, 'stiffness K2 of the spring C3-D3, N/m',
                  range=(1e-12, 1e12)),
    ParameterSpec('planar.L3_min', 'double', 0.0, 'actuator length lower bound, m',
                  range=(0.0, 1e9)),
    ParameterSpec('planar.L3_max', 'double', 2.0, 'actuator length upper bound, m (eq. 31: 2 L)',
                  range=(1e-9, 1e9)),
    ParameterSpec('planar.theta1_min', 'double', 0.0, 'actuator angle lower bound, rad',
                  range=_ANGLE_RANGE),
    ParameterSpec('planar.theta1_max', 'double', math.pi, 'actuator angle upper bound, rad',
                  range=_ANGLE_RANGE),
    ParameterSpec('planar.theta2_min', 'double', 0.0, 'platform angle lower bound, rad',
                  range=_ANGLE_RANGE),
    ParameterSpec('planar.theta2_max', 'double', math.pi, 'platform angle upper bound, rad',
                  range=_ANGLE_RANGE),
)


STIFFNESS_NODE_PARAMETERS: tuple[ParameterSpec, ...] = (
    JOINT_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + FRAME_PARAMETERS + TF_PARAMETERS
    + PLANAR_PARAMETERS + COMMON_PARAMETERS + JOINT_DYNAMICS_PARAMETERS)



def planar_from_values(values: Mapping[str, Any]) -> PlanarMechanism:
    """The planar mechanism of the ``planar.*`` values (ValueError names the bad field)."""
    try:
        return PlanarMechanism(**{spec.name[len('planar.'):]: float(values[spec.name])
                                  for spec in PLANAR_PARAMETERS})
    except ValueError as exc:
        raise ValueError(f'planar.{exc}') from None


@dataclass(frozen=True)
class JointNodeSettings:
    """Everything one computation of ``stiffness_node`` needs, swapped as a whole (never
    mutated): built from a complete set of parameter values by :func:`joint_node_settings`."""

    model: JointModel
    planar: PlanarMechanism
    link1_frame: str
    link2_frame: str
    max_array_length: int
    equilibrium_time_budget: float
    equilibrium_max_iterations: int
    marker_period: float
    dynamics: JointDynamics | None = None
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)


def joint_dynamics_from_values(model: JointModel, values: Mapping[str, Any]
                               ) -> JointDynamics | None:
    """The joint's dynamics from checked values (None unless ``dynamics.enabled``); errors
    name the parameter. The values are judged against the joint's range
    (:func:`~tensegrity_stiffness.mechanics.plausibility.check_dynamics`, the library's) also
    when the dynamics are off, so a parameter the library would refuse is never set."""
    inertia = link2_inertia_from_values(values)
    damping = values['dynamics.string_damping']
    check_dynamics(model, inertia.mass, inertia.com, damping, DYNAMICS_PARAMETER_NAMES)
    if not values['dynamics.enabled']:
        return None
    return JointDynamics(model, inertia, damping)



def joint_node_settings(values: Mapping[str, Any], generation: int = 0) -> JointNodeSettings:
    """Validate a whole parameter set of ``stiffness_node`` and build its settings; ValueError
    names the bad field. Every parameter of the table must be in ``values``."""
    checked = {spec.name: spec.check(values[spec.name]) for spec in STIFFNESS_NODE_PARAMETERS}
    for name in ('frames.link1', 'frames.link2'):
        if not checked[name].strip():
            raise ValueError(f'{name} must not be empty')
    model = joint_from_values(checked)
    return JointNodeSettings(
        model=model, planar=planar_from_values(checked),
        link1_frame=checked['frames.link1'], link2_frame=checked['frames.link2'],
        max_array_length=checked['limits.max_array_length'],
        equilibrium_time_budget=checked['equilibrium.time_budget'],
        equilibrium_max_iterations=checked['equilibrium.max_iterations'],
        marker_period=marker_period(checked['markers.max_rate']),
        dynamics=joint_dynamics_from_values(model, checked), generation=generation,
        values=checked)




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
    :class:`~tensegrity_stiffness.geometry.errors.BadRestLengthsError` (the model's or the
    range's text) when they are below the joint's range
    (:func:`~tensegrity_stiffness.mechanics.plausibility.check_rest_lengths`, the range the
    equilibrium service uses) or the model refuses them (no room for the maximum stretch)."""
    try:
        return model.with_rest_lengths(check_rest_lengths(model, rest_lengths))
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
    """The published arrays of ``outputs`` in :data:`OUTPUT_NAMES` order (the rows of
    :data:`~tensegrity_stiffness.nodes.layouts.JOINT_OUTPUT_TABLE`)."""
    return table_arrays(JOINT_OUTPUT_TABLE, outputs)


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
