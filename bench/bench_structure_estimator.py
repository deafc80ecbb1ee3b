#!/usr/bin/env python3
"""Structure estimator benchmark, run by hand: ``python3 bench/bench_structure_estimator.py
[--quick]``.

Prints, measured side by side in one run (timed in alternation, best of each, so that load on
a shared machine falls on all alike), for the 3-bar (9 lengths, 3 IMUs with gyros, 3 contacts:
the Rutgers/Yale set) and the 6-bar (24 lengths, 6 IMUs with gyros, 3 contacts) at their
equilibria on the ground:

* ``StructureFilter.update`` (one EKF update with every reading, plus ``predict``);
* ``estimate_structure_poses`` (the static form, from a start 1 cm / 0.01 rad off, plane motion
  held), and with the statics at rest.

Targets (issue 41): the estimator's update 3-bar <= 200 us, 6-bar <= 500 us.
"""

from __future__ import annotations

import argparse
import os
import sys
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tensegrity_stiffness.estimation.structure_estimator import (  # noqa: E402
    StructureFilter,
    StructureMeasurements,
    apply_increment,
    estimate_structure_poses,
)
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium  # noqa: E402
from tensegrity_stiffness.structures.structure import Structure  # noqa: E402
from tensegrity_stiffness.structures.templates import six_bar_document  # noqa: E402


def case(name: str) -> tuple[Structure, np.ndarray, StructureMeasurements, dict]:
    s = (Structure.from_yaml(ROOT / 'config' / 'examples' / 'three_bar.yaml') if name == '3-bar'
         else Structure.from_dict(six_bar_document(ground=True)))
    eq = solve_structure_equilibrium(s)
    T = eq.poses
    g = s.gravity / np.linalg.norm(s.gravity)
    m = StructureMeasurements(lengths=dict(zip(s.string_names, s.evaluate(T).lengths,
                                               strict=True)),
                              imu_gravity={b: T[i, :3, :3].T @ g
                                           for i, b in enumerate(s.body_names)},
                              contacts=list(eq.contacts))
    gyros = {b: np.zeros(3) for b in s.body_names}
    return s, T, m, gyros


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--quick', action='store_true')
    args = parser.parse_args()
    repeats, number = (3, 20) if args.quick else (7, 100)
    rng = np.random.default_rng(0)
    timers = {}
    for name in ('3-bar', '6-bar'):
        s, T, m, gyros = case(name)
        flt = StructureFilter(s, T)

        def update(flt=flt, m=m, gyros=gyros) -> None:
            flt.predict(0.01)
            flt.update(m, gyros)

        start = apply_increment(T, 0.01 * rng.standard_normal(6 * s.n_bodies))
        rest = StructureMeasurements(**{**m.__dict__, 'at_rest': True})
        timers[f'{name} filter update'] = (update, number)
        timers[f'{name} static estimate'] = (
            lambda s=s, m=m, start=start: estimate_structure_poses(s, m, start=start,
                                                                   hold_rigid_motion=True),
            max(number // 20, 1))
        timers[f'{name} static at rest'] = (
            lambda s=s, rest=rest, start=start: estimate_structure_poses(
                s, rest, start=start, hold_rigid_motion=True), max(number // 20, 1))
    best = {k: float('inf') for k in timers}
    for _ in range(repeats):
        for key, (fn, n) in timers.items():
            best[key] = min(best[key], timeit.timeit(fn, number=n) / n)
    print(f'load average: {os.getloadavg()[0]:.1f} (2 shared cores)')
    for key, value in best.items():
        print(f'{key:28s} {value * 1e6:10.0f} us')
    ratio = best['6-bar filter update'] / best['3-bar filter update']
    print(f'6-bar / 3-bar filter update: {ratio:.2f}')


if __name__ == '__main__':
    main()
