#!/usr/bin/env python3
"""Full fuzz of the running node, run by hand after ``source scripts/env.sh``:

    python bench/fuzz_node.py [--messages 100000] [--requests 10000] [--rounds 10] [--seed 1]

The installed ``stiffness_node`` runs as its own process (real middleware). In each round this
process sends ``messages / rounds`` topic inputs (``fuzz_inputs.InputFuzzer.topic_cases``:
hostile inputs on ``~/screw``, ``~/pose`` and ``~/rest_lengths``, each followed by a valid
screw), then ``requests / rounds`` service requests (planar forward / inverse kinematics on and
beside every singular curve and workspace boundary, equilibrium requests easy, hard and
invalid) while hostile and valid screws keep streaming. Every output is matched by value to
the library's answer (``ros_harness.NodeFuzzer``). Prints, per round and in total: messages and
requests sent, crashes, publications for invalid input, missing answers, wrong service answers,
the node's resident memory, and the node's own counts from ``/diagnostics``.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from support import fuzz_inputs as fi  # noqa: E402
from support import use_own_ros_domain  # noqa: E402
from support.ros_harness import NodeFuzzer, NodeProcess, RosClient, unique_namespace  # noqa: E402

from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402

use_own_ros_domain()

MB = 2**20


def main() -> int:
    sys.setswitchinterval(2e-4)  # the client publishes while its executor thread receives
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--messages', type=int, default=100_000, help='topic inputs (at least)')
    parser.add_argument('--requests', type=int, default=10_000, help='service requests')
    parser.add_argument('--rounds', type=int, default=10)
    parser.add_argument('--seed', type=int, default=1)
    parser.add_argument('--rate', type=float, default=1000.0, help='topic inputs per second')
    parser.add_argument('--oversized-every', type=int, default=2000,
                        help='one in this many array-bearing hostile inputs has 10**6 values')
    parser.add_argument('--hard-share', type=float, default=0.1,
                        help='share of equilibrium requests that use up the time budget')
    parser.add_argument('--json', type=Path, help='also write the figures to this file')
    args = parser.parse_args()

    model = JointModel.from_yaml(fi.CONFIG)
    planar = fi.planar_from_config()
    inputs = fi.InputFuzzer(model, planar, seed=args.seed,
                            oversized_every=args.oversized_every)
    ns = unique_namespace('fuzz')
    base = f'{ns}/stiffness_node'
    proc = NodeProcess(ns, fi.CONFIG, extra_args=['-p', 'qos.depth:=1000'])
    ros = RosClient('fuzz')
    diagnostics: dict[str, str] = {}

    def on_diagnostics(msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith('stiffness_node: joint'):
                diagnostics.update({kv.key: kv.value for kv in status.values})

    ros.node.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}, node pid {proc.pid}, seed {args.seed}, '
          f'log {proc.log_path}', flush=True)
    figures: dict[str, object] = {}
    code = None
    try:
        fuzzer = NodeFuzzer(ros, proc, base, fi.TopicOracle(model), planar, rate=args.rate,
                            timeout=30.0)
        fuzzer.run_topics(inputs.valid_screw_case() for _ in range(500))  # warm up
        time.sleep(1.0)
        rss_before = proc.rss_bytes()
        start = time.monotonic()
        screws = inputs.screw_cases(10**12)
        per_round_messages = args.messages // args.rounds
        per_round_requests = args.requests // args.rounds
        print(f'{"round":>5} {"messages":>9} {"requests":>9} {"wrong pub":>9} {"missing":>8} '
              f'{"wrong ans":>9} {"RSS MB":>7} {"s":>6}', flush=True)
        for r in range(1, args.rounds + 1):
            fuzzer.run_topics(inputs.topic_cases(per_round_messages))
            fuzzer.run_services(inputs.service_cases(per_round_requests,
                                                     hard_share=args.hard_share), screws)
            sent = sum(fuzzer.sent.values()) - 500
            print(f'{r:>5} {sent:>9} {sum(fuzzer.requests.values()):>9} '
                  f'{max(fuzzer.stiffness.wrong, fuzzer.wrench.wrong):>9} '
                  f'{max(fuzzer.stiffness.missing, fuzzer.wrench.missing):>8} '
                  f'{fuzzer.wrong_answers:>9} {proc.rss_bytes() / MB:>7.1f} '
                  f'{time.monotonic() - start:>6.0f}', flush=True)
            if not proc.alive():
                break
        figures = fuzzer.finish(quiet=2.0)
        figures['messages'] = int(figures['messages']) - 500  # without the warm-up
        figures['valid messages'] = int(figures['valid messages']) - 500
        figures['seconds'] = round(time.monotonic() - start, 1)
        figures['rss before [MB]'] = round(rss_before / MB, 1)
        figures['rss after [MB]'] = round(proc.rss_bytes() / MB, 1) if proc.alive() else None
        kinds = Counter(fuzzer.kinds)
        figures['inputs per kind'] = dict(sorted(kinds.items()))
        time.sleep(1.5)  # one more /diagnostics
        figures["node's rejected counts (/diagnostics)"] = diagnostics.get('rejected inputs')
        figures["node's outputs published (/diagnostics)"] = diagnostics.get('outputs published')
    finally:
        ros.close()
        alive = proc.alive()
        code = proc.stop(timeout=20.0)
        log = proc.log()
        figures['crashes'] = int(not alive) + int(code != 0)
        figures['node exit code'] = code
        figures['tracebacks in the node log'] = log.count('Traceback')
        figures['internal errors in the node log'] = log.count('internal error')
    print('\nfigures:')
    for key, value in figures.items():
        if key != 'inputs per kind':
            print(f'  {key}: {value}')
    print('  inputs per kind:')
    for key, value in figures.get('inputs per kind', {}).items():
        print(f'    {key}: {value}')
    if args.json:
        args.json.write_text(json.dumps(figures, indent=1, default=str))
    ok = (figures['crashes'] == 0 and figures.get('wrong publications') == 0
          and figures.get('missing answers') == 0 and figures.get('wrong answers') == 0
          and figures.get('generator errors') == [])
    print('\nRESULT:', 'PASS' if ok else 'FAIL')
    return 0 if ok else 1


if __name__ == '__main__':
    sys.exit(main())
