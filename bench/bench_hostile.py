#!/usr/bin/env python3
"""Hostile input at the library's doors, longer than the tests (issue #42), run by hand:
``python3 bench/bench_hostile.py [--n N] [--seed S]``.

Seeded; no node. For the controller: N random targets (half absurd: huge, indefinite,
antisymmetric, zero stiffnesses with pose estimates far away or turned by 180 deg about a random
axis), each refused by the door's checks or ticked; the refusals counted by reason and the worst
tick time of the accepted ones against the median of the plain ticks (a ratio: accepted input
must not cost more per tick). For the checks themselves, their cost per message side by side
with the work they guard (ratios, alternating repeats). For the estimator's door (ROS-free, the
nodes' ``check_reading`` / ``check_spine_reading``): N readings of a joint and of a 3-joint
spine, half bad (a negative length, an asymmetric pose covariance, a pose 1 m .. 1e308 m away,
a load of 1e9 N), each judged alone on arrival; the refusals counted by reason, the check's
cost per reading against one static estimate on the readings kept.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tensegrity_stiffness.control.controller import (  # noqa: E402
    ControlTarget,
    StiffnessController,
)
from tensegrity_stiffness.geometry.screw import exp_se3, exp_so3  # noqa: E402
from tensegrity_stiffness.mechanics.plausibility import (  # noqa: E402
    check_screw,
    check_target_stiffness,
    check_translation,
    joint_size,
)
from tensegrity_stiffness.nodes.estimator_node import (  # noqa: E402
    ESTIMATOR_NODE_PARAMETERS,
    EstimatorInput,
    Reading,
    check_reading,
    estimator_node_settings,
    estimator_outputs,
)
from tensegrity_stiffness.nodes.parameter_specs import defaults  # noqa: E402
from tensegrity_stiffness.nodes.spine_estimator_node import (  # noqa: E402
    check_spine_reading,
    spine_estimator_node_parameters,
    spine_estimator_node_settings,
)
from tensegrity_stiffness.nodes.stiffness_controller import (  # noqa: E402
    CONTROLLER_PARAMETERS,
    controller_settings,
)
from tensegrity_stiffness.nodes.stiffness_node import joint_outputs  # noqa: E402


def hostile_stiffness(rng: np.random.Generator, reachable: np.ndarray) -> np.ndarray:
    """One of: a diagonal of 0.1 .. 1e13, negative definite, antisymmetric, zero, 1e308
    everywhere, or a plausible one (``reachable`` scaled by 0.5 .. 2)."""
    A = rng.standard_normal((6, 6))
    return [np.diag(10.0 ** rng.uniform(-1, 13, 6)), -A @ A.T, A - A.T, np.zeros((6, 6)),
            np.full((6, 6), 1e308), reachable * rng.uniform(0.5, 2.0)][rng.integers(6)]


REASONS = ('layout', 'zero', 'antisymmetric', 'not positive semidefinite', 'too large',
           'largest eigenvalue', 'from link 1', 'from the base', 'symmetric', 'force',
           'must be > 0', 'positive')


def reason_of(message: str) -> str:
    """The kind of a refusal: the first of :data:`REASONS` it names."""
    kind = next((r for r in REASONS if r in message), message[:40])
    return f'{message.split(":")[0]}: {kind}'


def controller_run(n: int, rng: np.random.Generator) -> None:
    settings = controller_settings({s.name: s.default for s in CONTROLLER_PARAMETERS})
    model = settings.model
    ctl = StiffnessController(model, settings.limits, settings.start)
    T0 = exp_se3(model.initial_screw)
    reachable = joint_outputs(model, model.initial_screw).state.cartesian_stiffness
    refusals: Counter[str] = Counter()
    plain, accepted = [], []
    for i in range(n):
        K = None
        pose = T0
        if i % 2:
            K = hostile_stiffness(rng, reachable)
            pose = T0.copy()
            if i % 4 == 1:  # far away
                pose[:3, 3] += rng.normal(size=3) * 10.0 ** rng.uniform(-5, 3)
            else:  # turned by 180 deg about a random axis
                axis = rng.normal(size=3)
                pose[:3, :3] = exp_so3(np.pi * axis / np.linalg.norm(axis)) @ pose[:3, :3]
        try:
            if K is not None:
                check_target_stiffness(model, K, length_scale=ctl.length_scale)
            check_translation(model, pose[:3, 3], 'pose_estimate')
        except ValueError as exc:
            refusals[reason_of(str(exc))] += 1
            continue
        start = time.perf_counter()
        try:
            ctl.update(0.002, ControlTarget(pose=T0, cartesian_stiffness=K), pose=pose)
        except ValueError as exc:
            refusals['tick: ' + str(exc)[:40]] += 1
            continue
        (accepted if i % 2 else plain).append(time.perf_counter() - start)
    print(f'controller: {n} inputs, {len(plain)} plain ticks, {len(accepted)} hostile accepted,'
          f' {sum(refusals.values())} refused')
    for reason, count in refusals.most_common():
        print(f'  refused {count:5d}  {reason}')
    if plain and accepted:
        ms = {name: 1e3 * np.percentile(v, [50, 99, 100]) for name, v in
              (('plain', plain), ('accepted hostile', accepted))}
        for name, (median, p99, worst) in ms.items():
            print(f'  tick {name}: median {median:.3f} ms, p99 {p99:.3f} ms, worst {worst:.3f} '
                  f'ms ({worst / ms["plain"][0]:.1f} x the plain median)')


def check_costs(n: int, rng: np.random.Generator) -> None:
    settings = controller_settings({s.name: s.default for s in CONTROLLER_PARAMETERS})
    model = settings.model
    screws = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3, size=(n, 6))
    L = joint_size(model)
    Ks = [np.diag(rng.uniform(50, 500, 6) * [1, 1, 1, L * L, L * L, L * L]) for _ in range(n)]
    times = {'check_screw': [], 'joint_outputs': [], 'check_target_stiffness': []}
    for _ in range(5):  # alternating repeats
        start = time.perf_counter()
        for xi in screws:
            check_screw(model, xi)
        times['check_screw'].append((time.perf_counter() - start) / n)
        start = time.perf_counter()
        for xi in screws[: max(1, n // 10)]:
            joint_outputs(model, xi)
        times['joint_outputs'].append((time.perf_counter() - start) / max(1, n // 10))
        start = time.perf_counter()
        for K in Ks:
            check_target_stiffness(model, K)
        times['check_target_stiffness'].append((time.perf_counter() - start) / n)
    best = {k: min(v) for k, v in times.items()}
    print(f'per message (best of 5): check_screw {1e6 * best["check_screw"]:.2f} us, '
          f'check_target_stiffness {1e6 * best["check_target_stiffness"]:.2f} us, '
          f'stiffness_node outputs {1e6 * best["joint_outputs"]:.1f} us: the screw check is '
          f'{100 * best["check_screw"] / best["joint_outputs"]:.1f} % of the work it guards')


def hostile_reading(rng: np.random.Generator, i: int, name: str, good: dict, far: float
                    ) -> object:
    """``good[name]``, or for odd ``i`` a bad one: a negative length, an asymmetric pose
    covariance or a pose ``far`` .. 1e308 m away, a load of 1e9 N."""
    if i % 2 == 0:
        return good[name]
    if name == 'measured_lengths':
        bad = np.full(good['measured_tensions'].size, np.nan)
        bad[rng.integers(bad.size)] = -0.01
        return bad
    if name == 'measured_pose':
        T = good['measured_pose'][0].copy()
        if rng.integers(2):
            cov = np.diag([1e-6] * 6)
            cov[0, 1] = 5e-7
            return T, cov
        T[:3, 3] += rng.normal(size=3) * 10.0 ** rng.uniform(np.log10(far), 308)
        return T, None
    if name == 'measured_wrench':
        return np.array([1e9, 0.0, 0.0, 0.0, 0.0, 0.0])
    return good[name]


def judged(check, settings, n: int, rng: np.random.Generator, good: dict, far: float
           ) -> tuple[Counter[str], float]:
    """Judge ``n`` readings (half bad) with ``check``: (refusals by reason, best time per
    reading of 3 repeats, s)."""
    names = ('measured_lengths', 'measured_pose', 'measured_wrench')
    readings = [(names[i % 3], hostile_reading(rng, i, names[i % 3], good, far))
                for i in range(n)]
    refusals: Counter[str] = Counter()
    best = np.inf
    for repeat in range(3):
        start = time.perf_counter()
        for name, value in readings:
            try:
                check(settings, name, value)
            except ValueError as exc:
                if repeat == 0:
                    text = str(exc).split(': ', 1)[1].split(' (this reading dropped')[0]
                    refusals[reason_of(text)] += 1
        best = min(best, (time.perf_counter() - start) / n)
    return refusals, best


def estimator_run(n: int, rng: np.random.Generator) -> None:
    settings = estimator_node_settings({**defaults(ESTIMATOR_NODE_PARAMETERS),
                                        'estimation.method': 'static'})
    model = settings.model
    state = joint_outputs(model, model.initial_screw).state
    good = {'measured_tensions': state.tensions, 'measured_lengths': state.lengths,
            'measured_pose': (exp_se3(model.initial_screw), None),
            'measured_wrench': np.zeros(6)}
    values = defaults(spine_estimator_node_parameters(3))
    values.update({'chain.n_joints': 3, 'estimation.method': 'static'})
    spine = spine_estimator_node_settings(values)
    screws = spine.chain.unloaded_screws()
    chain_state = spine.chain.evaluate(screws)
    spine_good = {'measured_tensions': np.concatenate(list(chain_state.tensions)),
                  'measured_pose': (spine.chain.tip_transform(screws), None),
                  'measured_wrench': np.zeros(6)}
    spine_good['measured_lengths'] = np.concatenate(list(chain_state.lengths))
    for what, check, node_settings, readings in (
            ('joint', check_reading, settings, good),
            ('3-joint spine', check_spine_reading, spine, spine_good)):
        refusals, per_reading = judged(check, node_settings, n, rng, readings, 1.0)
        print(f'estimator door, {what}: {n} readings (half bad), {sum(refusals.values())} '
              f'dropped alone, {1e6 * per_reading:.1f} us per reading (best of 3)')
        for reason, count in refusals.most_common():
            print(f'  dropped {count:5d}  {reason}')
    now = 0.0
    snapshot = EstimatorInput({'measured_tensions': Reading(good['measured_tensions'], now)},
                              now)
    start = time.perf_counter()
    repeats = max(1, n // 100)
    for _ in range(repeats):
        estimator_outputs(settings, snapshot, False)
    estimate = (time.perf_counter() - start) / repeats
    print(f'  one static joint estimate on the readings kept: {1e3 * estimate:.2f} ms')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument('--n', type=int, default=4000)
    parser.add_argument('--seed', type=int, default=42)
    args = parser.parse_args()
    rng = np.random.default_rng(args.seed)
    controller_run(args.n, rng)
    check_costs(args.n, rng)
    estimator_run(args.n, rng)


if __name__ == '__main__':
    main()
