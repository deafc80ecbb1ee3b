"""A digital twin in MuJoCo: the joint and the spine simulated from the same models.

No integrator of ours: the dynamics are MuJoCo's (PyPI ``mujoco``). This module builds an MJCF
model from a :class:`~tensegrity_stiffness.mechanics.joint.JointModel` or a
:class:`~tensegrity_stiffness.mechanics.chain.JointChain` and steps it; it imports mujoco and
numpy only
(no rclpy).

The model
---------
* Link 1 of the joint (the base of a spine) is the world: frame {1} (the base frame {1}_1).
* Each moving link i is a body ``link_i`` (the joint's link 2: ``link2``) with a free joint;
  the body frame is {2}_i, so the free joint's position and quaternion are the pose of {2}_i in
  the base, ``L_i`` of :mod:`~tensegrity_stiffness.mechanics.chain`.
* Sites at the nodes: joint i's link-1 nodes on link i-1 at ``O_{i-1} p1`` (in {2}_{i-1}), its
  link-2 nodes on link i at ``p2``.
* One spatial tendon per string between its two sites, ``stiffness = k_j`` and
  ``springlength = "0 l0_j"``: tension 0 at or below the rest length and ``k (l - l0)`` above,
  exactly the library's Hooke law with slack strings (eq. 8). The per-string ``k`` and ``l0`` are
  the model's own (a model with drawn "true" parameters is simulated as it is).
* ``max_length``: MuJoCo has no constant tension past ``lmax`` (the library's saturation).
  ``'limit'`` (default) gives each string with a finite ``lmax`` a tendon length limit
  ``range = "0 lmax"``: an inextensible stop (a soft constraint with time constant
  ``2 timestep``, so it can be passed by a fraction of a millimetre under load);
  ``'ignore'`` keeps Hooke's law past ``lmax``.
* Gravity acts where the library's weights act, so that statics match it: a chain link with a
  mass in the chain config has that mass at its ``link_coms`` entry and feels gravity; every
  other link has the dynamic mass ``link_mass`` with its weight compensated (MuJoCo
  ``gravcomp = 1``). The joint's links never carry weights (the library's joint has none); the
  IMU still senses gravity (its specific force is ``a - g``).
* Loads: the external wrench (the library's convention: on link 2 in {1} about its origin; for a
  spine the tip wrench on link N in the base about its origin) is constant in the base frame
  and enters as the generalised force of the free joint, ``[f; R^T (m - p x f)]`` (force in the
  world, torque in the body about its origin), recomputed at every step's pose.

Stepping uses ``mj_step2`` then ``mj_step1`` (MuJoCo's split step), so that after each step the
positions, tendon lengths and passive forces are those of the new state and the load is set at
that pose before the next step; ``imu`` computes the acceleration stage at the current state
when it is read.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG, JointChain
from tensegrity_stiffness.mechanics.dynamics import (
    DEFAULT_LINK_MASS,
    DEFAULT_STRING_DAMPING,
    LinkInertia,
    default_inertia_moments,
)
from tensegrity_stiffness.mechanics.joint import JointModel

__all__ = [
    'DEFAULT_JOINT_DAMPING',
    'DEFAULT_JOINT_GRAVITY',
    'DEFAULT_LINK_MASS',
    'DEFAULT_MAX_FORCE',
    'DEFAULT_MAX_MOMENT',
    'DEFAULT_TENDON_DAMPING',
    'DEFAULT_TIMESTEP',
    'INTEGRATORS',
    'MAX_LENGTH_MODES',
    'MIN_REST_LENGTH_FRACTION',
    'REST_LENGTH_MARGIN',
    'REST_SPEED_FACTOR',
    'ChainSimulation',
    'ImuReading',
    'JointSimulation',
    'Measurements',
    'SensorNoise',
    'SimulationOptions',
    'chain_mjcf',
    'checked_wrench',
    'export_mjcf',
    'import_mujoco',
    'joint_mjcf',
    'measure',
    'rate_limited',
    'rest_length_bounds',
]

FloatArray = NDArray[np.float64]

#: Choices of ``max_length`` (see the module docstring).
MAX_LENGTH_MODES = ('limit', 'ignore')
#: Integrators that MuJoCo's split step (mj_step1 / mj_step2) supports.
INTEGRATORS = ('implicitfast', 'implicit', 'Euler')
#: Default time step (s): 1 kHz.
DEFAULT_TIMESTEP = 1e-3
#: Default damping of every string (N s/m): the dynamics' one value
#: (:data:`~tensegrity_stiffness.mechanics.dynamics.DEFAULT_STRING_DAMPING`).
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
    :class:`~tensegrity_stiffness.mechanics.dynamics.LinkInertia`, its mass, centre of mass and
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
        def positive(name: str, value: Any, allow_zero: bool = False,
                     allow_inf: bool = False) -> None:
            ok = isinstance(value, (int, float)) and not isinstance(value, bool) and \
                (math.isfinite(value) or (allow_inf and value == math.inf)) and \
                (value >= 0.0 if allow_zero else value > 0.0)
            if not ok:
                bound = ('>= 0' if allow_zero else '> 0') + (' or inf' if allow_inf else '')
                raise ValueError(f'{name} must be a finite number {bound}, got {value!r}')

        positive('timestep', self.timestep)
        positive('tendon_damping', self.tendon_damping, allow_zero=True)
        positive('joint_damping', self.joint_damping, allow_zero=True)
        positive('link_mass', self.link_mass)
        positive('string_width', self.string_width)
        positive('max_force', self.max_force, allow_inf=True)
        positive('max_moment', self.max_moment, allow_inf=True)
        if self.rest_length_range is not None:
            bounds = finite_array('rest_length_range', self.rest_length_range)
            if bounds.shape != (2,) or not 0.0 < bounds[0] < bounds[1]:
                raise ValueError(f'rest_length_range must be (min, max) with 0 < min < max (m), '
                                 f'got {self.rest_length_range!r}')
            object.__setattr__(self, 'rest_length_range', (float(bounds[0]), float(bounds[1])))
        if self.integrator not in INTEGRATORS:
            raise ValueError(f'integrator must be one of {INTEGRATORS}, got {self.integrator!r}')
        if self.max_length not in MAX_LENGTH_MODES:
            raise ValueError(f'max_length must be one of {MAX_LENGTH_MODES}, got '
                             f'{self.max_length!r}')
        if self.rest_length_rate is not None:
            positive('rest_length_rate', self.rest_length_rate)
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


def _options(options: SimulationOptions | None, overrides: dict[str, Any]) -> SimulationOptions:
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
class _Layout:
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


def _joint_layout(model: JointModel, options: SimulationOptions) -> _Layout:
    if not isinstance(model, JointModel):
        raise ValueError(f'model must be a JointModel, got {type(model).__name__}')
    g = np.array(DEFAULT_JOINT_GRAVITY if options.gravity is None else options.gravity)
    return _Layout([model], np.zeros((0, 4, 4)), np.zeros(1), np.zeros((1, 3)), g,
                   model.initial_screw[None].copy(), True, [list(model.string_names)])


def _chain_layout(chain: JointChain, options: SimulationOptions) -> _Layout:
    if not isinstance(chain, JointChain):
        raise ValueError(f'chain must be a JointChain, got {type(chain).__name__}')
    g = np.array(chain.gravity if options.gravity is None else options.gravity, dtype=float)
    names = [[f'j{i + 1}_{s}' for s in m.string_names] for i, m in enumerate(chain.joints)]
    return _Layout(list(chain.joints), chain.link_offsets.copy(), chain.link_masses.copy(),
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


def _rest_length_bounds(layout: _Layout, options: SimulationOptions
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


def _link_name(layout: _Layout, i: int) -> str:
    """Body name of link i (0 = the world / link 1 of the joint)."""
    if i == 0:
        return 'world'
    return 'link2' if layout.single else f'link_{i}'


def _site_name(layout: _Layout, joint: int, side: int, node: str) -> str:
    prefix = '' if layout.single else f'j{joint + 1}_'
    return f'{prefix}link{side}_{node}'


def _inertia(model: JointModel, com: FloatArray, mass: float,
             options: SimulationOptions) -> FloatArray:
    if options.link_inertia is not None:
        return np.array(options.link_inertia)
    return default_inertia_moments(model.link2_nodes, mass, com)


def _build_mjcf(layout: _Layout, options: SimulationOptions, model_name: str) -> str:
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
        body = ET.SubElement(world, 'body', name=_link_name(layout, i + 1), pos=_vec(pose[:3, 3]),
                             quat=_vec(_quat_wxyz(pose[:3, :3])))
        if not weighted:
            body.set('gravcomp', '1')
        free = ET.SubElement(body, 'joint', name=f'{_link_name(layout, i + 1)}_free', type='free')
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
    opts = _options(options, overrides)
    return _build_mjcf(_joint_layout(model, opts), opts, 'tensegrity_joint')


def chain_mjcf(chain: JointChain, options: SimulationOptions | None = None,
               **overrides: Any) -> str:
    """MJCF of a spine: the base fixed (the world, {1}_1), link i the body ``link_i`` with a
    free joint and frame {2}_i, at each joint's unloaded equilibrium; sites
    ``j<i>_link1_<node>`` / ``j<i>_link2_<node>``, tendons ``j<i>_<string>``. Options as
    :func:`joint_mjcf`."""
    opts = _options(options, overrides)
    return _build_mjcf(_chain_layout(chain, opts), opts, 'tensegrity_spine')


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


@dataclass(frozen=True)
class ImuReading:
    """An IMU on a link at the origin of its frame, in that frame: ``angular_velocity``
    (rad/s) and ``specific_force`` (m/s^2, acceleration minus gravity: +g up at rest)."""

    angular_velocity: FloatArray
    specific_force: FloatArray


def import_mujoco() -> Any:
    """The ``mujoco`` module (ImportError naming the package when it is missing)."""
    try:
        import mujoco
    except ImportError as exc:  # pragma: no cover - the setup installs it
        raise ImportError('tensegrity_stiffness.simulation.twin needs the mujoco package (pip '
                          'install mujoco; pinned in scripts/setup_env.sh)') from exc
    return mujoco


class _Simulation:
    """The MuJoCo model and data of a layout, and everything the two public classes share."""

    def __init__(self, layout: _Layout, options: SimulationOptions, model_name: str) -> None:
        mujoco = import_mujoco()
        self._mj = mujoco
        self.options = options
        self._layout = layout
        self.mjcf = _build_mjcf(layout, options, model_name)
        self.model = mujoco.MjModel.from_xml_string(self.mjcf)
        self.data = mujoco.MjData(self.model)
        n = layout.n
        self._n = n
        self._gravity = layout.gravity.copy()
        bodies = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY, _link_name(layout, i))
                  for i in range(1, n + 1)]
        self._bodies = np.array(bodies)
        joints = [self.model.body_jntadr[b] for b in bodies]
        self._qpos = np.array([self.model.jnt_qposadr[j] for j in joints])
        self._dof = np.array([self.model.jnt_dofadr[j] for j in joints])
        # Tendons of joint i: a contiguous block, in the model's string order.
        counts = [m.n_strings for m in layout.joints]
        self._tendon_start = np.concatenate([[0], np.cumsum(counts)]).astype(int)
        self._k = np.concatenate([m.k for m in layout.joints])
        self._stretch = np.concatenate([m.max_stretch for m in layout.joints])
        self._limited = np.array(self.model.tendon_limited, dtype=bool)
        self._rest = np.concatenate([m.rest_lengths for m in layout.joints])
        self._rest_bounds = _rest_length_bounds(layout, options)
        self._target = self._rest.copy()
        self._ramping = False
        self._rate: float | None = None
        # Sites of each tendon (link-1 end, link-2 end) for the string directions.
        adr = self.model.tendon_adr
        self._site_a = np.array([self.model.wrap_objid[adr[t]] for t in range(len(self._k))])
        self._site_b = np.array([self.model.wrap_objid[adr[t] + 1] for t in range(len(self._k))])
        self._load = np.zeros(6)
        self._load_list = [0.0] * 6
        self._loaded = False
        self._load_body, self._load_dof = int(self._bodies[-1]), int(self._dof[-1])
        self._limit_force = np.zeros(len(self._k))
        self._constraint = np.zeros(self.model.nv)
        self._constrained = True
        self._screws = layout.screws.copy()
        self._acceleration_time = math.nan
        self._acceleration_stale = True
        self._forward()

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return float(self.data.time)

    def _forward(self) -> None:
        """Everything at the current state (after a change of state, load or model)."""
        self._apply_load()
        self._mj.mj_forward(self.model, self.data)
        self._record_constraints()
        self._acceleration_time = self.data.time
        self._acceleration_stale = False

    def _record_constraints(self) -> None:
        """Constraint forces of the last acceleration stage (tendon limits), kept for the
        readings between steps (mj_step1 starts a new constraint set)."""
        d = self.data
        if not d.nefc and not self._constrained:
            return
        self._constrained = bool(d.nefc)
        self._constraint[:] = d.qfrc_constraint
        self._limit_force[:] = 0.0
        if d.nefc:
            sel = d.efc_type == self._mj.mjtConstraint.mjCNSTR_LIMIT_TENDON
            np.add.at(self._limit_force, d.efc_id[sel], d.efc_force[sel])

    def _link_transforms(self) -> FloatArray:
        """(N, 4, 4) L_i from MuJoCo's body poses (current after every step and change)."""
        d = self.data
        out = np.zeros((self._n, 4, 4))
        out[:, :3, :3] = d.xmat[self._bodies].reshape(self._n, 3, 3)
        out[:, :3, 3] = d.xpos[self._bodies]
        out[:, 3, 3] = 1.0
        return out

    def _joint_frames(self, L: FloatArray) -> FloatArray:
        """P_i: {1}_i in the base (identity, then L_{i-1} O_{i-1})."""
        P = np.empty_like(L)
        P[0] = np.eye(4)
        for i in range(1, self._n):
            P[i] = L[i - 1] @ self._layout.offsets[i - 1]
        return P

    def _set_link_transforms(self, L: FloatArray) -> None:
        q = self.data.qpos
        for i, a in enumerate(self._qpos):
            x, y, z, w = rotation_to_quaternion(L[i, :3, :3])
            q[a:a + 3] = L[i, :3, 3]
            q[a + 3:a + 7] = (w, x, y, z)
        self.data.qvel[:] = 0.0
        self.data.qacc[:] = 0.0

    def _joint_transforms(self) -> FloatArray:
        """(N, 4, 4) T_i: each {2}_i in {1}_i, ``P_i^-1 L_i`` (T_1 = L_1: {1}_1 is the base)."""
        L = self._link_transforms()
        if self._n > 1:
            L[1:] = np.linalg.solve(self._joint_frames(L)[1:], L[1:])
        return L

    def _current_screws(self) -> FloatArray:
        T = self._joint_transforms()
        for i in range(self._n):
            self._screws[i] = log_se3(T[i], reference=self._screws[i])
        return self._screws.copy()

    def _set_screws(self, screws: FloatArray) -> None:
        T = exp_se3(screws)
        L = np.empty((self._n, 4, 4))
        current = np.eye(4)
        for i in range(self._n):
            L[i] = current @ T[i]
            if i < self._n - 1:
                current = L[i] @ self._layout.offsets[i]
        self._set_link_transforms(L)
        self._screws = screws.copy()
        self._forward()

    # ------------------------------------------------------------------ inputs
    def _validated_rest(self, rest_lengths: ArrayLike) -> FloatArray:
        flat = []
        rows = rest_lengths if self._n > 1 else [rest_lengths]
        if self._n > 1 and len(rows) != self._n:
            raise ValueError(f'rest_lengths must hold one row per joint ({self._n}), got '
                             f'{len(rows)}')
        for model, row in zip(self._layout.joints, rows, strict=True):
            flat.append(model.validate_rest_lengths(row, batched=False))
        rest = np.concatenate(flat)
        low, high = self._rest_bounds
        outside = np.flatnonzero((rest < low) | (rest > high))
        if outside.size:
            j = int(outside[0])
            name = [n for names in self._layout.string_names for n in names][j]
            raise BadRestLengthsError(
                f'rest length of {name} = {rest[j]:.6g} m is outside its range [{low[j]:.6g}, '
                f'{high[j]:.6g}] m' + (f' ({outside.size} strings outside)'
                                       if outside.size > 1 else ''))
        return rest

    def _set_rest(self, rest: FloatArray, rate: float | None) -> None:
        if rate is not None and not (isinstance(rate, (int, float)) and rate > 0.0):
            raise ValueError(f'rate must be > 0 (m/s) or None, got {rate!r}')
        self._target = rest.copy()
        self._rate = self.options.rest_length_rate if rate is None else float(rate)
        self._ramping = True
        if self._rate is None or self._rate == math.inf:
            self._write_rest(rest)
            self._forward()

    def _write_rest(self, rest: FloatArray) -> None:
        self._rest = rest.copy()
        self.model.tendon_lengthspring[:, 1] = rest
        lmax = rest + self._stretch
        self.model.tendon_range[self._limited, 1] = lmax[self._limited]

    def _ramp_rest(self) -> None:
        if not self._ramping:
            return
        if np.array_equal(self._rest, self._target):
            self._ramping = False
            return
        step = (math.inf if self._rate is None else self._rate) * self.options.timestep
        self._write_rest(rate_limited(self._rest, self._target, step))

    def _set_load(self, wrench: ArrayLike) -> None:
        W = checked_wrench(wrench, self.options.max_force, self.options.max_moment)
        self._load = W.copy()
        self._load_list = W.tolist()
        self._loaded = bool(np.any(W))
        self.data.qfrc_applied[:] = 0.0
        self.data.qfrc_applied[self._load_dof:self._load_dof + 3] = W[:3]
        self._apply_load()  # at the current pose (no other quantity depends on the load)
        self._acceleration_stale = True

    def _apply_load(self) -> None:
        """The load on the last link as its free joint's generalised force (module docstring):
        ``[f; R^T (m - p x f)]`` at the link's current pose (R, p)."""
        d = self.data
        if not self._loaded:
            return
        dof = self._load_dof
        px, py, pz = d.xpos[self._load_body].tolist()
        fx, fy, fz, mx, my, mz = self._load_list
        moment = np.array([mx - (py * fz - pz * fy), my - (pz * fx - px * fz),
                           mz - (px * fy - py * fx)])
        d.qfrc_applied[dof + 3:dof + 6] = d.xmat[self._load_body].reshape(3, 3).T @ moment

    # ------------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps (split step: mj_step2 at the current state, then mj_step1 at
        the new one, the load set at its pose)."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f'n must be an integer >= 0, got {n!r}')
        mj, m, d = self._mj, self.model, self.data
        for _ in range(n):
            mj.mj_step2(m, d)
            self._record_constraints()
            self._ramp_rest()
            mj.mj_step1(m, d)
            self._apply_load()
        self._acceleration_stale = n > 0 or self._acceleration_stale

    def net_forces(self) -> FloatArray:
        """(N, 2): the largest of |force| (N) and |moment about the link origin| (N m) on each
        moving link, strings (springs, dampers, limits), loads and weights together."""
        d = self.data
        q = d.qfrc_passive - d.qfrc_bias + d.qfrc_applied + self._constraint
        out = np.empty((self._n, 2))
        for i, dof in enumerate(self._dof):
            out[i] = np.linalg.norm(q[dof:dof + 3]), np.linalg.norm(q[dof + 3:dof + 6])
        return out

    def at_rest(self, tolerance: float) -> bool:
        """Net force and moment on every link at most ``tolerance`` and every link speed (m/s,
        rad/s) at most ``REST_SPEED_FACTOR * tolerance``."""
        if self._ramping and not np.array_equal(self._rest, self._target):
            return False
        return bool(np.max(self.net_forces()) <= tolerance
                    and np.max(np.abs(self.data.qvel)) <= REST_SPEED_FACTOR * tolerance)

    def settle(self, tolerance: float = 1e-10, max_time: float = 60.0) -> bool:
        """Step until :meth:`at_rest` (True) or ``max_time`` seconds of simulated time have
        passed (False)."""
        if not (math.isfinite(tolerance) and tolerance > 0.0):
            raise ValueError(f'tolerance must be finite and > 0, got {tolerance}')
        if not (math.isfinite(max_time) and max_time >= 0.0):
            raise ValueError(f'max_time must be finite and >= 0, got {max_time}')
        end = self.data.time + max_time
        while not self.at_rest(tolerance):
            if self.data.time >= end - 0.5 * self.options.timestep:
                return False
            self.step(10)
        return True

    # ------------------------------------------------------------------ readings
    def _lengths(self) -> FloatArray:
        return np.array(self.data.ten_length)

    def _tensions(self) -> FloatArray:
        """From MuJoCo's tendon lengths and the tendon law: ``k max(l - l0, 0)`` plus the force
        of an active length limit."""
        lengths = self.data.ten_length
        return self._k * np.maximum(lengths - self._rest, 0.0) + self._limit_force

    def _joint_wrenches(self) -> FloatArray:
        """(N, 6): each joint's strings on its link 2, in {1}_i about its origin (the library's
        ``F_i``), from MuJoCo's site positions and the tensions."""
        d = self.data
        xa, xb = d.site_xpos[self._site_a], d.site_xpos[self._site_b]
        s = xa - xb
        f = (self._tensions() / np.linalg.norm(s, axis=1))[:, None] * s
        m = np.cross(xa, f)
        L = self._link_transforms()
        P = self._joint_frames(L)
        out = np.empty((self._n, 6))
        for i in range(self._n):
            lo, hi = self._tendon_start[i], self._tendon_start[i + 1]
            F, M = f[lo:hi].sum(axis=0), m[lo:hi].sum(axis=0)
            R, p = P[i, :3, :3], P[i, :3, 3]
            out[i, :3] = R.T @ F
            out[i, 3:] = R.T @ (M - np.cross(p, F))
        return out

    def _imu(self, link: int) -> ImuReading:
        """Angular velocity and specific force of link ``link`` (0-based) at the current state
        (the acceleration stage is computed here when a step has passed since the last)."""
        if self._acceleration_time != self.data.time or self._acceleration_stale:
            self._mj.mj_forwardSkip(self.model, self.data, self._mj.mjtStage.mjSTAGE_VEL, 1)
            self._record_constraints()
            self._acceleration_time = self.data.time
            self._acceleration_stale = False
        d = self.data
        body, dof = self._bodies[link], self._dof[link]
        R = d.xmat[body].reshape(3, 3)
        return ImuReading(np.array(d.qvel[dof + 3:dof + 6]),
                          R.T @ (d.qacc[dof:dof + 3] - self._gravity))


class _Twin:
    """What :class:`JointSimulation` and :class:`ChainSimulation` share: MuJoCo's own objects
    (for anything they do not wrap), the clock, gravity, the rest lengths and the load they
    take, stepping and settling."""

    _sim: _Simulation

    @property
    def mjcf(self) -> str:
        """The MJCF text this simulation was built from."""
        return self._sim.mjcf

    @property
    def mj_model(self) -> Any:
        """``mujoco.MjModel``."""
        return self._sim.model

    @property
    def mj_data(self) -> Any:
        """``mujoco.MjData``."""
        return self._sim.data

    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return self._sim.time

    @property
    def gravity(self) -> FloatArray:
        """(3,) m/s^2 in the fixed frame ({1} of a joint, the base of a spine), as simulated
        (compensated on the links without a configured mass; the IMU senses it)."""
        return self._sim._gravity.copy()

    @property
    def external_wrench(self) -> FloatArray:
        """The applied wrench (6,) on the last link (link 2 of a joint, link N of a spine), in
        the fixed frame about that link's origin."""
        return self._sim._load.copy()

    @property
    def rest_length_bounds(self) -> tuple[FloatArray, FloatArray]:
        """(low, high): the rest lengths (m) the twin takes, one pair per string (all strings,
        joint-major): ``options.rest_length_range``, or each string's physical range
        (above :data:`MIN_REST_LENGTH_FRACTION` of its configured rest length, at most
        ``1 + REST_LENGTH_MARGIN`` times its maximum length, or its rest length without one)."""
        low, high = self._sim._rest_bounds
        return low.copy(), high.copy()

    def validated_rest_lengths(self, rest_lengths: ArrayLike | Sequence[ArrayLike]
                               ) -> FloatArray:
        """The rest lengths :meth:`set_rest_lengths` takes, flat (joint-major), checked: finite,
        of the right shape, inside :attr:`rest_length_bounds`; otherwise
        :class:`~tensegrity_stiffness.geometry.errors.BadRestLengthsError` (a ValueError) naming
        the string and the value. Changes nothing."""
        return self._sim._validated_rest(rest_lengths)

    def set_rest_lengths(self, rest_lengths: ArrayLike | Sequence[ArrayLike],
                         rate: float | None = None) -> None:
        """New rest lengths (m): (n,) for a joint; (N, n) or one (n_i,) array per joint for a
        spine; inside :attr:`rest_length_bounds` (else a ValueError naming the string and the
        value, and the twin keeps its rest lengths). Each string keeps its maximum stretch.
        ``rate`` (m/s) limits the change per second (default ``options.rest_length_rate``;
        None: at once)."""
        self._sim._set_rest(self._sim._validated_rest(rest_lengths), rate)

    def apply_wrench(self, wrench: ArrayLike) -> None:
        """External wrench (6,) [f; m] on the last link (link 2 of a joint, link N of a spine),
        in the fixed frame about that link's origin, held constant; finite and within
        ``options.max_force`` / ``max_moment`` (:func:`checked_wrench`), else a ValueError
        naming the value, and the twin keeps its load."""
        self._sim._set_load(wrench)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps."""
        self._sim.step(n)

    def settle(self, tolerance: float = 1e-10, max_time: float = 60.0) -> bool:
        """Step until the net force and moment on every moving link (strings plus load) are at
        most ``tolerance`` (N, N m) and it is at rest; False if ``max_time`` (s, simulated)
        passes."""
        return self._sim.settle(tolerance, max_time)


class JointSimulation(_Twin):
    """A six-DOF joint in MuJoCo (see the module docstring): link 1 fixed, link 2 free.

    ``model`` is simulated as it is: its per-string stiffness, rest and maximum lengths (e.g.
    "true" parameters drawn for a test). Starts at rest at ``model.initial_screw`` (or
    ``initial_screw``). ``options`` / keywords: :class:`SimulationOptions`.
    """

    def __init__(self, model: JointModel, options: SimulationOptions | None = None, *,
                 initial_screw: ArrayLike | None = None, **overrides: Any) -> None:
        if model.force_law != 'hooke':
            raise ValueError(f"force_law: the twin simulates Hooke's law only (MuJoCo tendons), "
                             f'got {model.force_law!r}')
        self.joint_model = model
        self.options = _options(options, overrides)
        layout = _joint_layout(model, self.options)
        self._sim = _Simulation(layout, self.options, 'tensegrity_joint')
        if initial_screw is not None:
            self.set_screw(initial_screw)

    @property
    def rest_lengths(self) -> FloatArray:
        """Rest lengths in force now (n,) (on their way to the last set ones when rate-limited)."""
        return self._sim._rest.copy()

    def set_screw(self, screw: ArrayLike) -> None:
        """Put link 2 at ``T = exp(hat(screw))``, at rest (zero velocity)."""
        xi = finite_array('screw', screw)
        if xi.shape != (6,):
            raise ValueError(f'screw must have 6 values, got shape {xi.shape}')
        self._sim._set_screws(xi[None])

    def set_pose(self, transform: ArrayLike) -> None:
        """Put link 2 at the (4, 4) pose ``transform`` ({2} in {1}), at rest."""
        T = finite_array('transform', transform)
        if T.shape != (4, 4):
            raise ValueError(f'transform must have shape (4, 4), got {T.shape}')
        self.set_screw(log_se3(T, reference=self._sim._screws[0]))

    def net_force(self) -> FloatArray:
        """[|net force| N, |net moment about the link-2 origin| N m] on link 2."""
        return self._sim.net_forces()[0]

    def screw(self) -> FloatArray:
        """The configuration (6,) in the library's convention, on the branch nearest the
        previous one."""
        return self._sim._current_screws()[0]

    def pose(self) -> FloatArray:
        """(4, 4) pose of {2} in {1}."""
        return self._sim._link_transforms()[0]

    def string_lengths(self) -> FloatArray:
        """(n,) MuJoCo's tendon lengths (m), the config's string order."""
        return self._sim._lengths()

    def tensions(self) -> FloatArray:
        """(n,) N, from MuJoCo's tendon lengths and the tendon law (plus an active limit's
        force), the config's string order."""
        return self._sim._tensions()

    def string_wrench(self) -> FloatArray:
        """(6,) what the strings exert on link 2, in {1} about its origin (the library's ``F``),
        from MuJoCo's site positions and :meth:`tensions`."""
        return self._sim._joint_wrenches()[0]

    def cartesian_stiffness(self, step: float = 1e-6) -> FloatArray:
        """``K_c = -dF/d(delta)`` (6, 6) of the twin at its current pose by central differences
        of :meth:`string_wrench` under small spatial twists ``T -> exp(hat(delta)) T``
        (``delta = [dv; dw]``); the state is restored afterwards (at rest)."""
        T = self.pose()
        xi = self.screw()
        K = np.empty((6, 6))
        for c in range(6):
            d = np.zeros(6)
            d[c] = step
            twist = np.concatenate([d[3:], d[:3]])  # [dw; dv] screw order for exp_se3
            wrenches = []
            for sign in (1.0, -1.0):
                self.set_pose(exp_se3(sign * twist) @ T)
                wrenches.append(self.string_wrench())
            K[:, c] = -(wrenches[0] - wrenches[1]) / (2.0 * step)
        self.set_screw(xi)
        return K

    def imu(self) -> ImuReading:
        """IMU at the origin of {2}, in {2}: angular velocity and specific force."""
        return self._sim._imu(0)


class ChainSimulation(_Twin):
    """A spine in MuJoCo: the base fixed, every link free (see the module docstring).

    The chain's joint models are simulated as they are (per-joint ``k``, rest and maximum
    lengths). Starts at rest at ``chain.unloaded_screws()`` (or ``initial_screws``).
    ``options`` / keywords: :class:`SimulationOptions`.
    """

    def __init__(self, chain: JointChain, options: SimulationOptions | None = None, *,
                 initial_screws: ArrayLike | None = None, **overrides: Any) -> None:
        for i, model in enumerate(chain.joints):
            if model.force_law != 'hooke':
                raise ValueError(f"joint {i + 1} force_law: the twin simulates Hooke's law only, "
                                 f'got {model.force_law!r}')
        self.chain = chain
        self.options = _options(options, overrides)
        layout = _chain_layout(chain, self.options)
        self._sim = _Simulation(layout, self.options, 'tensegrity_spine')
        if initial_screws is not None:
            self.set_screws(initial_screws)

    @property
    def n_joints(self) -> int:
        """N."""
        return self._sim._n

    @property
    def rest_lengths(self) -> list[FloatArray]:
        """Rest lengths in force now, one (n_i,) array per joint."""
        s = self._sim
        return [s._rest[s._tendon_start[i]:s._tendon_start[i + 1]].copy()
                for i in range(self.n_joints)]

    def set_screws(self, screws: ArrayLike) -> None:
        """Put the chain at the screws (N, 6), at rest."""
        x = finite_array('screws', screws)
        if x.shape == (6 * self.n_joints,):
            x = x.reshape(self.n_joints, 6)
        if x.shape != (self.n_joints, 6):
            raise ValueError(f'screws must have shape ({self.n_joints}, 6), got {x.shape}')
        self._sim._set_screws(x)

    def net_forces(self) -> FloatArray:
        """(N, 2): [|net force| N, |net moment about the link origin| N m] per link."""
        return self._sim.net_forces()

    def screws(self) -> FloatArray:
        """(N, 6) the configuration, each on the branch nearest its previous one."""
        return self._sim._current_screws()

    def link_poses(self) -> FloatArray:
        """(N, 4, 4) pose of each {2}_i in the base."""
        return self._sim._link_transforms()

    def joint_transforms(self) -> FloatArray:
        """(N, 4, 4) ``T_i``: each {2}_i in {1}_i (``exp(hat(xi_i))`` of :meth:`screws`, without
        the log map)."""
        return self._sim._joint_transforms()

    def tip_pose(self) -> FloatArray:
        """(4, 4) pose of the tool frame in the base."""
        return self.link_poses()[-1] @ self.chain.tool

    def string_lengths(self) -> FloatArray:
        """(N, n) MuJoCo's tendon lengths (m), joint-major, each joint's string order."""
        return self._per_joint(self._sim._lengths())

    def tensions(self) -> FloatArray:
        """(N, n) N, from MuJoCo's tendon lengths and the tendon law."""
        return self._per_joint(self._sim._tensions())

    def joint_wrenches(self) -> FloatArray:
        """(N, 6) each joint's string wrench on its link 2 in {1}_i (the library's ``F_i``)."""
        return self._sim._joint_wrenches()

    def imu(self, link: int | None = None) -> ImuReading:
        """IMU at the origin of {2}_link (1..N, default N), in that frame."""
        index = self.n_joints if link is None else link
        if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or \
                not 1 <= index <= self.n_joints:
            raise ValueError(f'link must be in 1..{self.n_joints}, got {link!r}')
        return self._sim._imu(int(index) - 1)

    def _per_joint(self, values: FloatArray) -> Any:
        s = self._sim
        rows = [values[s._tendon_start[i]:s._tendon_start[i + 1]] for i in range(self.n_joints)]
        return np.array(rows) if len({len(r) for r in rows}) == 1 else rows


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of the simulated sensors (white Gaussian noise; 0: exact):
    ``lengths`` (m), ``tensions`` (N), ``gyro`` (rad/s), ``accelerometer`` (m/s^2), and of a
    structure twin's ``encoders`` (m, the rest lengths in force) and ``markers`` (m, each
    coordinate of a node position). The one home of the twins' noise model (the sim nodes'
    parameters fill it)."""

    lengths: float = 0.0
    tensions: float = 0.0
    gyro: float = 0.0
    accelerometer: float = 0.0
    encoders: float = 0.0
    markers: float = 0.0

    def __post_init__(self) -> None:
        for name in ('lengths', 'tensions', 'gyro', 'accelerometer', 'encoders', 'markers'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f'noise {name} must be a finite standard deviation >= 0, got '
                                 f'{value!r}')

    def add(self, values: ArrayLike, kind: str, rng: np.random.Generator) -> FloatArray:
        """``values`` plus noise of the sensor ``kind`` (a field name), drawn from ``rng``."""
        std = getattr(self, kind)
        arr = np.array(values, dtype=np.float64)
        return arr + rng.normal(0.0, std, arr.shape) if std > 0.0 else arr


@dataclass(frozen=True)
class Measurements:
    """One reading of every simulated sensor (with noise): ``lengths``, ``tensions`` (the
    simulation's shapes), ``imu`` (:class:`ImuReading`), ``time`` (s)."""

    lengths: FloatArray
    tensions: FloatArray
    imu: ImuReading
    time: float


def measure(simulation: JointSimulation | ChainSimulation, noise: SensorNoise,
            rng: np.random.Generator) -> Measurements:
    """Read the twin's sensors (string lengths, tensions, the IMU of link 2 / link N) and add
    ``noise`` drawn from ``rng`` (seeded by the caller: reproducible)."""
    imu = simulation.imu()
    return Measurements(
        noise.add(simulation.string_lengths(), 'lengths', rng),
        noise.add(simulation.tensions(), 'tensions', rng),
        ImuReading(noise.add(imu.angular_velocity, 'gyro', rng),
                   noise.add(imu.specific_force, 'accelerometer', rng)),
        simulation.time)

