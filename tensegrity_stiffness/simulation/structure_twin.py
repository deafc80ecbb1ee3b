"""The digital twin of any structure in MuJoCo: free bodies, strings that only pull, the ground
with friction (docs/structures.md, "The twin").

No integrator of ours: the physics is MuJoCo's, from the structure's own MuJoCo model
(:func:`~tensegrity_stiffness.structures.mjcf.structure_mjcf`: a free joint per free body, a
spatial tendon per string with Hooke's law and the slack deadband, contact spheres on the nodes,
the ground plane with Coulomb friction in elliptic cones). This module steps it and reads it; it
imports mujoco and numpy only (no rclpy).

* **Motors**: the rest lengths are motor positions; a command moves each towards its target at
  most ``rest_length_rate`` (m/s) per second (:func:`~.twin.rate_limited` every step), inside
  the physical range of :func:`~.twin.rest_length_bounds` (a command outside it is refused,
  naming the string, and the twin keeps its targets).
* **Loads**: constant wrenches ``[f; m]`` per body in the world about its origin (the
  equilibrium's convention, :func:`~tensegrity_stiffness.structures.equilibrium.structure_loads`)
  and pushes (a wrench on one body for a while); MuJoCo takes them as ``xfrc_applied`` at each
  body's centre of mass ``c``, ``[f; m - c x f]``, recomputed at every step's pose.
* **Sensors** at the current state: string lengths (MuJoCo's tendon lengths), load cells (the
  tensions ``k max(l - l0, 0)`` of the rest lengths in force, plus an active length limit's force),
  motor encoders (the rest lengths in force), one IMU per free bar at its origin (the middle) in
  its frame: gyro ``omega`` (the free joint's angular velocity, body frame) and accelerometer
  specific force ``R^T (a - g)`` (``a`` the origin's acceleration in the world from MuJoCo's
  acceleration stage, ``g`` gravity), optional markers (every body node in the world). Noise:
  :class:`~.twin.SensorNoise`, drawn from a caller's seeded generator.

Stepping uses MuJoCo's split step (``mj_step2`` then ``mj_step1``) as the joint's twin: after
each step the poses, tendon lengths and sites are those of the new state; the rest lengths and
loads are set there before the next step.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.validation import (
    positive_interval,
    positive_number,
)
from tensegrity_stiffness.simulation.twin import import_mujoco
from tensegrity_stiffness.simulation.twin_model import (
    DEFAULT_JOINT_DAMPING,
    DEFAULT_MAX_FORCE,
    DEFAULT_MAX_MOMENT,
    DEFAULT_TENDON_DAMPING,
    INTEGRATORS,
    checked_wrench,
    rate_limited,
    rest_length_bounds,
)
from tensegrity_stiffness.simulation.twin_sensors import ImuReading, SensorNoise
from tensegrity_stiffness.structures.elements import WORLD
from tensegrity_stiffness.structures.equilibrium import structure_loads
from tensegrity_stiffness.structures.mjcf import StructureMjcfOptions, structure_mjcf
from tensegrity_stiffness.structures.structure import Structure, StructureState, cross3

__all__ = [
    'DEFAULT_SETTLE_SPEED',
    'StructureMeasurements',
    'StructureSimulation',
    'StructureTwinOptions',
    'measure_structure',
]

FloatArray = NDArray[np.float64]

#: Settled (:meth:`StructureSimulation.settle`): every body speed (m/s, rad/s) at most this.
DEFAULT_SETTLE_SPEED = 1e-6


@dataclass(frozen=True)
class StructureTwinOptions:
    """Options of a structure twin (every field has a documented default).

    ``timestep`` (s, 1e-3), ``integrator`` (MuJoCo's split step: ``'implicitfast'``, ``'implicit'``
    or ``'Euler'``), ``node_radius`` (m, 0.005: the contact spheres), ``contact_time_constant`` (s,
    0.005), ``joint_damping`` (on each free-joint dof against the world, N s/m and N m s/rad;
    default the joint twin's 1e-3: air drag's order), ``string_damping`` (N s/m for strings whose
    config gives none; default the twin's 0.5; the configured damping is kept where it is > 0),
    ``rest_length_rate`` (m/s, the motors' speed; None: at once), ``rest_length_range`` ((min, max)
    m for every string; None: each string's physical range, :func:`~.twin.rest_length_bounds`),
    ``max_force`` / ``max_moment`` (N, N m, a larger load or push is refused; ``inf``: only
    finiteness), ``string_width`` (m, drawing only)."""

    timestep: float = 1e-3
    integrator: str = 'implicitfast'
    node_radius: float = 0.005
    contact_time_constant: float = 0.005
    joint_damping: float = DEFAULT_JOINT_DAMPING
    string_damping: float = DEFAULT_TENDON_DAMPING
    rest_length_rate: float | None = None
    rest_length_range: tuple[float, float] | None = None
    max_force: float = DEFAULT_MAX_FORCE
    max_moment: float = DEFAULT_MAX_MOMENT
    string_width: float = 0.002

    def __post_init__(self) -> None:
        def number(name: str, allow_zero: bool = False, allow_inf: bool = False) -> None:
            positive_number(name, getattr(self, name), allow_zero, allow_inf)

        for name in ('timestep', 'node_radius', 'contact_time_constant', 'string_width'):
            number(name)
        number('joint_damping', allow_zero=True)
        number('string_damping', allow_zero=True)
        number('max_force', allow_inf=True)
        number('max_moment', allow_inf=True)
        if self.rest_length_rate is not None:
            number('rest_length_rate', allow_inf=True)
        if self.integrator not in INTEGRATORS:
            raise ValueError(f'integrator must be one of {INTEGRATORS}, got {self.integrator!r}')
        if self.rest_length_range is not None:
            object.__setattr__(self, 'rest_length_range',
                               positive_interval('rest_length_range', self.rest_length_range))

    @property
    def mjcf(self) -> StructureMjcfOptions:
        """The MuJoCo export's options of these."""
        return StructureMjcfOptions(self.timestep, self.integrator, self.node_radius,
                                    self.contact_time_constant, self.joint_damping,
                                    self.string_width)


@dataclass(frozen=True)
class StructureMeasurements:
    """One reading of a structure twin's sensors (with noise): ``lengths``, ``tensions``,
    ``encoders`` (n,) in the config's string order; ``imus`` one
    :class:`~.twin.ImuReading` per free bar (:attr:`StructureSimulation.imu_bodies`);
    ``markers`` (n_markers, 3) the body nodes in the world (order of
    :attr:`StructureSimulation.marker_names`) or None; ``time`` (s, simulated)."""

    lengths: FloatArray
    tensions: FloatArray
    encoders: FloatArray
    imus: tuple[ImuReading, ...]
    markers: FloatArray | None
    time: float


@dataclass
class _Push:
    body: int
    wrench: FloatArray
    until: float


def _damped(structure: Structure, damping: float) -> Structure:
    """The structure with ``damping`` on every string whose config gives none."""
    strings = [s if s.damping > 0.0 else replace(s, damping=damping) for s in structure.strings]
    return Structure(structure.bodies, strings, structure.world_nodes, structure.gravity,
                     structure.ground, structure.force_law, use_kernel=structure.uses_kernel)


class StructureSimulation:
    """A structure in MuJoCo (module docstring), starting at rest at ``poses`` ((N, 4, 4) or
    (N, 7); default the config's). ``options`` / keywords: :class:`StructureTwinOptions`. The
    structure is simulated as it is (its stiffnesses, rest and maximum lengths, masses and
    inertias); only Hooke's law has a MuJoCo tendon (ValueError otherwise)."""

    def __init__(self, structure: Structure, options: StructureTwinOptions | None = None, *,
                 poses: ArrayLike | None = None, **overrides: Any) -> None:
        if not isinstance(structure, Structure):
            raise ValueError(f'structure must be a Structure, got {type(structure).__name__}')
        base = options if options is not None else StructureTwinOptions()
        unknown = set(overrides) - set(StructureTwinOptions.__dataclass_fields__)
        if unknown:
            raise ValueError(f'unknown structure twin options {sorted(unknown)}; known: '
                             f'{sorted(StructureTwinOptions.__dataclass_fields__)}')
        self.options = replace(base, **overrides) if overrides else base
        self.structure = structure
        T0 = structure.transforms(poses)
        mj = import_mujoco()
        self._mj = mj
        self.mjcf = structure_mjcf(_damped(structure, self.options.string_damping), T0,
                                   self.options.mjcf)
        self.model = mj.MjModel.from_xml_string(self.mjcf)
        self.data = mj.MjData(self.model)
        m = self.model
        self._bodies = np.array([mj.mj_name2id(m, mj.mjtObj.mjOBJ_BODY, name)
                                 for name in structure.body_names])
        self._free = np.flatnonzero(~structure.fixed)
        joints = [int(m.body_jntadr[self._bodies[i]]) for i in self._free]
        self._qpos = np.array([m.jnt_qposadr[j] for j in joints], dtype=int)
        self._dof = np.array([m.jnt_dofadr[j] for j in joints], dtype=int)
        self._masses = np.array([b.mass for b in structure.bodies])
        self._gravity = (np.zeros(3) if structure.gravity is None
                         else np.array(structure.gravity, dtype=float))
        self._k = structure.k.copy()
        self._stretch = structure.max_stretch.copy()
        self._limited = np.array(m.tendon_limited, dtype=bool)
        self._rest = structure.rest_lengths.copy()
        self._target = self._rest.copy()
        self._rate = self.options.rest_length_rate
        self._bounds = rest_length_bounds(structure.rest_lengths, structure.max_lengths,
                                          self.options.rest_length_range)
        #: The bodies that carry an IMU: every free bar (config order).
        self.imu_bodies: tuple[str, ...] = tuple(
            structure.body_names[i] for i in structure.bar_indices if not structure.fixed[i])
        self._imu_index = {name: structure.body_index(name) for name in self.imu_bodies}
        #: The marker nodes (``body.node``): every node of a body (world nodes excluded).
        self.marker_names: tuple[str, ...] = tuple(
            n for n in structure.node_names if not n.startswith(f'{WORLD}.'))
        self._marker_sites = np.array([mj.mj_name2id(m, mj.mjtObj.mjOBJ_SITE, n)
                                       for n in self.marker_names], dtype=int)
        self._contact_node = {}
        for n in self.marker_names:
            geom = mj.mj_name2id(m, mj.mjtObj.mjOBJ_GEOM, f'{n}_contact')
            if geom >= 0:
                self._contact_node[geom] = n
        self._ground_geom = mj.mj_name2id(m, mj.mjtObj.mjOBJ_GEOM, 'ground')
        self._loads = np.zeros((structure.n_bodies, 6))
        self._loaded = False
        self._xfrc_set = False
        self._moving = False
        self._pushes: list[_Push] = []
        self._limit_force = np.zeros(structure.n_strings)
        self._acceleration_time = math.nan
        self._forward()

    # ------------------------------------------------------------------ state
    @property
    def time(self) -> float:
        """Simulated time (s)."""
        return float(self.data.time)

    @property
    def gravity(self) -> FloatArray:
        """(3,) m/s^2 in the world (zero without one)."""
        return self._gravity.copy()

    @property
    def rest_lengths(self) -> FloatArray:
        """(n,) the rest lengths in force now (on their way to the targets when rate-limited):
        what the motor encoders read."""
        return self._rest.copy()

    @property
    def target_rest_lengths(self) -> FloatArray:
        """(n,) the last commanded rest lengths."""
        return self._target.copy()

    @property
    def rest_length_bounds(self) -> tuple[FloatArray, FloatArray]:
        """(low, high) (n,) m: the rest lengths the twin takes (module docstring)."""
        return self._bounds[0].copy(), self._bounds[1].copy()

    @property
    def moving(self) -> bool:
        """True while a motor is still on its way to its target."""
        return self._moving

    def poses(self) -> FloatArray:
        """(N, 4, 4) every body's pose in the world (config order), MuJoCo's."""
        d = self.data
        n = self.structure.n_bodies
        out = np.zeros((n, 4, 4))
        out[:, :3, :3] = d.xmat[self._bodies].reshape(n, 3, 3)
        out[:, :3, 3] = d.xpos[self._bodies]
        out[:, 3, 3] = 1.0
        return out

    def pose_vectors(self) -> FloatArray:
        """(N, 7) ``[x y z qx qy qz qw]`` of :meth:`poses`."""
        T = self.poses()
        return np.array([np.concatenate([P[:3, 3], rotation_to_quaternion(P[:3, :3])])
                         for P in T])

    def velocities(self) -> FloatArray:
        """(N, 6) ``[v; omega]`` of every body in the world (v of its frame's origin; zero for
        fixed bodies)."""
        out = np.zeros((self.structure.n_bodies, 6))
        R = self.data.xmat[self._bodies].reshape(-1, 3, 3)
        for i, dof in zip(self._free, self._dof, strict=True):
            out[i, :3] = self.data.qvel[dof:dof + 3]
            out[i, 3:] = R[i] @ self.data.qvel[dof + 3:dof + 6]
        return out

    def set_poses(self, poses: ArrayLike) -> None:
        """Put the free bodies at ``poses`` ((N, 4, 4) or (N, 7); fixed bodies stay), at
        rest."""
        T = self.structure.transforms(poses)
        q = self.data.qpos
        for i, a in zip(self._free, self._qpos, strict=True):
            x, y, z, w = rotation_to_quaternion(T[i, :3, :3])
            q[a:a + 3] = T[i, :3, 3]
            q[a + 3:a + 7] = (w, x, y, z)
        self.data.qvel[:] = 0.0
        self.data.qacc[:] = 0.0
        self._forward()

    def centre_of_mass(self) -> FloatArray:
        """(3,) the structure's centre of mass in the world."""
        c = self.data.xipos[self._bodies]
        return (self._masses @ c) / self._masses.sum()

    def evaluate(self) -> StructureState:
        """The structure's own model (:meth:`Structure.evaluate`) at the twin's poses and the
        rest lengths in force."""
        return self.structure.evaluate(self.poses(), self._rest)

    # ------------------------------------------------------------------ inputs
    def validated_rest_lengths(self, rest_lengths: ArrayLike) -> FloatArray:
        """``rest_lengths`` (n,) checked: finite, of the right shape, inside
        :attr:`rest_length_bounds`; otherwise
        :class:`~tensegrity_stiffness.geometry.errors.BadRestLengthsError` (a ValueError) naming
        the string and the value. Changes nothing."""
        n = self.structure.n_strings
        try:
            rest = np.array(rest_lengths, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise BadRestLengthsError(f'rest_lengths must be {n} numbers: {exc}') from None
        if rest.shape != (n,):
            raise BadRestLengthsError(f'rest_lengths must have {n} values (one per string), got '
                                      f'shape {rest.shape}')
        bad = np.flatnonzero(~np.isfinite(rest))
        if bad.size:
            j = int(bad[0])
            raise BadRestLengthsError(f'rest length of {self.structure.string_names[j]} = '
                                      f'{rest[j]} m is not finite')
        low, high = self._bounds
        outside = np.flatnonzero((rest < low) | (rest > high))
        if outside.size:
            j = int(outside[0])
            raise BadRestLengthsError(
                f'rest length of {self.structure.string_names[j]} = {rest[j]:.6g} m is outside '
                f'its range [{low[j]:.6g}, {high[j]:.6g}] m'
                + (f' ({outside.size} strings outside)' if outside.size > 1 else ''))
        return rest

    def set_rest_lengths(self, rest_lengths: ArrayLike, rate: float | None = None) -> None:
        """Command the motors: new target rest lengths (n,) m (checked by
        :meth:`validated_rest_lengths`; refused: the twin keeps its targets). ``rate`` (m/s)
        the motors' speed from now on (default ``options.rest_length_rate``; None or inf: at
        once). Each string keeps its maximum stretch."""
        rest = self.validated_rest_lengths(rest_lengths)
        if rate is not None and not (isinstance(rate, (int, float)) and rate > 0.0):
            raise ValueError(f'rate must be > 0 (m/s) or None, got {rate!r}')
        self._target = rest.copy()
        self._moving = not np.array_equal(self._rest, self._target)
        self._rate = self.options.rest_length_rate if rate is None else float(rate)
        if self._rate is None or self._rate == math.inf:
            self._write_rest(rest)
            self._forward()

    def _write_rest(self, rest: FloatArray) -> None:
        self._rest = rest.copy()
        self._moving = not np.array_equal(self._rest, self._target)
        self.model.tendon_lengthspring[:, 1] = rest
        lmax = rest + self._stretch
        self.model.tendon_range[self._limited, 1] = lmax[self._limited]

    def _checked(self, wrench: ArrayLike) -> FloatArray:
        return checked_wrench(wrench, self.options.max_force, self.options.max_moment)

    def apply_loads(self, loads: Any) -> None:
        """Constant external wrenches: None, {body: (6,)} or (N, 6) ``[f; m]`` in the world
        about its origin (the equilibrium's loads); each within ``options.max_force`` /
        ``max_moment`` (:func:`~.twin.checked_wrench`), else a ValueError naming the body and
        the value, and the twin keeps its loads. Fixed bodies' loads are ignored."""
        W = structure_loads(self.structure, loads)
        for i, row in enumerate(W):
            try:
                self._checked(row)
            except ValueError as exc:
                raise ValueError(f'load on {self.structure.body_names[i]}: {exc}') from None
        self._loads = W.copy()
        self._loaded = bool(np.any(W[self._free]))
        self._apply_loads()

    @property
    def loads(self) -> FloatArray:
        """(N, 6) the constant loads (world, about its origin)."""
        return self._loads.copy()

    def push(self, body: str, wrench: ArrayLike, duration: float) -> None:
        """A push: the wrench (6,) ``[f; m]`` (world, about the world origin) on ``body`` for
        ``duration`` seconds of simulated time from now, on top of the loads (checked as
        :meth:`apply_loads`)."""
        index = self.structure.body_index(body)
        W = self._checked(wrench)
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration > 0):
            raise ValueError(f'duration must be finite and > 0 (s), got {duration!r}')
        self._pushes.append(_Push(index, W, self.time + float(duration)))
        self._apply_loads()

    def _apply_loads(self) -> None:
        """The loads and pushes as ``xfrc_applied`` at each body's centre of mass (module
        docstring), at the current pose; ended pushes dropped (nothing to do without any)."""
        if self._pushes:
            now = self.data.time
            self._pushes = [p for p in self._pushes if p.until > now + 1e-12]
        xfrc = self.data.xfrc_applied
        if not self._pushes and not self._loaded:
            if self._xfrc_set:
                xfrc[:] = 0.0
                self._xfrc_set = False
            return
        W = self._loads.copy()
        for p in self._pushes:
            W[p.body] += p.wrench
        bodies = self._bodies[self._free]
        f = W[self._free, :3]
        xfrc[:] = 0.0
        xfrc[bodies, :3] = f
        xfrc[bodies, 3:] = W[self._free, 3:] - cross3(self.data.xipos[bodies], f)
        self._xfrc_set = True

    # ------------------------------------------------------------------ stepping
    def _forward(self) -> None:
        self._apply_loads()
        self._mj.mj_forward(self.model, self.data)
        self._record_limits()
        self._acceleration_time = self.data.time

    def _record_limits(self) -> None:
        d = self.data
        self._limit_force[:] = 0.0
        if d.nefc and self._limited.any():
            sel = d.efc_type == self._mj.mjtConstraint.mjCNSTR_LIMIT_TENDON
            np.add.at(self._limit_force, d.efc_id[sel], d.efc_force[sel])

    def step(self, n: int = 1) -> None:
        """Advance ``n`` time steps (split step; the motors move at their rate, the loads at
        each new pose)."""
        if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
            raise ValueError(f'n must be an integer >= 0, got {n!r}')
        mj, m, d = self._mj, self.model, self.data
        for _ in range(n):
            mj.mj_step2(m, d)
            self._record_limits()
            if self.moving:
                rate = math.inf if self._rate is None else self._rate
                self._write_rest(rate_limited(self._rest, self._target,
                                              rate * self.options.timestep))
            mj.mj_step1(m, d)
            self._apply_loads()

    def run(self, seconds: float) -> None:
        """Step for ``seconds`` of simulated time (rounded to whole steps)."""
        self.step(max(0, round(seconds / self.options.timestep)))

    def settle(self, speed: float = DEFAULT_SETTLE_SPEED, max_time: float = 30.0,
               min_time: float = 0.05) -> bool:
        """Step for at least ``min_time`` s, then until the motors have arrived and every free
        body's speed (m/s and rad/s) is at most ``speed``; False if ``max_time`` (s, simulated)
        passes first."""
        if not (math.isfinite(speed) and speed > 0.0):
            raise ValueError(f'speed must be finite and > 0, got {speed}')
        end = self.time + max_time
        self.run(min_time)
        while self.moving or float(np.max(np.abs(self.data.qvel), initial=0.0)) > speed:
            if self.time >= end:
                return False
            self.step(10)
        return True

    # ------------------------------------------------------------------ readings
    def string_lengths(self) -> FloatArray:
        """(n,) MuJoCo's tendon lengths (m), the config's string order."""
        return np.array(self.data.ten_length)

    def tensions(self) -> FloatArray:
        """(n,) N: ``k max(l - l0, 0)`` of the tendon lengths and the rest lengths in force,
        plus an active length limit's force (the load cells)."""
        return self._k * np.maximum(self.data.ten_length - self._rest, 0.0) + self._limit_force

    def slack(self) -> NDArray[np.bool_]:
        """(n,) True where a string is at or below its rest length."""
        return np.asarray(self.data.ten_length <= self._rest)

    def _acceleration(self) -> None:
        if self._acceleration_time != self.data.time:
            self._mj.mj_forwardSkip(self.model, self.data, self._mj.mjtStage.mjSTAGE_VEL, 1)
            self._record_limits()
            self._acceleration_time = self.data.time

    def imu(self, body: str) -> ImuReading:
        """The IMU of a free bar ``body`` at its origin, in its frame: angular velocity (rad/s)
        and specific force ``R^T (a - g)`` (m/s^2)."""
        if body not in self._imu_index:
            raise ValueError(f'no IMU on {body!r}; the IMUs: {list(self.imu_bodies)}')
        self._acceleration()
        i = self._imu_index[body]
        dof = int(self._dof[int(np.searchsorted(self._free, i))])
        d = self.data
        R = d.xmat[self._bodies[i]].reshape(3, 3)
        return ImuReading(np.array(d.qvel[dof + 3:dof + 6]),
                          R.T @ (d.qacc[dof:dof + 3] - self._gravity))

    def imus(self) -> tuple[ImuReading, ...]:
        """One :meth:`imu` per :attr:`imu_bodies`."""
        return tuple(self.imu(name) for name in self.imu_bodies)

    def markers(self) -> FloatArray:
        """(n_markers, 3) the body nodes in the world (order of :attr:`marker_names`)."""
        return np.array(self.data.site_xpos[self._marker_sites])

    def contact_forces(self) -> dict[str, FloatArray]:
        """{``body.node``: (3,) the ground's force on it in the world} for every node in contact
        now (MuJoCo's contacts with the ground and ``mj_contactForce``)."""
        self._acceleration()
        d, out = self.data, {}
        f6 = np.zeros(6)
        for c in range(d.ncon):
            contact = d.contact[c]
            g1, g2 = int(contact.geom1), int(contact.geom2)
            if self._ground_geom not in (g1, g2):
                continue
            node_geom = g2 if g1 == self._ground_geom else g1
            if node_geom not in self._contact_node:
                continue
            self._mj.mj_contactForce(self.model, self.data, c, f6)
            # In the contact frame (normal first, from geom1 to geom2): the force on geom2.
            f = np.asarray(contact.frame).reshape(3, 3).T @ f6[:3]
            name = self._contact_node[node_geom]
            out[name] = out.get(name, np.zeros(3)) + (f if node_geom == g2 else -f)
        return out

    def contact_nodes(self) -> list[str]:
        """The nodes in contact with the ground now (config order)."""
        touching = self.contact_forces()
        return [n for n in self.marker_names if n in touching]

    def bar_axes(self) -> FloatArray:
        """(n_bars, 3) the unit axis (z of its frame) of each bar (order of
        ``structure.bar_names``)."""
        R = self.data.xmat[self._bodies[self.structure.bar_indices]].reshape(-1, 3, 3)
        return R[:, :, 2]


def measure_structure(simulation: StructureSimulation, noise: SensorNoise,
                      rng: np.random.Generator, markers: bool = False
                      ) -> StructureMeasurements:
    """Read the twin's sensors (module docstring) and add ``noise`` drawn from ``rng`` (seeded by
    the caller: reproducible); ``markers``: the node positions too."""
    imus = tuple(ImuReading(noise.add(r.angular_velocity, 'gyro', rng),
                            noise.add(r.specific_force, 'accelerometer', rng))
                 for r in simulation.imus())
    return StructureMeasurements(
        noise.add(simulation.string_lengths(), 'lengths', rng),
        noise.add(simulation.tensions(), 'tensions', rng),
        noise.add(simulation.rest_lengths, 'encoders', rng),
        imus,
        noise.add(simulation.markers(), 'markers', rng) if markers else None,
        simulation.time)

