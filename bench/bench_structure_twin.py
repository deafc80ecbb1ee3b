#!/usr/bin/env python3
"""The structure twin's speed (tensegrity_stiffness.simulation.structure_twin), run by hand after
``source scripts/env.sh``:

    python bench/bench_structure_twin.py [--seconds 2] [--repeats 3]

For the 3-bar and the 6-bar of config/examples (resting on the ground at a 1 ms step) and,
side by side, the joint's twin (JointSimulation of config/default_joint.yaml): the real-time
factor of stepping alone, and of stepping plus the readings one publication takes every 10
steps (poses, lengths, tensions, encoders, every IMU, the contact nodes), as fast as possible.
Repeats alternate between the models; the median of each is printed with the load average
(timing on a shared 2-core machine is noisy: compare the ratios).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.simulation.structure_twin import StructureSimulation
from tensegrity_stiffness.simulation.twin import JointSimulation
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure


def structure_twin(name: str) -> StructureSimulation:
    structure = Structure.from_yaml(config.example_config_path(name))
    return StructureSimulation(structure,
                               poses=solve_structure_equilibrium(structure).poses)


def factor(sim, seconds: float, read: bool) -> float:
    """Simulated seconds per wall second over ``seconds`` of simulated time."""
    n = round(seconds / 1e-3)
    start = time.perf_counter()
    if not read:
        sim.step(n)
    elif isinstance(sim, StructureSimulation):
        for _ in range(n // 10):
            sim.step(10)
            sim.poses()
            sim.string_lengths()
            sim.tensions()
            sim.rest_lengths  # noqa: B018 - the encoders' read
            sim.imus()
            sim.contact_nodes()
    else:
        for _ in range(n // 10):
            sim.step(10)
            sim.pose()
            sim.string_lengths()
            sim.tensions()
            sim.imu()
    return seconds / (time.perf_counter() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description='real-time factor of the structure twin')
    parser.add_argument('--seconds', type=float, default=2.0, help='simulated s per run')
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    twins = {'joint (reference)': JointSimulation(JointModel.from_yaml(
        config.packaged_config_path())), '3-bar': structure_twin('three_bar.yaml'),
        '6-bar': structure_twin('six_bar.yaml')}
    results: dict[tuple[str, bool], list[float]] = {}
    for _ in range(args.repeats):
        for name, sim in twins.items():
            for read in (False, True):
                results.setdefault((name, read), []).append(factor(sim, args.seconds, read))
    print(f'load average {os.getloadavg()[0]:.1f} (2 shared cores); medians of '
          f'{args.repeats} alternating runs of {args.seconds:g} simulated s at 1 kHz')
    print(f'{"twin":>18}  {"step only":>10}  {"+ readings / 10 steps":>22}')
    for name in twins:
        step, read = (statistics.median(results[(name, r)]) for r in (False, True))
        print(f'{name:>18}  {step:9.1f}x  {read:21.1f}x')


if __name__ == '__main__':
    main()
