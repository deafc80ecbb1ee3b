"""Timing of the stiffness controller's tick (``tensegrity_stiffness.control``).

Run by hand: ``python3 bench/bench_control.py [--ticks N]``. For the default joint, side by side
in the same run: ``StiffnessController.update`` per 500 Hz tick (warm-started: the QP's active
set and tensions carried from the last tick) and a full ``design_rest_lengths`` per tick (cold,
what a controller without warm start would pay), in three regimes: holding a pose with a noisy
measurement, following a moving target (a 1 Hz circle of 1 mm and 0.02 rad), and the same with
a target K_c. Also the spine controller's tick (5 joints). Numbers only, no assertions; the
issue's goal for the joint tick is <= 200 us (median).
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from tensegrity_stiffness import config
from tensegrity_stiffness.chain import JointChain
from tensegrity_stiffness.control import (
    ActuatorLimits,
    ChainStiffnessController,
    ControlTarget,
    StiffnessController,
)
from tensegrity_stiffness.design import design_rest_lengths
from tensegrity_stiffness.joint import JointModel

DT = 0.002
TICK_TARGET_US = 200.0
NOISE = 2e-5


def stats(us: np.ndarray) -> str:
    return (f'median {np.median(us):7.1f} us   p99 {np.percentile(us, 99):7.1f} us   '
            f'max {us.max():8.1f} us')


def timed(fn: Callable[[int], object], ticks: int) -> np.ndarray:
    fn(0)
    out = np.empty(ticks)
    for k in range(ticks):
        t0 = time.perf_counter()
        fn(k)
        out[k] = (time.perf_counter() - t0) * 1e6
    return out


def joint_part(ticks: int) -> None:
    model = JointModel.from_yaml(config.packaged_config_path())
    lim = ActuatorLimits(0.5 * model.rest_lengths, 1.2 * model.rest_lengths, 0.05)
    rng = np.random.default_rng(0)
    xi0 = model.initial_screw
    K = design_rest_lengths(model, xi0, np.zeros(6), 0.5, 1.5).cartesian_stiffness

    def target_at(k: int, moving: bool, stiffness: bool) -> ControlTarget:
        phase = 2 * np.pi * k * DT
        d = (np.array([0.02 * np.cos(phase), 0.02 * np.sin(phase), 0, 1e-3 * np.sin(phase),
                       1e-3 * np.cos(phase), 0]) if moving else np.zeros(6))
        return ControlTarget(screw=xi0 + d, cartesian_stiffness=K if stiffness else None)

    print(f'joint (default config), {ticks} ticks of {DT * 1e3:g} ms each, goal median <= '
          f'{TICK_TARGET_US:g} us for update()')
    for label, moving, stiffness in (('hold a pose', False, False),
                                     ('moving target', True, False),
                                     ('moving target + K_c*', True, True)):
        ctl = StiffnessController(model, lim, model.rest_lengths)
        for k in range(500):  # reach the steady state / the orbit first
            tgt = target_at(k, moving, stiffness)
            ctl.update(DT, tgt, screw=tgt.screw + rng.normal(0, NOISE, 6))
        warm = [0]

        def tick(k: int, ctl: StiffnessController = ctl, moving: bool = moving,
                 stiffness: bool = stiffness, warm: list[int] = warm) -> None:
            tgt = target_at(k + 500, moving, stiffness)
            cmd = ctl.update(DT, tgt, screw=tgt.screw + rng.normal(0, NOISE, 6))
            warm[0] += cmd.warm

        def design(k: int, moving: bool = moving, stiffness: bool = stiffness) -> None:
            tgt = target_at(k + 500, moving, stiffness)
            design_rest_lengths(model, tgt.screw, np.zeros(6),
                                target_stiffness=tgt.cartesian_stiffness)

        a = timed(tick, ticks)
        b = timed(design, ticks)
        med = np.median(a)
        print(f' {label}:')
        print(f'  update() warm-started      {stats(a)}   ({warm[0] / (ticks + 1):.0%} ticks '
              f'optimal on the last face; goal {"met" if med <= TICK_TARGET_US else "NOT met"})')
        print(f'  design_rest_lengths (cold) {stats(b)}   ({np.median(b) / med:.1f}x)')


def spine_part(ticks: int) -> None:
    chain = JointChain.from_yaml(Path(config.packaged_config_path()).with_name(
        'default_spine.yaml'))
    model = chain.joints[0]
    lim = ActuatorLimits(0.5 * model.rest_lengths, 1.2 * model.rest_lengths, 0.05)
    ctl = ChainStiffnessController(chain, lim, [model.rest_lengths] * chain.n_joints)
    T0 = chain.tip_transform(chain.unloaded_screws())
    target = ControlTarget(pose=T0)
    for _ in range(200):
        ctl.update(DT, target, tip_pose=T0)
    a = timed(lambda k: ctl.update(DT, target, tip_pose=T0), max(1, ticks // 5))
    print(f'spine ({chain.n_joints} joints): ChainStiffnessController.update  {stats(a)}')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--ticks', type=int, default=2000)
    args = parser.parse_args()
    joint_part(args.ticks)
    spine_part(args.ticks)


if __name__ == '__main__':
    main()
