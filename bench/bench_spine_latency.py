#!/usr/bin/env python3
"""spine_node latency benchmark (two processes), run by hand after ``source scripts/env.sh``:

    python bench/bench_spine_latency.py [--rate 1000] [--seconds 10] [--joints 5 10] [--calls 50]
                                        [--client-loops lane executor] [--pacing sleep|spin]

For each joint count the installed ``spine_node`` runs as its own process on the default spine
(``config/default_spine.yaml``, ``chain.n_joints`` overridden). This process publishes screws on
``~/screws`` at ``--rate`` Hz for ``--seconds``; a controller-like client subscribes to
``~/tip_stiffness`` and, per message, forms the tip's restoring wrench ``-K e`` for a small
error ``e`` (as an impedance controller would), receiving on a lean wait-set loop (``lane``)
or on its rclpy executor (``executor``; ``ros_harness.receiving``). The latency of a screw is
the time until its ``~/tip_stiffness`` arrives (outputs come in input order over reliable QoS;
each is matched to its input by value against the library, so a drop cannot shift the pairing).
Then the round trip of ``~/solve_equilibrium`` for the first joint count (random moderate tip
wrenches).
Targets (issue 14, 5 joints): median <= 1.5 ms, p99 <= 5 ms, 0 drops; service median <= 30 ms.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
os.environ.setdefault('ROS_DOMAIN_ID', '231')  # Fast DDS takes domain ids up to 232

import numpy as np  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    NodeProcess,
    RosClient,
    add_client_arguments,
    latency_summary,
    pacing_spin_s,
    stream_latencies,
    timed_service_calls,
    unique_namespace,
)
from tensegrity_stiffness.srv import SolveChainEquilibrium  # noqa: E402

from tensegrity_stiffness.nodes.registry import values_from_config  # noqa: E402
from tensegrity_stiffness.nodes.spine_node import (  # noqa: E402
    SpineNodeSettings,
    spine_node_parameters,
    spine_node_settings,
    spine_outputs,
)
from tensegrity_stiffness.ros import conversions  # noqa: E402

CONFIG = ROOT / 'config' / 'default_spine.yaml'






#: A fixed small tip error: the client computes the restoring wrench ``-K e`` of it.
TIP_ERROR = np.array([1e-4, -2e-4, 1e-4, 1e-3, 0.0, -1e-3])


def settings_for(n_joints: int) -> SpineNodeSettings:
    values = values_from_config(CONFIG, spine_node_parameters(n_joints))
    values['chain.n_joints'] = n_joints
    return spine_node_settings(values)


def stream(ros: RosClient, base: str, n_joints: int, rate: float, seconds: float,
           rng: np.random.Generator, loop: str, spin_s: float) -> tuple[list[float], int, int]:
    """Publish screws at ``rate`` for ``seconds`` (``spin_s``: see :func:`publish_paced`), the
    client receiving on ``loop`` (:func:`receiving`) and computing ``-K e`` of each tip
    stiffness; returns (latencies, sent, drops)."""
    chain = settings_for(n_joints).chain
    n = int(rate * seconds)
    center = chain.unloaded_screws()
    screws = center + rng.normal(scale=[0.02] * 3 + [0.0005] * 3, size=(n, n_joints, 6))
    expected = [spine_outputs(chain, x).tip_stiffness_tool.ravel() for x in screws]
    return stream_latencies(ros, ros.publisher(Float64MultiArray, f'{base}/screws'),
                            (Float64MultiArray, f'{base}/tip_stiffness'),
                            [Float64MultiArray(data=x.ravel().tolist()) for x in screws],
                            expected, rate, loop, spin_s,
                            work=lambda K: -K.reshape(6, 6) @ TIP_ERROR)


def service_round_trips(ros: RosClient, base: str, calls: int, rng: np.random.Generator
                        ) -> tuple[list[float], int]:
    client = ros.client(SolveChainEquilibrium, f'{base}/solve_equilibrium')
    requests = (SolveChainEquilibrium.Request(tip_wrench=conversions.wrench_to_msg(
        np.r_[rng.normal(scale=0.03, size=3), rng.normal(scale=0.0006, size=3)]))
        for _ in range(calls))
    return timed_service_calls(ros, client, requests)


def main() -> None:
    sys.setswitchinterval(2e-4)  # as the node: the GIL changes hands often
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rate', type=float, default=1000.0, help='screw rate, Hz')
    parser.add_argument('--seconds', type=float, default=10.0, help='stream duration, s')
    parser.add_argument('--joints', type=int, nargs='+', default=[5, 10], help='joint counts')
    add_client_arguments(parser)
    parser.add_argument('--calls', type=int, default=50,
                        help='service calls (first joint count; 0: none)')
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}, load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores')
    spin_s = pacing_spin_s(args)
    first = True
    for n_joints in args.joints:
        for loop in args.client_loops:
            run(n_joints, loop, spin_s, args, rng, services=first and args.calls > 0)
            first = False


def run(n_joints: int, loop: str, spin_s: float, args: argparse.Namespace,
        rng: np.random.Generator, services: bool) -> None:
    ns = unique_namespace('bench_spine')
    proc = NodeProcess(ns, CONFIG, extra_args=['-p', f'chain.n_joints:={n_joints}'],
                       executable='spine_node')
    ros = RosClient('bench_spine')
    gc.collect()
    gc.freeze()
    base = f'{ns}/spine_node'
    try:
        latencies, sent, drops = stream(ros, base, n_joints, args.rate, args.seconds, rng, loop,
                                        spin_s)
        print(f'{n_joints} joints, client {loop:<8}: screws -> tip_stiffness at '
              f'{args.rate:.0f} Hz for {args.seconds:.0f} s: sent {sent}, drops {drops}')
        print(latency_summary('  latency', latencies))
        if services:
            times, failures = service_round_trips(ros, base, args.calls, rng)
            print(latency_summary(f'  solve_equilibrium (N = {n_joints})', times)
                  + f'  failed {failures}')
    finally:
        ros.close()
        code = proc.stop()
        if code != 0:
            print(f'node exited with {code}:\n{proc.log()}')

if __name__ == '__main__':
    main()
