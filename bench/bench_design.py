"""Timing of the stiffness design (``tensegrity_stiffness.mechanics.design``).

Run by hand: ``python3 bench/bench_design.py [--requests N]``. Library part: median and p90 time
of ``design_rest_lengths`` over random feasible requests near the default joint's unloaded
equilibrium (moderate loads, tensions in [0.1, 1.5] N), without and with a target K_c, for both
force laws, next to the issue's target (median <= 5 ms); ``stiffness_range`` and
``rest_length_sensitivity`` for reference. Part ``service``: the round trip of the installed
node's ``~/design_rest_lengths`` (the node as its own process; needs ``source scripts/env.sh``),
for the same requests, next to the library time of each. No assertions: numbers only.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.design import (
    design_rest_lengths,
    rest_length_sensitivity,
    stiffness_range,
)
from tensegrity_stiffness.mechanics.joint import JointModel

DESIGN_TARGET_MS = 5.0
LIMITS = (0.1, 1.5)


def joint(force_law: str) -> JointModel:
    section = dict(config.load_section(config.packaged_config_path(), 'joint'))
    section['force_law'] = force_law
    return JointModel.from_dict(section)


def requests(model: JointModel, count: int, seed: int) -> list[tuple[np.ndarray, ...]]:
    """``count`` feasible (screw, wrench, target K_c) triples: the target is a rescaled K_c of
    the mid-limit design, so that it is near the reachable set but not on it."""
    rng = np.random.default_rng(seed)
    out = []
    while len(out) < count:
        xi = model.initial_screw + np.concatenate([rng.normal(0, 0.05, 3),
                                                   rng.normal(0, 0.002, 3)])
        W = np.concatenate([rng.normal(0, 0.05, 3), rng.normal(0, 0.0015, 3)])
        base = design_rest_lengths(model, xi, W, *LIMITS)
        if base.success:
            d = np.exp(rng.normal(0, 0.15, 6))
            out.append((xi, W, d[:, None] * base.cartesian_stiffness * d[None, :],
                        base.rest_lengths))
    return out


def times_ms(fn: Callable[[tuple[np.ndarray, ...]], object], cases: list) -> np.ndarray:
    """Wall time (ms) of ``fn(case)`` for every case (after one warm-up call)."""
    fn(cases[0])
    out = np.empty(len(cases))
    for i, case in enumerate(cases):
        t0 = time.perf_counter()
        fn(case)
        out[i] = (time.perf_counter() - t0) * 1e3
    return out


def line(label: str, ms: np.ndarray, target: float | None = None) -> str:
    text = (f'  {label:<44} median {np.median(ms):7.3f} ms   p90 {np.percentile(ms, 90):7.3f} ms'
            f'   max {ms.max():7.3f} ms')
    if target is not None:
        text += f'   (target <= {target:g} ms: {"met" if np.median(ms) <= target else "NOT met"})'
    return text


def library_part(args: argparse.Namespace) -> None:
    print(f'library: {args.requests} random feasible requests per force law, tensions in '
          f'[{LIMITS[0]}, {LIMITS[1]}] N')
    for law in ('hooke', 'paper'):
        model = joint(law)
        cases = requests(model, args.requests, seed=1)
        print(f' force law {law}:')
        print(line('design_rest_lengths, no target',
                   times_ms(lambda c, m=model: design_rest_lengths(m, c[0], c[1], *LIMITS),
                            cases), DESIGN_TARGET_MS))
        print(line('design_rest_lengths, target K_c',
                   times_ms(lambda c, m=model: design_rest_lengths(
                       m, c[0], c[1], *LIMITS, target_stiffness=c[2]), cases),
                   DESIGN_TARGET_MS))
        few = cases[:max(1, args.requests // 10)]
        print(line('stiffness_range (12 LPs)',
                   times_ms(lambda c, m=model: stiffness_range(m, c[0], c[1], *LIMITS), few)))
        print(line('rest_length_sensitivity',
                   times_ms(lambda c, m=model: rest_length_sensitivity(m, c[0], c[3]), cases)))
        print(line('JointModel.evaluate (for scale)',
                   times_ms(lambda c, m=model: m.evaluate(c[0], c[3]), cases)))


def service_part(args: argparse.Namespace) -> None:
    """Round trips of the node's ``~/design_rest_lengths`` (two processes, real middleware)."""
    import os
    import random

    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ.setdefault('ROS_DOMAIN_ID', str(random.randint(100, 200)))
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / 'test'))
    from support.ros_harness import NodeProcess, RosClient, unique_namespace
    from tensegrity_stiffness.srv import DesignRestLengths

    from tensegrity_stiffness.ros import conversions

    model = joint('hooke')
    cases = requests(model, args.requests, seed=2)
    ns = unique_namespace('bench_design')
    proc = NodeProcess(ns)
    ros = RosClient('bench_design')
    try:
        client = ros.client(DesignRestLengths, f'{ns}/stiffness_node/design_rest_lengths')

        def call(case: tuple[np.ndarray, ...], target: bool) -> None:
            request = DesignRestLengths.Request(
                target_screw=case[0].tolist(), external_wrench=conversions.wrench_to_msg(case[1]),
                tension_min=LIMITS[0], tension_max=LIMITS[1],
                target_cartesian_stiffness=case[2].ravel().tolist() if target else [])
            if not ros.call(client, request, timeout=30.0).success:
                raise RuntimeError('a feasible design failed in the node')

        print(f'service ~/design_rest_lengths: {len(cases)} requests (hooke), two processes')
        print(line('round trip, no target', times_ms(lambda c: call(c, False), cases)))
        print(line('round trip, target K_c', times_ms(lambda c: call(c, True), cases)))
        print(line('library alone, target K_c', times_ms(lambda c: design_rest_lengths(
            model, c[0], c[1], *LIMITS, target_stiffness=c[2]), cases)))
    finally:
        ros.close()
        proc.stop()


#: The bench's parts, run in this order.
PARTS: dict[str, Callable[[argparse.Namespace], None]] = {'library': library_part,
                                                           'service': service_part}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--requests', type=int, default=300, help='requests per force law')
    parser.add_argument('--parts', nargs='+', choices=list(PARTS), default=list(PARTS),
                        help='parts to run (default: all)')
    args = parser.parse_args()
    for name in args.parts:
        PARTS[name](args)


if __name__ == '__main__':
    main()
