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
from ros_harness import (  # noqa: E402
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
from std_msgs.msg import Float64MultiArray  # noqa: E402

from tensegrity_stiffness.controller_stiffness import Conditioner, to_layout  # noqa: E402
from tensegrity_stiffness.joint import JointModel  # noqa: E402
from tensegrity_stiffness.parameters import BRIDGE_PRESETS  # noqa: E402

CONFIG = ROOT / 'config' / 'default_joint.yaml'
POSE = [0.02, 0.0, 0.01, 0.0, 0.0, math.sin(math.pi / 12), math.cos(math.pi / 12)]
WARM_UP_S = 1.0


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
                                        lambda: min(len(direct), len(bridged)), timeout=10.0)
            time.sleep(0.5)
        # direct outputs are matched to their screws by value (the node may drop inputs under
        # load: its queue); the bridge answers each direct output in order, so its k-th output
        # belongs to the k-th direct one (checked by value on a sample)
        expected = model.cartesian_stiffness(screws).reshape(n, 36)
        d = latencies_in_order([np.asarray(m.data) for m in direct.messages], direct.times,
                               expected, sent_at)
        if len(bridged) != len(direct):
            raise SystemExit(f'the bridge lost messages: {len(direct)} in, {len(bridged)} out')
        conditioner = Conditioner(pose=POSE, min_eigenvalue=1e-3)
        for k in range(0, len(direct), 97):
            want = to_layout(conditioner.apply(np.asarray(direct.messages[k].data).reshape(
                6, 6)).matrix, BRIDGE_PRESETS[args.preset].layout)
            if not np.allclose(bridged.messages[k].data, want, rtol=1e-9, atol=1e-12):
                raise SystemExit(f'bridged output {k} is not the conditioned direct one')
        added = [tb - td for tb, td in zip(bridged.times, direct.times, strict=True)]
        warm = int(args.rate * WARM_UP_S)
        d, added = d[warm:], added[warm:]
        b = [x + a for x, a in zip(d, added, strict=True)]
        dropped = n - len(direct)
    finally:
        ros.close()
        codes = (bridge.stop(), node.stop())
        params.unlink(missing_ok=True)
    load = os.getloadavg()
    print(f'stiffness_bridge latency, preset {args.preset}, {args.rate:g} Hz for '
          f'{args.seconds:g} s (after {WARM_UP_S:g} s warm-up), client loop {args.client_loop}, '
          f'pacing {args.pacing}; load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f} on '
          f'{os.cpu_count()} cores (shared machine: figures are noisy); {dropped} of {n} screws '
          'dropped by stiffness_node (its input queue), none by the bridge')
    print(latency_summary('direct ~/cartesian_stiffness', d))
    print(latency_summary('through the bridge', b))
    ms = [a * 1e3 for a in added]
    print(f'{"added by the bridge":<34} n={len(ms):>6}  median {statistics.median(ms):7.3f} ms  '
          f'p99 {percentile(ms, 0.99):7.3f} ms  max {max(ms):8.3f} ms')
    print(f'target: added median <= 0.3 ms -> '
          f'{"met" if statistics.median(ms) <= 0.3 else "NOT met"}; exit codes {codes}')


if __name__ == '__main__':
    main()
