#!/usr/bin/env python3
"""Latency the stiffness_bridge adds to the topic path (three processes), run by hand after
``source scripts/env.sh`` (uses the environment's ROS_DOMAIN_ID):

    python bench/bench_bridge.py [--rate 1000] [--seconds 5] [--preset crisp_full]
                                 [--client-loop lane|executor] [--pacing sleep|spin]

An installed ``stiffness_node`` and an installed ``stiffness_bridge`` (topic preset, no rate
limit, no low-pass, the controller frame 20 mm and 30 degrees off) run as processes of their
own; the bridge reads the node's ``~/cartesian_stiffness``. This process publishes screws on the
node's ``~/screw`` at ``--rate`` Hz for ``--seconds`` and receives, side by side in the same run,
the node's ``~/cartesian_stiffness`` (the direct topic: what a controller would read without the
bridge) and the bridge's ``~/output_stiffness``. Node outputs are paired with their screws by
value (the node may drop screws when its input queue overflows), the bridge's k-th output with the
node's k-th (one output per input; counted, and checked by value on a sample). Prints median /
p99 / max from the send time for both paths, and of the difference per screw: the latency the
bridge adds (one more hop and its conditioning).
Target (issue 22): the bridge adds <= 0.3 ms median at 1 kHz.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
if 'ROS_DOMAIN_ID' not in os.environ:
    raise SystemExit('set ROS_DOMAIN_ID (source scripts/env.sh with your domain id)')

import numpy as np  # noqa: E402
import yaml  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    CLIENT_LOOPS,
    Inbox,
    NodeProcess,
    RosClient,
    collector_paused,
    latencies_in_order,
    latency_summary,
    percentile,
    publish_paced,
    receiving,
    unique_namespace,
)

from tensegrity_stiffness.mechanics.controller_stiffness import Conditioner, to_layout  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.nodes.stiffness_bridge import BRIDGE_PRESETS  # noqa: E402

CONFIG = ROOT / 'config' / 'default_joint.yaml'
POSE = [0.02, 0.0, 0.01, 0.0, 0.0, math.sin(math.pi / 12), math.cos(math.pi / 12)]
WARM_UP_S = 1.0


def per_screw(inbox: Inbox, expected: np.ndarray, sent_at: list[float], skip: int
              ) -> dict[int, float]:
    """``{screw index: latency}`` of an inbox's outputs matched by value, from screw ``skip``
    on."""
    latencies = latencies_in_order([np.asarray(m.data) for m in inbox.messages], inbox.times,
                                   expected, sent_at)
    sent = np.asarray(sent_at)
    out = {}
    for arrived, latency in zip(inbox.times, latencies, strict=True):
        k = int(np.argmin(np.abs(sent - (arrived - latency))))
        if k >= skip:
            out[k] = latency
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--rate', type=float, default=1000.0)
    parser.add_argument('--seconds', type=float, default=5.0)
    parser.add_argument('--preset', default='crisp_full',
                        choices=[p for p, s in BRIDGE_PRESETS.items() if s.kind == 'topic'])
    parser.add_argument('--client-loop', choices=CLIENT_LOOPS, default='lane')
    parser.add_argument('--pacing', choices=['sleep', 'spin'], default='sleep')
    args = parser.parse_args()

    ns = unique_namespace('bench_bridge')
    params = Path(os.environ.get('TMPDIR', '/tmp')) / f'bench_bridge_{os.getpid()}.yaml'
    params.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'preset': args.preset, 'output.pose': POSE, 'output.max_rate': 0.0,
        'output.time_constant': 0.0}}}))
    direct_topic = f'{ns}/stiffness_node/cartesian_stiffness'
    bridged_topic = f'{ns}/stiffness_bridge/output_stiffness'
    node = NodeProcess(ns, CONFIG, extra_args=['-p', 'markers.max_rate:=0.0'])
    bridge = NodeProcess(ns, params, executable='stiffness_bridge',
                         extra_args=['-r', f'~/input_stiffness:={direct_topic}'])
    ros = RosClient('bench_bridge')
    direct, bridged = Inbox(), Inbox()
    model = JointModel.from_yaml(CONFIG)
    rng = np.random.default_rng(1)
    try:
        pub = ros.publisher(Float64MultiArray, f'{ns}/stiffness_node/screw')
        with receiving(ros, [(Float64MultiArray, direct_topic, direct),
                             (Float64MultiArray, bridged_topic, bridged)], args.client_loop):
            ros.wait_for_subscribers(pub)
            ros.wait_for_publishers(direct_topic)
            ros.wait_for_publishers(bridged_topic)
            deadline = time.monotonic() + 20
            while ros.node.count_subscribers(direct_topic) < 2:  # the bridge and this client
                if time.monotonic() > deadline:
                    raise TimeoutError('the bridge does not subscribe')
                time.sleep(0.05)
            n = int(args.rate * (args.seconds + WARM_UP_S))
            screws = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.001] * 3,
                                                      size=(n, 6))
            messages = [Float64MultiArray(data=[float(v) for v in xi]) for xi in screws]
            spin_s = 2e-4 if args.pacing == 'spin' else 0.0
            with collector_paused():
                sent_at = publish_paced(pub, messages, args.rate, spin_s,
                                        lambda: min(len(direct), len(bridged)), timeout=3.0)
            time.sleep(0.5)
        # every output is matched to its screw by value (the node and the bridge may each drop
        # inputs when their queue overflows under load; outputs come in input order)
        K_c = model.cartesian_stiffness(screws)
        conditioner = Conditioner(pose=POSE, min_eigenvalue=1e-3)
        layout = BRIDGE_PRESETS[args.preset].layout
        expected_bridged = np.array([to_layout(conditioner.apply(K).matrix, layout)
                                     for K in K_c])
        warm = int(args.rate * WARM_UP_S)
        d = per_screw(direct, K_c.reshape(n, 36), sent_at, warm)
        b = per_screw(bridged, expected_bridged, sent_at, warm)
        added = [b[k] - d[k] for k in sorted(d.keys() & b.keys())]
        dropped = (n - len(direct), n - len(bridged))
    finally:
        ros.close()
        codes = (bridge.stop(), node.stop())
        params.unlink(missing_ok=True)
    load = os.getloadavg()
    print(f'stiffness_bridge latency, preset {args.preset}, {args.rate:g} Hz for '
          f'{args.seconds:g} s (after {WARM_UP_S:g} s warm-up), client loop {args.client_loop}, '
          f'pacing {args.pacing}; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on '
          f'{os.cpu_count()} cores (shared machine: figures are noisy)')
    print(f'screws sent {n}; dropped (input queue overflow) by stiffness_node {dropped[0]}, '
          f'before the bridge\'s output {dropped[1]}')
    print(latency_summary('direct ~/cartesian_stiffness', list(d.values())))
    print(latency_summary('through the bridge', list(b.values())))
    ms = [a * 1e3 for a in added]
    print(f'{"added by the bridge":<34} n={len(ms):>6}  median {statistics.median(ms):7.3f} ms  '
          f'p99 {percentile(ms, 0.99):7.3f} ms  max {max(ms):8.3f} ms')
    print(f'target: added median <= 0.3 ms -> '
          f'{"met" if statistics.median(ms) <= 0.3 else "NOT met"}; exit codes {codes}')


if __name__ == '__main__':
    main()
