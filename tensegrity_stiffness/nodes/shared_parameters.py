"""The parameter sections several nodes share, in one home: the joint model (``joint.*``), its
frames and TF switch, the common parameters (QoS, limits, solver budget, markers, diagnostics,
the fast lane), the calibrated rest-length offsets, link 2's inertia and the joint's dynamics,
and a spine's ``chain.*``, ``frames.*`` and per-joint ``joint_<i>.*`` overrides; and the
builders of what they describe (:func:`joint_from_values`, :func:`rest_length_offsets`,
:func:`link2_inertia_from_values`, :func:`chain_document`, :func:`marker_period`). Each node's
own module (``stiffness_node``, ``spine_node``, ...) composes its table of these. No ROS
import.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from tensegrity_stiffness.mechanics import templates
from tensegrity_stiffness.mechanics.inertia import DEFAULT_LINK_MASS, LinkInertia
from tensegrity_stiffness.mechanics.joint import FORCE_LAWS, JointModel
from tensegrity_stiffness.mechanics.joint_dynamics import DEFAULT_STRING_DAMPING
from tensegrity_stiffness.mechanics.plausibility import MIN_LINK_MASS, PLAUSIBILITY_MARGIN
from tensegrity_stiffness.nodes.parameter_specs import RELIABILITIES, ParameterSpec

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
                  f"link 2's mass, kg; at most {PLAUSIBILITY_MARGIN:g} x the weight the joint's "
                  "strings can hold (the joint's range: mechanics.plausibility.check_dynamics)",
                  range=(MIN_LINK_MASS, math.inf)),
    ParameterSpec('joint.link2_com', 'double_array', [0.0, 0.0, 0.0],
                  "link 2's centre of mass in {2}, [x y z], m"),
    ParameterSpec('joint.link2_inertia', 'double_array', None,
                  "link 2's inertia about its centre of mass in {2}'s axes: 3 principal moments "
                  'or 9 values row-major, kg m^2 (empty: the twin\'s default m r^2 / 2)'),
)
#: The strings' damping: one value for the modes the nodes compute and the twin's tendon
#: damping (sim_node reads it too, read-only there), so that the modes predict the ringing the
#: twin shows.
STRING_DAMPING_PARAMETER = ParameterSpec(
    'dynamics.string_damping', 'double', DEFAULT_STRING_DAMPING,
    "damping of every string along its length, N s/m (one value: the modes' and the twin's); "
    f"at most {PLAUSIBILITY_MARGIN ** 2:g} x link 2's critical damping (the joint's range: "
    'mechanics.plausibility.check_dynamics)', range=(0.0, math.inf))
#: The parameters of link 2's dynamics, in
#: :func:`~tensegrity_stiffness.mechanics.plausibility.check_dynamics`' order (mass, com,
#: damping).
DYNAMICS_PARAMETER_NAMES = ('joint.link2_mass', 'joint.link2_com', STRING_DAMPING_PARAMETER.name)
JOINT_DYNAMICS_PARAMETERS: tuple[ParameterSpec, ...] = LINK2_PARAMETERS + (
    ParameterSpec('dynamics.enabled', 'bool', False,
                  'publish ~/natural_frequencies of every input (the modes of the joint held '
                  'at its pose by the load that balances it there)', read_only=True),
    STRING_DAMPING_PARAMETER,
)

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



def link2_inertia_from_values(values: Mapping[str, Any]) -> LinkInertia:
    """Link 2's :class:`LinkInertia` from checked ``joint.link2_*`` values (the dynamics' and
    the twin's); errors name the key."""
    return LinkInertia.from_config({key: values[f'joint.{key}'] for key in (
        'link2_mass', 'link2_com', 'link2_inertia')})


def marker_period(rate: float) -> float:
    """Seconds between markers for ``markers.max_rate`` (0: one per input)."""
    return 0.0 if rate <= 0.0 else 1.0 / rate


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

