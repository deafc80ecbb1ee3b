#!/usr/bin/env python3
"""Node latency benchmark (two processes), run by hand after ``source scripts/env.sh``:

    python bench/bench_latency.py [--rates 1000 2000] [--seconds 10] [--paths fast executor]
                                  [--client-loops lane executor]
                                  [--clients stiffness all] [--calls 300]

For each input path (``fast``: ``realtime.fast_lane: true``, the screws on the node's fast lane;
``executor``: the previous path, rclpy's executor with draining callbacks), each rate and each
client, a fresh installed ``stiffness_node`` runs as its own process on the default joint (markers
at 30 Hz and diagnostics at 1 Hz, the defaults). This process publishes screws on ``~/screw`` for
``--seconds`` and measures, per screw, the time until its ``~/stiffness`` message arrives (outputs
come in input order over reliable QoS, so each is matched to its screw by value against the
library). Client ``stiffness`` subscribes to ``~/stiffness`` alone (a controller); ``all`` also to
the other four outputs. The client receives on a lean wait-set loop (``lane``, the node's own
:class:`FastLane`, as a compiled controller's loop would) or on its rclpy executor
(``executor``, whose per-message cost then shares the 2 cores with the node). Then the round
trip of each service on the first path, and the equilibrium service against its floor (an rclpy
round trip plus the library's solve, both measured in the run). Prints median / p99 / max
latency and drops, side by side.
Targets (issue 12): at 1 kHz median <= 0.8 ms, p99 <= 3 ms, 0 drops; at 2 kHz 0 drops, median
<= 1.5 ms.
"""

from __future__ import annotations

import argparse
import gc
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402
from geometry_msgs.msg import WrenchStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support import use_own_ros_domain  # noqa: E402
from support.ros_harness import (  # noqa: E402
    NodeProcess,
    RosClient,
    add_client_arguments,
    latency_summary,
    pacing_spin_s,
    stream_latencies,
    unique_namespace,
)
from tensegrity_stiffness.srv import (  # noqa: E402
    PlanarForwardKinematics,
    PlanarInverseKinematics,
    SolveEquilibrium,
)

from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402

use_own_ros_domain()







#: The node's outputs besides ~/stiffness (the ``all`` client takes them too).
OTHER_OUTPUTS = {'wrench': WrenchStamped, 'cartesian_stiffness': Float64MultiArray,
                 'string_tensions': Float64MultiArray,
                 'stiffness_interpretation': Float64MultiArray}


def stream(ros: RosClient, base: str, model: JointModel, rate: float, seconds: float,
           rng: np.random.Generator, all_outputs: bool = False, loop: str = 'executor',
           spin_s: float = 0.0) -> tuple[list[float], int, int]:
    """Publish screws at ``rate`` for ``seconds``; returns (latencies, sent, drops). The client
    receives on its rclpy executor (``loop='executor'``) or on a lean wait-set loop of its own
    (``'lane'``: the node's :class:`FastLane`, as a compiled controller's loop would)."""
    n = int(rate * seconds)
    screws = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3, size=(n, 6))
    # One screw at a time, as the node computes (the batched path rounds differently).
    expected = np.array([model.stiffness(x).ravel() for x in screws])
    others = [(t, f'{base}/{topic}') for topic, t in OTHER_OUTPUTS.items()] if all_outputs \
        else []
    return stream_latencies(ros, ros.publisher(Float64MultiArray, f'{base}/screw'),
                            (Float64MultiArray, f'{base}/stiffness'),
                            [Float64MultiArray(data=x.tolist()) for x in screws], expected,
                            rate, loop, spin_s, others=others)


def service_round_trips(ros: RosClient, base: str, calls: int, rng: np.random.Generator
                        ) -> dict[str, list[float]]:
    clients = {
        'solve_equilibrium': ros.client(SolveEquilibrium, f'{base}/solve_equilibrium'),
        'planar_forward_kinematics': ros.client(PlanarForwardKinematics,
                                                f'{base}/planar_forward_kinematics'),
        'planar_inverse_kinematics': ros.client(PlanarInverseKinematics,
                                                f'{base}/planar_inverse_kinematics'),
    }
    out: dict[str, list[float]] = {name: [] for name in clients}
    failures = 0
    for _ in range(calls):
        W = np.r_[rng.normal(scale=0.1, size=3), rng.normal(scale=0.002, size=3)]
        requests = {
            'solve_equilibrium': SolveEquilibrium.Request(
                external_wrench=conversions.wrench_to_msg(W)),
            'planar_forward_kinematics': PlanarForwardKinematics.Request(
                actuator_length=rng.uniform(0.2, 1.8), actuator_angle=rng.uniform(0.2, 2.9)),
            'planar_inverse_kinematics': PlanarInverseKinematics.Request(
                x=rng.uniform(-1.0, 1.0), y=rng.uniform(0.2, 1.5)),
        }
        for name, client in clients.items():
            start = time.perf_counter()
            res = ros.call(client, requests[name])
            out[name].append(time.perf_counter() - start)
            failures += name == 'solve_equilibrium' and not res.success
    print(f'  (equilibrium solves that failed: {failures})')
    return out


def equilibrium_floor(model: JointModel, times: dict[str, list[float]], calls: int,
                      rng: np.random.Generator) -> str:
    """The equilibrium service's floor, measured in this run: an rclpy service round trip (the
    planar forward service, whose computation is 20 us) plus the library's solve of the same
    kind of request from the last solution; and the service's median against it."""
    solves, start = [], model.initial_screw
    for _ in range(calls):
        W = np.r_[rng.normal(scale=0.1, size=3), rng.normal(scale=0.002, size=3)]
        t0 = time.perf_counter()
        result = solve_equilibrium(model, W, initial_screw=start)
        solves.append(time.perf_counter() - t0)
        start = result.screw if result.success else start
    trip = float(np.median(times['planar_forward_kinematics']))
    solve = float(np.median(solves))
    service = float(np.median(times['solve_equilibrium']))
    return (f'  equilibrium floor: round trip {trip * 1e3:.3f} ms + solve {solve * 1e3:.3f} ms '
            f'= {(trip + solve) * 1e3:.3f} ms; service median {service * 1e3:.3f} ms '
            f'= {service / (trip + solve):.2f}x the floor')


PATHS = {'fast': 'true', 'executor': 'false'}


def run(path: str, rate: float, client: str, loop: str, args: argparse.Namespace,
        model: JointModel, services: bool) -> None:
    rng = np.random.default_rng(0)
    ns = unique_namespace('bench')
    extra = ['-p', f'realtime.fast_lane:={PATHS[path]}']
    proc = NodeProcess(ns, extra_args=extra + [a for p in args.param for a in ('-p', p)])
    ros = RosClient('bench')
    base = f'{ns}/stiffness_node'
    try:
        latencies, sent, drops = stream(ros, base, model, rate, args.seconds, rng,
                                        all_outputs=client == 'all', loop=loop,
                                        spin_s=pacing_spin_s(args))
        print(latency_summary(f'{path:<8} {rate:5.0f} Hz  client {client:<9} {loop:<8}',
                              latencies)
              + f'  drops {drops} of {sent}', flush=True)
        if services:
            trips = service_round_trips(ros, base, args.calls, rng)
            for name, times in trips.items():
                print(latency_summary(f'  {name}', times), flush=True)
            print(equilibrium_floor(model, trips, args.calls, rng), flush=True)
    finally:
        ros.close()
        code = proc.stop()
        if code != 0:
            print(f'node exited with {code}:\n{proc.log()}')


def main() -> None:
    # The client publishes from the main thread while its executor thread receives: let the GIL
    # change hands often, as the node does, so the client's own waits stay small.
    sys.setswitchinterval(2e-4)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--rates', type=float, nargs='+', default=[1000.0, 2000.0],
                        help='screw rates, Hz')
    parser.add_argument('--seconds', type=float, default=10.0, help='stream duration, s')
    parser.add_argument('--paths', nargs='+', choices=sorted(PATHS), default=['fast', 'executor'])
    parser.add_argument('--clients', nargs='+', choices=['stiffness', 'all'],
                        default=['stiffness'])
    add_client_arguments(parser)
    parser.add_argument('--calls', type=int, default=300, help='calls per service (0: none)')
    parser.add_argument('--param', action='append', default=[],
                        help='node parameter override NAME:=VALUE (repeatable)')
    args = parser.parse_args()
    model = JointModel.from_yaml(ROOT / 'config' / 'default_joint.yaml')
    gc.collect()
    gc.freeze()
    print(f'ROS_DOMAIN_ID={os.environ["ROS_DOMAIN_ID"]}; screw -> ~/stiffness latency')
    first = True
    for client in args.clients:
        for rate in args.rates:
            for loop in args.client_loops:
                for path in args.paths:
                    run(path, rate, client, loop, args, model,
                        services=first and args.calls > 0)
                    first = False


if __name__ == '__main__':
    main()
