#!/usr/bin/env python3
"""Filter benchmark, run by hand after ``source scripts/env.sh``:

    python bench/bench_filter.py [--repeats 2000] [--rounds 5] [--profile]

One ``JointFilter.step`` (prediction over 1 ms and the update) with 12 load cells and an IMU
(accelerometer and gyro), unknown load, on the default joint at rest at a seeded state with
new noise each step, side by side in one run with ``estimate_joint_state`` warm-started on the
same readings (12 tensions and the accelerometer's direction of gravity; its previous
estimate as the warm start) and one ``JointModel.evaluate`` (the floor). The filter runs twice,
with its linear algebra in the compiled kernel (``use_kernel=True``, the default) and on the
numpy path (the reference); all are timed in alternating rounds (``--rounds``) of
``--repeats`` calls each; medians and p90 in us and the ratios to ``evaluate``, to the static
estimator and (``/numpy``) of the kernel path to the numpy path. Target (issue 37): <= 100 us
per update.
Then the spine of 5 joints (the packaged one, every joint's 12 load cells, unknown tip load):
one ``ChainFilter.step`` beside a warm-started ``estimate_chain_state`` on the same readings,
alternating; target <= 1 ms.
``--profile``: cProfile of the filter's steps (kernel path), the functions by their own time.
"""

from __future__ import annotations

import argparse
import cProfile
import io
import os
import pstats
import statistics
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))

import numpy as np  # noqa: E402
from support.estimation_trials import GRAVITY_STD, TENSION_STD, TRUTH_SPREAD  # noqa: E402

from tensegrity_stiffness.config import packaged_config_path  # noqa: E402
from tensegrity_stiffness.estimation import sensor_models as sm  # noqa: E402
from tensegrity_stiffness.estimation.chain_estimator import estimate_chain_state  # noqa: E402
from tensegrity_stiffness.estimation.chain_filter import ChainFilter  # noqa: E402
from tensegrity_stiffness.estimation.joint_estimator import estimate_joint_state  # noqa: E402
from tensegrity_stiffness.estimation.joint_filter import JointFilter  # noqa: E402
from tensegrity_stiffness.estimation.measurements import Measurements  # noqa: E402
from tensegrity_stiffness.mechanics import kernel  # noqa: E402
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG, JointChain  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402

CONFIG = ROOT / 'config' / 'default_joint.yaml'
GRAVITY = np.array([0.0, -9.81, 0.0])
ACCELEROMETER_STD = 0.05
GYRO_STD = 0.005


def readings(model: JointModel, xi: np.ndarray, rng: np.random.Generator, count: int
             ) -> tuple[list, list]:
    """``count`` noisy readings of the joint at rest at ``xi``: the filter's (12 tensions,
    specific force, gyro) and the static estimator's (the same tensions, the accelerometer's
    direction of gravity), both prepared."""
    st = model.evaluate(xi)
    f0 = -st.transform[:3, :3].T @ GRAVITY
    ours, static = [], []
    for _ in range(count):
        t = st.tensions + rng.normal(scale=TENSION_STD, size=12)
        f = f0 + rng.normal(scale=ACCELEROMETER_STD, size=3)
        ours.append(Measurements(tensions=t, tension_std=TENSION_STD, specific_force=f,
                                 specific_force_std=ACCELEROMETER_STD,
                                 angular_velocity=rng.normal(scale=GYRO_STD, size=3),
                                 angular_velocity_std=GYRO_STD).prepared(12))
        static.append(Measurements(tensions=t, tension_std=TENSION_STD,
                                   gravity=sm.gravity_from_specific_force(f),
                                   gravity_std=GRAVITY_STD,
                                   gravity_base=GRAVITY / 9.81).prepared(12))
    return ours, static


def timed(fn, items) -> list[float]:
    out = []
    for item in items:
        start = time.perf_counter()
        fn(item)
        out.append(time.perf_counter() - start)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--repeats', type=int, default=2000)
    parser.add_argument('--rounds', type=int, default=5)
    parser.add_argument('--profile', action='store_true')
    parser.add_argument('--spine-repeats', type=int, default=100)
    args = parser.parse_args()
    model = JointModel.from_yaml(CONFIG)
    rng = np.random.default_rng(0)
    xi = model.initial_screw + rng.normal(scale=TRUTH_SPREAD)
    n = args.repeats
    ours, static = readings(model, xi, rng, n * args.rounds + 200)
    filters = {
        f'JointFilter.step{label}, {path}': JointFilter(model, string_damping=0.5,
                                                        stiffness_std=std,
                                                        use_kernel=path == 'kernel')
        for label, std in ((' (12 cells + IMU)', False), (' + std of K_c', True))
        for path in ('kernel', 'numpy')}
    rows: dict[str, list[float]] = {'JointModel.evaluate (floor)': [],
                                    'estimate_joint_state, warm': []}
    rows.update({name: [] for name in filters})
    clock = {name: 0 for name in filters}
    for name, flt in filters.items():  # start-up: out of the timing
        for k in range(200):
            flt.step(k * 1e-3, ours[k])
        clock[name] = 200
    warm = [estimate_joint_state(model, static[0], stiffness_std=False).screw]

    def static_step(prep):
        est = estimate_joint_state(model, prep, initial_screw=warm[0], stiffness_std=False)
        warm[0] = est.screw

    for r in range(args.rounds):
        chunk = slice(200 + r * n, 200 + (r + 1) * n)
        rows['JointModel.evaluate (floor)'] += timed(lambda _: model.evaluate(xi), range(n))
        rows['estimate_joint_state, warm'] += timed(static_step, static[chunk])
        for name, flt in filters.items():
            def step(prep, flt=flt, name=name):
                clock[name] += 1
                flt.step(clock[name] * 1e-3, prep)
            rows[name] += timed(step, ours[chunk])
    floor = statistics.median(rows['JointModel.evaluate (floor)'])
    static_median = statistics.median(rows['estimate_joint_state, warm'])
    print(f'kernel: {kernel.status()}')
    print(f'load: {os.getloadavg()[0]:.2f} (1 min); {args.rounds} alternating rounds of {n}')
    print(f'{"":46s} {"median us":>10s} {"p90 us":>8s} {"/evaluate":>10s} {"/static":>8s} '
          f'{"/numpy":>7s}')
    for name, times in rows.items():
        med = statistics.median(times)
        p90 = float(np.percentile(times, 90))
        twin = name.replace(', kernel', ', numpy')
        ratio = (f'{med / statistics.median(rows[twin]):7.2f}'
                 if twin != name and twin in rows else '')
        print(f'{name:46s} {med * 1e6:10.1f} {p90 * 1e6:8.1f} {med / floor:10.1f} '
              f'{med / static_median:8.2f} {ratio}')
    print('target: one filter update <= 100 us (the kernel path)')
    spine(args.spine_repeats, args.rounds)
    if args.profile:
        first = next(iter(filters))
        flt = filters[first]
        profile = cProfile.Profile()
        t0 = clock[first]
        profile.enable()
        for k, prep in enumerate(ours[200:200 + n]):
            flt.step((t0 + k + 1) * 1e-3, prep)
        profile.disable()
        out = io.StringIO()
        pstats.Stats(profile, stream=out).sort_stats('tottime').print_stats(15)
        print(out.getvalue())


def spine(repeats: int, rounds: int) -> None:
    """The 5-joint spine: ``ChainFilter.step`` against a warm-started
    ``estimate_chain_state``, alternating rounds of ``repeats``."""
    chain = JointChain.from_yaml(packaged_config_path(DEFAULT_SPINE_CONFIG))
    rng = np.random.default_rng(1)
    xi = chain.unloaded_screws()
    st = chain.evaluate(xi)

    def reading():
        return [Measurements(tensions=st.tensions[i] + rng.normal(scale=TENSION_STD,
                                                                   size=st.tensions[i].size),
                             tension_std=TENSION_STD) for i in range(chain.n_joints)]

    flt = ChainFilter(chain, string_damping=0.5, stiffness_std=False)
    clock = [0]
    for _ in range(20):
        clock[0] += 1
        flt.step(clock[0] * 1e-3, reading())
    warm = [estimate_chain_state(chain, reading(), stiffness_std=False).screws]

    def static_step(m):
        warm[0] = estimate_chain_state(chain, m, initial_screws=warm[0],
                                       stiffness_std=False).screws

    def filter_step(m):
        clock[0] += 1
        flt.step(clock[0] * 1e-3, m)

    rows: dict[str, list[float]] = {'estimate_chain_state, warm (5 joints)': [],
                                    'ChainFilter.step (5 joints, 60 cells)': []}
    for _ in range(rounds):
        rows['estimate_chain_state, warm (5 joints)'] += timed(
            static_step, [reading() for _ in range(repeats)])
        rows['ChainFilter.step (5 joints, 60 cells)'] += timed(
            filter_step, [reading() for _ in range(repeats)])
    base = statistics.median(rows['estimate_chain_state, warm (5 joints)'])
    for name, times in rows.items():
        med = statistics.median(times)
        print(f'{name:40s} {med * 1e3:8.2f} ms {float(np.percentile(times, 90)) * 1e3:8.2f} ms '
              f'{med / base:8.2f}')
    print('target: one spine filter update (5 joints) <= 1 ms')


if __name__ == '__main__':
    main()
