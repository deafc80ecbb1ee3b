#!/usr/bin/env python3
"""The MuJoCo twin's speed, run by hand after ``source scripts/env.sh``:

    python bench/bench_sim.py [--steps 5000] [--seconds 10] [--rate 1000] [--skip-node]

1. Library (no ROS), joint and 5-joint spine at a 1 ms step: the cost of one step
   (``step()``), of one step plus every reading a publication takes (screw(s), pose(s), string
   lengths, tensions, IMU), and the real-time factor as fast as possible (targets >= 20x joint,
   >= 5x spine).
2. ``sim_node`` in this process, as fast as possible (``sim.real_time: false``), every output
   subscribed by a reader that is never spun (the messages are built and published, their
   delivery costs this process nothing more): steps per second, cost of step + publish, the
   real-time factor.
3. ``sim_node`` as its own process in real time at ``--rate`` for ``--seconds``: steps missed
   (its /diagnostics; target 0), messages received of those expected, and the jitter of its
   publications: intervals between the stamps of ``~/pose`` (taken when the node publishes) and
   between their arrivals here, as |interval - period| median and p99.

Timing on a shared 2-core machine is noisy: the load average is printed next to the figures.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', '231')

import numpy as np  # noqa: E402

from tensegrity_stiffness.mechanics.chain import JointChain  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.simulation.twin import ChainSimulation, JointSimulation  # noqa: E402

JOINT_CONFIG = ROOT / 'config' / 'default_joint.yaml'
SPINE_CONFIG = ROOT / 'config' / 'default_spine.yaml'
#: A moderate swinging-free load for the library figures (the twin moves, not at rest).
JOINT_LOAD = np.array([0.05, -0.05, 0.02, 0.0, 5e-4, 0.0])
SPINE_LOAD = np.array([0.02, 0.0, -0.01, 0.0, 0.0, 0.0])


def load_average() -> str:
    return ' '.join(Path('/proc/loadavg').read_text().split()[:3])


def library(name: str, sim, steps: int) -> None:
    readings = (sim.screws if isinstance(sim, ChainSimulation) else sim.screw,
                sim.link_poses if isinstance(sim, ChainSimulation) else sim.pose,
                sim.string_lengths, sim.tensions, sim.imu)
    sim.step(100)  # warm
    start = time.perf_counter()
    sim.step(steps)
    step_s = (time.perf_counter() - start) / steps
    start = time.perf_counter()
    for _ in range(steps):
        sim.step()
        for read in readings:
            read()
    read_s = (time.perf_counter() - start) / steps
    dt = sim.options.timestep
    print(f'library {name:<6} step {step_s * 1e6:7.1f} us (real-time factor {dt / step_s:6.1f}x)'
          f'   step + readings {read_s * 1e6:7.1f} us ({dt / read_s:6.1f}x)')


def node_in_process(name: str, params_file: Path, spine: bool, seconds: float) -> None:
    import rclpy
    from rclpy.parameter import Parameter

    from tensegrity_stiffness.ros.sim_node import SimNode

    rclpy.init()
    overrides = [Parameter('sim.real_time', value=False)]
    # Parameters of the config file, as --params-file would give them.
    from tensegrity_stiffness.nodes.registry import values_from_config
    from tensegrity_stiffness.nodes.sim_node import sim_node_parameters
    values = values_from_config(params_file, sim_node_parameters(spine, 5))
    values['sim.spine'] = spine
    values['sim.real_time'] = False
    overrides = [Parameter(k, value=v) for k, v in values.items()
                 if not (isinstance(v, list) and not v)]
    node = SimNode(parameter_overrides=overrides)
    reader = rclpy.create_node('bench_sim_reader')
    from geometry_msgs.msg import PoseArray, PoseStamped
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64MultiArray
    topics = [(Float64MultiArray, 'screws' if spine else 'screw'),
              (PoseArray if spine else PoseStamped, 'poses' if spine else 'pose'),
              (Float64MultiArray, 'measured_lengths'), (Float64MultiArray, 'measured_tensions'),
              (Imu, 'imu')]
    subs = [reader.create_subscription(t, f'/sim_node/{topic}', lambda _: None, 10)
            for t, topic in topics]
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and not all(
            node.count_subscribers(f'/sim_node/{topic}') for _, topic in topics):
        time.sleep(0.05)
    steps0, publications0, t0 = node.steps, node.publications, time.perf_counter()
    time.sleep(seconds)
    steps, publications = node.steps - steps0, node.publications - publications0
    elapsed = time.perf_counter() - t0
    node.close()
    del subs
    reader.destroy_node()
    node.destroy_node()
    rclpy.shutdown()
    per_step = elapsed / steps
    print(f'sim_node {name:<6} as fast as possible: {steps / elapsed:8.0f} steps/s, '
          f'{publications} publications; step + publish {per_step * 1e6:7.1f} us '
          f'(real-time factor {1e-3 / per_step:5.1f}x at 1 ms)')


def node_real_time(seconds: float, rate: float) -> None:
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseStamped
    from support.ros_harness import DEEP, NodeProcess, RosClient, unique_namespace

    ns = unique_namespace('bench_sim')
    proc = NodeProcess(ns, JOINT_CONFIG, executable='sim_node',
                       extra_args=['-p', f'sim.rate:={rate}'])
    ros = RosClient('bench_sim')
    try:
        poses = ros.subscribe(PoseStamped, f'{ns}/sim_node/pose', DEEP)
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
        poses.wait_for(1, timeout=30.0)
        time.sleep(2.0)  # let start-up settle
        first = len(poses)
        diag_first = diagnostics.wait_until(lambda m: _missed(m, ns) is not None, 5.0)
        missed0 = _missed(diag_first, ns)
        time.sleep(seconds)
        last = len(poses)
        msgs, times = poses.messages[first:last], poses.times[first:last]
        diagnostics.clear()
        missed1 = _missed(diagnostics.wait_until(lambda m: _missed(m, ns) is not None, 5.0), ns)
    finally:
        ros.close()
        proc.stop()
    period = 1.0 / rate
    stamps = [m.header.stamp.sec + m.header.stamp.nanosec * 1e-9 for m in msgs]
    stamp_jitter = np.abs(np.diff(stamps) - period) * 1e3
    arrival_jitter = np.abs(np.diff(times) - period) * 1e3
    expected = seconds * rate
    print(f'sim_node real time {rate:g} Hz for {seconds:g} s: {len(msgs)} of ~{expected:.0f} '
          f'poses received, steps missed {missed1 - missed0} (node /diagnostics, this window '
          f'give or take 1 s)')
    for label, jitter in (('publication stamps', stamp_jitter),
                          ('arrivals here', arrival_jitter)):
        print(f'  jitter of {label:<19} |interval - {period * 1e3:g} ms|: median '
              f'{statistics.median(jitter):.3f} ms, p99 {np.percentile(jitter, 99):.3f} ms, '
              f'max {jitter.max():.3f} ms')


def _missed(msg, ns: str) -> int | None:
    for status in msg.status:
        if status.name.startswith(f'{ns[1:]}') or status.name.endswith('sim_node: twin'):
            values = {kv.key: kv.value for kv in status.values}
            if 'missed steps' in values:
                return int(values['missed steps'])
    return None


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--steps', type=int, default=5000)
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--fast-seconds', type=float, default=3.0,
                        help='seconds of each in-process sim_node run')
    parser.add_argument('--skip-node', action='store_true', help='library figures only')
    args = parser.parse_args()
    print(f'load average {load_average()} (2 shared cores: figures are noisy)')
    joint = JointSimulation(JointModel.from_yaml(JOINT_CONFIG))
    joint.apply_wrench(JOINT_LOAD)
    library('joint', joint, args.steps)
    spine = ChainSimulation(JointChain.from_yaml(SPINE_CONFIG))
    spine.apply_wrench(SPINE_LOAD)
    library('spine5', spine, args.steps)
    if args.skip_node:
        return
    node_in_process('joint', JOINT_CONFIG, False, args.fast_seconds)
    node_in_process('spine5', SPINE_CONFIG, True, args.fast_seconds)
    node_real_time(args.seconds, args.rate)
    print(f'load average {load_average()}')


if __name__ == '__main__':
    main()
