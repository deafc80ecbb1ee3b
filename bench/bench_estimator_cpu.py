#!/usr/bin/env python3
"""``estimator_node``'s CPU per estimate at fixed input rates (issue 37, item 4), run by hand
after ``source scripts/env.sh`` (uses the environment's ROS_DOMAIN_ID and the installed node):

    python bench/bench_estimator_cpu.py [--seconds 10] [--readings 2000] [--command-every 2]

The twin's readings (``bench_estimate_path.twin_readings``: load cells and IMU at 1 kHz, the rest
lengths following a slow command) are replayed from this process to an ``estimator_node``
process (filter, trigger ``~/measured_tensions``) at 1 kHz, a ``~/rest_lengths`` command every
``--command-every`` readings (2: the controller's 500 Hz), with subscribers on
``~/pose_estimate`` and ``~/wrench_estimate`` (the controller's two). Unlike the closed loop
(``bench_loop.py``), the inputs' rates do not follow the machine's load. Printed: the rates sent,
the estimates received per second and the node process's CPU time (``/proc``) per estimate and
per second over the stream. To set two checkouts side by side, run this file alternately
under each checkout's environment (the node is the installed one). Numbers only, no
assertions; ``uptime`` first and last.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT / 'bench'))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
if 'ROS_DOMAIN_ID' not in os.environ:
    raise SystemExit('set ROS_DOMAIN_ID (source scripts/env.sh with your domain id)')

from bench_estimate_path import twin_readings  # noqa: E402
from bench_loop import process_cpu_s  # noqa: E402
from geometry_msgs.msg import PoseWithCovarianceStamped, WrenchStamped  # noqa: E402
from rclpy.qos import DurabilityPolicy  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    NodeProcess,
    RosClient,
    reliable_qos,
    unique_namespace,
)

#: Seconds between the node's first estimate and the stream's measured part.
SETTLE_S = 2.0


def uptime() -> str:
    return subprocess.run(['uptime'], capture_output=True, text=True, check=False).stdout.strip()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=10.0)
    parser.add_argument('--readings', type=int, default=2000,
                        help='twin readings recorded (replayed in a loop)')
    parser.add_argument('--command-every', type=int, default=2)
    args = parser.parse_args()
    print(f'start: {uptime()}', flush=True)
    readings = twin_readings(args.readings)
    commands = [c for _, _, _, c in readings if c is not None]
    ns = unique_namespace('bench_estimator_cpu')
    est = f'{ns}/estimator_node'
    node = NodeProcess(ns, executable='estimator_node', extra_args=[
        '-p', 'estimation.method:=filter', '-p', 'markers.max_rate:=0.0'])
    ros = RosClient('bench_estimator_cpu')
    try:
        poses = ros.subscribe(PoseWithCovarianceStamped, f'{est}/pose_estimate')
        ros.subscribe(WrenchStamped, f'{est}/wrench_estimate')
        pub_t = ros.publisher(Float64MultiArray, f'{est}/measured_tensions')
        pub_i = ros.publisher(Imu, f'{est}/imu')
        # latched, as the controller's
        pub_r = ros.publisher(Float64MultiArray, f'{est}/rest_lengths',
                              reliable_qos(1, DurabilityPolicy.TRANSIENT_LOCAL))
        deadline = time.monotonic() + 60.0
        i = 0
        window = None
        sent = 0
        start = time.monotonic()
        while True:
            now = time.monotonic()
            if window is None and poses.messages and now - start > SETTLE_S:
                window = (now, process_cpu_s(node.pid), len(poses.messages), sent)
            if window is not None and now - window[0] >= args.seconds:
                break
            if window is None and now > deadline:
                raise SystemExit(f'no estimate in 60 s: {node.log()[-2000:]}')
            _, tensions, imu, _ = readings[i % len(readings)]
            pub_i.publish(imu)
            pub_t.publish(tensions)
            if i % args.command_every == 0:
                pub_r.publish(commands[(i // args.command_every) % len(commands)])
            sent += 1
            i += 1
            # 1 kHz on the wall clock (a late reading is sent at once, none made up)
            delay = start + i * 1e-3 - time.monotonic()
            if delay > 0:
                time.sleep(delay)
        t1, cpu1 = time.monotonic(), process_cpu_s(node.pid)
        time.sleep(0.2)
        t0, cpu0, n0, s0 = window
        estimates = len(poses.messages) - n0
        span = t1 - t0
        print(f'readings sent {(sent - s0) / span:.0f}/s, commands '
              f'{(sent - s0) / span / args.command_every:.0f}/s; estimates received '
              f'{estimates / span:.0f}/s; node CPU {1e3 * (cpu1 - cpu0) / max(estimates, 1):.3f} '
              f'ms per estimate, {(cpu1 - cpu0) / span:.3f} s/s; {uptime()}', flush=True)
    finally:
        ros.close()
        node.stop()
    print(f'end: {uptime()}')


if __name__ == '__main__':
    main()
