"""Starter configs of a joint and of a spine from a few choices (``tensegrity-stiffness
new-config``; docs/your_joint.md) and the check of a config (:func:`check_config`,
``tensegrity-stiffness check-config``): a template, node radius, string stiffness, a pretension or
rest lengths, link 2's inertia, with the unloaded equilibrium solved and written as
``initial_screw`` (:func:`~tensegrity_stiffness.mechanics.unloaded.unloaded_equilibrium`).

Templates (:data:`TEMPLATES`):

* ``vertebra``: the default sub-vertebra (``config/default_joint.yaml``, 12 strings) scaled to
  ``radius`` (the distance of nodes A and D from the origin; 0.030162 m as printed). Its design
  pose is the default's unloaded equilibrium (link 2 turned over by pi about (1, 0, -1)/sqrt 2),
  scaled; its spine axis is +y of {1}.
* ``ring``: ``n_strings`` (even, >= 6) strings between two equal links, each a ring of
  ``n_strings / 2`` nodes ``R<i>`` of ``radius`` in the z = 0 plane and an apex ``P`` on a mast
  of ``height`` along +z. String ``vertical_<i>`` joins ring node i of link 1 to ring node i of
  link 2, ``apex_<i>`` link 1's apex to ring node i of link 2. Design pose: link 2 raised by
  ``gap`` (0 < gap < height) along +z, no turn; with a ``pretension`` (the apex strings'
  tension) the rest lengths make it an exact equilibrium: the vertical strings carry
  ``pretension (height - gap) / l_apex``. Its spine axis is +z.

Given ``rest_lengths`` instead of a pretension, the equilibrium is solved from the design pose
(neither: a template's own rest lengths, the default's or a pretension of
:data:`DEFAULT_PRETENSION`). Maximum lengths: rest length + ``max_stretch``.

A spine stacks ``n_joints`` copies ``spacing`` apart along the template's axis, upright: the
link offset (pose of {1}_(i+1) in {2}_i) is ``T0^-1 Trans(spacing axis)`` with ``T0`` the
unloaded pose (:func:`stacking_offset`), the tool frame ``T0``'s rotation undone at the origin
of {2}_N.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.geometry.validation import per_string
from tensegrity_stiffness.mechanics.chain import MAX_JOINTS, JointChain
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium, stability_margin
from tensegrity_stiffness.mechanics.inertia import DEFAULT_LINK_MASS, LinkInertia
from tensegrity_stiffness.mechanics.joint import MAX_STRINGS, JointModel
from tensegrity_stiffness.mechanics.joint_dynamics import JointDynamics
from tensegrity_stiffness.mechanics.unloaded import (
    InitialScrewWarning,
    check_initial_screw,
    unloaded_equilibrium,
)

FloatArray = NDArray[np.float64]

TEMPLATES = ('vertebra', 'ring')
#: The printed sub-vertebra (config/default_joint.yaml, the nodes' default joint): nodes,
#: strings (name, link-1 node, link-2 node), rest and maximum lengths, and its unloaded
#: equilibrium (the design pose of the template).
VERTEBRA_RADIUS = 0.030162
VERTEBRA_NODE_NAMES = ('A', 'B', 'C', 'D')
VERTEBRA_NODES = (-0.030162, 0.0, 0.0, -0.01524, -0.026035, 0.0,
                  0.01524, -0.026035, 0.0, 0.030162, 0.0, 0.0)
VERTEBRA_STRINGS = (('cross_AA', 'A', 'A'), ('cross_AD', 'A', 'D'), ('cross_DA', 'D', 'A'),
                    ('cross_DD', 'D', 'D'), ('straight_AB', 'A', 'B'),
                    ('straight_AC', 'A', 'C'), ('straight_BA', 'B', 'A'),
                    ('straight_BD', 'B', 'D'), ('straight_CA', 'C', 'A'),
                    ('straight_CD', 'C', 'D'), ('straight_DB', 'D', 'B'),
                    ('straight_DC', 'D', 'C'))
VERTEBRA_REST = (0.0381,) * 4 + (0.03175,) * 8
VERTEBRA_MAX = (0.0581,) * 4 + (0.05175,) * 8
_VERTEBRA_POSE = (2.221441469079183, 0.0, -2.221441469079183,
                  0.016657666062385, 0.0, 0.016657666062385)
#: The default spine's vertebra spacing along +y (config/default_spine.yaml), m, at the
#: printed radius.
VERTEBRA_SPACING = 0.040003
DEFAULT_STIFFNESS = 77.0
#: Default maximum stretch lmax - l0 (m), the default joint's.
DEFAULT_MAX_STRETCH = 0.02
#: Default pretension (N) of the ring template's apex strings.
DEFAULT_PRETENSION = 1.0
DEFAULT_RING_RADIUS = 0.03
#: The ring template's default number of strings.
DEFAULT_RING_STRINGS = 8
#: The choices that only the ring template takes (a vertebra refuses them).
RING_ONLY_CHOICES = ('n_strings', 'height', 'gap')
DEFAULT_GRAVITY = 9.81


@dataclass(frozen=True)
class JointChoices:
    """The choices of a starter joint (module docstring); None: the template's default.

    ``radius`` m; ``stiffness`` N/m (one or one per string); ``pretension`` N or
    ``rest_lengths`` m (one or one per string, not both); ``max_stretch`` m; ``link2_mass`` kg,
    ``link2_com`` [x y z] m in {2}, ``link2_inertia`` 3 or 9 values kg m^2 (empty: the default
    rule of docs/dynamics.md); ring only (:data:`RING_ONLY_CHOICES`; the vertebra refuses them):
    ``n_strings`` (default :data:`DEFAULT_RING_STRINGS`), ``height`` (mast, m), ``gap`` (m)."""

    template: str = 'vertebra'
    radius: float | None = None
    stiffness: Sequence[float] | float = DEFAULT_STIFFNESS
    pretension: float | None = None
    rest_lengths: Sequence[float] | None = None
    max_stretch: float = DEFAULT_MAX_STRETCH
    link2_mass: float = DEFAULT_LINK_MASS
    link2_com: Sequence[float] = (0.0, 0.0, 0.0)
    link2_inertia: Sequence[float] = field(default_factory=list)
    n_strings: int | None = None
    height: float | None = None
    gap: float | None = None


@dataclass(frozen=True)
class _Layout:
    """A template's geometry: node names and coordinates, strings (name, link-1 node, link-2
    node), design pose (screw), rest lengths (None: from a pretension) and spine axis."""

    names: list[str]
    nodes: FloatArray
    strings: list[tuple[str, str, str]]
    design_screw: FloatArray
    rest: FloatArray | None
    axis: FloatArray
    spacing: float
    tensions: FloatArray | None = None


def _or(value: float | None, default: float) -> float:
    """``value``, or ``default`` when it is None (a given 0 stays 0, and is refused)."""
    return default if value is None else value


def _positive(name: str, value: float) -> float:
    value = float(value)
    if not (math.isfinite(value) and value > 0.0):
        raise ValueError(f'{name} must be finite and > 0, got {value}')
    return value


def _vertebra(choices: JointChoices) -> _Layout:
    scale = _positive('radius', _or(choices.radius, VERTEBRA_RADIUS)) / VERTEBRA_RADIUS
    screw = np.array(_VERTEBRA_POSE)
    screw[3:] *= scale
    return _Layout(list(VERTEBRA_NODE_NAMES), scale * np.reshape(VERTEBRA_NODES, (-1, 3)),
                   list(VERTEBRA_STRINGS), screw, scale * np.array(VERTEBRA_REST),
                   np.array([0.0, 1.0, 0.0]), scale * VERTEBRA_SPACING)


def _ring(choices: JointChoices) -> _Layout:
    n = int(_or(choices.n_strings, DEFAULT_RING_STRINGS))
    if n < 6 or n % 2 or n > MAX_STRINGS:
        raise ValueError(f'n_strings must be even, >= 6 and <= {MAX_STRINGS} (MAX_STRINGS) for '
                         f'the ring template, got {n}')
    m = n // 2
    radius = _positive('radius', _or(choices.radius, DEFAULT_RING_RADIUS))
    height = _positive('height', _or(choices.height, radius))
    gap = _positive('gap', _or(choices.gap, height / 2.0))
    if gap >= height:
        raise ValueError(f'gap must be below the mast height {height}, got {gap}')
    angles = 2.0 * math.pi * np.arange(m) / m
    ring = radius * np.column_stack([np.cos(angles), np.sin(angles), np.zeros(m)])
    names = [f'R{i}' for i in range(m)] + ['P']
    strings = ([(f'vertical_{i}', f'R{i}', f'R{i}') for i in range(m)]
               + [(f'apex_{i}', 'P', f'R{i}') for i in range(m)])
    apex_length = math.hypot(radius, height - gap)
    apex = _positive('pretension', _or(choices.pretension, DEFAULT_PRETENSION))
    tensions = np.r_[np.full(m, apex * (height - gap) / apex_length), np.full(m, apex)]
    return _Layout(names, np.vstack([ring, [0.0, 0.0, height]]), strings,
                   np.array([0.0, 0.0, 0.0, 0.0, 0.0, gap]), None, np.array([0.0, 0.0, 1.0]),
                   gap, tensions)


def joint_section(choices: JointChoices) -> dict[str, Any]:
    """The ``joint`` section of a starter config (keys of ``config/default_joint.yaml``) with
    the unloaded equilibrium as ``initial_screw``; ValueError names a bad choice or says that no
    stable unloaded equilibrium was found."""
    return starter_joint(choices)[0]


def starter_joint(choices: JointChoices) -> tuple[dict[str, Any], JointModel, FloatArray,
                                                  float]:
    """:func:`joint_section`, the model it describes, the template's spine axis (3,) and
    vertebra spacing (m)."""
    if choices.template not in TEMPLATES:
        raise ValueError(f'template must be one of {TEMPLATES}, got {choices.template!r}')
    if choices.pretension is not None and choices.rest_lengths is not None:
        raise ValueError('give a pretension or rest_lengths, not both')
    if choices.template != 'ring':
        given = [name for name in RING_ONLY_CHOICES if getattr(choices, name) is not None]
        if given:
            raise ValueError(f'{", ".join(given)}: only the ring template takes '
                             f'{"these" if len(given) > 1 else "this"}, not '
                             f'{choices.template!r}')
    # Refused here what the dynamics (check-config, modes, the twin) would refuse in the file.
    LinkInertia.from_config({'link2_mass': choices.link2_mass,
                             'link2_com': list(choices.link2_com),
                             'link2_inertia': list(choices.link2_inertia)})
    layout = _vertebra(choices) if choices.template == 'vertebra' else _ring(choices)
    n = len(layout.strings)
    k = per_string('stiffness', choices.stiffness, n, repeat_one=True)
    ends = np.array([[layout.names.index(a), layout.names.index(b)]
                     for _, a, b in layout.strings])
    design = JointModel(layout.nodes, ends, k, np.ones(n), use_kernel=False)
    lengths = design.evaluate(layout.design_screw).lengths
    if choices.rest_lengths is not None:
        rest = per_string('rest_lengths', choices.rest_lengths, n, repeat_one=True)
    elif layout.tensions is not None:
        rest = lengths - layout.tensions / k
    elif choices.pretension is not None:
        rest = lengths - _positive('pretension', choices.pretension) / k
    else:
        rest = layout.rest
    max_stretch = _positive('max_stretch', choices.max_stretch)
    if np.any(rest <= 0.0):
        raise ValueError('the pretension leaves no positive rest length (lower it or raise '
                         'the stiffness)')
    carried = k * max_stretch
    design_tensions = k * (lengths - rest)
    over = np.flatnonzero(design_tensions >= carried * (1.0 - 1e-9))
    if over.size:
        j = int(over[0])
        raise ValueError(
            f'string {layout.strings[j][0]}: a design tension of {design_tensions[j]:.4g} N '
            f'needs a stretch of {design_tensions[j] / k[j]:.4g} m, at or above its maximum '
            f'stretch {max_stretch:g} m (it can carry at most {carried[j]:.4g} N): lower the '
            'pretension or raise the max stretch or the stiffness')
    model = JointModel(layout.nodes, ends, k, rest, max_lengths=rest + max_stretch,
                       node_names=layout.names, string_names=[s[0] for s in layout.strings],
                       initial_screw=layout.design_screw)
    result = unloaded_equilibrium(model)
    if not result.success:
        raise ValueError(f'the starter joint has no stable unloaded equilibrium: '
                         f'{result.message}')
    model.initial_screw = result.screw
    saturated = [layout.strings[j][0] for j in np.flatnonzero(result.state.saturated)]
    if saturated:
        raise ValueError(f'strings at their maximum length at the unloaded equilibrium: '
                         f'{saturated} (raise the max stretch, or lower the rest lengths\' '
                         'difference from the design lengths)')
    section = {
        'node_names': layout.names,
        'link1_nodes': _floats(layout.nodes),
        'string_names': [s[0] for s in layout.strings],
        'string_link1_nodes': [s[1] for s in layout.strings],
        'string_link2_nodes': [s[2] for s in layout.strings],
        'stiffness': _floats(k),
        'rest_lengths': _floats(rest),
        'max_lengths': _floats(rest + max_stretch),
        'force_law': 'hooke',
        'initial_screw': _floats(result.screw),
        'link2_mass': _positive('link2_mass', choices.link2_mass),
        'link2_com': _floats(choices.link2_com),
        'link2_inertia': _floats(choices.link2_inertia),
    }
    return section, model, layout.axis, layout.spacing


def _floats(values: ArrayLike) -> list[float]:
    """Plain floats for YAML (rounded to 1e-15 of a unit: no -0.0, no 1e-17 noise)."""
    return [float(v) + 0.0 for v in np.round(np.asarray(values, dtype=np.float64).ravel(), 15)]


def pose_vector(T: ArrayLike) -> list[float]:
    """A 4x4 rigid transform as the config's ``[x y z qx qy qz qw]``."""
    T = np.asarray(T, dtype=np.float64)
    return _floats(np.r_[T[:3, 3], rotation_to_quaternion(T[:3, :3])])


def stacking_offset(unloaded_screw: ArrayLike, translation: ArrayLike) -> FloatArray:
    """The link offset (pose of {1}_(i+1) in {2}_i, 4x4) that stacks vertebrae upright:
    ``T0^-1 Trans(translation)`` with ``T0 = exp(hat(unloaded_screw))``, so that at the unloaded
    equilibrium joint i+1's base is joint i's base moved by ``translation`` (in {1}_i)."""
    step = np.eye(4)
    step[:3, 3] = np.asarray(translation, dtype=np.float64)
    return np.linalg.inv(exp_se3(np.asarray(unloaded_screw, dtype=np.float64))) @ step


def chain_section(joint: dict[str, Any], axis: ArrayLike, spacing: float, n_joints: int
                  ) -> dict[str, Any]:
    """The ``chain`` section of a spine of ``n_joints`` copies of ``joint`` (a joint section
    with ``initial_screw``) stacked ``spacing`` (m) apart along ``axis`` of the base, upright
    (:func:`stacking_offset`), the tool at the origin of {2}_N turned upright, gravity along
    -axis."""
    if not 1 <= int(n_joints) <= MAX_JOINTS:
        raise ValueError(f'n_joints must be in [1, {MAX_JOINTS}] (MAX_JOINTS), got {n_joints}')
    axis = np.asarray(axis, dtype=np.float64)
    screw = np.asarray(joint['initial_screw'], dtype=np.float64)
    tool = np.eye(4)
    tool[:3, :3] = exp_se3(screw)[:3, :3].T
    section: dict[str, Any] = {'n_joints': int(n_joints),
                               'tool': pose_vector(tool),
                               'gravity': _floats(-DEFAULT_GRAVITY * axis)}
    if n_joints > 1:
        section['link_offsets'] = pose_vector(
            stacking_offset(screw, _positive('spacing', spacing) * axis))
    return section


def starter_config(choices: JointChoices, spine_joints: int = 0, spacing: float | None = None
                   ) -> dict[str, Any]:
    """A starter config document: ``{'/**': {'ros__parameters': {...}}}`` (a ROS parameter file
    every reader takes) with the ``joint`` section and, when ``spine_joints`` > 0, a ``chain``
    section (``spacing`` default: the template's)."""
    joint, _, axis, default_spacing = starter_joint(choices)
    params: dict[str, Any] = {'joint': joint}
    if spine_joints:
        params['chain'] = chain_section(joint, axis, _or(spacing, default_spacing), spine_joints)
    return {'/**': {'ros__parameters': params}}



# ------------------------------------------------------------------------------ the check
def check_config(document: Any) -> dict[str, Any]:
    """The check of a config document (``tensegrity-stiffness check-config``): the joint
    section's unloaded equilibrium (``screw``, solved from ``initial_screw`` after the rule of
    :mod:`~tensegrity_stiffness.mechanics.unloaded`) with its ``residual`` |F|, ``stable`` (K_c
    positive definite) and ``stability_margin``, the ``slack`` and ``saturated`` strings, the
    ``modes`` (frequencies in Hz, link 2's inertia from the config), ``initial_screw`` (given /
    missing, its residual, whether it is an equilibrium), a spine's per-joint unloaded screws
    (``chain``), ``problems`` (why the file is not sound; empty: sound) and ``notes``. A config
    that cannot be read raises ValueError naming the key."""
    section = config.section(document, 'joint')
    given = np.asarray(section.get('initial_screw') or [], dtype=np.float64).ravel()
    with warnings.catch_warnings():
        warnings.simplefilter('ignore', InitialScrewWarning)  # reported below instead
        dynamics = JointDynamics.from_config(document)
    model = dynamics.model
    problems: list[str] = []
    notes: list[str] = []
    report: dict[str, Any] = {'n_strings': model.n_strings, 'strings': model.string_names}
    if given.size:
        screw_check = check_initial_screw(model, given)
        report['initial_screw'] = {'given': True, 'value': given.tolist(),
                                   'residual': screw_check.residual,
                                   'equilibrium': screw_check.is_equilibrium}
        if not screw_check.is_equilibrium:
            problems.append(screw_check.message)
    else:
        report['initial_screw'] = {'given': False, 'value': model.initial_screw.tolist(),
                                   'residual': None, 'equilibrium': None}
        notes.append('joint.initial_screw is missing: solved from the documented starts '
                     '(write the screw below into the file)')
    result = solve_equilibrium(model, np.zeros(6))
    report.update(screw=result.screw, residual=result.residual, converged=result.success,
                  message=result.message, stable=bool(result.stable))
    if not result.success:
        problems.append(f'no unloaded equilibrium: {result.message}')
    state = result.state
    if state is not None:
        report.update(
            stability_margin=stability_margin(state.cartesian_stiffness),
            tensions=state.tensions, lengths=state.lengths,
            slack=[model.string_names[j] for j in np.flatnonzero(state.slack)],
            saturated=[model.string_names[j] for j in np.flatnonzero(state.saturated)])
        if result.success and not result.stable:
            problems.append('the unloaded equilibrium is not stable (K_c is not positive '
                            'definite)')
        if report['saturated']:
            problems.append(f"strings at their maximum length at the unloaded equilibrium: "
                            f"{report['saturated']} (they carry no more tension when "
                            'stretched: raise joint.max_lengths or lower the pretension)')
        if report['slack']:
            notes.append(f"slack strings: {report['slack']}")
    if result.success:
        modes = dynamics.modes(result.screw)
        report['modes'] = {'frequencies_hz': modes.frequencies, 'stable': modes.stable}
    if isinstance(config.parameters(document).get('chain'), dict):
        with warnings.catch_warnings():
            warnings.simplefilter('ignore', InitialScrewWarning)
            chain = JointChain.from_dict(document)
        report['chain'] = {'n_joints': chain.n_joints,
                           'unloaded_screws': chain.unloaded_screws()}
    report['problems'] = problems
    report['notes'] = notes
    report['sound'] = not problems
    return report
