"""Synthetic calibration recordings for the tests and the bench: a joint whose true parameters
are drawn away from the nominal (each ``k_j`` within +-20 %, each rest-length offset within
+-1 mm), driven through commanded rest lengths and loads, measured with noise.

The true configurations come from the MuJoCo twin (:mod:`tensegrity_stiffness.simulation.twin`)
when it is installed, else from the library's equilibrium solver (``backend='library'``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.estimation.calibration import (
    CalibrationNoise,
    CalibrationSample,
    model_with_parameters,
)
from tensegrity_stiffness.geometry.screw import exp_so3
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.recordings.calibration_recording import Recording

#: Spread of the commanded rest lengths around the nominal (m, uniform) and of the loads
#: (force N, moment N m, normal): loads of the order of the pretension excite the offsets.
REST_SPREAD = 3e-3
FORCE_SPREAD = 0.6
MOMENT_SPREAD = 0.01
#: The twin's state counts as quasi-static when the net force and moment on link 2 are below
#: this (N, N m; far below the sensors' noise) ...
SETTLE_TOLERANCE = 1e-9
#: ... within this much simulated time (s).
SETTLE_TIME = 20.0


def nominal_model() -> JointModel:
    return JointModel.from_yaml(packaged_config_path())


def true_parameters(model: JointModel, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = model.n_strings
    return model.k * (1.0 + rng.uniform(-0.2, 0.2, n)), rng.uniform(-1e-3, 1e-3, n)


@dataclass
class States:
    """True quasi-static states: commanded rest lengths (N, n), applied loads (N, 6), screws
    (N, 6), poses (N, 4, 4) and tensions (N, n)."""

    rest: np.ndarray
    loads: np.ndarray
    screws: np.ndarray
    poses: np.ndarray
    tensions: np.ndarray

    def __getitem__(self, rows: slice) -> States:
        return States(self.rest[rows], self.loads[rows], self.screws[rows], self.poses[rows],
                      self.tensions[rows])


def twin_available() -> bool:
    try:
        import mujoco  # noqa: F401
    except ImportError:
        return False
    return True


def configurations(model: JointModel, k: np.ndarray, d: np.ndarray, count: int, seed: int,
                   force: float = FORCE_SPREAD, moment: float = MOMENT_SPREAD,
                   rest_spread: float = REST_SPREAD, backend: str = 'twin',
                   taut: bool = False) -> States:
    """``count`` stable quasi-static states of the true joint (stiffness ``k``, rest lengths
    commanded + ``d``) under random commanded rest lengths (uniform, +-``rest_spread``) and
    loads (normal, std ``force`` N and ``moment`` N m): settled in the MuJoCo twin
    (``backend='twin'``, when mujoco is installed) or solved by the library. ``taut``: only
    states with every string taut (docs/calibration.md: loads "as large as the strings allow
    without going slack"), so that many sit near a string's slack boundary."""
    rng = np.random.default_rng(seed + 1000)
    true = model_with_parameters(model, k, model.rest_lengths + d)
    n = model.n_strings
    rows: list[tuple] = []
    start = solve_equilibrium(true, np.zeros(6)).screw
    sim = None
    if backend == 'twin' and twin_available():
        from tensegrity_stiffness.simulation.twin import JointSimulation

        sim = JointSimulation(true, initial_screw=start)
    previous = start
    while len(rows) < count:
        command = model.rest_lengths + rng.uniform(-rest_spread, rest_spread, n)
        W = np.concatenate([rng.normal(0.0, force, 3), rng.normal(0.0, moment, 3)])
        eq = solve_equilibrium(true, W, command + d, initial_screw=previous)
        # A string at its maximum length is beyond the model (the twin stops it, the library
        # saturates its tension): such states are left out, as a lab avoids them.
        if not (eq.success and eq.stable) or eq.state.saturated.any() or \
                (taut and eq.state.slack.any()):
            continue
        if sim is None:
            rows.append((command, W, eq.screw, eq.state.transform, eq.state.tensions))
        else:
            sim.set_rest_lengths(command + d)
            sim.apply_wrench(W)
            if not sim.settle(tolerance=SETTLE_TOLERANCE, max_time=SETTLE_TIME) or \
                    true.evaluate(sim.screw(), command + d).saturated.any():
                sim.set_screw(eq.screw)  # start the next one from a state at rest
                continue
            rows.append((command, W, sim.screw(), sim.pose(), sim.tensions()))
        previous = rows[-1][2]
    return States(*(np.array(column) for column in zip(*rows, strict=True)))


def measure(model: JointModel, states: States, seed: int, noise: CalibrationNoise,
            pose: bool = True, wrench: bool = True, tensions: tuple[int, ...] = (),
            unloaded_disturbance: bool = False) -> list[CalibrationSample]:
    """Noisy samples of the true states: poses (PoseWithCovariance convention), the applied
    load and the tensions of the strings ``tensions``. ``unloaded_disturbance``: the recorded
    wrench is zero (the joint carried small random loads: an "unloaded" joint)."""
    rng = np.random.default_rng(seed + 2000)
    samples = []
    for i in range(len(states.rest)):
        T = states.poses[i].copy()
        T[:3, :3] = exp_so3(rng.normal(0.0, noise.rotation, 3)) @ T[:3, :3]
        T[:3, 3] += rng.normal(0.0, noise.position, 3)
        W = states.loads[i] + np.concatenate([rng.normal(0.0, noise.force, 3),
                                              rng.normal(0.0, noise.moment, 3)])
        t = np.full(model.n_strings, np.nan)
        idx = list(tensions)
        t[idx] = states.tensions[i, idx] + rng.normal(0.0, noise.tension, len(idx))
        samples.append(CalibrationSample(
            rest_lengths=states.rest[i], pose=T if pose else None,
            tensions=t if idx else None,
            external_wrench=(np.zeros(6) if unloaded_disturbance else W) if wrench else None))
    return samples


#: Time series of the command tests: samples per second, instants moving into each hold and
#: held instants per hold (the hold outlasts the quasi-static window of 0.5 s).
RATE = 20.0
MOVING = 3
HELD = 12


def time_series(model: JointModel, states: States, seed: int, noise: CalibrationNoise,
                tensions: tuple[int, ...] = (), wrench: bool = True) -> Recording:
    """A recording that moves from one state to the next (poses interpolated, rest lengths
    commanded at the start of the move) and holds each: every instant measured with noise.
    The last held instant of hold i is the sample the quasi-static rule should pick."""
    rng = np.random.default_rng(seed + 3000)
    n = model.n_strings
    rows = []
    previous = states.poses[0]
    t = 0.0
    for i in range(len(states.rest)):
        target = states.poses[i]
        for step in range(MOVING + HELD):
            t += 1.0 / RATE
            if step < MOVING:  # on the way: a straight-line motion between the poses
                a = (step + 1) / (MOVING + 1)
                T = target.copy()
                T[:3, 3] = (1 - a) * previous[:3, 3] + a * target[:3, 3]
                T[:3, :3] = previous[:3, :3] if a < 0.5 else target[:3, :3]
            else:
                T = target.copy()
            T[:3, :3] = exp_so3(rng.normal(0.0, noise.rotation, 3)) @ T[:3, :3]
            T[:3, 3] += rng.normal(0.0, noise.position, 3)
            W = states.loads[i] + np.concatenate([rng.normal(0.0, noise.force, 3),
                                                  rng.normal(0.0, noise.moment, 3)])
            tt = np.full(n, np.nan)
            idx = list(tensions)
            tt[idx] = states.tensions[i, idx] + rng.normal(0.0, noise.tension, len(idx))
            rows.append((t, states.rest[i], T, W if wrench else np.full(6, np.nan), tt))
        previous = target
    times, rest, poses, loads, tens = (np.array(c) for c in zip(*rows, strict=True))
    return Recording(times, rest, poses, loads, tens, np.full((len(times), n), np.nan),
                     'synthetic')


def write_bag(path, recording: Recording, storage: str = 'mcap',
              topics: dict[str, str] | None = None, pose_type: str = 'PoseStamped') -> None:
    """``recording`` as a rosbag2: poses (header stamps), rest lengths when they change,
    tensions and wrench (when recorded) at every instant."""
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
    from tensegrity_stiffness.recordings.calibration_recording import DEFAULT_TOPICS

    names = dict(DEFAULT_TOPICS, **(topics or {}))
    store = get_typestore(Stores.ROS2_JAZZY)
    ty = store.types

    def header(t: float):
        ns = round(float(t) * 1e9)
        return ty['std_msgs/msg/Header'](
            stamp=ty['builtin_interfaces/msg/Time'](sec=ns // 10**9, nanosec=ns % 10**9),
            frame_id='tensegrity_link1')

    def array(values):
        return ty['std_msgs/msg/Float64MultiArray'](
            layout=ty['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
            data=np.asarray(values, dtype=np.float64))

    pose_msgtype = f'geometry_msgs/msg/{pose_type}'
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()]) as writer:
        conn = {
            'pose': writer.add_connection(names['pose'], pose_msgtype, typestore=store),
            'rest_lengths': writer.add_connection(names['rest_lengths'],
                                                  'std_msgs/msg/Float64MultiArray',
                                                  typestore=store)}
        if np.isfinite(recording.tensions).any():
            conn['tensions'] = writer.add_connection(
                names['tensions'], 'std_msgs/msg/Float64MultiArray', typestore=store)
        if np.isfinite(recording.wrench).all():
            conn['wrench'] = writer.add_connection(names['wrench'],
                                                   'geometry_msgs/msg/WrenchStamped',
                                                   typestore=store)
        last_rest = None
        for i, t in enumerate(recording.times):
            log = round(float(t) * 1e9)
            if last_rest is None or not np.array_equal(recording.rest[i], last_rest):
                last_rest = recording.rest[i]
                writer.write(conn['rest_lengths'], log - 1000, store.serialize_cdr(
                    array(last_rest), 'std_msgs/msg/Float64MultiArray'))
            T = recording.poses[i]
            q = rotation_to_quaternion(T[:3, :3])
            pose = ty['geometry_msgs/msg/Pose'](
                position=ty['geometry_msgs/msg/Point'](x=T[0, 3], y=T[1, 3], z=T[2, 3]),
                orientation=ty['geometry_msgs/msg/Quaternion'](x=q[0], y=q[1], z=q[2], w=q[3]))
            if pose_type == 'PoseStamped':
                msg = ty[pose_msgtype](header=header(t), pose=pose)
            else:
                msg = ty[pose_msgtype](header=header(t), pose=ty[
                    'geometry_msgs/msg/PoseWithCovariance'](pose=pose,
                                                            covariance=np.zeros(36)))
            writer.write(conn['pose'], log, store.serialize_cdr(msg, pose_msgtype))
            if 'tensions' in conn:
                writer.write(conn['tensions'], log, store.serialize_cdr(
                    array(recording.tensions[i]), 'std_msgs/msg/Float64MultiArray'))
            if 'wrench' in conn:
                w = recording.wrench[i]
                msg = ty['geometry_msgs/msg/WrenchStamped'](
                    header=header(t), wrench=ty['geometry_msgs/msg/Wrench'](
                        force=ty['geometry_msgs/msg/Vector3'](x=w[0], y=w[1], z=w[2]),
                        torque=ty['geometry_msgs/msg/Vector3'](x=w[3], y=w[4], z=w[5])))
                writer.write(conn['wrench'], log, store.serialize_cdr(
                    msg, 'geometry_msgs/msg/WrenchStamped'))


def chain_states(chain, true_joints: list[JointModel], offsets: np.ndarray, count: int,
                 seed: int, force: float, moment: float, backend: str = 'twin'
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(commanded rest lengths (count, N, n), tip loads (count, 6), link poses (count, N, 4,
    4)) of a spine whose joints are ``true_joints`` (rest lengths commanded + ``offsets``
    (N, n)): settled in the twin's ChainSimulation (or solved by the library)."""
    from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium

    rng = np.random.default_rng(seed + 4000)
    true = JointChain(true_joints, chain.link_offsets, chain.tool, chain.link_masses,
                      chain.link_coms, gravity=chain.gravity)
    N, n = chain.n_joints, chain.joints[0].n_strings
    sim = None
    if backend == 'twin' and twin_available():
        from tensegrity_stiffness.simulation.twin import ChainSimulation

        sim = ChainSimulation(true)
    nominal_rest = np.array([j.rest_lengths for j in chain.joints])
    rows = []
    previous = None
    while len(rows) < count:
        command = nominal_rest + rng.uniform(-REST_SPREAD, REST_SPREAD, (N, n))
        W = np.concatenate([rng.normal(0.0, force, 3), rng.normal(0.0, moment, 3)])
        eq = solve_chain_equilibrium(true, W, rest_lengths=command + offsets,
                                     initial_screws=previous)
        if not (eq.success and eq.stable) or np.any(eq.state.saturated):
            continue
        if sim is None:
            rows.append((command, W, eq.state.link_transforms))
        else:
            sim.set_rest_lengths(command + offsets)
            sim.apply_wrench(W)
            if not sim.settle(tolerance=SETTLE_TOLERANCE, max_time=SETTLE_TIME):
                sim.set_screws(eq.screws)
                continue
            rows.append((command, W, sim.link_poses()))
        previous = eq.screws
    return tuple(np.array(c) for c in zip(*rows, strict=True))
