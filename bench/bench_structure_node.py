#!/usr/bin/env python3
"""structure_node latency benchmark (two processes), run by hand after ``source scripts/env.sh``:

    python bench/bench_structure_node.py [--rate 1000] [--seconds 10] [--structures six_bar.yaml]
                                         [--calls 20] [--client-loops lane executor]
                                         [--pacing sleep|spin]

For each structure (a packaged example) the installed ``structure_node`` runs as its own process.
This process publishes the bodies' poses on ``~/pose_values`` (7N values, small seeded motions
about the equilibrium on the ground) at ``--rate`` Hz for ``--seconds``; a controller-like client
subscribes to ``~/stiffness`` (6N x 6N; ``--output body_wrenches``: the 6N wrenches) and, per
message, forms the restoring wrenches ``-K e`` of a small error. The latency of a set of poses
is the time until its output arrives (outputs come in input order over reliable QoS; each is
matched to its input by value against the library, so a drop cannot shift the pairing). Then
the round trip of ``~/solve_equilibrium`` (the equilibrium on the ground from the config's
start).
Target (issue 41, the 6-bar): median <= 1 ms at 1 kHz, 0 drops.
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
from tensegrity_stiffness.srv import SolveStructureEquilibrium  # noqa: E402

from tensegrity_stiffness.config import example_config_path  # noqa: E402
from tensegrity_stiffness.mechanics.templates import pose_vector  # noqa: E402
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium  # noqa: E402
from tensegrity_stiffness.structures.structure import Structure, twist_exp  # noqa: E402

#: A fixed small error per body: the client computes ``K e`` of it.
BODY_ERROR = np.array([1e-4, -2e-4, 1e-4, 1e-3, 0.0, -1e-3])


def stream(ros: RosClient, base: str, structure: Structure, rate: float, seconds: float,
           rng: np.random.Generator, loop: str, spin_s: float, output: str
           ) -> tuple[list[float], int, int]:
    """Publish poses at ``rate`` for ``seconds``, the client reading ``output``
    (``stiffness`` or ``body_wrenches``); returns (latencies, sent, drops)."""
    n_bodies = structure.n_bodies
    eq = solve_structure_equilibrium(structure)
    n = int(rate * seconds)
    poses = [[pose_vector(twist_exp(d) @ P) for d, P in zip(
        rng.normal(scale=[0.002] * 3 + [0.01] * 3, size=(n_bodies, 6)), eq.poses,
        strict=True)] for _ in range(n)]
    expected = [getattr(structure.evaluate(np.array(p)), 'stiffness' if output == 'stiffness'
                        else 'wrenches').ravel() for p in poses]
    error = np.tile(BODY_ERROR, n_bodies)
    return stream_latencies(ros, ros.publisher(Float64MultiArray, f'{base}/pose_values'),
                            (Float64MultiArray, f'{base}/{output}'),
                            [Float64MultiArray(data=np.ravel(p).tolist()) for p in poses],
                            expected, rate, loop, spin_s,
                            work=lambda K: K[:6 * n_bodies] * error)


def service_round_trips(ros: RosClient, base: str, structure: Structure, calls: int
                        ) -> tuple[list[float], int]:
    client = ros.client(SolveStructureEquilibrium, f'{base}/solve_equilibrium')
    start = [v for P in structure.start_poses() for v in pose_vector(P)]
    return timed_service_calls(ros, client, (SolveStructureEquilibrium.Request(start=start)
                                             for _ in range(calls)))


def run(name: str, loop: str, spin_s: float, args: argparse.Namespace,
        rng: np.random.Generator, services: bool) -> None:
    ns = unique_namespace('bench_structure')
    params = Path(os.environ.get('TMPDIR', '/tmp')) / f'bench_structure_{os.getpid()}.yaml'
    params.write_text(f'/**:\n  ros__parameters:\n    structure.config: {name}\n')
    proc = NodeProcess(ns, params, executable='structure_node')
    ros = RosClient('bench_structure')
    gc.collect()
    gc.freeze()
    base = f'{ns}/structure_node'
    structure = Structure.from_yaml(example_config_path(name))
    try:
        latencies, sent, drops = stream(ros, base, structure, args.rate, args.seconds, rng,
                                        loop, spin_s, args.output)
        print(f'{name} ({structure.n_bodies} bodies), client {loop:<8}: pose_values -> '
              f'{args.output} at {args.rate:.0f} Hz for {args.seconds:.0f} s: sent {sent}, '
              f'drops {drops}')
        print(latency_summary('  latency', latencies))
        if services:
            times, failures = service_round_trips(ros, base, structure, args.calls)
            print(latency_summary(f'  solve_equilibrium ({name})', times)
                  + f'  failed {failures}')
    finally:
        ros.close()
        code = proc.stop()
        if code != 0:
            print(f'node exited with {code}:\n{proc.log()}')


def main() -> None:
    sys.setswitchinterval(2e-4)  # as the node: the GIL changes hands often
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rate', type=float, default=1000.0, help='pose rate, Hz')
    parser.add_argument('--seconds', type=float, default=10.0, help='stream duration, s')
    parser.add_argument('--structures', nargs='+', default=['six_bar.yaml'],
                        help='packaged examples (config/examples)')
    parser.add_argument('--output', choices=['stiffness', 'body_wrenches'],
                        default='stiffness', help='the output the client reads')
    add_client_arguments(parser)
    parser.add_argument('--calls', type=int, default=20,
                        help='service calls (first structure; 0: none)')
    args = parser.parse_args()
    rng = np.random.default_rng(0)
    print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}, load average '
          f'{os.getloadavg()[0]:.2f} on {os.cpu_count()} cores')
    spin_s = pacing_spin_s(args)
    first = True
    for name in args.structures:
        for loop in args.client_loops:
            run(name, loop, spin_s, args, rng, services=first and args.calls > 0)
            first = False


if __name__ == '__main__':
    main()
