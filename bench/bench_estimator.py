#!/usr/bin/env python3
"""Estimator benchmark, run by hand after ``source scripts/env.sh``:

    python bench/bench_estimator.py [--repeats 3000] [--rate 1000] [--seconds 10]
                                    [--client-loops lane executor] [--no-node]
                                    [--triggers imu measured_tensions]

1. The library: one warm-started ``estimate_joint_state`` per reading, as a tracker at 1 kHz
   calls it (a fixed true configuration of the default joint, new sensor noise each call, warm
   start = the previous estimate), for each sensor set, with and without the std of K_c; beside
   it one ``JointModel.evaluate`` (the floor: every iteration evaluates once) and a cold start
   from the unloaded equilibrium. Median / p90 in us and the ratio to ``evaluate``, side by
   side. Target (issue 23): 12 tensions with an unknown load <= 100 us.
2. ``estimator_node`` as its own process (12 tensions + IMU, unknown load, trigger ``~/imu``):
   this process publishes ``~/imu`` at ``--rate`` for ``--seconds`` and ``~/measured_tensions``
   before every ``--tensions-every``-th of them; each ``~/pose_estimate`` carries its IMU
   message's stamp, so it is paired with its input exactly. Median / p99 / max latency and
   drops. Beside it the sensor set of the library's target row as its own trigger
   (``estimation.trigger`` = ``measured_tensions``, 12 load cells alone, unknown load): this
   process publishes ``~/measured_tensions`` at ``--rate``; a ``Float64MultiArray`` has no stamp,
   so the k-th ``~/pose_estimate`` is paired with the k-th reading sent (exact without drops;
   with drops it overstates the latency, as a later reading answers an earlier one's slot).
   Target: at 1 kHz for 10 s, median <= 1 ms, 0 drops.
"""

from __future__ import annotations

import argparse
import gc
import os
import random
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(100, 200)))

import numpy as np  # noqa: E402
from support.estimation_trials import (  # noqa: E402
    SENSOR_SETS,
    TENSION_STD,
    TRUTH_SPREAD,
    measure,
    truth_from_model,
)

from tensegrity_stiffness.estimation.joint_estimator import estimate_joint_state  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402

CONFIG = ROOT / 'config' / 'default_joint.yaml'
#: Seconds between the node being reachable and the start of the stream.
STARTUP_SETTLE_S = 3.0


def timed(fn, repeats: int) -> list[float]:
    out = []
    for _ in range(repeats):
        start = time.perf_counter()
        fn()
        out.append(time.perf_counter() - start)
    return out


def library(model: JointModel, repeats: int) -> None:
    rng = np.random.default_rng(0)
    xi = model.initial_screw + rng.normal(scale=TRUTH_SPREAD)
    truth = truth_from_model(model, xi)
    floor = timed(lambda: model.evaluate(xi), repeats)
    base = statistics.median(floor)
    rows = [('JointModel.evaluate (one per iteration)', floor, None)]
    for name, sensor_set in SENSOR_SETS.items():
        for with_std in (False, True):
            readings = [measure(truth, sensor_set, rng).prepared(model.n_strings)
                        for _ in range(repeats)]
            last = [xi.copy()]
            iterations = []

            def tracked(readings=readings, last=last, iterations=iterations, with_std=with_std):
                est = estimate_joint_state(model, readings[len(iterations)],
                                           initial_screw=last[0], stiffness_std=with_std)
                last[0] = est.screw
                iterations.append(est.iterations)

            times = timed(tracked, repeats)
            label = f'{name}{", + std of K_c" if with_std else ""}'
            rows.append((label, times, float(np.mean(iterations))))
    readings = [measure(truth, SENSOR_SETS['12 tensions'], rng) for _ in range(repeats // 10)]
    cold = timed(lambda: estimate_joint_state(model, readings[0], stiffness_std=False),
                 repeats // 10)
    rows.append(('12 tensions, cold start (unloaded screw)', cold, None))
    print('library (one process, this machine; median / p90 us, x evaluate, iterations):')
    for label, times, its in rows:
        us = np.array(times) * 1e6
        extra = f'  iterations {its:.2f}' if its is not None else ''
        print(f'  {label:<48} {np.median(us):8.1f} / {np.percentile(us, 90):8.1f} us  '
              f'x{np.median(times) / base:6.1f}{extra}', flush=True)


def node(model: JointModel, rate: float, seconds: float, loop: str, params: list[str],
         tensions_every: int = 1, trigger: str = 'imu') -> None:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from sensor_msgs.msg import Imu
    from std_msgs.msg import Float64MultiArray
    from support.ros_harness import (
        NodeProcess,
        RosClient,
        collector_paused,
        latency_summary,
        publish_paced,
        receiving,
        unique_namespace,
    )

    rng = np.random.default_rng(1)
    xi = model.initial_screw + rng.normal(scale=TRUTH_SPREAD)
    truth = truth_from_model(model, xi)
    ns = unique_namespace('bench_estimator')
    proc = NodeProcess(ns, CONFIG, executable='estimator_node',
                       extra_args=['-p', f'estimation.trigger:={trigger}',
                                   *[a for p in params for a in ('-p', p)]])
    ros = RosClient('bench_estimator')
    base = f'{ns}/estimator_node'
    arrivals: dict[int, float] = {}
    by_imu = trigger == 'imu'

    def on_pose(msg: PoseWithCovarianceStamped) -> None:
        # the IMU's stamp (trigger ~/imu) or the arrival order (trigger ~/measured_tensions)
        key = (msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec if by_imu
               else len(arrivals) + 1)
        arrivals[key] = time.perf_counter()

    try:
        tensions_pub = ros.publisher(Float64MultiArray, f'{base}/measured_tensions')
        imu_pub = ros.publisher(Imu, f'{base}/imu')
        ros.wait_for_subscribers(tensions_pub)
        ros.wait_for_subscribers(imu_pub)
        n = int(rate * seconds)
        specific_force = -9.81 * truth.gravity
        tensions = [Float64MultiArray(data=(truth.tensions + rng.normal(
            scale=TENSION_STD, size=model.n_strings)).tolist()) for _ in range(n)]
        imus = []
        for k in range(n):
            msg = Imu()
            msg.header.frame_id = 'tensegrity_link2'
            msg.header.stamp = Time(sec=0, nanosec=k + 1)
            msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z = \
                specific_force.tolist()
            imus.append(msg)
        # warm up: the node's first estimate (cold start) and its imports
        tensions_pub.publish(tensions[0])
        time.sleep(STARTUP_SETTLE_S)
        # the load cells' reading before every tensions_every-th IMU reading (the others use the
        # latest one, no older than estimation.max_age); or the load cells alone
        pairs = []
        for k in range(n):
            if not by_imu:
                pairs.append(tensions[k])
                continue
            if k % tensions_every == 0:
                pairs.append(tensions[k])
            pairs.append(imus[k])

        class Both:  # one publisher interface over the two topics, in order
            def publish(self, msg):
                (imu_pub if isinstance(msg, Imu) else tensions_pub).publish(msg)

        with receiving(ros, [(PoseWithCovarianceStamped, f'{base}/pose_estimate', on_pose)],
                       loop), collector_paused():
            per_cycle = len(pairs) / n
            sent = publish_paced(Both(), pairs, per_cycle * rate, 0.0,
                                 lambda: int(per_cycle * len(arrivals)))
        trigger_type = Imu if by_imu else Float64MultiArray
        trigger_sent = [t for t, msg in zip(sent, pairs, strict=True)
                        if isinstance(msg, trigger_type)]
        latencies = [arrivals[k + 1] - trigger_sent[k] for k in range(n) if k + 1 in arrivals]
        inputs = (f'12 tensions every {tensions_every} + IMU, trigger ~/imu' if by_imu
                  else '12 tensions alone, trigger ~/measured_tensions')
        label = f'  estimator_node {rate:.0f} Hz, {inputs} {" ".join(params)}, client {loop}'
        drops = n - len(latencies)
        caveat = '' if by_imu or not drops else ' (paired in order with drops: upper bounds)'
        print(latency_summary(label, latencies) + f'  drops {drops} of {n}{caveat}', flush=True)
    finally:
        ros.close()
        code = proc.stop()
        if code != 0:
            print(f'node exited with {code}:\n{proc.log()}')


def main() -> None:
    sys.setswitchinterval(2e-4)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeats', type=int, default=3000, help='estimates per library row')
    parser.add_argument('--rate', type=float, default=1000.0, help='node input rate, Hz')
    parser.add_argument('--seconds', type=float, default=10.0, help='node stream, s')
    parser.add_argument('--client-loops', nargs='+', choices=['lane', 'executor'],
                        default=['lane'])
    parser.add_argument('--no-node', action='store_true', help='the library part only')
    parser.add_argument('--no-library', action='store_true', help='the node part only')
    parser.add_argument('--tensions-every', type=int, default=1,
                        help='send the load cells every this many IMU readings (trigger: ~/imu)')
    parser.add_argument('--triggers', nargs='+', choices=['imu', 'measured_tensions'],
                        default=['imu', 'measured_tensions'],
                        help='node rows: 12 tensions + IMU (trigger ~/imu) and / or the 12 '
                             'tensions alone (trigger ~/measured_tensions)')
    parser.add_argument('--param', action='append', default=[],
                        help='node parameter override NAME:=VALUE (repeatable)')
    args = parser.parse_args()
    model = JointModel.from_yaml(CONFIG)
    print(f'compiled kernel: {model.uses_kernel}; load average {os.getloadavg()[0]:.1f} '
          f'on {os.cpu_count()} cores')
    gc.collect()
    gc.freeze()
    if not args.no_library:
        library(model, args.repeats)
    if not args.no_node:
        print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}; trigger -> ~/pose_estimate '
              'latency')
        for loop in args.client_loops:
            for trigger in args.triggers:
                node(model, args.rate, args.seconds, loop, args.param, args.tensions_every,
                     trigger)


if __name__ == '__main__':
    main()
