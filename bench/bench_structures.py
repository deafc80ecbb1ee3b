#!/usr/bin/env python3
"""Structures benchmark, run by hand: ``python3 bench/bench_structures.py [--quick]``.

Prints, measured side by side in one run (timed in alternation, best of each, so that load on
a shared machine falls on all alike):

* the joint's compiled kernel (``JointModel.evaluate`` of the default joint, one screw: the
  4 us figure of docs/performance.md) next to the structure kernel
  (``tsk_structure_evaluate``) of the 6-bar (6 bodies, 24 strings: wrenches and the 36x36
  stiffness), of the default joint as a structure (2 bodies, 12 strings) and of the 3-prism;
  the structure's ``evaluate_transforms`` (kernel and the state: node positions, bar forces)
  and its numpy reference;
* equilibria: the joint's ``solve_equilibrium`` under a load and the same joint through
  ``solve_structure_equilibrium``; the free 6-bar from a perturbed start; the 6-bar dropped on
  a ground with friction on a face, and set down in any orientation (tipped onto a face first)
  (median and p90 over seeded starts).

Targets (issue 38): the 6-bar's wrench + stiffness <= 20 us in the kernel; its equilibrium on
the ground <= 20 ms; the joint kernel's 4 us unchanged.
"""

from __future__ import annotations

import argparse
import copy
import math
import os
import statistics
import sys
import time
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tensegrity_stiffness import config  # noqa: E402
from tensegrity_stiffness.geometry.screw import exp_so3  # noqa: E402
from tensegrity_stiffness.mechanics import kernel  # noqa: E402
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.structures import kernel as structure_kernel  # noqa: E402
from tensegrity_stiffness.structures.equilibrium import (  # noqa: E402
    solve_structure_equilibrium,
)
from tensegrity_stiffness.structures.structure import Structure, twist_exp  # noqa: E402

EXAMPLES = ROOT / 'test' / 'structures'


def side_by_side(fns: dict, repeat: int, number: int) -> dict:
    """Best per-call time (us) of each of ``fns``, timed in alternation."""
    best = dict.fromkeys(fns, math.inf)
    for _ in range(repeat):
        for name, fn in fns.items():
            best[name] = min(best[name], timeit.timeit(fn, number=number) / number * 1e6)
    return best


def on_the_ground(six: Structure) -> tuple[Structure, np.ndarray]:
    """The 6-bar with a triangular face on a ground with friction 0.8, under gravity."""
    document = copy.deepcopy(six.to_dict())
    document['structure']['gravity'] = [0.0, 0.0, -9.81]
    document['structure']['ground'] = {'normal': [0, 0, 1], 'height': 0.0, 'friction': 0.8}
    structure = Structure.from_dict(document)
    u, v = np.ones(3) / math.sqrt(3.0), np.array([0.0, 0.0, -1.0])
    axis = np.cross(u, v)
    G = np.eye(4)
    G[:3, :3] = exp_so3(axis / np.linalg.norm(axis) * math.acos(u @ v))
    G[:3, 3] = [0.0, 0.0, 1.0]
    return structure, np.array([G @ P for P in structure.start_poses()])


def solve_times(solve, starts) -> tuple[float, float]:
    """Median and p90 (ms) of ``solve(start)`` over ``starts`` (two rounds, best of each)."""
    times = []
    for start in starts:
        best = math.inf
        for _ in range(2):
            t = time.perf_counter()
            result = solve(start)
            best = min(best, time.perf_counter() - t)
        assert result.success, result.message
        times.append(best * 1e3)
    times.sort()
    return statistics.median(times), times[int(0.9 * (len(times) - 1))]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--quick', action='store_true', help='fewer repeats')
    args = parser.parse_args()
    repeat, number, starts = (3, 300, 5) if args.quick else (7, 2000, 20)
    print(f'kernel: {kernel.status()}')
    print(f'structure kernel: {structure_kernel.status()}')
    print(f'load: {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} cores')

    joint = JointModel.from_yaml(config.packaged_config_path())
    xi = joint.initial_screw
    six = Structure.from_yaml(EXAMPLES / 'sixbar_structure.yaml')
    six_numpy = Structure.from_yaml(EXAMPLES / 'sixbar_structure.yaml', use_kernel=False)
    prism = Structure.from_yaml(EXAMPLES / 'prism3_structure.yaml')
    as_structure = Structure.from_joint(joint)
    T6, Tp, Tj = six.start_poses(), prism.start_poses(), as_structure.start_poses()
    r6, rp, rj = six.rest_lengths, prism.rest_lengths, as_structure.rest_lengths
    k6, kp, kj = (s.compiled_kernel for s in (six, prism, as_structure))
    if k6 is None:
        print('no structure kernel: build it (bash scripts/setup_env.sh)')
        return
    times = side_by_side({
        'joint kernel, JointModel.evaluate (12 strings)': lambda: joint.evaluate(xi),
        'structure kernel, the joint (2 bodies, 12 strings)': lambda: kj.run(Tj, rj, False),
        'structure kernel, 3-prism (3 bodies, 9 strings)': lambda: kp.run(Tp, rp, False),
        'structure kernel, 6-bar (6 bodies, 24 strings)': lambda: k6.run(T6, r6, False),
        '6-bar evaluate_transforms (kernel + state)': lambda: six.evaluate_transforms(T6, r6),
        '6-bar evaluate_numpy (reference)': lambda: six_numpy.evaluate_numpy(T6, r6),
    }, repeat, number)
    print('\nper call (us, best of alternating repeats):')
    base = times['joint kernel, JointModel.evaluate (12 strings)']
    for name, us in times.items():
        print(f'  {name:55s} {us:9.2f}  ({us / base:6.2f} x the joint kernel)')

    rng = np.random.default_rng(0)
    loads = [rng.normal(scale=[0.2, 0.2, 0.2, 0.002, 0.002, 0.002]) for _ in range(starts)]
    print('\nequilibria (ms, median / p90 over seeded cases):')
    med, p90 = solve_times(lambda W: solve_equilibrium(joint, W), loads)
    print(f'  {"joint, solve_equilibrium under a load":55s} {med:7.2f} / {p90:7.2f}')
    med, p90 = solve_times(lambda W: solve_structure_equilibrium(
        as_structure, loads={'link2': W}), loads)
    print(f'  {"the joint through solve_structure_equilibrium":55s} {med:7.2f} / {p90:7.2f}')
    free_starts = [np.array([twist_exp(rng.normal(scale=0.02, size=6)) @ P for P in T6])
                   for _ in range(starts)]
    med, p90 = solve_times(lambda S: solve_structure_equilibrium(six, start=S), free_starts)
    print(f'  {"6-bar, free, perturbed start":55s} {med:7.2f} / {p90:7.2f}')
    ground, face_down = on_the_ground(six)
    ground_starts = []
    for _ in range(starts):
        turn = twist_exp(np.r_[rng.uniform(-0.5, 0.5, 2), 0.0, 0.0, 0.0,
                               rng.uniform(-math.pi, math.pi)])
        ground_starts.append(np.array([turn @ P for P in face_down]))
    med, p90 = solve_times(lambda S: solve_structure_equilibrium(ground, start=S),
                           ground_starts)
    print(f'  {"6-bar dropped on the ground, friction 0.8":55s} {med:7.2f} / {p90:7.2f}')
    any_starts = []
    for _ in range(starts):
        turn = twist_exp(np.r_[0.0, 0.0, 0.0, rng.uniform(-math.pi, math.pi, 3)])
        any_starts.append(np.array([turn @ P for P in ground.start_poses()]))
    med, p90 = solve_times(lambda S: solve_structure_equilibrium(ground, start=S), any_starts)
    print(f'  {"6-bar set down in any orientation (tipped onto a face)":55s} '
          f'{med:7.2f} / {p90:7.2f}')


if __name__ == '__main__':
    main()
