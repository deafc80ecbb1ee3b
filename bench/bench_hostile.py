#!/usr/bin/env python3
"""Hostile input at the library's doors, longer than the tests (issue #42), run by hand:
``python3 bench/bench_hostile.py [--n N] [--seed S]``.

Seeded; no node. For the controller: N random targets (half absurd: huge, indefinite,
antisymmetric, zero stiffnesses with pose estimates far away or turned by 180 deg about a random
axis), each refused by the door's checks or ticked, by the controller the node builds (its
``control.time_budget``: half a period) and, on the same inputs, by one without a budget; the
refusals and the held ticks counted by reason, the tick times of the plain and the accepted
hostile inputs (median, p99, worst) and the slowest accepted input (its kind and values) against
the plain median and the node's period (ratios: accepted input must not cost more than a period
per tick). For the checks themselves, their cost per message side by side
with the work they guard (ratios, alternating repeats). For the estimator's door (ROS-free, the
nodes' ``check_reading`` / ``check_spine_reading``): N readings of a joint and of a 3-joint
spine, half bad (a negative length, an asymmetric pose covariance, a pose 1 m .. 1e308 m away,
a load of 1e9 N), each judged alone on arrival; the refusals counted by reason, the check's
cost per reading (median, and the slowest accepted reading: its kind and values) against one
static estimate on the readings kept and the stream's period (1 kHz, docs/estimation.md).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tensegrity_stiffness.control.controller import (  # noqa: E402
    OUT_OF_TIME,
    ControlTarget,
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
    new_controller,
)
from tensegrity_stiffness.nodes.stiffness_node import joint_outputs  # noqa: E402

#: The stream period of the estimator nodes' readings (s): 1 kHz, the rate they are
#: documented and benchmarked at (docs/estimation.md).
STREAM_PERIOD_S = 1e-3


def hostile_stiffness(rng: np.random.Generator, reachable: np.ndarray
                      ) -> tuple[np.ndarray, str]:
    """One of: a diagonal of 0.1 .. 1e13, negative definite, antisymmetric, zero, 1e308
    everywhere, or a plausible one (``reachable`` scaled by 0.5 .. 2); and what it is."""
    A = rng.standard_normal((6, 6))
    diagonal = 10.0 ** rng.uniform(-1, 13, 6)
    scale = rng.uniform(0.5, 2.0)
    kinds = [(np.diag(diagonal), f'diagonal {diagonal.min():.2g} .. {diagonal.max():.2g}'),
             (-A @ A.T, 'negative definite'), (A - A.T, 'antisymmetric'),
             (np.zeros((6, 6)), 'zero'), (np.full((6, 6), 1e308), '1e308 everywhere'),
             (reachable * scale, f'plausible: {scale:.3g} x the unloaded joint\'s')]
    return kinds[rng.integers(6)]


REASONS = ('layout', 'zero', 'antisymmetric', 'not positive semidefinite', 'too large',
           'largest eigenvalue', 'from link 1', 'from the base', 'symmetric', 'force',
           'must be > 0', 'positive')


def reason_of(message: str) -> str:
    """The kind of a refusal: the first of :data:`REASONS` it names."""
    kind = next((r for r in REASONS if r in message), message[:40])
    return f'{message.split(":")[0]}: {kind}'


def controller_inputs(n: int, rng: np.random.Generator, model, T0: np.ndarray,
                      reachable: np.ndarray) -> list[tuple[np.ndarray | None, np.ndarray, str]]:
    """``n`` inputs ``(K*, pose estimate, what they are)``: every even one plain (the unloaded
    pose, no stiffness target), every odd one hostile; then the known stall (issue #42): the
    unloaded joint's own K* after 3 times it (unreachable), whose warm start the active set
    cycles on (about 630 iterations without a budget)."""
    inputs = []
    for i in range(n):
        if not i % 2:
            inputs.append((None, T0, 'plain'))
            continue
        K, kind = hostile_stiffness(rng, reachable)
        pose = T0.copy()
        if i % 4 == 1:  # far away
            shift = rng.normal(size=3) * 10.0 ** rng.uniform(-5, 3)
            pose[:3, 3] += shift
            where = f'pose {np.linalg.norm(shift):.2g} m away'
        else:  # turned by 180 deg about a random axis
            axis = rng.normal(size=3)
            axis /= np.linalg.norm(axis)
            pose[:3, :3] = exp_so3(np.pi * axis) @ pose[:3, :3]
            where = 'pose turned 180 deg about ({:.2f}, {:.2f}, {:.2f})'.format(*axis)
        inputs.append((K, pose, f'K* {kind}, {where}'))
    inputs += [(3.0 * reachable, T0, "K* 3 x the unloaded joint's (unreachable)"),
               (reachable, T0, "K* the unloaded joint's (reachable; a stalling warm start)")]
    return inputs


def controller_run(n: int, rng: np.random.Generator) -> None:
    settings = controller_settings({s.name: s.default for s in CONTROLLER_PARAMETERS})
    model = settings.model
    period = 1.0 / settings.values['control.rate']
    T0 = exp_se3(model.initial_screw)
    reachable = joint_outputs(model, model.initial_screw).state.cartesian_stiffness
    inputs = controller_inputs(n, rng, model, T0, reachable)
    for budgeted in (True, False):
        ctl = new_controller(settings)
        if not budgeted:
            ctl.time_budget = None
        refusals: Counter[str] = Counter()
        held: Counter[str] = Counter()
        times: dict[str, list[float]] = {'plain': [], 'accepted hostile': []}
        slowest: tuple[float, str, int] = (0.0, '', 0)
        cpu: tuple[float, str, int] = (0.0, '', 0)  # by the thread's CPU time (no load)
        plain_cpu: list[float] = []
        previous = 'none'
        for K, pose, what in inputs:
            try:
                if K is not None:
                    check_target_stiffness(model, K, length_scale=ctl.length_scale)
                check_translation(model, pose[:3, 3], 'pose_estimate')
            except ValueError as exc:
                refusals[reason_of(str(exc))] += 1
                previous = f'refused ({what})'
                continue
            start, cpu_start = time.perf_counter(), time.thread_time()
            try:
                cmd = ctl.update(period, ControlTarget(pose=T0, cartesian_stiffness=K),
                                 pose=pose)
            except ValueError as exc:
                refusals['tick: ' + str(exc)[:40]] += 1
                previous = f'refused ({what})'
                continue
            elapsed = time.perf_counter() - start
            spent = time.thread_time() - cpu_start
            if cmd.out_of_time:
                held[OUT_OF_TIME] += 1
            elif not cmd.feasible:
                held[cmd.message.split(':')[0]] += 1
            times['plain' if K is None else 'accepted hostile'].append(elapsed)
            if K is None:
                plain_cpu.append(spent)
            if elapsed > slowest[0]:
                slowest = (elapsed, f'{what} (after {previous}): {cmd.message[:90]}',
                           cmd.iterations)
            if spent > cpu[0]:
                cpu = (spent, f'{what} (after {previous}): {cmd.message[:90]}',
                       cmd.iterations)
            previous = what
        budget = ('no time budget' if ctl.time_budget is None else
                  f'control.time_budget {1e3 * ctl.time_budget:g} ms (half a period)')
        print(f'controller, {budget}: {n} inputs, {len(times["plain"])} plain ticks, '
              f'{len(times["accepted hostile"])} hostile accepted, '
              f'{sum(refusals.values())} refused, {sum(held.values())} ticks held')
        if budgeted:
            for reason, count in refusals.most_common():
                print(f'  refused {count:5d}  {reason}')
        for reason, count in held.most_common():
            print(f'  held    {count:5d}  {reason}')
        if not times['plain']:
            continue
        plain = float(np.median(times['plain']))
        for name, values in times.items():
            if values:
                median, p99, worst = 1e3 * np.percentile(values, [50, 99, 100])
                print(f'  tick {name}: median {median:.3f} ms, p99 {p99:.3f} ms, worst '
                      f'{worst:.3f} ms ({1e-3 * worst / plain:.1f} x the plain median, '
                      f'{1e-3 * worst / period:.2f} x the period {1e3 * period:g} ms)')
        medians = {'wall': plain, 'CPU': float(np.median(plain_cpu))}
        for label, (elapsed, what, iterations) in (('wall', slowest), ('CPU', cpu)):
            print(f'  slowest accepted input ({label} time): {1e3 * elapsed:.3f} ms = '
                  f'{elapsed / medians[label]:.1f} x the plain median '
                  f'({1e3 * medians[label]:.3f} ms) = {elapsed / period:.2f} x the period; '
                  f'{iterations} QP iterations; {what}')


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


def summary(value: object) -> str:
    """A reading's values in a few words (shape, range, what is not finite)."""
    if isinstance(value, tuple):
        T, cov = value
        text = f'pose at {np.linalg.norm(T[:3, 3]):.3g} m'
        return text + ('' if cov is None else ', covariance given')
    a = np.asarray(value, dtype=np.float64)
    finite = a[np.isfinite(a)]
    span = f'{finite.min():.3g} .. {finite.max():.3g}' if finite.size else 'none finite'
    return f'{a.size} values {span}' + (f', {a.size - finite.size} NaN'
                                        if finite.size < a.size else '')


@dataclass
class Judged:
    """What :func:`judged` found: refusals by reason, the best time per reading of 3 repeats
    (s), the median and the slowest accepted reading's time (s) and what it was."""

    refusals: Counter[str]
    per_reading: float
    accepted_median: float
    slowest: float
    slowest_reading: str


def judged(check, settings, n: int, rng: np.random.Generator, good: dict, far: float
           ) -> Judged:
    """Judge ``n`` readings (half bad) with ``check``, each timed alone (its best of 3
    repeats)."""
    names = ('measured_lengths', 'measured_pose', 'measured_wrench')
    readings = [(names[i % 3], hostile_reading(rng, i, names[i % 3], good, far))
                for i in range(n)]
    refusals: Counter[str] = Counter()
    best = np.full(n, np.inf)
    accepted = np.zeros(n, bool)
    for repeat in range(3):
        for k, (name, value) in enumerate(readings):
            start = time.perf_counter()
            try:
                check(settings, name, value)
                ok = True
            except ValueError as exc:
                ok = False
                if repeat == 0:
                    text = str(exc).split(': ', 1)[1].split(' (this reading dropped')[0]
                    refusals[reason_of(text)] += 1
            best[k] = min(best[k], time.perf_counter() - start)
            accepted[k] = ok
    kept = np.flatnonzero(accepted)
    worst = int(kept[np.argmax(best[kept])]) if kept.size else 0
    name, value = readings[worst]
    return Judged(refusals, float(best.mean()),
                  float(np.median(best[kept])) if kept.size else np.nan,
                  float(best[worst]) if kept.size else np.nan, f'{name}: {summary(value)}')


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
            ('joint (estimator_node)', check_reading, settings, good),
            ('3-joint spine (spine_estimator_node)', check_spine_reading, spine, spine_good)):
        j = judged(check, node_settings, n, rng, readings, 1.0)
        print(f'estimator door, {what}: {n} readings (half bad), {sum(j.refusals.values())} '
              f'dropped alone, {1e6 * j.per_reading:.1f} us per reading (best of 3)')
        for reason, count in j.refusals.most_common():
            print(f'  dropped {count:5d}  {reason}')
        print(f'  slowest accepted reading: {1e6 * j.slowest:.1f} us = '
              f'{j.slowest / j.accepted_median:.1f} x the accepted median '
              f'({1e6 * j.accepted_median:.1f} us) = {j.slowest / STREAM_PERIOD_S:.3f} x the '
              f'stream period {1e3 * STREAM_PERIOD_S:g} ms; {j.slowest_reading}')
    now = 0.0
    snapshot = EstimatorInput({'measured_tensions': Reading(good['measured_tensions'], now)},
                              now)
    start = time.perf_counter()
    repeats = max(1, n // 100)
    for _ in range(repeats):
        estimator_outputs(settings, snapshot, False)
    estimate = (time.perf_counter() - start) / repeats
    print(f'  one static joint estimate on the readings kept: {1e3 * estimate:.2f} ms = '
          f'{estimate / STREAM_PERIOD_S:.2f} x the stream period')


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
