#!/usr/bin/env python3
"""``estimator_node``'s per-estimate path without ROS, on the twin's readings (issue 37, item 4).

Run by hand after ``source scripts/env.sh``:

    python bench/bench_estimate_path.py [--readings 400] [--rounds 6] [--previous DIR]
                                        [--profile FILE]

The MuJoCo twin (``JointSimulation``, the packaged joint) at 1 kHz gives a load-cell reading
(``Float64MultiArray``) and an IMU reading (``sensor_msgs/Imu``) every step while its rest
lengths follow a slow command (a ``~/rest_lengths`` message every second step: the controller's
500 Hz). Each reading goes through what ``estimator_node`` does with it (the messages built
directly, no rclpy.init): a rest-length command swaps the settings' model
(``JointRestLengthTopic._with_rest_lengths``' computation); an IMU message is decoded and
judged (``imu_motion``, ``imu_reading``, ``check_reading``); a load-cell message likewise
(``measured_values``, ``measured_array``, ``check_reading``) and then triggers one estimate
(``filter_outputs``, the std of K_c not wanted) whose pose and load messages are filled (the
two topics ``stiffness_controller`` subscribes to). Printed: the CPU time per estimate
(``time.thread_time``) of each round, rounds alternating with ``--previous`` (a checkout of an
earlier commit, ``git archive C | tar -x -C DIR``, imported beside this one by
``bench/previous_checkout.py``); then whether both paths gave bitwise equal estimates and
messages. ``--profile FILE``: a cProfile of this checkout's path to FILE. ``uptime`` first and
last; numbers only, no assertions.
"""

from __future__ import annotations

import argparse
import cProfile
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path
from types import ModuleType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'bench'))
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from builtin_interfaces.msg import Time  # noqa: E402
from previous_checkout import build_kernel, import_modules  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402

#: The modules of the path, per checkout.
MODULES = ['tensegrity_stiffness.config', 'tensegrity_stiffness.nodes.estimator_node',
           'tensegrity_stiffness.nodes.parameters', 'tensegrity_stiffness.nodes.messages',
           'tensegrity_stiffness.nodes.stiffness_node',
           'tensegrity_stiffness.nodes.shared_parameters',
           'tensegrity_stiffness.ros.conversions.estimation',
           'tensegrity_stiffness.ros.conversions.outputs']
#: Which of the estimator's outputs are wanted (the controller's two: pose and load).
WANTED_TOPICS = ('~/pose_estimate', '~/wrench_estimate')
TENSION_NOISE = 0.005
#: Amplitude (m) and period (s) of the rest-length command about the packaged rest lengths.
REST_SWING = (2e-3, 0.4)


def uptime() -> str:
    return subprocess.run(['uptime'], capture_output=True, text=True, check=False).stdout.strip()


def twin_readings(n: int) -> list[tuple[float, Any, Any, Any]]:
    """``n`` steps of the twin at 1 kHz: (time, load-cell message, IMU message, rest-length
    message or None)."""
    from tensegrity_stiffness import config
    from tensegrity_stiffness.mechanics.joint import JointModel
    from tensegrity_stiffness.simulation.twin import JointSimulation

    model = JointModel.from_yaml(config.packaged_config_path())
    sim = JointSimulation(model)
    rng = np.random.default_rng(0)
    base = model.rest_lengths.copy()
    phase = np.linspace(0.0, 2 * np.pi, model.n_strings, endpoint=False)
    out = []
    for i in range(n):
        t = 1e-3 * (i + 1)
        command = None
        if i % 2 == 0:
            rest = base + REST_SWING[0] * np.sin(2 * np.pi * t / REST_SWING[1] + phase)
            sim.set_rest_lengths(rest)
            command = Float64MultiArray(data=rest.tolist())
        sim.step()
        tensions = Float64MultiArray(data=(sim.tensions() + rng.normal(
            scale=TENSION_NOISE, size=model.n_strings)).tolist())
        reading = sim.imu()
        imu = Imu()
        imu.header.frame_id = 'tensegrity_link2'
        imu.header.stamp = Time(sec=1, nanosec=i * 1_000_000)
        imu.angular_velocity.x, imu.angular_velocity.y, imu.angular_velocity.z = \
            (float(v) for v in reading.angular_velocity)
        imu.linear_acceleration.x, imu.linear_acceleration.y, imu.linear_acceleration.z = \
            (float(v) for v in reading.specific_force)
        out.append((t, tensions, imu, command))
    return out


class EstimatePath:
    """One checkout's estimator path over the readings (fresh settings and filter per run)."""

    def __init__(self, mods: dict[str, ModuleType]) -> None:
        self.m = mods

    def run(self, readings: list[tuple[float, Any, Any, Any]]) -> tuple[float, int, list]:
        """(thread CPU s, estimates, per estimate: (screw, covariance, wrench, K, K_c,
        tensions, pose message values, wrench message values))."""
        en = self.m['tensegrity_stiffness.nodes.estimator_node']
        values = self.m['tensegrity_stiffness.nodes.parameters'].defaults(
            en.ESTIMATOR_NODE_PARAMETERS)
        settings = en.estimator_node_settings(values)
        conv = self.m['tensegrity_stiffness.ros.conversions.estimation']
        offsets = self.m['tensegrity_stiffness.nodes.shared_parameters'].rest_length_offsets
        with_rest = self.m['tensegrity_stiffness.nodes.stiffness_node'].with_rest_lengths
        multiarray = self.m['tensegrity_stiffness.nodes.messages'].multiarray_payload
        messages = conv.EstimatorOutputMessages(tuple(settings.model.string_names))
        wanted = self._wanted(messages)
        track = en.new_joint_filter(settings)
        n = settings.model.n_strings
        store: dict[str, Any] = {}
        results = []
        last = None
        estimates = 0
        start = time.thread_time()
        for t, tension_msg, imu_msg, command in readings:
            if command is not None:
                commanded = multiarray(command, settings.max_array_length)
                rest = commanded + offsets(settings.values, n)
                settings = replace(replace(settings, model=with_rest(settings.model, rest)),
                                   generation=settings.generation + 1)
            imu = en.imu_reading(settings, *conv.imu_motion(imu_msg))
            en.check_reading(settings, 'imu', imu)
            store['imu'] = en.Reading(imu, t)
            tensions = en.measured_array(conv.measured_values(tension_msg,
                                                              settings.max_array_length),
                                         n, '~/measured_tensions')
            en.check_reading(settings, 'measured_tensions', tensions)
            store['measured_tensions'] = en.Reading(tensions, t)
            outputs = en.filter_outputs(settings, en.EstimatorInput(dict(store), t, last),
                                        track, False)
            messages.fill(outputs, imu_msg.header.stamp, settings.link1_frame, wanted)
            last = outputs.screw
            estimates += 1
            results.append(self._record(outputs, messages))
        return time.thread_time() - start, estimates, results

    @staticmethod
    def _wanted(messages: Any) -> tuple[bool, ...]:
        from tensegrity_stiffness.ros.estimator_node import EstimatorNode

        topics = [topic for _, topic in EstimatorNode.OUTPUT_TOPICS]
        assert len(topics) == len(messages.messages())
        return tuple(topic in WANTED_TOPICS for topic in topics)

    @staticmethod
    def _record(outputs: Any, messages: Any) -> tuple:
        est = outputs.estimate
        pose, wrench = messages.messages()[0], messages.messages()[1]
        p, q = pose.pose.pose.position, pose.pose.pose.orientation
        w = wrench.wrench
        return (est.screw.copy(), np.array(est.covariance), np.array(est.external_wrench),
                est.state.stiffness.copy(), est.state.cartesian_stiffness.copy(),
                est.state.tensions.copy(),
                (p.x, p.y, p.z, q.x, q.y, q.z, q.w, tuple(pose.pose.covariance),
                 pose.header.stamp.nanosec, pose.header.frame_id),
                (w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z))


def equal(a: list, b: list) -> str:
    """Whether two runs' records are bitwise equal (NaN equal to NaN), else the first
    difference."""
    if len(a) != len(b):
        return f'{len(a)} against {len(b)} estimates'
    for i, (x, y) in enumerate(zip(a, b, strict=True)):
        for j, (u, v) in enumerate(zip(x, y, strict=True)):
            if isinstance(u, np.ndarray):
                same = u.shape == v.shape and np.array_equal(u, v, equal_nan=True)
            else:
                same = u == v
            if not same:
                return f'estimate {i}, field {j} differs: {u} against {v}'
    return 'bitwise equal'


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--readings', type=int, default=400)
    parser.add_argument('--rounds', type=int, default=6)
    parser.add_argument('--previous', type=Path, help='an earlier checkout, side by side')
    parser.add_argument('--profile', type=Path, help="cProfile of this checkout's path here")
    args = parser.parse_args()
    print(f'start: {uptime()}', flush=True)
    readings = twin_readings(args.readings)
    paths = {'this checkout': EstimatePath({name: sys.modules.get(name) or __import__(
        name, fromlist=['_']) for name in MODULES})}
    if args.previous is not None:
        root = args.previous.resolve()
        library = build_kernel(root, Path(tempfile.mkdtemp()))
        paths[f'previous ({root})'] = EstimatePath(import_modules(root, MODULES, library))
    times: dict[str, list[float]] = {name: [] for name in paths}
    records: dict[str, list] = {}
    for _ in range(args.rounds):
        for name, path in paths.items():
            cpu, count, records[name] = path.run(readings)
            times[name].append(1e3 * cpu / count)
    for name, per in times.items():
        print(f'{name}: CPU per estimate {statistics.median(per):.3f} ms (median of '
              f'{len(per)} rounds of {args.readings}; rounds: '
              f'{", ".join(f"{x:.3f}" for x in per)})')
    if len(records) == 2:
        first, second = records.values()
        print(f'outputs: {equal(first, second)}')
    if args.profile is not None:
        profile = cProfile.Profile(time.thread_time)
        path = paths['this checkout']
        profile.runcall(path.run, readings)
        profile.dump_stats(str(args.profile))
        print(f'profile: {args.profile}')
    print(f'end: {uptime()}')


if __name__ == '__main__':
    main()
