"""Timing of the planar mechanism: FK and IK per point, 200 x 200 stiffness maps.

Run by hand: ``python3 bench/bench_planar.py [--repeat N]``. Prints per-point times of single
calls and of the vectorised grid functions, and the map times, next to the issue's targets
(FK <= 20 us, IK <= 100 us per point, map <= 1 s). No assertions: numbers only.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tensegrity_stiffness.mechanics.planar import PlanarMechanism
from tensegrity_stiffness.mechanics.planar_workspace import (
    actuator_stiffness_map,
    cartesian_stiffness_map,
)

FK_TARGET_US = 20.0
IK_TARGET_US = 100.0
MAP_TARGET_S = 1.0
MAP_SIZE = 200


def best_of(fn: Callable[[], object], repeat: int) -> float:
    """Smallest wall time (s) of ``repeat`` calls of ``fn``."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--points', type=int, default=2000, help='points per single-call loop')
    parser.add_argument('--repeat', type=int, default=5, help='repetitions (best is kept)')
    args = parser.parse_args()

    mech = PlanarMechanism(L=1.0, K1=200.0, K2=100.0)
    rng = np.random.default_rng(0)
    n = args.points
    L3 = rng.uniform(0.0, 2.0, n).tolist()
    t1 = rng.uniform(0.0, math.pi, n).tolist()
    fk = [mech.forward(a, b) for a, b in zip(L3, t1, strict=True)]
    xs, ys = [r.x for r in fk], [r.y for r in fk]

    def fk_loop() -> None:
        for a, b in zip(L3, t1, strict=True):
            mech.forward(a, b)

    def ik_loop() -> None:
        for x, y in zip(xs, ys, strict=True):
            mech.inverse(x, y)

    big = 100_000
    L3v, t1v = rng.uniform(0.0, 2.0, big), rng.uniform(0.0, math.pi, big)
    g = mech.forward_grid(L3v, t1v)
    xv, yv = g.x, g.y

    Lg, Tg = np.meshgrid(np.linspace(0.0, 2.0, MAP_SIZE), np.linspace(0.0, math.pi, MAP_SIZE))
    Xg, Yg = np.meshgrid(np.linspace(-3.0, 3.0, MAP_SIZE), np.linspace(-1.5, 3.0, MAP_SIZE))

    rows = [
        ('FK single call', best_of(fk_loop, args.repeat) / n * 1e6, 'us/pt', FK_TARGET_US),
        ('FK vectorised (forward_grid)',
         best_of(lambda: mech.forward_grid(L3v, t1v), args.repeat) / big * 1e6, 'us/pt',
         FK_TARGET_US),
        ('IK single call', best_of(ik_loop, args.repeat) / n * 1e6, 'us/pt', IK_TARGET_US),
        ('IK vectorised (inverse_grid)',
         best_of(lambda: mech.inverse_grid(xv, yv), args.repeat) / big * 1e6, 'us/pt',
         IK_TARGET_US),
        (f'actuator stiffness map {MAP_SIZE}x{MAP_SIZE} (Fig. 7)',
         best_of(lambda: actuator_stiffness_map(mech, Lg, Tg), args.repeat), 's', MAP_TARGET_S),
        (f'Cartesian stiffness map {MAP_SIZE}x{MAP_SIZE} (Fig. 8)',
         best_of(lambda: cartesian_stiffness_map(mech, Xg, Yg), args.repeat), 's',
         MAP_TARGET_S),
        (f'forward_grid {MAP_SIZE}x{MAP_SIZE} (all fields)',
         best_of(lambda: mech.forward_grid(Lg, Tg), args.repeat), 's', MAP_TARGET_S),
    ]
    print(f'planar mechanism bench (numpy {np.__version__}, python '
          f'{sys.version.split()[0]}, best of {args.repeat})')
    print(f'{"what":<44}{"time":>12}  {"unit":<6}{"target":>8}  ok')
    for name, value, unit, target in rows:
        print(f'{name:<44}{value:>12.4g}  {unit:<6}{target:>8g}  '
              f'{"yes" if value <= target else "NO"}')


if __name__ == '__main__':
    main()
