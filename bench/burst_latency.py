#!/usr/bin/env python3
"""Worst-case stiffness latency while the equilibrium service solves hard requests, run by hand
after ``source scripts/env.sh``:

    python bench/burst_latency.py [--seconds 15] [--burst 120] [--concurrent 1] [--rate 1000]
                                  [--param markers.max_rate:=30.0]

The installed ``stiffness_node`` runs as its own process. This process publishes screws on
``~/screw`` at ``--rate`` Hz for ``--seconds``; in the middle third it sends ``--burst``
equilibrium requests that each use up the solve's time budget (a 50 N force, beyond the joint's
reach), ``--concurrent`` at a time. Each ``~/stiffness`` is matched to its screw by value (the
library's K, computed one screw at a time as the node does). Prints median / p99 / max latency
and drops before, during and after the burst, the node's CPU time per screw in each phase
(/proc/<pid>/stat), and the service round trips.
"""

from __future__ import annotations

import argparse
import itertools
import os
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support import use_own_ros_domain  # noqa: E402
from support.ros_harness import (  # noqa: E402
    DEEP,
    NodeProcess,
    RosClient,
    latency_summary,
    sleep_until,
    unique_namespace,
)
from tensegrity_stiffness.srv import SolveEquilibrium  # noqa: E402

from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402

use_own_ros_domain()

HARD_WRENCH = np.r_[50.0, 0.0, 0.0, 0.0, 0.0, 0.0]


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process (s)."""
    with open(f'/proc/{pid}/stat') as f:
        fields = f.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')






class Matcher:
    """~/stiffness callback: match each message to the oldest screw whose K it equals."""

    def __init__(self, expected: np.ndarray) -> None:
        self.expected = expected
        self.arrived = np.full(len(expected), np.nan)
        self.next = 0
        self.unmatched = 0

    def __call__(self, msg: Float64MultiArray) -> None:
        now = time.perf_counter()
        K = np.asarray(msg.data)
        for k in range(self.next, min(self.next + 200, len(self.expected))):
            if np.allclose(K, self.expected[k], rtol=1e-12, atol=1e-12):
                self.arrived[k] = now
                self.next = k + 1
                return
        self.unmatched += 1


def run(args: argparse.Namespace) -> dict[str, object]:
    model = JointModel.from_yaml(ROOT / 'config' / 'default_joint.yaml')
    rng = np.random.default_rng(args.seed)
    n = int(args.rate * args.seconds)
    screws = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3, size=(n, 6))
    expected = np.array([model.stiffness(xi).ravel() for xi in screws])  # the node's path
    ns = unique_namespace('burst')
    proc = NodeProcess(ns, extra_args=['-p', f'qos.depth:={args.depth}',
                                       *(a for p in args.param for a in ('-p', p))])
    ros = RosClient('burst')
    base = f'{ns}/stiffness_node'
    matcher = Matcher(expected)
    try:
        ros.subscribe_callback(Float64MultiArray, f'{base}/stiffness', matcher, DEEP)
        pub = ros.publisher(Float64MultiArray, f'{base}/screw', DEEP)
        client = ros.client(SolveEquilibrium, f'{base}/solve_equilibrium')
        ros.wait_for_subscribers(pub)
        ros.wait_for_publishers(f'{base}/stiffness')
        time.sleep(3.0)  # the node's start-up (its solver process warms up) is not measured
        request = SolveEquilibrium.Request(external_wrench=conversions.wrench_to_msg(HARD_WRENCH),
                                           initial_screw=model.initial_screw.tolist())
        round_trips: list[float] = []
        answers: list[str] = []
        window: list[float] = []
        lock = threading.Lock()
        todo = iter(range(args.burst))

        def burst() -> None:
            while True:
                with lock:
                    if next(todo, None) is None:
                        return
                t = time.perf_counter()
                res = ros.call(client, request, timeout=60.0)
                with lock:
                    round_trips.append(time.perf_counter() - t)
                    answers.append(res.message.split(':')[0])

        workers = [threading.Thread(target=burst, daemon=True) for _ in range(args.concurrent)]
        sent = np.full(n, np.nan)
        period = 1.0 / args.rate
        cpu = [(0, cpu_seconds(proc.pid))]
        start = time.perf_counter()
        for k in range(n):
            sleep_until(start + k * period)
            if k == n // 3:
                window.append(time.perf_counter())
                cpu.append((k, cpu_seconds(proc.pid)))
                for w in workers:
                    w.start()
            if k > n // 3 and len(cpu) == 2 and not any(w.is_alive() for w in workers):
                cpu.append((k, cpu_seconds(proc.pid)))
            sent[k] = time.perf_counter()
            pub.publish(Float64MultiArray(data=screws[k].tolist()))
        for w in workers:
            w.join(120.0)
        window.append(max(time.perf_counter() if not round_trips else 0.0, window[0]))
        end_of_burst = window[0] + sum(round_trips) / max(1, args.concurrent)
        deadline = time.monotonic() + 10.0
        while matcher.next < n and time.monotonic() < deadline:
            time.sleep(0.05)
        latency = matcher.arrived - sent
        phase = np.where(sent < window[0], 0, np.where(sent <= end_of_burst, 1, 2))
        out: dict[str, object] = {'sent': n, 'unmatched': matcher.unmatched,
                                  'drops': int(np.isnan(latency).sum())}
        for p, name in enumerate(('before the burst', 'during the burst', 'after the burst')):
            lat = latency[(phase == p) & ~np.isnan(latency)].tolist()
            out[name] = lat
        cpu.append((n, cpu_seconds(proc.pid)))
        out['cpu ms per screw'] = [
            round(1e3 * (c1 - c0) / max(1, k1 - k0), 3)
            for (k0, c0), (k1, c1) in itertools.pairwise(cpu)]
        out['round trips'] = round_trips
        out['answers'] = sorted(set(answers))
        out['rss MB'] = proc.rss_bytes() / 2**20
        return out
    finally:
        ros.close()
        code = proc.stop()
        if code != 0:
            print(f'node exited with {code}:\n{proc.log()[-3000:]}')


def main() -> None:
    sys.setswitchinterval(2e-4)  # the client publishes while its executor thread receives
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rate', type=float, default=1000.0, help='screw rate, Hz')
    parser.add_argument('--seconds', type=float, default=15.0, help='stream duration, s')
    parser.add_argument('--burst', type=int, default=120, help='hard equilibrium requests')
    parser.add_argument('--concurrent', type=int, default=1, help='requests in flight')
    parser.add_argument('--depth', type=int, default=100, help="the node's qos.depth")
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--param', action='append', default=[],
                        help='node parameter override NAME:=VALUE (repeatable)')
    args = parser.parse_args()
    print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}: {args.rate:.0f} Hz screws for '
          f'{args.seconds:.0f} s, {args.burst} hard equilibrium requests '
          f'({args.concurrent} in flight) from t = {args.seconds / 3:.1f} s, '
          f'params {args.param or "default"}')
    out = run(args)
    print(f'sent {out["sent"]}, drops {out["drops"]}, unmatched (wrong) {out["unmatched"]}, '
          f'node RSS {out["rss MB"]:.1f} MB')
    for name in ('before the burst', 'during the burst', 'after the burst'):
        print(latency_summary(f'  latency {name}', out[name]))
    print(f'  node CPU per screw (before, during, after) [ms]: {out["cpu ms per screw"]}')
    print(latency_summary('  equilibrium round trip', out['round trips']))
    print(f'  equilibrium answers: {out["answers"]}')


if __name__ == '__main__':
    main()
