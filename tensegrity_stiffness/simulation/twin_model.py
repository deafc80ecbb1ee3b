"""The twin's model: its options (:class:`SimulationOptions`, the limits of its inputs) and
the MJCF it is built from (:func:`joint_mjcf`, :func:`chain_mjcf`, :func:`export_mjcf`), as
:mod:`~tensegrity_stiffness.simulation.twin` describes them (the model, the strings' limits,
gravity). numpy only; MuJoCo reads the MJCF in :mod:`~tensegrity_stiffness.simulation.twin`.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.geometry.validation import (
    finite_array,
    positive_interval,
    positive_number,
)
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG, JointChain
from tensegrity_stiffness.mechanics.inertia import (
    DEFAULT_LINK_MASS,
    LinkInertia,
    default_inertia_moments,
)
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.joint_dynamics import DEFAULT_STRING_DAMPING

FloatArray = NDArray[np.float64]

#: Choices of ``max_length`` (see the module docstring).
MAX_LENGTH_MODES = ('limit', 'ignore')
#: Integrators that MuJoCo's split step (mj_step1 / mj_step2) supports.
INTEGRATORS = ('implicitfast', 'implicit', 'Euler')
#: Default time step (s): 1 kHz.
DEFAULT_TIMESTEP = 1e-3
#: Default damping of every string (N s/m): the dynamics' one value
#: (:data:`~tensegrity_stiffness.mechanics.joint_dynamics.DEFAULT_STRING_DAMPING`).
DEFAULT_TENDON_DAMPING = DEFAULT_STRING_DAMPING
#: Default damping of each free-joint dof of every link (N s/m, N m s/rad): a small damping
#: against the world that damps the spine's slow bending mode (about 4 rad/s with 10 g links),
#: which the strings' damping barely reaches; negligible against the joint's own modes.
DEFAULT_JOINT_DAMPING = 1e-3
#: Default gravity (m/s^2, base frame) of the single joint: the vertebra's axis is +y, as in
#: ``config/default_spine.yaml``. Compensated (the library's joint has no weights); the IMU
#: senses it.
DEFAULT_JOINT_GRAVITY = (0.0, -9.81, 0.0)
#: Settled: the largest link speed (m/s and rad/s) is at most this factor times ``tolerance``.
REST_SPEED_FACTOR = 1.0
#: The physical range of a rest length the twin takes (unless ``rest_length_range`` sets one):
#: above this fraction of the string's configured rest length, and at most its maximum length
#: (its configured rest length when it has none) times ``1 + REST_LENGTH_MARGIN``. Outside it a
#: string could not be mounted (1e308, 1e6 or 5e-324 m: MuJoCo's soft length limit then drives
#: the links far away or crushes them together, and the twin needs minutes to recover).
MIN_REST_LENGTH_FRACTION = 0.1
REST_LENGTH_MARGIN = 0.5
#: The largest external force (N) and moment (N m) the twin is asked to hold by default
#: (``max_force`` / ``max_moment``; the sim node's ``limits.max_force`` / ``limits.max_moment``):
#: a larger wrench is refused as absurd (the default joint's strings carry about 1.5 N each).
DEFAULT_MAX_FORCE = 100.0
DEFAULT_MAX_MOMENT = 10.0


@dataclass(frozen=True)
class SimulationOptions:
    """Options of the MJCF model and the simulation (every field has a documented default).

    ``timestep`` (s, default 1e-3); ``integrator`` (``'implicitfast'``, ``'implicit'`` or
    ``'Euler'``, MuJoCo's names; default ``'implicitfast'``); ``tendon_damping`` (N s/m per
    string, default 0.5); ``joint_damping`` (on each of the 6 free-joint dofs of a link, N s/m
    and N m s/rad, default 1e-3); ``link_mass`` (kg, default 0.01: links whose config has no
    mass); ``link_inertia`` ((3,) kg m^2 principal moments about the centre of mass; default
    ``None``: ``m r^2 / 2`` on each axis, ``r`` the RMS distance of the link's nodes from its
    centre of mass); ``link2`` (a single joint's link 2: a
    :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia`, its mass, centre of mass and
    full inertia, the config's ``joint.link2_*``; default ``None``: ``link_mass`` at the origin
    with ``link_inertia``); ``gravity`` ((3,) m/s^2 in the
    base; default ``None``: the chain's ``gravity``, for the joint (0, -9.81, 0));
    ``max_length`` (``'limit'`` or ``'ignore'``, default ``'limit'``); ``rest_length_rate``
    (m/s, the largest change of a rest length per second, like a motor; default ``None``:
    changes apply at once); ``string_width`` (m, drawn width of the tendons, default 5e-4);
    ``rest_length_range`` ((min, max) m for every string; default ``None``: each string's
    physical range, :data:`MIN_REST_LENGTH_FRACTION` and :data:`REST_LENGTH_MARGIN`);
    ``max_force`` / ``max_moment`` (N, N m: a larger external wrench is refused; default
    :data:`DEFAULT_MAX_FORCE` / :data:`DEFAULT_MAX_MOMENT`; ``inf``: no bound but finiteness).
    """

    timestep: float = DEFAULT_TIMESTEP
    integrator: str = 'implicitfast'
    tendon_damping: float = DEFAULT_TENDON_DAMPING
    joint_damping: float = DEFAULT_JOINT_DAMPING
    link_mass: float = DEFAULT_LINK_MASS
    link_inertia: tuple[float, float, float] | None = None
    link2: LinkInertia | None = None
    gravity: tuple[float, float, float] | None = None
    max_length: str = 'limit'
    rest_length_rate: float | None = None
    string_width: float = 5e-4
    rest_length_range: tuple[float, float] | None = None
    max_force: float = DEFAULT_MAX_FORCE
    max_moment: float = DEFAULT_MAX_MOMENT

    def __post_init__(self) -> None:
        positive_number('timestep', self.timestep)
        positive_number('tendon_damping', self.tendon_damping, allow_zero=True)
        positive_number('joint_damping', self.joint_damping, allow_zero=True)
        positive_number('link_mass', self.link_mass)
        positive_number('string_width', self.string_width)
        positive_number('max_force', self.max_force, allow_inf=True)
        positive_number('max_moment', self.max_moment, allow_inf=True)
        if self.rest_length_range is not None:
            object.__setattr__(self, 'rest_length_range',
                               positive_interval('rest_length_range', self.rest_length_range))
        if self.integrator not in INTEGRATORS:
            raise ValueError(f'integrator must be one of {INTEGRATORS}, got {self.integrator!r}')
        if self.max_length not in MAX_LENGTH_MODES:
            raise ValueError(f'max_length must be one of {MAX_LENGTH_MODES}, got '
                             f'{self.max_length!r}')
        if self.rest_length_rate is not None:
            positive_number('rest_length_rate', self.rest_length_rate)
        if self.link_inertia is not None:
            inertia = finite_array('link_inertia', self.link_inertia)
            if inertia.shape != (3,) or np.any(inertia <= 0.0):
                raise ValueError(f'link_inertia must be 3 positive values, got {inertia}')
            object.__setattr__(self, 'link_inertia', tuple(float(v) for v in inertia))
        if self.link2 is not None and not isinstance(self.link2, LinkInertia):
            raise ValueError(f'link2 must be a LinkInertia, got {type(self.link2).__name__}')
        if self.gravity is not None:
            g = finite_array('gravity', self.gravity)
            if g.shape != (3,):
                raise ValueError(f'gravity must have 3 values, got shape {g.shape}')
            object.__setattr__(self, 'gravity', tuple(float(v) for v in g))


def resolved_options(options: SimulationOptions | None, overrides: dict[str, Any]
                     ) -> SimulationOptions:
    """``options`` (default :class:`SimulationOptions`) with the keyword ``overrides`` applied;
    ValueError naming an unknown option."""
    base = options if options is not None else SimulationOptions()
    unknown = set(overrides) - set(SimulationOptions.__dataclass_fields__)
    if unknown:
        raise ValueError(f'unknown simulation options {sorted(unknown)}; known: '
                         f'{sorted(SimulationOptions.__dataclass_fields__)}')
    return replace(base, **overrides) if overrides else base


def checked_wrench(wrench: ArrayLike, max_force: float = DEFAULT_MAX_FORCE,
                   max_moment: float = DEFAULT_MAX_MOMENT,
                   names: tuple[str, str] = ('max_force', 'max_moment')) -> FloatArray:
    """The wrench (6,) ``[f; m]`` as a float array if it is finite and ``|f| <= max_force`` (N),
    ``|m| <= max_moment`` (N m); ValueError naming the value and the bound (called ``names``)
    otherwise. The one check of an external wrench the twin takes (library and sim node)."""
    W = finite_array('wrench', wrench)
    if W.shape != (6,):
        raise ValueError(f'wrench must have 6 values [fx fy fz mx my mz], got shape {W.shape}')
    with np.errstate(over='ignore'):  # 1e308: an infinite norm, refused below
        force, moment = float(np.linalg.norm(W[:3])), float(np.linalg.norm(W[3:]))
    if force > max_force:
        raise ValueError(f'|force| = {force:.6g} N exceeds {names[0]} = {max_force:g} N')
    if moment > max_moment:
        raise ValueError(f'|moment| = {moment:.6g} N m exceeds {names[1]} = {max_moment:g} N m')
    return W


@dataclass(frozen=True)
class TwinLayout:
    """What the MJCF is built from: N joints in series (the single joint is N = 1)."""

    joints: list[JointModel]
    offsets: FloatArray            # (N-1, 4, 4): {1}_{i+1} in {2}_i
    masses: FloatArray             # (N,) kg of the library's weights (0: none)
    coms: FloatArray               # (N, 3) in {2}_i
    gravity: FloatArray            # (3,) base
    screws: FloatArray             # (N, 6) initial configuration
    single: bool                   # names of the single joint (link2, string names)
    string_names: list[list[str]] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.joints)


def joint_layout(model: JointModel, options: SimulationOptions) -> TwinLayout:
    """The layout of the joint's twin (N = 1, gravity :data:`DEFAULT_JOINT_GRAVITY` unless the
    options give one). ValueError for a force law other than Hooke's (MuJoCo's tendon springs):
    the twin and its exported MJCF would simulate another joint."""
    if not isinstance(model, JointModel):
        raise ValueError(f'model must be a JointModel, got {type(model).__name__}')
    if model.force_law != 'hooke':
        raise ValueError(f"force_law: the twin simulates Hooke's law only (MuJoCo tendons), "
                         f'got {model.force_law!r}')
    g = np.array(DEFAULT_JOINT_GRAVITY if options.gravity is None else options.gravity)
    return TwinLayout([model], np.zeros((0, 4, 4)), np.zeros(1), np.zeros((1, 3)), g,
                   model.initial_screw[None].copy(), True, [list(model.string_names)])


def chain_layout(chain: JointChain, options: SimulationOptions) -> TwinLayout:
    """The layout of the spine's twin (its joints, link offsets, masses and gravity);
    ValueError for a force law other than Hooke's, as :func:`joint_layout`."""
    if not isinstance(chain, JointChain):
        raise ValueError(f'chain must be a JointChain, got {type(chain).__name__}')
    for i, model in enumerate(chain.joints):
        if model.force_law != 'hooke':
            raise ValueError(f"joint {i + 1} force_law: the twin simulates Hooke's law only, "
                             f'got {model.force_law!r}')
    g = np.array(chain.gravity if options.gravity is None else options.gravity, dtype=float)
    names = [[f'j{i + 1}_{s}' for s in m.string_names] for i, m in enumerate(chain.joints)]
    return TwinLayout(list(chain.joints), chain.link_offsets.copy(), chain.link_masses.copy(),
                   chain.link_coms.copy(), g, chain.unloaded_screws(), False, names)


def rest_length_bounds(rest_lengths: FloatArray, max_lengths: FloatArray,
                       rest_length_range: tuple[float, float] | None = None
                       ) -> tuple[FloatArray, FloatArray]:
    """(low, high) (n,) m: the rest lengths a twin takes, ``rest_length_range`` for every
    string, or each string's physical range: above :data:`MIN_REST_LENGTH_FRACTION` of its
    configured rest length, at most ``1 + REST_LENGTH_MARGIN`` times its maximum length (its
    rest length without one). The one home of that rule (joint, spine and structure twins)."""
    rest = np.asarray(rest_lengths, dtype=np.float64)
    if rest_length_range is not None:
        low, high = rest_length_range
        return np.full(rest.shape, low), np.full(rest.shape, high)
    lmax = np.asarray(max_lengths, dtype=np.float64)
    longest = np.where(np.isfinite(lmax), lmax, rest)
    return MIN_REST_LENGTH_FRACTION * rest, (1.0 + REST_LENGTH_MARGIN) * longest


def rate_limited(current: FloatArray, target: FloatArray, max_step: float) -> FloatArray:
    """``current`` moved towards ``target`` by at most ``max_step`` per entry (a motor's rate
    limit over one time step; ``inf``: at once). An entry within ``max_step`` of its target
    lands on it exactly."""
    change = target - current
    return np.where(np.abs(change) <= max_step, target,
                    current + np.clip(change, -max_step, max_step))


def layout_rest_length_bounds(layout: TwinLayout, options: SimulationOptions
                              ) -> tuple[FloatArray, FloatArray]:
    """:func:`rest_length_bounds` of every string of the layout (joint-major)."""
    return rest_length_bounds(np.concatenate([m.rest_lengths for m in layout.joints]),
                              np.concatenate([m.max_lengths for m in layout.joints]),
                              options.rest_length_range)


def _num(value: float) -> str:
    """Shortest repr that round-trips the double (MJCF is parsed with full precision)."""
    return repr(float(value))


def _vec(values: ArrayLike) -> str:
    return ' '.join(_num(v) for v in np.ravel(values))


def _quat_wxyz(R: FloatArray) -> FloatArray:
    x, y, z, w = rotation_to_quaternion(R)
    return np.array([w, x, y, z])


def link_body_name(layout: TwinLayout, i: int) -> str:
    """Body name of link i (0 = the world / link 1 of the joint)."""
    if i == 0:
        return 'world'
    return 'link2' if layout.single else f'link_{i}'


def _site_name(layout: TwinLayout, joint: int, side: int, node: str) -> str:
    prefix = '' if layout.single else f'j{joint + 1}_'
    return f'{prefix}link{side}_{node}'


def _inertia(model: JointModel, com: FloatArray, mass: float,
             options: SimulationOptions) -> FloatArray:
    if options.link_inertia is not None:
        return np.array(options.link_inertia)
    return default_inertia_moments(model.link2_nodes, mass, com)


def build_mjcf(layout: TwinLayout, options: SimulationOptions, model_name: str) -> str:
    """The MJCF text of ``layout`` (the model of :mod:`~tensegrity_stiffness.simulation.twin`'s
    docstring) under ``model_name``."""
    root = ET.Element('mujoco', model=model_name)
    ET.SubElement(root, 'compiler', angle='radian', autolimits='true')
    opt = ET.SubElement(root, 'option', timestep=_num(options.timestep),
                        integrator=options.integrator, gravity=_vec(layout.gravity))
    ET.SubElement(opt, 'flag', contact='disable')
    ET.SubElement(ET.SubElement(root, 'visual'), 'global', offwidth='1280', offheight='960')
    world = ET.SubElement(root, 'worldbody')
    ET.SubElement(world, 'light', pos='0 0.3 0.3', dir='0 -1 -1', directional='true')
    transforms = exp_se3(layout.screws)
    pose = np.eye(4)
    bodies: list[ET.Element] = [world]
    for i, model in enumerate(layout.joints):
        pose = pose @ transforms[i]
        weighted = layout.masses[i] > 0.0 and bool(np.any(layout.gravity != 0.0))
        mass = float(layout.masses[i]) if layout.masses[i] > 0.0 else options.link_mass
        com = layout.coms[i] if layout.masses[i] > 0.0 else np.zeros(3)
        body = ET.SubElement(world, 'body', name=link_body_name(layout, i + 1),
                             pos=_vec(pose[:3, 3]), quat=_vec(_quat_wxyz(pose[:3, :3])))
        if not weighted:
            body.set('gravcomp', '1')
        free = ET.SubElement(body, 'joint', name=f'{link_body_name(layout, i + 1)}_free',
                             type='free')
        if options.joint_damping > 0.0:
            free.set('damping', _num(options.joint_damping))
        if layout.single and options.link2 is not None:
            link = options.link2
            inertia = link.inertia_matrix(model.link2_nodes)
            off = [inertia[0, 1], inertia[0, 2], inertia[1, 2]]
            shape = ({'fullinertia': _vec([*np.diag(inertia), *off])} if any(off)
                     else {'diaginertia': _vec(np.diag(inertia))})
            ET.SubElement(body, 'inertial', pos=_vec(link.com), mass=_num(link.mass), **shape)
        else:
            ET.SubElement(body, 'inertial', pos=_vec(com), mass=_num(mass),
                          diaginertia=_vec(_inertia(model, com, mass, options)))
        bodies.append(body)
        if i < layout.n - 1:
            pose = pose @ layout.offsets[i]
    tendons = ET.SubElement(root, 'tendon')
    for i, model in enumerate(layout.joints):
        offset = np.eye(4) if i == 0 else layout.offsets[i - 1]
        lower, upper = bodies[i], bodies[i + 1]
        for a, name in enumerate(model.node_names):
            p = offset[:3, :3] @ model.link1_nodes[a] + offset[:3, 3]
            ET.SubElement(lower, 'site', name=_site_name(layout, i, 1, name), pos=_vec(p),
                          size='0.002', rgba='0.2 0.4 0.9 1')
        for b, name in enumerate(model.link2_node_names):
            ET.SubElement(upper, 'site', name=_site_name(layout, i, 2, name),
                          pos=_vec(model.link2_nodes[b]), size='0.002', rgba='0.9 0.4 0.2 1')
        for j, (a, b) in enumerate(model.connections):
            attrs = {'name': layout.string_names[i][j], 'stiffness': _num(model.k[j]),
                     'springlength': f'0 {_num(model.rest_lengths[j])}',
                     'damping': _num(options.tendon_damping), 'width': _num(options.string_width),
                     'rgba': '0.1 0.1 0.1 1'}
            if options.max_length == 'limit' and math.isfinite(model.max_lengths[j]):
                attrs.update(limited='true', range=f'0 {_num(model.max_lengths[j])}',
                             solreflimit=f'{_num(2.0 * options.timestep)} 1')
            tendon = ET.SubElement(tendons, 'spatial', **attrs)
            ET.SubElement(tendon, 'site', site=_site_name(layout, i, 1, model.node_names[a]))
            ET.SubElement(tendon, 'site', site=_site_name(layout, i, 2,
                                                          model.link2_node_names[b]))
    ET.indent(root)
    return ET.tostring(root, encoding='unicode') + '\n'


def joint_mjcf(model: JointModel, options: SimulationOptions | None = None,
               **overrides: Any) -> str:
    """MJCF (XML text) of a joint: link 1 fixed (the world, frame {1}), link 2 the body
    ``link2`` with a free joint and frame {2}, at the model's ``initial_screw``; sites
    ``link1_<node>`` / ``link2_<node>``, one tendon per string named after it. Options: the
    fields of :class:`SimulationOptions` (as keywords or an ``options`` object)."""
    opts = resolved_options(options, overrides)
    return build_mjcf(joint_layout(model, opts), opts, 'tensegrity_joint')


def chain_mjcf(chain: JointChain, options: SimulationOptions | None = None,
               **overrides: Any) -> str:
    """MJCF of a spine: the base fixed (the world, {1}_1), link i the body ``link_i`` with a
    free joint and frame {2}_i, at each joint's unloaded equilibrium; sites
    ``j<i>_link1_<node>`` / ``j<i>_link2_<node>``, tendons ``j<i>_<string>``. Options as
    :func:`joint_mjcf`."""
    opts = resolved_options(options, overrides)
    return build_mjcf(chain_layout(chain, opts), opts, 'tensegrity_spine')


def export_mjcf(config_path: str | Path | None = None, spine: bool = False,
                options: SimulationOptions | None = None, **overrides: Any) -> str:
    """MJCF of the joint (``spine``: the spine) of a config file (default: the packaged
    ``default_joint.yaml`` / ``default_spine.yaml``), for MuJoCo's viewer (``python -m
    mujoco.viewer --mjcf FILE.xml``); the command line's ``export-mjcf``. A joint's link 2
    has the config's ``joint.link2_mass`` / ``link2_com`` / ``link2_inertia`` (unless
    ``link2`` is given). ValueError names a bad field of the config."""
    if spine:
        path = Path(config_path) if config_path else config.packaged_config_path(
            DEFAULT_SPINE_CONFIG)
        try:
            chain = JointChain.from_yaml(path)
        except ValueError as exc:
            raise ValueError(f'config {path}: {exc}') from None
        return chain_mjcf(chain, options, **overrides)
    path = Path(config_path) if config_path else config.packaged_config_path()
    try:
        model = JointModel.from_yaml(path)
        if 'link2' not in overrides and (options is None or options.link2 is None):
            overrides['link2'] = LinkInertia.from_config(config.load_section(path, 'joint'))
    except ValueError as exc:
        raise ValueError(f'config {path}: {exc}') from None
    return joint_mjcf(model, options, **overrides)
