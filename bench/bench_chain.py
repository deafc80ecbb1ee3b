"""Chain (spine) timings: evaluate + tip stiffness and the equilibrium solve for N joints.

For N = 1, 5, 10, 20 default vertebrae stacked as in config/default_spine.yaml: the median of
``evaluate`` alone, of ``evaluate`` + ``tip_stiffness_from_state`` (what a 1 kHz spine node does
per input: target <= 1 ms at N = 10), and of ``solve_chain_equilibrium`` under moderate random tip
wrenches (the tests' distribution; target median <= 20 ms at N = 10), without and with 20 g link
weights. Side by side in one run: the single joint's ``JointModel.evaluate`` (one screw).

    python3 bench/bench_chain.py [--repeats 200] [--solves 50]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel

REPO = Path(__file__).resolve().parents[1]
SPINE = REPO / 'config' / 'default_spine.yaml'
SIZES = (1, 5, 10, 20)
GRAVITY = np.array([0.0, -9.81, 0.0])
LINK_MASS = 0.02


def median_time(fn, repeats: int) -> float:
    """Median wall time (s) of ``fn()`` over ``repeats`` calls after 5 warm-up calls."""
    for _ in range(5):
        fn()
    times = np.empty(repeats)
    for k in range(repeats):
        t0 = time.perf_counter()
        fn()
        times[k] = time.perf_counter() - t0
    return float(np.median(times))


def spine(n: int, masses: bool) -> JointChain:
    base = JointChain.from_yaml(SPINE)
    model = base.joints[0]
    return JointChain([model] * n, np.repeat(base.link_offsets[:1], n - 1, axis=0), base.tool,
                      link_masses=np.full(n, LINK_MASS) if masses else None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--repeats', type=int, default=200)
    parser.add_argument('--solves', type=int, default=50)
    args = parser.parse_args()
    model = JointModel.from_yaml(REPO / 'config' / 'default_joint.yaml')
    t_joint = median_time(lambda: model.evaluate(model.initial_screw), args.repeats)
    print(f'single joint evaluate (one screw): {t_joint * 1e6:.0f} us')
    print('medians; evaluation in us, solves in ms')
    print(f"{'N':>3} {'evaluate':>10} {'eval+K_tip':>11} {'solve':>9} {'p90':>8} {'iters':>6} "
          f"{'fails':>6} {'solve+w':>9} {'fails':>6}")
    rng = np.random.default_rng(0)
    for n in SIZES:
        chain = spine(n, masses=False)
        x = chain.unloaded_screws()
        W = np.r_[rng.normal(scale=0.1, size=3), rng.normal(scale=0.002, size=3)] * 0.3
        res = solve_chain_equilibrium(chain, W)
        xs = res.screws if res.success else x
        t_eval = median_time(lambda c=chain, s=xs: c.evaluate(s), args.repeats)
        t_both = median_time(
            lambda c=chain, s=xs, w=W: c.tip_stiffness_from_state(c.evaluate(s), w),
            args.repeats)
        cols = []
        for masses in (False, True):
            chain_m = spine(n, masses)
            chain_m.unloaded_screws()
            times, iters, fails = [], [], 0
            for _ in range(args.solves):
                # Moderate tip wrenches, scaled down with the lever arm of a longer spine.
                Wk = np.r_[rng.normal(scale=0.1, size=3), rng.normal(scale=0.002, size=3)]
                Wk *= min(1.0, 3.0 / n)
                t0 = time.perf_counter()
                r = solve_chain_equilibrium(chain_m, Wk, GRAVITY if masses else None)
                times.append(time.perf_counter() - t0)
                iters.append(r.iterations)
                fails += not r.success
            cols.append((np.median(times), np.percentile(times, 90), np.median(iters), fails))
        (s0, p0, i0, f0), (s1, _, _, f1) = cols
        print(f'{n:>3} {t_eval * 1e6:>10.0f} {t_both * 1e6:>11.0f} {s0 * 1e3:>9.2f} '
              f'{p0 * 1e3:>8.2f} {i0:>6.0f} {f0:>6d} {s1 * 1e3:>9.2f} {f1:>6d}')


if __name__ == '__main__':
    main()
