#!/usr/bin/env python3
"""Soak test of the running node, run by hand after ``source scripts/env.sh``:

    python bench/soak.py [--minutes 10] [--rate 1000] [--param NAME:=VALUE ...]

The installed ``stiffness_node`` runs as its own process with its default configuration (plus
``--param`` overrides). This process publishes screws on ``~/screw`` at ``--rate`` Hz for
``--minutes``; each ``~/stiffness`` is matched by value to its screw (outputs come in input
order; a screw whose K never comes is a drop). Prints one line per minute: inputs sent, answers,
drops, latency median / p99 / max, and the resident memory (VmRSS) of the node process at the end
of the minute; then the growth of the resident memory from the end of the first minute to the
end of the last (the acceptance bound is 5 MB).
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import statistics
import sys
import threading
import time
from collections import deque
from pathlib import Path
from typing import Any

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
    percentile,
    sleep_until,
    unique_namespace,
)

from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402

use_own_ros_domain()

MB = 2**20
#: Bound on the growth of the node's resident memory over the soak (issue: under 5 MB).
RSS_GROWTH_LIMIT_MB = 5.0


class Matcher:
    """~/stiffness callback: each message is matched to the oldest pending screw whose K it
    equals; the pending screws before it are drops. Latencies go to the minute of their send."""

    def __init__(self) -> None:
        self.pending: deque[tuple[int, float, np.ndarray]] = deque()
        self.lock = threading.Lock()
        self.latencies: dict[int, list[float]] = {}
        self.drops: dict[int, int] = {}
        self.unmatched = 0

    def expect(self, minute: int, sent: float, K: np.ndarray) -> None:
        with self.lock:
            self.pending.append((minute, sent, K))

    def __call__(self, msg: Float64MultiArray) -> None:
        now = time.perf_counter()
        K = np.frombuffer(msg.data, dtype=np.float64) if isinstance(msg.data, (bytes, bytearray)) \
            else np.asarray(msg.data)
        with self.lock:
            for j, (_minute, _sent, expected) in enumerate(self.pending):
                if j > 5000:
                    break
                scale = 1.0 + float(np.max(np.abs(expected)))
                if float(np.max(np.abs(K - expected))) <= 1e-9 * scale:
                    for _ in range(j):
                        minute, _, _ = self.pending.popleft()
                        self.drops[minute] = self.drops.get(minute, 0) + 1
                    minute, sent, _ = self.pending.popleft()
                    self.latencies.setdefault(minute, []).append(now - sent)
                    return
            self.unmatched += 1

    def flush(self) -> None:
        """Count everything still pending as dropped."""
        with self.lock:
            while self.pending:
                minute, _, _ = self.pending.popleft()
                self.drops[minute] = self.drops.get(minute, 0) + 1




def _arguments() -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--minutes', type=float, default=10.0)
    parser.add_argument('--rate', type=float, default=1000.0, help='screw rate, Hz')
    parser.add_argument('--param', action='append', default=[],
                        help='node parameter override NAME:=VALUE (repeatable)')
    parser.add_argument('--seed', type=int, default=0)
    parser.add_argument('--json', type=Path, help='also write the figures to this file')
    return parser.parse_args()


def _warm_up(ros: RosClient, pub: Any, base: str, screw: np.ndarray, matcher: Matcher) -> None:
    """Publish ``screw`` until answers come back (the node's writer may match this reader
    later), then forget the warm-up answers. Its own subscription, destroyed afterwards: kept
    for the whole run, it would hold every answer (an Inbox keeps them all), and the client's
    full garbage collections would grow with them (a once-a-minute stall of 0.2% of the
    elapsed time, seen)."""
    answered = threading.Event()
    warm = ros.subscribe_callback(Float64MultiArray, f'{base}/stiffness',
                                  lambda _msg: answered.set())
    deadline = time.monotonic() + 30.0
    while not answered.is_set() and time.monotonic() < deadline:
        pub.publish(Float64MultiArray(data=screw.tolist()))
        time.sleep(0.01)
    ros.node.destroy_subscription(warm)
    time.sleep(1.0)
    with matcher.lock:
        matcher.unmatched = 0  # the warm-up answers


def _summary(rows: list[dict[str, float]], matcher: Matcher, alive: bool, code: int | None,
             json_path: Path | None) -> bool:
    """Print (and with ``json_path`` write) the totals and the memory growth; whether the soak
    passed (node alive, exit 0, growth under the limit, no wrong answer)."""
    growth = rows[-1]['rss MB'] - rows[0]['rss MB'] if rows else float('nan')
    total_drops = sum(r['drops'] for r in rows) + sum(
        v for m, v in matcher.drops.items() if m >= len(rows))
    print(f'\nsent {sum(r["sent"] for r in rows)}, answers {sum(r["answers"] for r in rows)}, '
          f'drops {total_drops}, unmatched (wrong) {matcher.unmatched}, node alive {alive}, '
          f'exit code {code}')
    print(f'node RSS: minute 1 {rows[0]["rss MB"]:.2f} MB -> minute {len(rows)} '
          f'{rows[-1]["rss MB"]:.2f} MB: growth {growth:+.2f} MB (limit {RSS_GROWTH_LIMIT_MB} MB)')
    if json_path:
        json_path.write_text(json.dumps({'rows': rows, 'growth MB': growth,
                                         'unmatched': matcher.unmatched, 'exit code': code},
                                        indent=1))
    ok = alive and code == 0 and growth < RSS_GROWTH_LIMIT_MB and matcher.unmatched == 0
    print('RESULT:', 'PASS' if ok else 'FAIL')
    return ok


def main() -> int:
    sys.setswitchinterval(2e-4)  # the client publishes while its executor thread receives
    args = _arguments()

    model = JointModel.from_yaml(ROOT / 'config' / 'default_joint.yaml')
    rng = np.random.default_rng(args.seed)
    ns = unique_namespace('soak')
    base = f'{ns}/stiffness_node'
    proc = NodeProcess(ns, extra_args=[a for p in args.param for a in ('-p', p)])
    ros = RosClient('soak')
    matcher = Matcher()
    ros.subscribe_callback(Float64MultiArray, f'{base}/stiffness', matcher, DEEP)
    pub = ros.publisher(Float64MultiArray, f'{base}/screw', DEEP)
    rows: list[dict[str, float]] = []
    code = None
    try:
        ros.wait_for_subscribers(pub)
        ros.wait_for_publishers(f'{base}/stiffness')
        _warm_up(ros, pub, base, model.initial_screw, matcher)
        minutes = max(1, round(args.minutes))
        per_minute = int(args.rate * 60 * args.minutes / minutes)
        print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}, node pid {proc.pid}, '
              f'{args.rate:.0f} Hz for {args.minutes:g} min, params {args.param or "default"}',
              flush=True)
        print(f'{"minute":>6} {"sent":>7} {"answers":>7} {"drops":>6} {"median ms":>9} '
              f'{"p99 ms":>8} {"max ms":>8} {"RSS MB":>8}', flush=True)
        rss_at_end: list[float] = []

        def emit(m: int) -> None:
            """The row of minute m (statistics taken between minutes, RSS at its end)."""
            with matcher.lock:
                lat = matcher.latencies.pop(m, [])
                drops = matcher.drops.get(m, 0)
            ms = [1e3 * v for v in lat]
            row = {'minute': m + 1, 'sent': per_minute, 'answers': len(ms), 'drops': drops,
                   'median ms': statistics.median(ms) if ms else float('nan'),
                   'p99 ms': percentile(ms, 0.99), 'max ms': max(ms) if ms else float('nan'),
                   'rss MB': rss_at_end[m]}
            rows.append(row)
            print(f'{row["minute"]:>6} {row["sent"]:>7} {row["answers"]:>7} {row["drops"]:>6} '
                  f'{row["median ms"]:>9.3f} {row["p99 ms"]:>8.3f} {row["max ms"]:>8.3f} '
                  f'{row["rss MB"]:>8.2f}', flush=True)

        # Everything is computed before the stream starts: the client must not pause in it.
        screws = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3,
                                                  size=(minutes * per_minute, 6))
        expected = model.stiffness(screws).reshape(-1, 36)
        gc.collect()
        gc.freeze()
        period = 1.0 / args.rate
        start = time.perf_counter()
        k = 0
        for minute in range(minutes):
            for _ in range(per_minute):
                target = start + k * period
                now = sleep_until(target)
                if now - target > 2e-3:  # the client was held up: go on at the rate, no burst
                    start += now - target
                matcher.expect(minute, time.perf_counter(), expected[k])
                pub.publish(Float64MultiArray(data=screws[k].tolist()))
                k += 1
            rss_at_end.append(proc.rss_bytes() / MB)
            if minute > 0:  # the previous minute's answers are all in by now
                emit(minute - 1)
            if not proc.alive():
                print('the node died')
                break
        time.sleep(0.5)
        emit(len(rss_at_end) - 1)
        matcher.flush()
    finally:
        ros.close()
        alive = proc.alive()
        code = proc.stop()
    return 0 if _summary(rows, matcher, alive, code, args.json) else 1


if __name__ == '__main__':
    sys.exit(main())
