"""What ``structure_node`` does with each input, without ROS: its parameter table and settings,
the checks of the bodies' poses and the rest lengths, the outputs of one set of poses of a
:class:`~tensegrity_stiffness.structures.structure.Structure` (conventions in
docs/structures.md), their names, layouts and order (one table: :data:`STRUCTURE_OUTPUT_TABLE`),
its output messages for any message implementation, and the health it reports in
``/diagnostics``. The ROS twin is :mod:`tensegrity_stiffness.ros.structure_node`.

Decoding a message into numbers (length, NaN and size checks, quaternions) is
:mod:`tensegrity_stiffness.nodes.messages`' part; this module takes the numbers. Every check
names the body it rejects.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.components import TWIST_NAMES, WRENCH_NAMES
from tensegrity_stiffness.geometry.errors import WrongLengthError, in_context
from tensegrity_stiffness.geometry.quaternion import (
    QUATERNION_UNIT_TOLERANCE,
    unit_quaternions_to_rotations,
)
from tensegrity_stiffness.geometry.screw import hat3
from tensegrity_stiffness.geometry.validation import require_all_finite, require_frame
from tensegrity_stiffness.nodes.frames import FrameTransform
from tensegrity_stiffness.nodes.health import StringHealth
from tensegrity_stiffness.nodes.layouts import (
    FLOAT64_MULTIARRAY,
    WRENCH_LABEL,
    OutputLayout,
    OutputRow,
    matrix_dims,
    table_arrays,
    table_layouts,
    tensions_label,
    vector_dims,
)
from tensegrity_stiffness.nodes.messages import MessageTypes, OutputMessages
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.shared_parameters import (
    COMMON_PARAMETERS,
    REST_LENGTH_OFFSET_PARAMETERS,
    TF_PARAMETERS,
    marker_period,
    rest_length_offsets,
)
from tensegrity_stiffness.structures.equilibrium import (
    Contact,
    gauge_twists,
    tangent_basis,
)
from tensegrity_stiffness.structures.structure import Structure, StructureState, geometric_block

FloatArray = NDArray[np.float64]

NODE_NAME = 'structure_node'
#: The structure ``structure_node`` runs unless ``structure.config`` names another.
DEFAULT_STRUCTURE = 'six_bar.yaml'

# ------------------------------------------------------------------------------ parameters
STRUCTURE_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('structure.config', 'string', DEFAULT_STRUCTURE,
                  'the structure file (docs/structures.md, "The model"): a path, or the name '
                  'of a packaged example of config/examples (three_bar.yaml, six_bar.yaml)',
                  read_only=True),
    ParameterSpec('structure.contact_distance', 'double', 0.002,
                  'a node of a free body at most this far above the ground (or below it) is a '
                  'contact: ~/contact_forces and the stiffness on the tangent space, m',
                  range=(0.0, 1.0)),
    ParameterSpec('frames.world', 'string', 'world',
                  'the world frame: frame_id of the poses in and of every output'),
    ParameterSpec('frames.body_prefix', 'string', '',
                  "prefix of the bodies' frames on /tf: <prefix><body name>"),
)

#: Every parameter of ``structure_node``, in declaration order (the offsets are the joint's:
#: a commanded rest length ``c`` is the rest length ``c + d`` of the structure).
STRUCTURE_NODE_PARAMETERS: tuple[ParameterSpec, ...] = (
    STRUCTURE_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + TF_PARAMETERS + COMMON_PARAMETERS)


def structure_path(name: str) -> Path:
    """The file of ``structure.config``: an existing path, else a packaged example; ValueError
    names the parameter."""
    if not name.strip():
        raise ValueError('structure.config must not be empty')
    path = Path(name).expanduser()
    if path.is_file():
        return path
    try:
        return config.example_config_path(name)
    except ValueError as exc:
        raise ValueError(f'structure.config: no file {name!r} and {exc}') from None


@dataclass(frozen=True)
class StructureNodeSettings:
    """Everything one computation of ``structure_node`` needs, swapped as a whole (never
    mutated): built from a complete set of parameter values by :func:`structure_node_settings`.
    ``rest_lengths`` (n,) are the structure's: the config's, or the commands of ``~/rest_lengths``
    (``commanded_rest_lengths``) plus the offsets."""

    structure: Structure
    rest_lengths: FloatArray
    world_frame: str
    body_frames: tuple[str, ...]
    contact_distance: float
    max_array_length: int
    equilibrium_time_budget: float
    equilibrium_max_iterations: int
    marker_period: float
    commanded_rest_lengths: FloatArray | None = None
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def n_bodies(self) -> int:
        return self.structure.n_bodies


def structure_node_settings(values: Mapping[str, Any], generation: int = 0
                            ) -> StructureNodeSettings:
    """Validate a whole parameter set of ``structure_node`` and build its settings; ValueError
    names the bad field. Every parameter of :data:`STRUCTURE_NODE_PARAMETERS` must be in
    ``values``."""
    checked = {spec.name: spec.check(values[spec.name]) for spec in STRUCTURE_NODE_PARAMETERS}
    if not checked['frames.world'].strip():
        raise ValueError('frames.world must not be empty')
    path = structure_path(checked['structure.config'])
    try:
        structure = Structure.from_yaml(path)
    except ValueError as exc:
        raise ValueError(f'structure.config ({path}): {exc}') from None
    rest_length_offsets(checked, structure.n_strings)  # checks the count
    longest = max(7 * structure.n_bodies, structure.n_strings)
    if checked['limits.max_array_length'] < longest:
        raise ValueError(f'limits.max_array_length = {checked["limits.max_array_length"]} is '
                         f'below the longest input of this structure ({longest} values)')
    prefix = checked['frames.body_prefix']
    return StructureNodeSettings(
        structure=structure, rest_lengths=structure.rest_lengths,
        world_frame=checked['frames.world'],
        body_frames=tuple(prefix + name for name in structure.body_names),
        contact_distance=checked['structure.contact_distance'],
        max_array_length=checked['limits.max_array_length'],
        equilibrium_time_budget=checked['equilibrium.time_budget'],
        equilibrium_max_iterations=checked['equilibrium.max_iterations'],
        marker_period=marker_period(checked['markers.max_rate']),
        generation=generation, values=checked)


# ------------------------------------------------------------------------------ inputs
def poses_input(frame_id: str, poses: Sequence[Any], world_frame: str, n_bodies: int,
                to_transform: Callable[[Any], ArrayLike] = np.asarray) -> FloatArray:
    """The (N, 4, 4) transforms of a ``~/poses`` message's poses (each made a transform by
    ``to_transform``, which checks it, after the count is checked); ValueError when
    ``frame_id`` is set and is not the world frame, or the count is not N, naming the body."""
    require_frame(frame_id, world_frame, 'the world frame')
    if len(poses) != n_bodies:
        raise WrongLengthError(f'expected N = {n_bodies} poses (one per body, config order), '
                               f'got {len(poses)}')
    out = np.empty((n_bodies, 4, 4))
    for i, pose in enumerate(poses):
        try:
            out[i] = to_transform(pose)
        except ValueError as exc:
            raise in_context(exc, f'body {i} pose') from None
    return out


def pose_values_input(values: FloatArray, structure: Structure) -> FloatArray:
    """The (N, 4, 4) transforms of a ``~/pose_values`` message's 7N finite values
    ``[x y z qx qy qz qw]`` per body (config order), as :meth:`Structure.transforms` reads them
    (quaternions of unit norm within ``QUATERNION_UNIT_TOLERANCE``, renormalised), in one
    batch; ValueError on another length or a pose that is not rigid (naming the body:
    :meth:`Structure.transforms`)."""
    n = structure.n_bodies
    if values.shape != (7 * n,):
        raise WrongLengthError(f'expected 7 N = {7 * n} values ([x y z qx qy qz qw] per body), '
                               f'got {values.size}')
    poses = values.reshape(n, 7)
    q = poses[:, 3:]
    norms = np.sqrt(np.sum(q * q, axis=1))
    if not np.all(np.abs(norms - 1.0) <= QUATERNION_UNIT_TOLERANCE):  # NaN too
        return structure.transforms(poses)  # the error names the body
    T = np.zeros((n, 4, 4))
    T[:, :3, :3] = unit_quaternions_to_rotations(q / norms[:, None])
    T[:, :3, 3] = poses[:, :3]
    T[:, 3, 3] = 1.0
    return T


def with_commanded_rest_lengths(settings: StructureNodeSettings, commanded: FloatArray
                                ) -> StructureNodeSettings:
    """``settings`` with commanded rest lengths (``~/rest_lengths``, config order): the
    structure's are ``c + d`` with the offsets ``joint.rest_length_offsets``, each > 0;
    ValueError names the problem."""
    s = settings.structure
    if commanded.shape != (s.n_strings,):
        raise WrongLengthError(f'expected {s.n_strings} values (one per string, config order), '
                               f'got {commanded.size}')
    rest = s.validate_rest_lengths(commanded + rest_length_offsets(settings.values, s.n_strings))
    return replace(settings, rest_lengths=rest, commanded_rest_lengths=commanded.copy())


# ------------------------------------------------------------------------------ outputs
#: The label prefix of the bar forces and of the contact forces' rows.
BAR_FORCES_LABEL_PREFIX = 'bar compressions [N], compression positive, bars in config order: '
CONTACT_FORCES_ROW_PREFIX = ('rows: the ground\'s force on each node [N] (zero: not a contact), '
                             'nodes: ')


def body_components(body_names: Sequence[str], components: Sequence[str]) -> str:
    """``'b.c1 b.c2 ... '`` of every body and component (the stiffness' row or column names)."""
    return ' '.join(f'{b}.{c}' for b in body_names for c in components)


def stiffness_labels(body_names: Sequence[str]) -> tuple[str, str]:
    """Row and column labels of the (6N, 6N) stiffness ``K = -dW/d(delta)``."""
    return ('rows: wrench on each body in the world about its origin ['
            + body_components(body_names, WRENCH_NAMES) + ']',
            'cols: spatial twist of each body in the world ['
            + body_components(body_names, TWIST_NAMES) + '] (linear first, as ROS)')


def body_nodes(structure: Structure) -> list[str]:
    """The nodes on bodies (``body.node``, the order of :attr:`Structure.node_names` without
    the world's): the rows of ``~/contact_forces``."""
    return [name for name, b in zip(structure.node_names, structure.node_bodies, strict=True)
            if b >= 0]


def _array(dims: Sequence[tuple[str, int, int]]) -> OutputLayout:
    return OutputLayout(FLOAT64_MULTIARRAY, tuple(dims))


def _body_wrenches_layout(structure: Structure) -> OutputLayout:
    return _array(matrix_dims(structure.n_bodies, 6, 'bodies: ' + ' '.join(structure.body_names),
                              WRENCH_LABEL + ' in the world about its origin'))


def _stiffness_layout(structure: Structure) -> OutputLayout:
    n6 = 6 * structure.n_bodies
    return _array(matrix_dims(n6, n6, *stiffness_labels(structure.body_names)))


def _contact_forces_layout(structure: Structure) -> OutputLayout | None:
    if structure.ground is None:
        return None
    nodes = body_nodes(structure)
    return _array(matrix_dims(len(nodes), 3, CONTACT_FORCES_ROW_PREFIX + ' '.join(nodes),
                              'cols: [fx fy fz]'))


#: ``structure_node``'s per-input outputs (topic names relative to the node), in the order they
#: are computed, filled and published: one row each (name, layout of the
#: :class:`~tensegrity_stiffness.structures.structure.Structure`, value of
#: :class:`StructureOutputs`; :class:`~tensegrity_stiffness.nodes.layouts.OutputRow`): the body
#: wrenches (N, 6), the stiffness (6N, 6N), the tensions (n), the bar forces and, only with a
#: ground, every body node's contact force (n_nodes, 3). Adding or reordering an output is one
#: row here; the node, the structure estimator, the bag command and the messages read it.
STRUCTURE_OUTPUT_TABLE: tuple[OutputRow, ...] = (
    OutputRow('body_wrenches', _body_wrenches_layout, 'state.wrenches'),
    OutputRow('stiffness', _stiffness_layout, 'state.stiffness'),
    OutputRow('string_tensions', lambda s: _array(vector_dims(
        s.n_strings, tensions_label(s.string_names))), 'state.tensions'),
    OutputRow('bar_forces', lambda s: _array(vector_dims(
        len(s.bar_names), BAR_FORCES_LABEL_PREFIX + ' '.join(s.bar_names))), 'state.bar_forces'),
    OutputRow('contact_forces', _contact_forces_layout, 'contact_forces', optional=True),
)
#: The names of :data:`STRUCTURE_OUTPUT_TABLE`, in its order (``contact_forces`` only when the
#: config has a ground).
STRUCTURE_OUTPUTS = tuple(row.name for row in STRUCTURE_OUTPUT_TABLE)


def structure_output_layouts(structure: Structure) -> dict[str, OutputLayout]:
    """``structure_node``'s per-input outputs of ``structure`` by topic, in
    :data:`STRUCTURE_OUTPUT_TABLE` order."""
    return table_layouts(STRUCTURE_OUTPUT_TABLE, structure)


@dataclass(frozen=True)
class StructureOutputs:
    """Everything the node publishes for one set of poses: the ``state`` (the library's
    :meth:`Structure.evaluate`), the contacts (node indices in :attr:`Structure.node_names`)
    and the ground's force on each body node (n_body_nodes, 3; None without a ground)."""

    state: StructureState
    contacts: tuple[int, ...] = ()
    contact_forces: FloatArray | None = None


def contact_nodes(structure: Structure, T: FloatArray, distance: float) -> tuple[int, ...]:
    """The nodes of free bodies at most ``distance`` above the ground (or below it) at the
    transforms ``T``; none without a ground."""
    ground = structure.ground
    if ground is None:
        return ()
    x = structure.node_positions(T)
    heights = x @ ground.normal - ground.height
    body = structure.node_bodies
    free = (body >= 0) & ~structure.fixed[np.maximum(body, 0)]
    return tuple(int(j) for j in np.flatnonzero(free & (heights <= distance)))


def contact_wrench_matrix(structure: Structure, T: FloatArray, contacts: Sequence[int]
                          ) -> FloatArray:
    """(6N, 3c) the wrenches ``[lambda; x_c x lambda]`` (world, about its origin) on each body of
    the contact forces ``lambda`` (3 per contact)."""
    x = structure.node_positions(T)
    G = np.zeros((6 * structure.n_bodies, 3 * len(contacts)))
    for m, j in enumerate(contacts):
        b = int(structure.node_bodies[j])
        G[6 * b:6 * b + 3, 3 * m:3 * m + 3] = np.eye(3)
        G[6 * b + 3:6 * b + 6, 3 * m:3 * m + 3] = hat3(x[j])
    return G


def balancing_contact_forces(structure: Structure, state: StructureState,
                             contacts: Sequence[int]) -> FloatArray:
    """The contact forces (c, 3) that balance the free bodies' string wrenches and weights at
    the state's poses in least squares (minimum norm when the contacts are indeterminate): at
    an equilibrium on the ground with determinate contacts, its contact forces."""
    if not contacts:
        return np.zeros((0, 3))
    T = state.poses
    Wg, _ = structure.gravity_wrenches(T)
    free = np.repeat(~structure.fixed, 6)
    G = contact_wrench_matrix(structure, T, contacts)[free]
    rhs = -(state.wrenches + Wg).ravel()[free]
    return np.linalg.lstsq(G, rhs, rcond=None)[0].reshape(-1, 3)


def structure_outputs(settings: StructureNodeSettings, T: FloatArray, contacts: bool = True
                      ) -> StructureOutputs:
    """The outputs at the checked transforms ``T`` (N, 4, 4): the library's evaluation
    (:meth:`Structure.evaluate_transforms`, the compiled kernel when built) with the settings'
    rest lengths and, with a ground, the balancing contact forces of the nodes on it
    (``contacts=False``: zeros, for a node whose ``~/contact_forces`` nobody reads; the markers
    and the diagnostics find them from the state, :func:`outputs_of_state`). ValueError where a
    string has zero length; overflow shows as non-finite values, which :func:`require_finite`
    rejects."""
    with np.errstate(all='ignore'):
        state = settings.structure.evaluate_transforms(T, settings.rest_lengths)
        if contacts or settings.structure.ground is None:
            return outputs_of_state(settings, state)
    return StructureOutputs(state, (), np.zeros((int(np.count_nonzero(
        settings.structure.node_bodies >= 0)), 3)))


def outputs_of_state(settings: StructureNodeSettings, state: StructureState
                     ) -> StructureOutputs:
    """The outputs of an evaluated ``state``: with a ground, its contacts
    (:func:`contact_nodes`) and their balancing forces (:func:`balancing_contact_forces`)."""
    s = settings.structure
    if s.ground is None:
        return StructureOutputs(state)
    contacts = contact_nodes(s, state.poses, settings.contact_distance)
    forces = np.zeros((len(s.node_names), 3))
    forces[list(contacts)] = balancing_contact_forces(s, state, contacts)
    return StructureOutputs(state, contacts, forces[s.node_bodies >= 0])


def output_arrays(outputs: StructureOutputs) -> tuple[FloatArray, ...]:
    """The published arrays of ``outputs``, in the order of :data:`STRUCTURE_OUTPUT_TABLE` (the
    contact forces only with a ground)."""
    return table_arrays(STRUCTURE_OUTPUT_TABLE, outputs)


def require_finite(outputs: StructureOutputs) -> None:
    """ValueError naming the first published array of ``outputs`` that is not finite."""
    arrays = output_arrays(outputs)
    require_all_finite(STRUCTURE_OUTPUTS[:len(arrays)], arrays)


class StructureOutputMessages(OutputMessages):
    """``structure_node``'s per-input output messages of ``structure``
    (:func:`structure_output_layouts`), refilled by :meth:`fill`."""

    def __init__(self, structure: Structure, types: MessageTypes) -> None:
        super().__init__(structure_output_layouts(structure), types)

    def fill(self, outputs: StructureOutputs, stamp: Any, frame_id: str,
             wanted: Sequence[bool] | None = None) -> None:
        """Set the messages from ``outputs`` (those flagged in ``wanted``; default all);
        ValueError if any output is not finite (then none is set)."""
        require_finite(outputs)
        self.fill_arrays(output_arrays(outputs), stamp, frame_id, wanted)


def body_frame_transforms(settings: StructureNodeSettings, state: StructureState
                          ) -> tuple[FrameTransform, ...]:
    """World -> every body's frame (``<frames.body_prefix><body>``) at the state's poses."""
    return tuple(FrameTransform(settings.world_frame, child, pose)
                 for child, pose in zip(settings.body_frames, state.poses, strict=True))


# ------------------------------------------------------------------------------ health
@dataclass(frozen=True)
class StructureHealth(StringHealth):
    """The health of one configuration (:class:`~tensegrity_stiffness.nodes.health.StringHealth`,
    the problems naming the strings): the ``contacts`` (node names), the smallest eigenvalue of the
    symmetric part of the total stiffness on the tangent space without the gauge
    (``smallest_eigenvalue``; inf when no motion is left) and ``stability_margin`` (it over the
    largest modulus)."""

    contacts: list[str] = field(default_factory=list)
    smallest_eigenvalue: float = math.inf

    NAMES_IN_PROBLEMS = True

    def extra_values(self) -> list[tuple[str, Any]]:
        return [
            ('ground contacts', self.contacts or 'none'),
            ('smallest eigenvalue of the tangent stiffness', self.smallest_eigenvalue),
            ('stability margin (smallest / largest eigenvalue)', self.stability_margin),
        ]


def total_stiffness(structure: Structure, outputs: StructureOutputs) -> FloatArray:
    """``K_total`` (6N, 6N) at the outputs' poses: the strings', the weights' and the contact
    forces' ``E`` blocks (the equilibrium's tangent stiffness, docs/structures.md)."""
    state = outputs.state
    T = state.poses
    _, Kg = structure.gravity_wrenches(T)
    K = state.stiffness + Kg
    if outputs.contacts:
        x = structure.node_positions(T)
        forces = outputs.contact_forces
        rows = np.flatnonzero(structure.node_bodies >= 0)
        by_node = dict(zip(rows.tolist(), forces, strict=True))
        for j in outputs.contacts:
            b = int(structure.node_bodies[j])
            K[6 * b:6 * b + 6, 6 * b:6 * b + 6] += geometric_block(by_node[j], x[j])
    return K


def contact_constraints(structure: Structure, T: FloatArray, contacts: Sequence[int]
                        ) -> FloatArray:
    """The contacts' constraints on small motions (rows (c, 6N)): 3 rows per contact with
    friction (it sticks), the normal row on a frictionless ground (the equilibrium's)."""
    G = contact_wrench_matrix(structure, T, contacts).T
    if not contacts or structure.ground.friction > 0.0:
        return G
    n = structure.ground.normal
    return np.array([n @ G[3 * m:3 * m + 3] for m in range(len(contacts))])


def structure_health(settings: StructureNodeSettings, outputs: StructureOutputs
                     ) -> StructureHealth:
    """The health of one evaluated configuration (:class:`StructureHealth`; its contacts found
    again from the state, :func:`outputs_of_state`): the tangent space keeps the contacts in
    place and removes the gauge (the bars' spins, the rigid or plane motions:
    :func:`~tensegrity_stiffness.structures.equilibrium.gauge_twists`)."""
    s = settings.structure
    outputs = outputs_of_state(settings, outputs.state)
    state = outputs.state
    T = state.poses
    names = np.array(s.string_names)
    contacts = [Contact(j, int(s.node_bodies[j]), s.node_positions(T)[j])
                for j in outputs.contacts]
    B = tangent_basis(contact_constraints(s, T, outputs.contacts),
                      gauge_twists(s, T, contacts), s.fixed)
    smallest, margin = math.inf, math.inf
    if B.shape[1]:
        H = B.T @ total_stiffness(s, outputs) @ B
        eig = np.linalg.eigvalsh(0.5 * (H + H.T))
        smallest = float(eig[0])
        top = float(np.max(np.abs(eig)))
        margin = smallest / top if top > 0.0 else -math.inf
    return StructureHealth(
        slack=names[state.slack].tolist(), saturated=names[state.saturated].tolist(),
        contacts=[s.node_names[j] for j in outputs.contacts],
        smallest_eigenvalue=smallest, stability_margin=margin)


# ------------------------------------------------------------------------------ services
@dataclass(frozen=True)
class EquilibriumJob:
    """A validated equilibrium request: the worker computes
    ``solve_structure_equilibrium(structure, loads, start, **kwargs())``."""

    structure: Structure
    loads: FloatArray | None
    start: FloatArray | None
    rest_lengths: FloatArray
    time_budget: float
    max_iterations: int

    def args(self) -> tuple[Any, ...]:
        return (self.structure, self.loads, self.start)

    def kwargs(self) -> dict[str, Any]:
        return {'rest_lengths': self.rest_lengths, 'time_budget': self.time_budget,
                'max_iterations': self.max_iterations}


def structure_variant(structure: Structure, gravity: bool = True, ground: bool = True
                      ) -> Structure:
    """``structure`` itself, or a copy without its gravity and / or its ground."""
    if (gravity or structure.gravity is None) and (ground or structure.ground is None):
        return structure
    document = structure.to_dict()
    section = document['structure']
    if not gravity:
        section.pop('gravity', None)
    if not ground:
        section.pop('ground', None)
    return Structure.from_dict(document)


def request_rest_lengths(values: Sequence[float], settings: StructureNodeSettings
                         ) -> FloatArray:
    """A request's rest lengths (empty: the node's current ones); ValueError names the field."""
    if len(values) == 0:
        return settings.rest_lengths
    try:
        return settings.structure.validate_rest_lengths(np.asarray(values, dtype=np.float64))
    except ValueError as exc:
        raise ValueError(f'rest_lengths: {exc}') from None


def equilibrium_job(settings: StructureNodeSettings, loads: Sequence[float],
                    start: Sequence[float], rest_lengths: Sequence[float], without_gravity: bool,
                    without_ground: bool, last_poses: FloatArray | None) -> EquilibriumJob:
    """The job of an equilibrium request: ``loads`` 6N values body-major (empty: none),
    ``start`` 7N values (empty: ``last_poses``, the last input's, else the config's); ValueError
    names the field."""
    s = settings.structure
    n = s.n_bodies
    W = None
    if len(loads):
        W = np.asarray(loads, dtype=np.float64)
        if W.shape != (6 * n,) or not np.all(np.isfinite(W)):
            raise ValueError(f'loads: expected 6 N = {6 * n} finite values, got {W.size}')
        W = W.reshape(n, 6)
    T = last_poses
    if len(start):
        values = np.asarray(start, dtype=np.float64)
        if values.shape != (7 * n,):
            raise ValueError(f'start: expected 7 N = {7 * n} values, got {values.size}')
        try:
            T = s.transforms(values.reshape(n, 7))
        except ValueError as exc:
            raise ValueError(f'start: {exc}') from None
    return EquilibriumJob(structure_variant(s, not without_gravity, not without_ground), W, T,
                          request_rest_lengths(rest_lengths, settings),
                          settings.equilibrium_time_budget, settings.equilibrium_max_iterations)


def structure_report(structure: Structure, rest_lengths: FloatArray) -> dict[str, Any]:
    """:func:`~tensegrity_stiffness.structures.report.check_structure` of ``structure`` with
    ``rest_lengths`` (the analysis report service; in the node's worker process)."""
    from tensegrity_stiffness.structures.report import check_structure

    return check_structure(structure.with_rest_lengths(rest_lengths))
