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
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.inertia import DEFAULT_LINK_MASS
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.simulation.twin_model import (
    DEFAULT_JOINT_DAMPING,
    DEFAULT_JOINT_GRAVITY,
    DEFAULT_MAX_FORCE,
    DEFAULT_MAX_MOMENT,
    DEFAULT_TENDON_DAMPING,
    DEFAULT_TIMESTEP,
    INTEGRATORS,
    MAX_LENGTH_MODES,
    MIN_REST_LENGTH_FRACTION,
    REST_LENGTH_MARGIN,
    REST_SPEED_FACTOR,
    SimulationOptions,
    TwinLayout,
    build_mjcf,
    chain_layout,
    chain_mjcf,
    checked_wrench,
    export_mjcf,
    joint_layout,
    joint_mjcf,
    layout_rest_length_bounds,
    link_body_name,
    rate_limited,
    resolved_options,
    rest_length_bounds,
)
from tensegrity_stiffness.simulation.twin_sensors import (
    ImuReading,
    Measurements,
    SensorNoise,
    measure,
)

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

    def __init__(self, layout: TwinLayout, options: SimulationOptions, model_name: str) -> None:
        mujoco = import_mujoco()
        self._mj = mujoco
        self.options = options
        self._layout = layout
        self.mjcf = build_mjcf(layout, options, model_name)
        self.model = mujoco.MjModel.from_xml_string(self.mjcf)
        self.data = mujoco.MjData(self.model)
        n = layout.n
        self._n = n
        self._gravity = layout.gravity.copy()
        bodies = [mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_BODY,
                                    link_body_name(layout, i)) for i in range(1, n + 1)]
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
        self._rest_bounds = layout_rest_length_bounds(layout, options)
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
        self.joint_model = model
        self.options = resolved_options(options, overrides)
        layout = joint_layout(model, self.options)
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
        self.chain = chain
        self.options = resolved_options(options, overrides)
        layout = chain_layout(chain, self.options)
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


