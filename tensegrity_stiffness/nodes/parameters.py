"""The parameters of the package's nodes: one table of names, types, defaults, ranges, read-only
flags and descriptions, and the whole-set validation built on it.

The table feeds the nodes' declarations and descriptors
(:mod:`tensegrity_stiffness.ros.runtime.declared_parameters`), the command line's defaults, the
bag command and
the tests; ``config/default_joint.yaml`` is a ROS parameter file that agrees with it
(``test/nodes/test_parameters.py``). No ROS import.

Types are ROS parameter types by name: ``bool``, ``int``, ``double``, ``string``,
``double_array``, ``string_array``. A ``default`` of ``None`` on an array means "empty" (an
optional array left out, e.g. ``joint.link2_nodes``: link 2 uses link 1's nodes).
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, fields, replace
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.estimation.estimators import CONSISTENCY_PROBABILITY
from tensegrity_stiffness.estimation.joint_filter import (
    DEFAULT_CHAIN_PROCESS_NOISE,
    DEFAULT_PROCESS_NOISE,
    ProcessNoise,
)
from tensegrity_stiffness.mechanics import templates
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.dynamics import (
    DEFAULT_LINK_MASS,
    DEFAULT_STRING_DAMPING,
    ChainDynamics,
    JointDynamics,
    LinkInertia,
    chain_link_inertias,
)
from tensegrity_stiffness.mechanics.joint import FORCE_LAWS, JointModel
from tensegrity_stiffness.mechanics.planar import PlanarMechanism
from tensegrity_stiffness.nodes.frames import spine_link_frame
from tensegrity_stiffness.simulation.twin import (
    DEFAULT_MAX_FORCE,
    DEFAULT_MAX_MOMENT,
    SimulationOptions,
)

TYPES = ('bool', 'int', 'double', 'string', 'double_array', 'string_array')
RELIABILITIES = ('reliable', 'best_effort')


@dataclass(frozen=True)
class ParameterSpec:
    """One parameter: ``name`` (dotted), ROS ``type`` name, ``default``, ``description``,
    ``read_only`` (fixed once the node runs), numeric ``range`` (inclusive) and string
    ``choices``."""

    name: str
    type: str
    default: Any
    description: str
    read_only: bool = False
    range: tuple[float, float] | None = None
    choices: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        if self.type not in TYPES:
            raise ValueError(f'{self.name}: unknown type {self.type!r}')

    @property
    def constraints(self) -> str:
        """Human-readable constraints (the descriptor's ``additional_constraints``)."""
        return ' | '.join(self.choices)

    def check(self, value: Any) -> Any:
        """``value`` converted to this parameter's Python type; ValueError naming the parameter
        when it has another type, lies outside ``range`` or is not one of ``choices``."""
        kind = self.type
        if kind in ('double_array', 'string_array'):
            if value is None:
                return []
            if isinstance(value, (str, bytes)) or not isinstance(value, Iterable):
                raise ValueError(f'{self.name} must be a list ({kind}), got {value!r}')
            value = list(value)
            if kind == 'double_array':
                if not all(_is_number(v) for v in value):
                    raise ValueError(f'{self.name} must be a list of numbers')
                return [float(v) for v in value]
            if not all(isinstance(v, str) for v in value):
                raise ValueError(f'{self.name} must be a list of strings')
            return value
        if kind == 'bool':
            if not isinstance(value, bool):
                raise ValueError(f'{self.name} must be true or false, got {value!r}')
            return value
        if kind == 'string':
            if not isinstance(value, str):
                raise ValueError(f'{self.name} must be a string, got {value!r}')
            if self.choices and value not in self.choices:
                raise ValueError(f'{self.name} must be one of {self.constraints}, got {value!r}')
            return value
        if kind == 'int':
            if isinstance(value, bool) or not isinstance(value, int):
                raise ValueError(f'{self.name} must be an integer, got {value!r}')
        elif not _is_number(value):
            raise ValueError(f'{self.name} must be a number, got {value!r}')
        else:
            value = float(value)
            if not math.isfinite(value):
                raise ValueError(f'{self.name} must be finite, got {value}')
        if self.range is not None and not self.range[0] <= value <= self.range[1]:
            raise ValueError(f'{self.name} = {value:g} is outside [{self.range[0]:g}, '
                             f'{self.range[1]:g}]')
        return value


def _is_number(value: Any) -> bool:
    return isinstance(value, (int, float)) and not isinstance(value, bool)


# ---------------------------------------------------------------------------------- the table
#: The default joint: the sub-vertebra of the authors' published code (docs/conventions.md, "The
#: default joint"; its one home: mechanics.templates); nodes A, B, C, D, the same set on both
#: links.
_VERTEBRA_STRINGS = tuple(zip(*templates.VERTEBRA_STRINGS, strict=True))

JOINT_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('joint.node_names', 'string_array', list(templates.VERTEBRA_NODE_NAMES),
                  'names of the link-1 nodes (string ends refer to them)'),
    ParameterSpec('joint.link1_nodes', 'double_array', list(templates.VERTEBRA_NODES),
                  'link-1 node coordinates in {1}, flat [x y z] per node, m'),
    ParameterSpec('joint.link2_nodes', 'double_array', None,
                  'link-2 node coordinates in {2}, flat [x y z] per node, m (empty: same as '
                  'link1_nodes)'),
    ParameterSpec('joint.link2_node_names', 'string_array', None,
                  'names of the link-2 nodes (empty: same as node_names)'),
    ParameterSpec('joint.string_names', 'string_array', list(_VERTEBRA_STRINGS[0]),
                  'one name per string (orders every per-string array)'),
    ParameterSpec('joint.string_link1_nodes', 'string_array', list(_VERTEBRA_STRINGS[1]),
                  'link-1 node of each string'),
    ParameterSpec('joint.string_link2_nodes', 'string_array', list(_VERTEBRA_STRINGS[2]),
                  'link-2 node of each string'),
    ParameterSpec('joint.stiffness', 'double_array',
                  [templates.DEFAULT_STIFFNESS] * len(templates.VERTEBRA_STRINGS),
                  'string stiffness k, N/m, one per string (or one for all)'),
    ParameterSpec('joint.rest_lengths', 'double_array', list(templates.VERTEBRA_REST),
                  'rest lengths l0, m, one per string'),
    ParameterSpec('joint.max_lengths', 'double_array', list(templates.VERTEBRA_MAX),
                  'maximum lengths lmax, m, one per string (empty: no limit)'),
    ParameterSpec('joint.force_law', 'string', 'hooke', 'string force law', choices=FORCE_LAWS),
    ParameterSpec('joint.initial_screw', 'double_array', None,
                  'the unloaded equilibrium [wx wy wz vx vy vz] (rad, m): start of equilibrium '
                  'solves and reference branch of the first pose (empty: solved from the '
                  'documented starts; not an equilibrium: a warning, docs/your_joint.md)'),
)

FRAME_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('frames.link1', 'string', 'tensegrity_link1',
                  "link 1's frame: frame_id of every output"),
    ParameterSpec('frames.link2', 'string', 'tensegrity_link2',
                  "link 2's frame (child frame of ~/pose)"),
)

#: The frames a node broadcasts on /tf (:mod:`tensegrity_stiffness.nodes.frames`): the joint's
#: link 1 -> link 2, a spine's base -> every link (and link N -> tool on /tf_static).
TF_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('tf.enabled', 'bool', True,
                  "broadcast every input's frames on /tf (a spine's tool frame on /tf_static) "
                  'when tf2_msgs is installed; the frames: docs/nodes.md, section TF'),
)

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

#: Parameters every node of the package has (QoS, limits, solver budget, markers, diagnostics).
COMMON_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('qos.depth', 'int', 100,
                  'history depth of inputs and outputs (100: 100 ms of a 1 kHz stream)',
                  read_only=True, range=(1, 10_000)),
    ParameterSpec('qos.input_reliability', 'string', 'reliable',
                  'QoS reliability of the streamed inputs', read_only=True,
                  choices=RELIABILITIES),
    ParameterSpec('limits.max_array_length', 'int', 1024,
                  'longer Float64MultiArray inputs are rejected unread',
                  range=(6, 1_000_000)),
    ParameterSpec('equilibrium.time_budget', 'double', 0.05,
                  'wall-clock budget of one equilibrium solve, s', range=(1e-4, 10.0)),
    ParameterSpec('equilibrium.max_iterations', 'int', 60,
                  'Newton iterations per solve stage', range=(1, 10_000)),
    ParameterSpec('markers.max_rate', 'double', 30.0,
                  'highest ~/markers rate, Hz (0: one per input)', range=(0.0, 10_000.0)),
    ParameterSpec('diagnostics.period', 'double', 1.0, '/diagnostics period, s',
                  read_only=True, range=(0.01, 60.0)),
    ParameterSpec('realtime.fast_lane', 'bool', True,
                  'serve the streamed inputs on a thread of their own (a lean wait-set loop) '
                  'instead of the executor', read_only=True),
)

#: Every parameter of ``stiffness_node``, in declaration order.
#: The calibration's offsets between a commanded rest length and the joint's (one home for the
#: nodes that take commanded rest lengths: stiffness_node, estimator_node, sim_node,
#: stiffness_controller).
REST_LENGTH_OFFSET_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('joint.rest_length_offsets', 'double_array', None,
                  'calibrated rest-length offsets d, m: one per string or one for all (empty: '
                  'zeros); a commanded rest length c (~/rest_lengths, the controller\'s '
                  'commands) is the rest length c + d of the model, whose joint.rest_lengths '
                  'are true rest lengths'),
)


#: The dynamics of ``stiffness_node``'s joint (:mod:`tensegrity_stiffness.mechanics.dynamics`):
#: link 2's inertia (the twin's default when left at the defaults) and the strings' damping.
LINK2_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('joint.link2_mass', 'double', DEFAULT_LINK_MASS,
                  "link 2's mass, kg", range=(1e-12, 1e9)),
    ParameterSpec('joint.link2_com', 'double_array', [0.0, 0.0, 0.0],
                  "link 2's centre of mass in {2}, [x y z], m"),
    ParameterSpec('joint.link2_inertia', 'double_array', None,
                  "link 2's inertia about its centre of mass in {2}'s axes: 3 principal moments "
                  'or 9 values row-major, kg m^2 (empty: the twin\'s default m r^2 / 2)'),
)
JOINT_DYNAMICS_PARAMETERS: tuple[ParameterSpec, ...] = LINK2_PARAMETERS + (
    ParameterSpec('dynamics.enabled', 'bool', False,
                  'publish ~/natural_frequencies of every input (the modes of the joint held '
                  'at its pose by the load that balances it there)', read_only=True),
    ParameterSpec('dynamics.string_damping', 'double', DEFAULT_STRING_DAMPING,
                  "damping of every string along its length, N s/m (default: the twin's)",
                  range=(0.0, 1e9)),
)

STIFFNESS_NODE_PARAMETERS: tuple[ParameterSpec, ...] = (
    JOINT_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + FRAME_PARAMETERS + TF_PARAMETERS
    + PLANAR_PARAMETERS + COMMON_PARAMETERS + JOINT_DYNAMICS_PARAMETERS)


def by_name(table: Iterable[ParameterSpec]) -> dict[str, ParameterSpec]:
    """The table as a mapping from parameter name to spec."""
    return {spec.name: spec for spec in table}


def defaults(table: Iterable[ParameterSpec]) -> dict[str, Any]:
    """``{name: default}`` of a table (arrays without a default as empty lists)."""
    return {spec.name: spec.check(spec.default) for spec in table}


def flatten(section: Mapping[str, Any], prefix: str = '') -> dict[str, Any]:
    """Dotted names of a nested parameter mapping (``{'qos': {'depth': 1}}`` ->
    ``{'qos.depth': 1}``), as ROS names the parameters of a parameter file."""
    out: dict[str, Any] = {}
    for key, value in section.items():
        name = f'{prefix}{key}'
        if isinstance(value, Mapping):
            out.update(flatten(value, name + '.'))
        else:
            out[name] = value
    return out


#: A spine's per-joint override section ``joint_<i>`` (any i) as one section.
_OVERRIDE_SECTION = re.compile(r'^joint_\d+(?=\.)')


def _generic(name: str) -> str:
    return _OVERRIDE_SECTION.sub('joint_<i>', name)


#: Every node's switch between refusing and warning about an unknown parameter of its own
#: sections (declared by every node beside its table: ``ros/runtime/declared_parameters.py``).
STRICT_PARAMETERS = ParameterSpec(
    'strict_parameters', 'bool', True,
    "an unknown parameter in one of the node's own sections (joint.stifness) makes the node "
    "refuse to start, naming the nearest name; false (a file shared with other packages' nodes "
    'that use the same section names): warn and run', read_only=True)


def unknown_parameter_messages(given: Iterable[str], table: Iterable[ParameterSpec]
                               ) -> list[str]:
    """One message per name of ``given`` (the parameters a node's parameter file and overrides
    set) that lies under one of the node's own sections (the first part of a dotted name of
    ``table``: ``joint``, ``joint_<i>``, ``estimation``, ``control``, ...) and is a parameter of
    none of the package's nodes, in the one format of :func:`config.unknown_key_messages`:
    ``joint.stifness: unknown key (did you mean joint.stiffness?)``. Such a value would be left
    out and the default used instead. A parameter of another node (a shared file) is no
    mistake; names outside the node's sections (``use_sim_time``, ``qos_overrides.*``, another
    package's) are not judged."""
    own = sorted({_generic(spec.name) for spec in table})
    sections = {name.split('.', 1)[0] for name in own if '.' in name}
    known = set(own) | {_generic(spec.name) for t in node_tables() for spec in t.parameters}
    lines = []
    for name in sorted(set(given)):
        generic = _generic(name)
        if '.' not in name or generic.split('.', 1)[0] not in sections or generic in known:
            continue
        section, key = name.split('.', 1)
        generic_section = generic.split('.', 1)[0]
        keys = [n.split('.', 1)[1] for n in own if n.startswith(generic_section + '.')]
        lines += config.unknown_key_messages({key: None}, keys, section)
    return lines


def refuse_unknown_parameters(given: Iterable[str], table: Iterable[ParameterSpec],
                              strict: bool = True) -> list[str]:
    """Refuse (ValueError, every message of :func:`unknown_parameter_messages` and the opt-out)
    the unknown parameters of the node's own sections in ``given``; with ``strict=False``
    (``strict_parameters: false``) return them as warnings (``...: ignored``) instead."""
    lines = unknown_parameter_messages(given, table)
    if lines and strict:
        raise ValueError('; '.join(lines) + f' ({STRICT_PARAMETERS.name}:=false to warn and '
                         'run with the defaults instead)')
    return [f'{line}: ignored' for line in lines]


def values_from_config(path: Any, table: Iterable[ParameterSpec], strict: bool | None = None
                       ) -> dict[str, Any]:
    """The table's defaults overridden by the parameters of a config file (a ROS parameter file
    or a plain config of the same sections); ValueError names a mistyped one, and an unknown one
    of the table's own sections (:func:`refuse_unknown_parameters`, as a node refuses it)
    unless ``strict`` is False (None: the file's ``strict_parameters``, default true; the
    unknown names are then warned about, :class:`config.UnknownKeyWarning`). Names that are not
    in the table are left out, as a node leaves out the undeclared parameters of its
    ``--params-file`` (``use_sim_time``, ``qos_overrides``, another node's)."""
    specs = by_name(table)
    values = defaults(specs.values())
    given = flatten(config.parameters(config.load_yaml(path)))
    if strict is None:
        strict = bool(STRICT_PARAMETERS.check(given.get(STRICT_PARAMETERS.name, True)))
    for line in refuse_unknown_parameters(given, specs.values(), strict):
        warnings.warn(f'{path}: {line}', config.UnknownKeyWarning, stacklevel=2)
    for name, value in given.items():
        if name in specs:
            values[name] = specs[name].check(value)
    return values


# ------------------------------------------------------------------------- building from values
def joint_from_values(values: Mapping[str, Any]) -> JointModel:
    """The joint model of the ``joint.*`` values (ValueError names the bad field), and the check
    of ``joint.rest_length_offsets`` where the table has it."""
    section = {spec.name[len('joint.'):]: values[spec.name] for spec in JOINT_PARAMETERS}
    model = JointModel.from_dict({k: (v if v is not None else []) for k, v in section.items()})
    rest_length_offsets(values, model.n_strings)
    return model


def rest_length_offsets(values: Mapping[str, Any], n_strings: int) -> np.ndarray:
    """``joint.rest_length_offsets`` (n,) m of checked values (zeros when empty or absent): the
    true rest length of a commanded ``c`` is ``c + d``. ValueError names the key."""
    raw = values.get('joint.rest_length_offsets') or []
    if not raw:
        return np.zeros(n_strings)
    if len(raw) not in (1, n_strings):
        raise ValueError(f'joint.rest_length_offsets must have 1 or {n_strings} values, got '
                         f'{len(raw)}')
    d = np.broadcast_to(np.asarray(raw, dtype=np.float64), (n_strings,)).copy()
    if not np.all(np.isfinite(d)):
        raise ValueError(f'joint.rest_length_offsets must be finite, got {raw}')
    return d


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
    name the parameter."""
    if not values['dynamics.enabled']:
        return None
    return JointDynamics(model, link2_inertia_from_values(values),
                         values['dynamics.string_damping'])


def link2_inertia_from_values(values: Mapping[str, Any]) -> LinkInertia:
    """Link 2's :class:`LinkInertia` from checked ``joint.link2_*`` values (the dynamics' and
    the twin's); errors name the key."""
    return LinkInertia.from_config({key: values[f'joint.{key}'] for key in (
        'link2_mass', 'link2_com', 'link2_inertia')})


def marker_period(rate: float) -> float:
    """Seconds between markers for ``markers.max_rate`` (0: one per input)."""
    return 0.0 if rate <= 0.0 else 1.0 / rate


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


# ---------------------------------------------------------------------------------- spine_node
#: The default spine's link offset and tool pose (config/default_spine.yaml): turn the vertebra's
#: link 2 back upright (rotation by pi about (1, 0, -1)/sqrt 2) and move 55 mm along -y of {2}_i.
_UPRIGHT = [0.7071067811865476, 0.0, -0.7071067811865476, 0.0]
_DEFAULT_LINK_OFFSET = [0.0, -0.055, 0.0, *_UPRIGHT]
_DEFAULT_TOOL = [0.0, 0.0, 0.0, *_UPRIGHT]
#: Largest number of joints of a spine_node.
MAX_SPINE_JOINTS = 100

CHAIN_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('chain.n_joints', 'int', 5,
                  'number of joints N (the joint model repeated, with joint_<i> overrides)',
                  read_only=True, range=(1, MAX_SPINE_JOINTS)),
    ParameterSpec('chain.link_offsets', 'double_array', _DEFAULT_LINK_OFFSET,
                  'pose of {1}_(i+1) in {2}_i, flat [x y z qx qy qz qw] per offset: N - 1 of '
                  'them, or one for all (empty: identity)'),
    ParameterSpec('chain.tool', 'double_array', _DEFAULT_TOOL,
                  'pose of the tool frame in {2}_N, [x y z qx qy qz qw] (empty: identity)'),
    ParameterSpec('chain.link_masses', 'double_array', None,
                  'link masses, kg, link i = link 2 of joint i: N values or one for all (empty: '
                  'massless)'),
    ParameterSpec('chain.link_coms', 'double_array', None,
                  'centres of mass, flat [x y z] per link in {2}_i, m, or one for all (empty: '
                  'the link origins)'),
    ParameterSpec('chain.gravity', 'double_array', [0.0, -9.81, 0.0],
                  'gravity in the base frame, m/s^2 (3 values)'),
)

SPINE_FRAME_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('frames.base', 'string', 'spine_base',
                  "the base frame ({1} of joint 1): frame_id of the base-frame outputs"),
    ParameterSpec('frames.tool', 'string', 'spine_tool', 'the tool frame on link N'),
)

#: The common parameters with the spine's solver budget (a 6N-unknown solve).
SPINE_COMMON_PARAMETERS: tuple[ParameterSpec, ...] = tuple(
    ParameterSpec(s.name, s.type, 0.1, s.description, s.read_only, s.range, s.choices)
    if s.name == 'equilibrium.time_budget' else s for s in COMMON_PARAMETERS)

_JOINT_OVERRIDE_SUFFIXES = tuple(spec.name[len('joint.'):] for spec in JOINT_PARAMETERS)


def joint_override_parameters(n_joints: int) -> tuple[ParameterSpec, ...]:
    """``joint_<i>.<key>`` (i = 1..N) for every key of the joint model: set, it overrides
    ``joint.<key>`` for joint i (``JointChain.from_dict``); left empty, joint i uses the joint
    model."""
    specs = []
    for i in range(1, n_joints + 1):
        for spec in JOINT_PARAMETERS:
            key = spec.name[len('joint.'):]
            description = f'joint {i}: overrides joint.{key} (empty: joint.{key})'
            if spec.type == 'string':
                specs.append(ParameterSpec(f'joint_{i}.{key}', 'string', '', description,
                                           choices=('', *spec.choices)))
            else:
                specs.append(ParameterSpec(f'joint_{i}.{key}', spec.type, None, description))
    return tuple(specs)


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


# ------------------------------------------------------------- the documented tables (registry)
@dataclass(frozen=True)
class NodeTable:
    """One node's parameter table as ``docs/parameters.md`` shows it: the ``node`` (executable)
    name, its ``parameters`` in declaration order, the packaged ``config`` file that agrees with
    their defaults (empty: none), a one-line ``summary`` and the docs ``page`` of its topics and
    services (the node's ``--help`` names them)."""

    node: str
    parameters: tuple[ParameterSpec, ...]
    config: str = ''
    summary: str = ''
    page: str = ''


def node_tables() -> tuple[NodeTable, ...]:
    """Every node's parameter table, in the order of ``docs/parameters.md``: the one registry
    the page is generated from (:mod:`tensegrity_stiffness.nodes.parameter_docs`). A node's table
    is listed here once; after a change run ``python -m tensegrity_stiffness.nodes.parameter_docs
    --write`` (``test/nodes/test_parameter_docs.py`` fails while the committed page differs). A
    function, so that tables defined further down this module, and the controller's in
    :mod:`.control_processing` (which builds on this module), can be listed too."""
    from tensegrity_stiffness.nodes.control_processing import CONTROLLER_PARAMETERS
    from tensegrity_stiffness.nodes.structure_estimator_node import (
        STRUCTURE_ESTIMATOR_PARAMETERS,
    )
    from tensegrity_stiffness.nodes.structure_node import STRUCTURE_NODE_PARAMETERS
    from tensegrity_stiffness.nodes.structure_sim_node import STRUCTURE_SIM_PARAMETERS

    return (
        NodeTable('stiffness_node', STIFFNESS_NODE_PARAMETERS, 'config/default_joint.yaml',
                  'one joint: wrench, K, K_c per screw or pose; equilibrium, design and planar '
                  'services', 'docs/nodes.md'),
        NodeTable('spine_node', SPINE_NODE_PARAMETERS, 'config/default_spine.yaml',
                  'a spine of chain.n_joints joints (the table for the default N = 5): '
                  'per-joint outputs, tip pose, tip wrench and tip stiffness; chain '
                  'equilibrium service', 'docs/nodes.md'),
        NodeTable('sim_node', sim_node_parameters(), 'config/default_joint.yaml',
                  'the MuJoCo twin of the joint (with sim.spine true and a spine config, of the '
                  'spine): truth in the nodes\' input formats and simulated sensors',
                  'docs/simulation.md'),
        NodeTable('stiffness_bridge', BRIDGE_PARAMETERS, '',
                  'the stiffness in the form an impedance or admittance controller takes: '
                  'frame change, symmetric positive definite projection, clamps, low-pass, rate '
                  'limit; published or set as the controller\'s parameters',
                  'docs/controllers.md'),
        NodeTable('estimator_node', ESTIMATOR_NODE_PARAMETERS, 'config/default_joint.yaml',
                  'pose, load and stiffness with their uncertainty from measured tensions, '
                  'lengths, an IMU, motion capture or a force-torque sensor',
                  'docs/estimation.md'),
        NodeTable('spine_estimator_node', spine_estimator_node_parameters(),
                  'config/default_spine.yaml',
                  'the estimator of a spine (the table for the default N = 5): every screw, the '
                  'tip load, tip pose and tip stiffness with their covariances',
                  'docs/estimation.md'),
        NodeTable('stiffness_controller', CONTROLLER_PARAMETERS, 'config/default_joint.yaml',
                  'rest-length commands that hold a target pose with a target K_c in closed '
                  'loop, within the actuators\' range and rate', 'docs/control.md'),
        NodeTable('structure_node', STRUCTURE_NODE_PARAMETERS, '',
                  'a structure of rigid bodies and strings (the 3-bar, the 6-bar): per-body '
                  'wrenches, the 6N x 6N stiffness, tensions, bar and contact forces; '
                  'equilibrium and analysis-report services', 'docs/structures.md'),
        NodeTable('structure_sim_node', STRUCTURE_SIM_PARAMETERS, '',
                  'the MuJoCo twin of a structure on the ground: body poses, string lengths, '
                  'tensions, encoders, one IMU per bar; rest-length commands, loads, pushes and '
                  'the scripted roll', 'docs/structures.md'),
        NodeTable('structure_estimator_node', STRUCTURE_ESTIMATOR_PARAMETERS, '',
                  "every body's pose of a structure with its covariance from string lengths, "
                  'load cells, encoders, per-bar IMUs and markers; the trust, the structure '
                  "node's outputs at the estimate", 'docs/structures.md'),
    )


def chain_document(values: Mapping[str, Any]) -> dict[str, Any]:
    """The config document of :meth:`JointChain.from_dict` of a spine's values (overrides left
    empty are left out)."""
    n = values['chain.n_joints']
    document: dict[str, Any] = {
        'joint': {spec.name[len('joint.'):]: values[spec.name] for spec in JOINT_PARAMETERS},
        'chain': {spec.name[len('chain.'):]: values[spec.name] for spec in CHAIN_PARAMETERS},
        'frames': {'base': values['frames.base'], 'tool': values['frames.tool']},
    }
    for i in range(1, n + 1):
        override = {key: values[f'joint_{i}.{key}'] for key in _JOINT_OVERRIDE_SUFFIXES
                    if values.get(f'joint_{i}.{key}') not in (None, '', [])}
        if override:
            document[f'joint_{i}'] = override
    return document


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


# ---------------------------------------------------------------------------------- sim_node
#: Noise kinds of the simulated sensors (fields of simulation.SensorNoise).
NOISE_KINDS = ('lengths', 'tensions', 'gyro', 'accelerometer')
_NOISE_UNITS = {'lengths': 'm', 'tensions': 'N', 'gyro': 'rad/s', 'accelerometer': 'm/s^2'}

SIM_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('sim.spine', 'bool', False,
                  'simulate the spine of the joint.*, joint_<i>.* and chain.* parameters (a '
                  'spine config) instead of the joint', read_only=True),
    ParameterSpec('sim.rate', 'double', 1000.0,
                  'simulation rate, Hz (the MuJoCo time step is 1 / rate)', read_only=True,
                  range=(1.0, 100_000.0)),
    ParameterSpec('sim.real_time', 'bool', True,
                  'true: paced by the wall clock; false: as fast as possible, publishing /clock '
                  '(stamps are simulated time)', read_only=True),
    ParameterSpec('sim.publish_every', 'int', 1, 'publish every this many steps',
                  range=(1, 1_000_000)),
    ParameterSpec('sim.max_length', 'string', 'limit',
                  "strings past their maximum length: 'limit' an inextensible stop, 'ignore' "
                  "Hooke's law goes on", read_only=True, choices=('limit', 'ignore')),
    ParameterSpec('sim.tendon_damping', 'double', DEFAULT_STRING_DAMPING,
                  'damping of every string, N s/m (the dynamics\' dynamics.string_damping '
                  'default: one value)',
                  read_only=True, range=(0.0, 1e6)),
    ParameterSpec('sim.joint_damping', 'double', 1e-3,
                  'damping of each free-joint dof of every link against the world, N s/m and '
                  'N m s/rad', read_only=True, range=(0.0, 1e6)),
    ParameterSpec('sim.link_mass', 'double', 0.01,
                  "dynamic mass of every spine link whose config gives none, kg (its weight is "
                  "compensated: the library applies none; a joint's link 2: joint.link2_mass)",
                  read_only=True, range=(1e-9, 1e6)),
    ParameterSpec('sim.rest_length_rate', 'double', 0.0,
                  'largest change of a rest length per second, m/s, like a motor (0: at once)',
                  range=(0.0, 1e3)),
    ParameterSpec('load.swing_amplitude', 'double', 0.0,
                  'a force of this size (N) turning in the plane normal to gravity, added to '
                  '~/external_wrench: the twin swings a load (0: off)', range=(0.0, 1e3)),
    ParameterSpec('load.swing_period', 'double', 10.0, 'period of the swinging load, s',
                  range=(1e-2, 1e6)),
    *(ParameterSpec(f'noise.{kind}', 'double', 0.0,
                    f'standard deviation of the simulated {kind} sensor, {_NOISE_UNITS[kind]}',
                    range=(0.0, 1e3)) for kind in NOISE_KINDS),
    ParameterSpec('noise.seed', 'int', 0, 'seed of the sensor noise', read_only=True,
                  range=(0, 2**31 - 1)),
    ParameterSpec('limits.max_force', 'double', DEFAULT_MAX_FORCE,
                  '~/external_wrench with a larger force is rejected as absurd, N',
                  range=(0.0, 1e9)),
    ParameterSpec('limits.max_moment', 'double', DEFAULT_MAX_MOMENT,
                  '~/external_wrench with a larger moment is rejected as absurd, N m',
                  range=(0.0, 1e9)),
    ParameterSpec('limits.rest_length_range', 'double_array', None,
                  '[min, max] of the rest lengths the twin takes (c + d of ~/rest_lengths), m '
                  '(empty: each string\'s physical range, docs/simulation.md)', read_only=True),
    ParameterSpec('frames.imu', 'string', '',
                  'frame_id of ~/imu (empty: frames.link2 for the joint, '
                  '"<frames.base>_link_<N>" for a spine)'),
)

#: The common parameters the twin reads (output depth, array size limit).
_SIM_COMMON = tuple(s for s in COMMON_PARAMETERS
                    if s.name in ('qos.depth', 'limits.max_array_length'))


def sim_node_parameters(spine: bool = False, n_joints: int = 5) -> tuple[ParameterSpec, ...]:
    """Every parameter of ``sim_node``: the joint's model and frames, or (``spine``) the
    spine's, then the twin's own."""
    model = (JOINT_PARAMETERS + joint_override_parameters(n_joints) + CHAIN_PARAMETERS
             + SPINE_FRAME_PARAMETERS) if spine else (
                 JOINT_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + LINK2_PARAMETERS
                 + FRAME_PARAMETERS)
    return model + TF_PARAMETERS + SIM_PARAMETERS + _SIM_COMMON


@dataclass(frozen=True)
class SimNodeSettings:
    """Everything ``sim_node`` needs, swapped as a whole: the model (``model`` for the joint,
    ``chain`` for a spine: exactly one is set), frames, pacing, loads, noise and limits."""

    model: JointModel | None
    chain: JointChain | None
    base_frame: str
    child_frame: str
    imu_frame: str
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def spine(self) -> bool:
        return self.chain is not None

    @property
    def n_strings(self) -> int:
        """Strings of the whole model (the length of the measured arrays)."""
        if self.chain is not None:
            return sum(m.n_strings for m in self.chain.joints)
        return self.model.n_strings

    def noise(self) -> dict[str, float]:
        """``{kind: standard deviation}`` of the simulated sensors."""
        return {kind: self.values[f'noise.{kind}'] for kind in NOISE_KINDS}

    @property
    def rest_length_range(self) -> tuple[float, float] | None:
        """``limits.rest_length_range`` as ``(min, max)`` (None: the twin's physical range)."""
        bounds = self.values['limits.rest_length_range']
        return (bounds[0], bounds[1]) if bounds else None


def sim_node_settings(values: Mapping[str, Any], generation: int = 0) -> SimNodeSettings:
    """Validate a whole parameter set of ``sim_node`` and build its settings; ValueError names
    the bad field. ``generation`` is accepted for symmetry with the other nodes' builders."""
    spine = by_name(SIM_PARAMETERS)['sim.spine'].check(values['sim.spine'])
    n = by_name(CHAIN_PARAMETERS)['chain.n_joints'].check(values['chain.n_joints']) \
        if spine else 1
    checked = {spec.name: spec.check(values[spec.name]) for spec in sim_node_parameters(spine, n)}
    if spine:
        for name in ('frames.base', 'frames.tool'):
            if not checked[name].strip():
                raise ValueError(f'{name} must not be empty')
        chain = JointChain.from_dict(chain_document(checked))
        base, child = checked['frames.base'], checked['frames.tool']
        imu = checked['frames.imu'] or spine_link_frame(base, n)
        model = None
        longest = max(6 * n, sum(m.n_strings for m in chain.joints))
    else:
        for name in ('frames.link1', 'frames.link2'):
            if not checked[name].strip():
                raise ValueError(f'{name} must not be empty')
        model, chain = joint_from_values(checked), None
        base, child = checked['frames.link1'], checked['frames.link2']
        imu = checked['frames.imu'] or child
        longest = max(6, model.n_strings)
    if checked['limits.max_array_length'] < longest:
        raise ValueError(f'limits.max_array_length = {checked["limits.max_array_length"]} is '
                         f'below the longest input of this model ({longest} values)')
    if checked['limits.rest_length_range']:
        try:
            SimulationOptions(rest_length_range=tuple(checked['limits.rest_length_range']))
        except ValueError as exc:
            raise ValueError(f'limits.{exc}') from None
    return SimNodeSettings(model=model, chain=chain, base_frame=base, child_frame=child,
                           imu_frame=imu, values=checked)


# ---------------------------------------------------------------------------- stiffness_bridge
#: What ``target.kind`` selects: publish ``~/output_stiffness``, or set a controller's parameters.
BRIDGE_TARGET_KINDS = ('topic', 'parameters')
#: ``output.max_rate`` of parameter targets when left at -1 (Hz): a controller re-reads its
#: parameters each cycle, but every set is a service call and may destabilise it if abrupt.
PARAMETER_TARGET_RATE = 50.0
#: The bridge's tick (Hz) when no rate limit sets it: retries, and the low-pass settling after the
#: last input.
BRIDGE_IDLE_TICK_RATE = 100.0


@dataclass(frozen=True)
class BridgePreset:
    """A controller's form of the stiffness: ``kind`` (:data:`BRIDGE_TARGET_KINDS`); a topic
    target's ``layout``; a parameter target's ``parameters`` (six double parameters, the diagonal
    in the order [x y z rx ry rz], or one double array of those six); ``source``: where that form
    is defined (docs/controllers.md cites the file and version)."""

    kind: str
    layout: str = ''
    parameters: tuple[str, ...] = ()
    source: str = ''


BRIDGE_PRESETS: dict[str, BridgePreset] = {
    'crisp': BridgePreset('topic', 'diagonal_6',
                          source='crisp_controllers target_stiffness topic, 6 values'),
    'crisp_full': BridgePreset('topic', 'row_major_36',
                               source='crisp_controllers target_stiffness topic, 36 values '
                                      'row-major'),
    'column_major_36': BridgePreset('topic', 'column_major_36',
                                    source='Franka stacks: 36 values column-major'),
    'cartesian_controllers': BridgePreset(
        'parameters', parameters=('stiffness.trans_x', 'stiffness.trans_y', 'stiffness.trans_z',
                                  'stiffness.rot_x', 'stiffness.rot_y', 'stiffness.rot_z'),
        source='fzi cartesian_compliance_controller (ros2 branch, f53f798)'),
    'admittance': BridgePreset('parameters', parameters=('admittance.stiffness',),
                               source='ros2_controllers admittance_controller 6.9.0 (94e74de)'),
    'crisp_parameters': BridgePreset(
        'parameters', parameters=('task.k_pos_x', 'task.k_pos_y', 'task.k_pos_z',
                                  'task.k_rot_x', 'task.k_rot_y', 'task.k_rot_z'),
        source='crisp_controllers 0.1.0 cartesian_impedance_controller (809354897a)'),
}

_IDENTITY_POSE = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
_COMMON_BY_NAME = by_name(COMMON_PARAMETERS)

BRIDGE_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('preset', 'string', 'crisp',
                  'controller form: fills target.kind, target.layout, target.parameters',
                  read_only=True, choices=tuple(BRIDGE_PRESETS)),
    ParameterSpec('input.frame', 'string', 'tensegrity_link1',
                  'frame ~/input_stiffness is expressed in (rows a wrench about its origin, '
                  'columns a twist of it)'),
    ParameterSpec('output.frame', 'string', '',
                  "the controller's frame (its name, for diagnostics; its pose: output.pose)"),
    ParameterSpec('output.pose', 'double_array', _IDENTITY_POSE,
                  "pose [x y z qx qy qz qw] of the controller's frame in input.frame (m)"),
    ParameterSpec('output.min_eigenvalue', 'double', 1e-3,
                  'eigenvalue floor of the positive definite projection', range=(0.0, 1e12)),
    ParameterSpec('output.scale', 'double', 1.0, 'factor applied after the projection',
                  range=(1e-12, 1e12)),
    ParameterSpec('output.translational_clamp', 'double_array', None,
                  '[min, max] of the translational block eigenvalues, N/m (empty: no clamp)'),
    ParameterSpec('output.rotational_clamp', 'double_array', None,
                  '[min, max] of the rotational block eigenvalues, N m/rad (empty: no clamp)'),
    ParameterSpec('output.time_constant', 'double', 0.0,
                  'first-order low-pass time constant, s (0: off)', range=(0.0, 1000.0)),
    ParameterSpec('output.max_rate', 'double', -1.0,
                  f'highest output rate, Hz (0: one per input; -1: the target kind\'s: one per '
                  f'input for topics, {PARAMETER_TARGET_RATE:g} Hz for parameters)',
                  range=(-1.0, 10_000.0)),
    ParameterSpec('target.kind', 'string', '', "topic | parameters (empty: the preset's)",
                  read_only=True, choices=('', *BRIDGE_TARGET_KINDS)),
    ParameterSpec('target.layout', 'string', '',
                  "layout of ~/output_stiffness (empty: the preset's)",
                  choices=('', 'row_major_36', 'column_major_36', 'diagonal_6')),
    ParameterSpec('target.node', 'string', '',
                  'full name of the controller node whose parameters are set (parameters '
                  'targets)', read_only=True),
    ParameterSpec('target.parameters', 'string_array', None,
                  "six double parameters [x y z rx ry rz] or one double array (empty: the "
                  "preset's)"),
    ParameterSpec('target.deadband', 'double', 0.01,
                  'parameters are set only when a value moved by more than this (relative)',
                  range=(0.0, 1.0)),
    ParameterSpec('target.timeout', 'double', 1.0,
                  'seconds a set_parameters call may take before it counts as lost (and is '
                  'sent again)',
                  range=(0.01, 60.0)),
    _COMMON_BY_NAME['qos.depth'],
    _COMMON_BY_NAME['qos.input_reliability'],
    _COMMON_BY_NAME['diagnostics.period'],
    _COMMON_BY_NAME['realtime.fast_lane'],
)


@dataclass(frozen=True)
class BridgeSettings:
    """Everything ``stiffness_bridge`` needs, swapped as a whole: built by
    :func:`bridge_settings`. ``conditioner``: a
    :class:`~tensegrity_stiffness.mechanics.controller_stiffness.Conditioner`; ``max_rate``
    resolved (0:
    one output per input)."""

    preset: str
    kind: str
    layout: str
    parameter_names: tuple[str, ...]
    target_node: str
    conditioner: Any
    time_constant: float
    max_rate: float
    deadband: float
    timeout: float
    input_frame: str
    output_frame: str
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def tick_period(self) -> float:
        """Seconds between the bridge's ticks (rate-limited outputs, retries, settling)."""
        return 1.0 / (self.max_rate if self.max_rate > 0.0 else BRIDGE_IDLE_TICK_RATE)


def _clamp_bounds(name: str, value: list[float]) -> tuple[float, float] | None:
    if not value:
        return None
    if len(value) != 2 or not 0.0 <= value[0] <= value[1]:
        raise ValueError(f'{name} must be empty or [min, max] with 0 <= min <= max, got {value}')
    return value[0], value[1]


def bridge_settings(values: Mapping[str, Any], generation: int = 0) -> BridgeSettings:
    """Validate a whole parameter set of ``stiffness_bridge`` and build its settings; ValueError
    names the bad field."""
    from tensegrity_stiffness.mechanics.controller_stiffness import Conditioner

    checked = {spec.name: spec.check(values[spec.name]) for spec in BRIDGE_PARAMETERS}
    preset = BRIDGE_PRESETS[checked['preset']]
    kind = checked['target.kind'] or preset.kind
    layout = checked['target.layout'] or preset.layout
    names = tuple(checked['target.parameters']) or preset.parameters
    node = checked['target.node'].strip()
    if kind == 'topic' and not layout:
        raise ValueError(f'target.layout must be set: preset {checked["preset"]!r} has none')
    if kind == 'parameters':
        if len(names) not in (1, 6) or not all(n.strip() for n in names):
            raise ValueError('target.parameters must name six double parameters or one double '
                             f'array, got {list(names)}')
        if not node:
            raise ValueError('target.node must name the controller node of a parameters target')
    try:
        conditioner = Conditioner(
            pose=checked['output.pose'], min_eigenvalue=checked['output.min_eigenvalue'],
            scale=checked['output.scale'],
            translational=_clamp_bounds('output.translational_clamp',
                                        checked['output.translational_clamp']),
            rotational=_clamp_bounds('output.rotational_clamp',
                                     checked['output.rotational_clamp']))
    except ValueError as exc:
        message = str(exc)
        raise ValueError(message if message.startswith('output.') else f'output.{message}'
                         ) from None
    rate = checked['output.max_rate']
    if rate < 0.0:
        rate = PARAMETER_TARGET_RATE if kind == 'parameters' else 0.0
    return BridgeSettings(
        preset=checked['preset'], kind=kind, layout=layout,
        parameter_names=names if kind == 'parameters' else (), target_node=node,
        conditioner=conditioner, time_constant=checked['output.time_constant'], max_rate=rate,
        deadband=checked['target.deadband'], timeout=checked['target.timeout'],
        input_frame=checked['input.frame'], output_frame=checked['output.frame'],
        generation=generation, values=checked)


# ---------------------------------------------------------------------------------- estimator_node
#: What ``estimator_node`` assumes about the external load (``estimation.external_wrench``).
LOAD_MODES = ('unknown', 'zero', 'measured')
#: Inputs of ``estimator_node`` by the name ``estimation.trigger`` gives them (topic ``~/<name>``).
ESTIMATOR_INPUTS = ('measured_tensions', 'measured_lengths', 'measured_pose', 'imu',
                    'measured_wrench')

#: What ``estimation.method`` selects: the recursive filter on the joint's dynamics
#: (:class:`~tensegrity_stiffness.estimation.JointFilter`) or the quasi-static estimate of each
#: reading set (:func:`~tensegrity_stiffness.estimation.estimate_joint_state`).
ESTIMATION_METHODS = ('filter', 'static')
#: The filter's process noise densities, by parameter (``filter.<field>``: the fields of
#: :class:`~tensegrity_stiffness.estimation.ProcessNoise`, whose defaults are the one home).
PROCESS_NOISE_UNITS = {'angular_acceleration': 'rad/s^2 sqrt(s)',
                       'linear_acceleration': 'm/s^2 sqrt(s)', 'force_rate': 'N/s sqrt(s)',
                       'moment_rate': 'N m/s sqrt(s)'}

ESTIMATION_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('estimation.method', 'string', 'filter',
                  "'filter' (recursive, on the joint's dynamics: a moving joint) or 'static' "
                  '(each reading set on its own, the joint at rest); docs/estimation.md',
                  choices=ESTIMATION_METHODS),
    *(ParameterSpec(f'filter.{name}', 'double', getattr(DEFAULT_PROCESS_NOISE, name),
                    f'process noise of the filter: {name.replace("_", " ")} density, {unit}',
                    range=(0.0, 1e9)) for name, unit in PROCESS_NOISE_UNITS.items()),
    ParameterSpec('estimation.external_wrench', 'string', 'unknown',
                  "the load on link 2: 'unknown' (estimated, W = -F), 'zero' (unloaded, to "
                  "sensors.force_std / moment_std) or 'measured' (~/measured_wrench)",
                  choices=LOAD_MODES),
    ParameterSpec('estimation.trigger', 'string', 'measured_tensions',
                  'the input whose messages trigger an estimate (with the latest of the others '
                  'no older than estimation.max_age)', choices=ESTIMATOR_INPUTS),
    ParameterSpec('estimation.max_age', 'double', 0.05,
                  'inputs older than this (s, by arrival) are left out of an estimate',
                  range=(0.0, 3600.0)),
    ParameterSpec('estimation.consistency_probability', 'double', CONSISTENCY_PROBABILITY,
                  'probability of the chi-square test of each estimate (consistent: False when '
                  'its chi2 exceeds the 1 - p quantile; contradicted readings are then left out '
                  'while redundancy remains)', range=(1e-15, 0.5)),
    ParameterSpec('estimation.stiffness_std', 'bool', True,
                  'publish the first-order std of the stiffness (~/cartesian_stiffness_std; the '
                  "spine's ~/tip_stiffness_base_std), computed only while it has a subscriber"),
    ParameterSpec('sensors.tension_std', 'double', 0.005, 'load cells: tension std, N',
                  range=(1e-12, 1e6)),
    ParameterSpec('sensors.length_std', 'double', 1e-4, 'string length sensors: std, m',
                  range=(1e-12, 1e3)),
    ParameterSpec('sensors.gravity_std', 'double', 0.01,
                  'IMU: std of each component of the measured gravity direction (unit vector)',
                  range=(1e-9, 1.0)),
    ParameterSpec('sensors.gravity_base', 'double_array', [0.0, -1.0, 0.0],
                  'direction of gravity in {1} (3 values; normalised)'),
    ParameterSpec('sensors.imu_rest_tolerance', 'double', 1.0,
                  "estimation.method 'static': an ~/imu reading whose specific force differs "
                  'from 9.81 m/s^2 by more than this (m/s^2) is not at rest and is rejected',
                  range=(0.0, 1e3)),
    ParameterSpec('sensors.accelerometer_std', 'double', 0.0981,
                  "estimation.method 'filter': accelerometer std of each component, m/s^2 "
                  '(modelled with the link\'s acceleration)', range=(1e-9, 1e3)),
    ParameterSpec('sensors.gyro_std', 'double', 0.01,
                  "estimation.method 'filter': gyro std of each component, rad/s (an ~/imu "
                  'whose angular_velocity_covariance[0] is -1 has no gyro)',
                  range=(1e-9, 1e3)),
    ParameterSpec('sensors.pose_position_std', 'double', 1e-4,
                  'motion capture position std, m, used when ~/measured_pose carries no '
                  'covariance (all zeros)', range=(1e-12, 1e3)),
    ParameterSpec('sensors.pose_angle_std', 'double', 0.0017453292519943296,
                  'motion capture angle std, rad, used when ~/measured_pose carries no '
                  'covariance', range=(1e-12, 10.0)),
    ParameterSpec('sensors.force_std', 'double', 0.01,
                  'force-torque sensor force std, N (also the tolerance of a zero load)',
                  range=(1e-12, 1e6)),
    ParameterSpec('sensors.moment_std', 'double', 0.0005,
                  'force-torque sensor moment std, N m (also the tolerance of a zero load)',
                  range=(1e-12, 1e6)),
)

#: Every parameter of ``estimator_node``, in declaration order (link 2's inertia and the
#: strings' damping: the filter's dynamics).
ESTIMATOR_NODE_PARAMETERS: tuple[ParameterSpec, ...] = (
    JOINT_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + FRAME_PARAMETERS + TF_PARAMETERS
    + ESTIMATION_PARAMETERS + COMMON_PARAMETERS + LINK2_PARAMETERS
    + (JOINT_DYNAMICS_PARAMETERS[-1],))


@dataclass(frozen=True)
class EstimatorNodeSettings:
    """Everything one estimate of ``estimator_node`` needs, swapped as a whole (never mutated):
    built from a complete set of parameter values by :func:`estimator_node_settings`."""

    model: JointModel
    link1_frame: str
    link2_frame: str
    load_mode: str
    trigger: str
    method: str
    process_noise: ProcessNoise
    accelerometer_std: float
    gyro_std: float
    max_age: float
    stiffness_std: bool
    consistency_probability: float
    tension_std: float
    length_std: float
    gravity_std: float
    gravity_base: tuple[float, float, float]
    imu_rest_tolerance: float
    pose_position_std: float
    pose_angle_std: float
    force_std: float
    moment_std: float
    max_array_length: int
    marker_period: float
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)


def estimator_node_settings(values: Mapping[str, Any], generation: int = 0
                            ) -> EstimatorNodeSettings:
    """Validate a whole parameter set of ``estimator_node`` and build its settings; ValueError
    names the bad field. Every parameter of the table must be in ``values``."""
    checked = {spec.name: spec.check(values[spec.name]) for spec in ESTIMATOR_NODE_PARAMETERS}
    for name in ('frames.link1', 'frames.link2'):
        if not checked[name].strip():
            raise ValueError(f'{name} must not be empty')
    base = checked['sensors.gravity_base']
    if len(base) != 3 or not all(math.isfinite(v) for v in base) or math.hypot(*base) < 1e-9:
        raise ValueError(f'sensors.gravity_base must be 3 finite values, not all zero, got '
                         f'{base}')
    return EstimatorNodeSettings(
        model=joint_from_values(checked), link1_frame=checked['frames.link1'],
        link2_frame=checked['frames.link2'],
        load_mode=checked['estimation.external_wrench'], trigger=checked['estimation.trigger'],
        method=checked['estimation.method'],
        process_noise=ProcessNoise(**{name: checked[f'filter.{name}']
                                      for name in PROCESS_NOISE_UNITS}),
        accelerometer_std=checked['sensors.accelerometer_std'],
        gyro_std=checked['sensors.gyro_std'], max_age=checked['estimation.max_age'],
        stiffness_std=checked['estimation.stiffness_std'],
        consistency_probability=checked['estimation.consistency_probability'],
        tension_std=checked['sensors.tension_std'], length_std=checked['sensors.length_std'],
        gravity_std=checked['sensors.gravity_std'],
        gravity_base=(float(base[0]), float(base[1]), float(base[2])),
        imu_rest_tolerance=checked['sensors.imu_rest_tolerance'],
        pose_position_std=checked['sensors.pose_position_std'],
        pose_angle_std=checked['sensors.pose_angle_std'],
        force_std=checked['sensors.force_std'], moment_std=checked['sensors.moment_std'],
        max_array_length=checked['limits.max_array_length'],
        marker_period=marker_period(checked['markers.max_rate']),
        generation=generation, values=checked)


# --------------------------------------------------------------------------- spine_estimator_node
#: Inputs of ``spine_estimator_node`` (no IMU on a spine yet): per-string arrays of every joint,
#: joint-major; ``measured_pose`` is the tool frame in the base; ``measured_wrench`` the tip load.
SPINE_ESTIMATOR_INPUTS = ('measured_tensions', 'measured_lengths', 'measured_pose',
                          'measured_wrench')


#: The filter's process noise of a spine (``ChainFilter``'s defaults,
#: :data:`~tensegrity_stiffness.estimation.DEFAULT_CHAIN_PROCESS_NOISE`).
SPINE_PROCESS_NOISE_PARAMETERS = tuple(
    replace(spec, default=getattr(DEFAULT_CHAIN_PROCESS_NOISE, spec.name[len('filter.'):]))
    for spec in ESTIMATION_PARAMETERS if spec.name.startswith('filter.'))


def spine_estimator_node_parameters(n_joints: int = 5) -> tuple[ParameterSpec, ...]:
    """Every parameter of ``spine_estimator_node``: the spine's (as ``spine_node``: the links'
    inertias and the strings' damping are the filter's dynamics) and the estimator's
    (``estimation.*``, ``filter.*`` with the spine's defaults, ``sensors.*``; the IMU's are not
    used)."""
    spine_noise = by_name(SPINE_PROCESS_NOISE_PARAMETERS)
    return spine_node_parameters(n_joints) + tuple(
        spine_noise.get(spec.name, spec) for spec in ESTIMATION_PARAMETERS)


@dataclass(frozen=True)
class SpineEstimatorNodeSettings(SpineNodeSettings):
    """Everything one estimate of ``spine_estimator_node`` needs, swapped as a whole: the spine's
    settings (``chain``, frames, topic-set ``rest_lengths``: :class:`SpineNodeSettings`) and
    the estimator's (``estimator``: the sensors' stds, load mode, trigger, max age)."""

    estimator: EstimatorNodeSettings = field(kw_only=True)

    @property
    def stiffness_std(self) -> bool:
        """``estimation.stiffness_std`` (as :attr:`EstimatorNodeSettings.stiffness_std`)."""
        return self.estimator.stiffness_std


def spine_estimator_node_settings(values: Mapping[str, Any], generation: int = 0
                                  ) -> SpineEstimatorNodeSettings:
    """Validate a whole parameter set of ``spine_estimator_node``; ValueError names the bad
    field (an ``estimation.trigger`` the spine has no input for among them)."""
    spine = spine_node_settings(values, generation)
    if values['estimation.trigger'] not in SPINE_ESTIMATOR_INPUTS:
        raise ValueError(f'estimation.trigger must be one of {" | ".join(SPINE_ESTIMATOR_INPUTS)}'
                         f' for a spine, got {values["estimation.trigger"]!r}')
    joint_values = {name: values[name] for name in (spec.name for spec in JOINT_PARAMETERS)}
    estimator = estimator_node_settings({
        **defaults(ESTIMATOR_NODE_PARAMETERS), **joint_values,
        **{spec.name: values[spec.name] for spec in ESTIMATION_PARAMETERS + COMMON_PARAMETERS}})
    inherited = {f.name: getattr(spine, f.name) for f in fields(SpineNodeSettings)}
    inherited['values'] = spine.values | {
        spec.name: estimator.values[spec.name] for spec in ESTIMATION_PARAMETERS}
    return SpineEstimatorNodeSettings(**inherited, estimator=estimator)
