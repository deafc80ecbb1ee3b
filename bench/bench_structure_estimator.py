#!/usr/bin/env python3
"""Structure estimator benchmark, run by hand: ``python3 bench/bench_structure_estimator.py
[--quick] [--previous DIR]``.

Prints, measured side by side in one run (timed in alternation, best of each, so that load on
a shared machine falls on all alike), for the 3-bar (the Rutgers/Yale set: 9 lengths, the
encoders, 3 IMUs' accelerometers and gyros, 3 contacts) and the 6-bar (24 lengths, 6 IMUs, 3
contacts) at their equilibria on the ground:

* ``StructureFilter.predict`` + ``update`` (one EKF step with every reading; the accelerometers
  by the dynamics, three bars on a contact node each: the pivot's model);
* the same on the readings of a previous filter (the accelerometers as gravity directions,
  ``imu_gravity``) and, with ``--previous DIR`` (an earlier checkout: ``git archive <commit> |
  tar -x -C DIR``), that checkout's ``StructureFilter`` on them, and the ratio;
* ``estimate_structure_poses`` (the static form, from a start 1 cm / 0.01 rad off, plane motion
  held), and with the statics at rest.

Targets (issue 41): the estimator's update 3-bar <= 200 us, 6-bar <= 500 us.
"""

from __future__ import annotations

import argparse
import inspect
import os
import sys
import tempfile
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'bench'))

from previous_checkout import build_kernel, import_modules  # noqa: E402

from tensegrity_stiffness.estimation.structure_estimator import (  # noqa: E402
    StructureFilter,
    StructureMeasurements,
    apply_increment,
    estimate_structure_poses,
)
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium  # noqa: E402
from tensegrity_stiffness.structures.structure import Structure  # noqa: E402
from tensegrity_stiffness.structures.templates import six_bar_document  # noqa: E402

TARGETS_US = {'3-bar': 200.0, '6-bar': 500.0}


def case(name: str) -> tuple[Structure, np.ndarray, StructureMeasurements, dict, dict]:
    """The structure at its equilibrium on the ground, its readings there, gyros and
    accelerometers (the specific force at rest, ``-R^T g``)."""
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
    accelerometers = {b: -T[i, :3, :3].T @ s.gravity for i, b in enumerate(s.body_names)}
    return s, T, m, gyros, accelerometers


def filter_step(filter_class: type, s: Structure, T: np.ndarray, m: StructureMeasurements,
                gyros: dict, accelerometers: dict | None):
    """A closure of one predict + update of a filter of ``filter_class`` (without
    ``accelerometers`` or a previous filter: their gravity directions in ``m``)."""
    flt = filter_class(s, T)
    takes = (accelerometers is not None
             and 'accelerometers' in inspect.signature(flt.update).parameters)
    extra = {'accelerometers': accelerometers} if takes else {}

    def step() -> None:
        flt.predict(0.01)
        flt.update(m, gyros, **extra)
    return step


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--quick', action='store_true')
    parser.add_argument('--previous', type=Path, metavar='DIR',
                        help='an earlier checkout whose StructureFilter is timed alongside')
    args = parser.parse_args()
    repeats, number = (3, 20) if args.quick else (7, 100)
    previous = None
    if args.previous is not None:
        root = args.previous.resolve()
        library = build_kernel(root, Path(tempfile.mkdtemp()))
        names = ['tensegrity_stiffness.estimation.structure_estimator',
                 'tensegrity_stiffness.structures.structure']
        previous = import_modules(root, names, library)
    rng = np.random.default_rng(0)
    timers = {}
    for name in ('3-bar', '6-bar'):
        s, T, m, gyros, acc = case(name)
        timers[f'{name} filter update'] = (filter_step(StructureFilter, s, T, m, gyros, acc),
                                           number)
        timers[f'{name} filter, gravity directions'] = (
            filter_step(StructureFilter, s, T, m, gyros, None), number)
        if previous is not None:
            prev_s = previous['tensegrity_stiffness.structures.structure'].Structure.from_dict(
                s.to_dict())
            prev_class = previous['tensegrity_stiffness.estimation.structure_estimator'] \
                .StructureFilter
            timers[f'{name} previous filter update'] = (
                filter_step(prev_class, prev_s, T, m, gyros, None), number)
        start = apply_increment(T, 0.01 * rng.standard_normal(6 * s.n_bodies))
        rest = StructureMeasurements(**{**m.__dict__, 'at_rest': True})
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
        target = next((t for k, t in TARGETS_US.items()
                       if key == f'{k} filter update'), None)
        note = f'   target {target:.0f} us: {value * 1e6 / target:.1f} x' if target else ''
        print(f'{key:34s} {value * 1e6:10.0f} us{note}')
    if previous is not None:
        for name in TARGETS_US:
            ratio = (best[f'{name} previous filter update']
                     / best[f'{name} filter, gravity directions'])
            print(f'{name} previous / new filter update on the same readings: {ratio:.2f}')


if __name__ == '__main__':
    main()
