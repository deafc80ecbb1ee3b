#!/usr/bin/env python3
"""Dynamics benchmark (issue 28), run by hand: ``python3 bench/bench_dynamics.py [--quick]``.

Prints, measured side by side in one run on the default joint and the default 5-joint spine
(twin default inertia, string damping 0.5 N s/m):
* per call: ``mass_matrix``, ``acceleration`` (with a velocity: the Coriolis terms' 12x12 block
  exponential), ``linearize`` and ``modes`` at the unloaded equilibrium (with damping: 12x12
  eigenproblem; without: the 6x6 one), ``linearize`` at a state off equilibrium (the 21 block
  exponentials of the derivatives of J and M), and numpy's ``eig`` alone for scale;
* against them, a central-difference linear model from the same run (12 + 12 + n + 6 pairs of
  ``acceleration`` calls) and its eigen-decomposition;
* the spine's ``mass_matrix``, ``modes`` and its central-difference linear model.
Targets (issue 28): joint mass matrix <= 20 us, joint modes <= 100 us. Everything is numpy:
the mass matrix is one closed-form ScrewKinematics (plain floats) and two 6x6 products, and
``modes`` is dominated by LAPACK's 12x12 eigen-decomposition and the joint's evaluation (itself
in the compiled kernel when built), which a C twin of this module would not make faster.
"""

from __future__ import annotations

import argparse
import sys
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tensegrity_stiffness.mechanics import kernel  # noqa: E402
from tensegrity_stiffness.mechanics.chain import JointChain  # noqa: E402
from tensegrity_stiffness.mechanics.dynamics import ChainDynamics, JointDynamics  # noqa: E402
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402

STEP = 1e-6
DAMPING = 0.5


def per_call_us(fn, repeat: int, number: int) -> float:
    """Best-of-``repeat`` mean time per call, microseconds."""
    return min(timeit.repeat(fn, repeat=repeat, number=number)) / number * 1e6


def side_by_side(fns: list, repeat: int, number: int) -> list[float]:
    """Best per-call time (us) of each of ``fns``, timed in alternation."""
    best = [float('inf')] * len(fns)
    for _ in range(repeat):
        for i, fn in enumerate(fns):
            best[i] = min(best[i], per_call_us(fn, 1, number))
    return best


def numerical_joint_model(dyn: JointDynamics, xi: np.ndarray) -> np.ndarray:
    """A (12, 12) and B (12, n + 6) of central differences of ``acceleration``."""
    n = dyn.model.n_strings
    rest = dyn.model.rest_lengths
    zero = np.zeros(6)
    A = np.zeros((12, 12))
    A[:6, 6:] = np.eye(6)
    B = np.zeros((12, n + 6))
    for i, e in enumerate(np.eye(6) * STEP):
        A[6:, i] = (dyn.acceleration(xi + e, zero) - dyn.acceleration(xi - e, zero)) / (2 * STEP)
        A[6:, 6 + i] = (dyn.acceleration(xi, e) - dyn.acceleration(xi, -e)) / (2 * STEP)
        B[6:, n + i] = (dyn.acceleration(xi, zero, external_wrench=e) -
                        dyn.acceleration(xi, zero, external_wrench=-e)) / (2 * STEP)
    for j in range(n):
        d = np.zeros(n)
        d[j] = STEP
        B[6:, j] = (dyn.acceleration(xi, zero, rest + d) -
                    dyn.acceleration(xi, zero, rest - d)) / (2 * STEP)
    return A


def numerical_chain_model(dyn: ChainDynamics, xi: np.ndarray) -> np.ndarray:
    """The state matrix (12N, 12N) of central differences of the spine's ``acceleration``."""
    m = 6 * dyn.n_joints
    zero = np.zeros_like(xi)
    A = np.zeros((2 * m, 2 * m))
    A[:m, m:] = np.eye(m)
    for c in range(m):
        e = np.zeros(m)
        e[c] = STEP
        e = e.reshape(xi.shape)
        A[m:, c] = (dyn.acceleration(xi + e, zero) - dyn.acceleration(xi - e, zero)
                    ).ravel() / (2 * STEP)
        A[m:, m + c] = (dyn.acceleration(xi, e) - dyn.acceleration(xi, -e)).ravel() / (2 * STEP)
    return A


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='fewer repetitions')
    args = parser.parse_args()
    repeat, number = (3, 200) if args.quick else (7, 2000)
    model = JointModel.from_yaml(ROOT / 'config' / 'default_joint.yaml')
    xi = solve_equilibrium(model, np.zeros(6)).screw
    off = xi + np.array([0.04, -0.03, 0.02, 0.001, 0.002, -0.001])
    dyn = JointDynamics(model, string_damping=DAMPING)
    undamped = JointDynamics(model)
    rate = np.array([0.5, -0.3, 0.2, 0.01, 0.0, -0.01])
    print(f'compiled kernel: {"loaded" if kernel.library() is not None else "not built"} '
          f'(used by the joint evaluation inside modes / linearize)')
    print(f'numpy {np.__version__}; repeat {repeat} x {number} calls, best mean per call\n')

    print('joint (default, twin inertia, string damping 0.5 N s/m)')
    mm, acc0, acc, lin, modes, modes0, pose, lin_off = side_by_side([
        lambda: dyn.mass_matrix(xi),
        lambda: dyn.acceleration(xi, np.zeros(6)),
        lambda: dyn.acceleration(xi, rate),
        lambda: dyn.linearize(xi),
        lambda: dyn.modes(xi),
        lambda: undamped.modes(xi),
        lambda: dyn.modes_at_pose(off),
        lambda: dyn.linearize(off)], repeat, max(number // 10, 20))
    cd_number = max(number // 200, 5)
    cd_lin, cd_modes = side_by_side([
        lambda: numerical_joint_model(dyn, xi),
        lambda: np.linalg.eig(numerical_joint_model(dyn, xi))], repeat, cd_number)
    print(f'  {"mass_matrix":36s} {mm:9.1f} us   (target <= 20 us)')
    print(f'  {"acceleration, zero velocity":36s} {acc0:9.1f} us')
    print(f'  {"acceleration, with velocity":36s} {acc:9.1f} us')
    print(f'  {"linearize at the equilibrium":36s} {lin:9.1f} us   central differences '
          f'{cd_lin:9.1f} us ({cd_lin / lin:.0f}x)')
    print(f'  {"modes at the equilibrium":36s} {modes:9.1f} us   (target <= 100 us)   '
          f'central differences + eig {cd_modes:9.1f} us ({cd_modes / modes:.0f}x)')
    print(f'  {"modes without damping (6x6 eig)":36s} {modes0:9.1f} us')
    print(f'  {"modes_at_pose, off equilibrium":36s} {pose:9.1f} us')
    print(f'  {"linearize off equilibrium":36s} {lin_off:9.1f} us')
    A = np.random.default_rng(0).normal(size=(12, 12))
    eig12, eig6 = side_by_side([lambda: np.linalg.eig(A), lambda: np.linalg.eig(A[:6, :6])],
                               repeat, number)
    print(f'  {"(numpy eig alone: 12x12 / 6x6)":36s} {eig12:9.1f} us / {eig6:.1f} us')

    chain = JointChain.from_yaml(ROOT / 'config' / 'default_spine.yaml')
    screws = chain.unloaded_screws()
    cdyn = ChainDynamics(chain, string_damping=DAMPING)
    c_number = max(number // 100, 5)
    c_mm, c_lin, c_modes = side_by_side([
        lambda: cdyn.mass_matrix(screws),
        lambda: cdyn.linearize(screws),
        lambda: cdyn.modes(screws)], repeat, c_number)
    (c_cd,) = side_by_side([lambda: np.linalg.eig(numerical_chain_model(cdyn, screws))],
                           max(repeat // 2, 1), 1)
    print(f'\nspine ({chain.n_joints} joints, {6 * chain.n_joints} modes)')
    print(f'  {"mass_matrix":36s} {c_mm:9.1f} us')
    print(f'  {"linearize at the equilibrium":36s} {c_lin:9.1f} us')
    print(f'  {"modes at the equilibrium":36s} {c_modes:9.1f} us   central differences + eig '
          f'{c_cd:9.1f} us ({c_cd / c_modes:.0f}x)')


if __name__ == '__main__':
    main()
