"""``spine_node``'s behaviour without ROS (:mod:`tensegrity_stiffness.ros.spine_node` converts,
validates and publishes): its parameter table (:func:`spine_node_parameters`: the shared joint,
chain and frame sections, the spine's solver budget and dynamics), its settings
(:func:`spine_node_settings`), the checks of the joints' screws, poses and rest lengths, and the
outputs of one configuration of a :class:`~tensegrity_stiffness.mechanics.chain.JointChain`
(conventions in :mod:`tensegrity_stiffness.mechanics.chain`).

Decoding a message into numbers (length, NaN and size checks, quaternions) is
:mod:`tensegrity_stiffness.ros.conversions`' part; this module takes the numbers. Every check
names the joint (1-based) it rejects.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
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
from tensegrity_stiffness.mechanics.chain_dynamics import ChainDynamics
from tensegrity_stiffness.mechanics.equilibrium import stability_margin
from tensegrity_stiffness.mechanics.inertia import chain_link_inertias
from tensegrity_stiffness.nodes.health import JointHealth
from tensegrity_stiffness.nodes.layouts import SPINE_OUTPUT_TABLE, SPINE_OUTPUTS, table_arrays
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name
from tensegrity_stiffness.nodes.shared_parameters import (
    CHAIN_PARAMETERS,
    COMMON_PARAMETERS,
    JOINT_DYNAMICS_PARAMETERS,
    JOINT_PARAMETERS,
    SPINE_FRAME_PARAMETERS,
    TF_PARAMETERS,
    chain_document,
    joint_override_parameters,
    marker_period,
)

FloatArray = NDArray[np.float64]

#: The common parameters with the spine's solver budget (a 6N-unknown solve).
SPINE_COMMON_PARAMETERS: tuple[ParameterSpec, ...] = tuple(
    ParameterSpec(s.name, s.type, 0.1, s.description, s.read_only, s.range, s.choices)
    if s.name == 'equilibrium.time_budget' else s for s in COMMON_PARAMETERS)


#: The dynamics of ``spine_node``'s spine: the links' inertias (masses and centres of mass are
#: ``chain.link_masses`` / ``chain.link_coms``) and the strings' damping.
SPINE_DYNAMICS_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('chain.link_inertias', 'double_array', None,
                  'inertias of the links about their centres of mass: 3 principal moments or 9 '
                  'values per link, or one set for all, kg m^2 (empty: the twin\'s m r^2 / 2)'),
    ParameterSpec('dynamics.enabled', 'bool', False,
                  'publish ~/natural_frequencies (6N) of every input that is an equilibrium of '
                  'its implied tip wrench (a spine off equilibrium has no linear model here)',
                  read_only=True),
    JOINT_DYNAMICS_PARAMETERS[-1],
)


def spine_node_parameters(n_joints: int = 5) -> tuple[ParameterSpec, ...]:
    """Every parameter of ``spine_node`` for a spine of ``n_joints``, in declaration order."""
    return (JOINT_PARAMETERS + joint_override_parameters(n_joints) + CHAIN_PARAMETERS
            + SPINE_FRAME_PARAMETERS + TF_PARAMETERS + SPINE_COMMON_PARAMETERS
            + SPINE_DYNAMICS_PARAMETERS)


#: The parameters of ``spine_node`` with the default ``chain.n_joints``.
SPINE_NODE_PARAMETERS: tuple[ParameterSpec, ...] = spine_node_parameters()


@dataclass(frozen=True)
class SpineNodeSettings:
    """Everything one computation of ``spine_node`` needs, swapped as a whole (never mutated):
    built from a complete set of parameter values by :func:`spine_node_settings`.
    ``rest_lengths``: per-joint rest lengths set on ``~/rest_lengths`` (None: the models')."""

    chain: JointChain
    base_frame: str
    tool_frame: str
    max_array_length: int
    equilibrium_time_budget: float
    equilibrium_max_iterations: int
    marker_period: float
    rest_lengths: tuple[Any, ...] | None = None
    dynamics: ChainDynamics | None = None
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_joints(self) -> int:
        return self.chain.n_joints

    @property
    def n_strings(self) -> list[int]:
        """String count of every joint."""
        return [model.n_strings for model in self.chain.joints]

    def current_rest_lengths(self) -> list[Any]:
        """Every joint's rest lengths now (topic-set or configured)."""
        if self.rest_lengths is not None:
            return list(self.rest_lengths)
        return [model.rest_lengths for model in self.chain.joints]


def spine_node_settings(values: Mapping[str, Any], generation: int = 0) -> SpineNodeSettings:
    """Validate a whole parameter set of ``spine_node`` and build its settings; ValueError
    names the bad field. Every parameter of :func:`spine_node_parameters` for
    ``values['chain.n_joints']`` must be in ``values``."""
    n = by_name(CHAIN_PARAMETERS)['chain.n_joints'].check(values['chain.n_joints'])
    checked = {spec.name: spec.check(values[spec.name]) for spec in spine_node_parameters(n)}
    for name in ('frames.base', 'frames.tool'):
        if not checked[name].strip():
            raise ValueError(f'{name} must not be empty')
    chain = JointChain.from_dict(chain_document(checked))
    longest = max(6 * n, sum(model.n_strings for model in chain.joints))
    if checked['limits.max_array_length'] < longest:
        raise ValueError(f'limits.max_array_length = {checked["limits.max_array_length"]} is '
                         f'below the longest input of this spine ({longest} values)')
    return SpineNodeSettings(
        chain=chain, base_frame=checked['frames.base'], tool_frame=checked['frames.tool'],
        max_array_length=checked['limits.max_array_length'],
        equilibrium_time_budget=checked['equilibrium.time_budget'],
        equilibrium_max_iterations=checked['equilibrium.max_iterations'],
        marker_period=marker_period(checked['markers.max_rate']),
        dynamics=ChainDynamics(chain, chain_link_inertias(chain, checked['chain.link_inertias']),
                               checked['dynamics.string_damping'])
        if checked['dynamics.enabled'] else None,
        generation=generation, values=checked)




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
    """The published arrays of ``outputs``, in the order of :data:`OUTPUT_NAMES` (the rows of
    :data:`~tensegrity_stiffness.nodes.layouts.SPINE_OUTPUT_TABLE`)."""
    return table_arrays(SPINE_OUTPUT_TABLE, outputs)


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
