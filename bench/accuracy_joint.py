#!/usr/bin/env python3
"""Accuracy figures of the six-DOF core, run by hand: ``python3 bench/accuracy_joint.py [--n N]``.

The paper's own validation (Section IV, eqs. 21-22, Table II; Section VI, Table III) on the
default joint, with the numbers the tests only bound:
* dT/dxi against central differences (step 1e-6): mean / max relative Frobenius error over N
  random screws with |omega| <= pi (paper: 2.4e-10), and the error against the exact
  block-exponential derivative at theta = 0, 1e-12, 1e-8, 1e-6, 1e-4 and pi - 1e-9;
* K against central differences of F at N equilibria under random moderate wrenches
  (paper: 4.4e-10), with the solver's convergence count and largest residual |F + W|;
* the load-response check: a 10 mN force at node A of link 2 along x, y, z; the wrench change
  of the new equilibrium against K * delta_xi (relative error).
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))

from support.screw_samples import (  # noqa: E402  (the tests' generators and oracle)
    moderate_wrench,
    random_screws,
    reference_dexp,
)

from tensegrity_stiffness.geometry.screw import dexp_se3, exp_se3  # noqa: E402
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402

STEP = 1e-6


def relative_errors(analytic: np.ndarray, numeric: np.ndarray) -> np.ndarray:
    n = analytic.shape[0]
    return (np.linalg.norm((analytic - numeric).reshape(n, -1), axis=1)
            / np.linalg.norm(analytic.reshape(n, -1), axis=1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--n', type=int, default=10_000, help='screws and equilibria')
    args = parser.parse_args()
    n = args.n
    rng = np.random.default_rng(0)
    model = JointModel.from_yaml(ROOT / 'config' / 'default_joint.yaml')

    xs = random_screws(rng, n)
    analytic = dexp_se3(xs)
    numeric = np.empty_like(analytic)
    for i in range(6):
        e = np.zeros(6)
        e[i] = STEP
        numeric[..., i] = (exp_se3(xs + e) - exp_se3(xs - e)) / (2 * STEP)
    err = relative_errors(analytic, numeric)
    print(f'dT/dxi vs central differences, {n} screws |omega| <= pi: mean {err.mean():.2e}, '
          f'max {err.max():.2e} (paper 2.4e-10)')
    worst = 0.0
    for theta in (0.0, 1e-12, 1e-8, 1e-6, 1e-4, math.pi - 1e-9):
        a = rng.normal(size=3)
        xi = np.r_[a / np.linalg.norm(a) * theta, rng.normal(size=3)]
        worst = max(worst, float(np.abs(dexp_se3(xi) - reference_dexp(xi)).max()))
    print(f'dT/dxi vs exact derivative at theta = 0, 1e-12, 1e-8, 1e-6, 1e-4, pi - 1e-9: '
          f'largest entry error {worst:.1e}')

    screws = np.zeros((n, 6))
    converged, residual = 0, 0.0
    for _ in range(n):
        res = solve_equilibrium(model, moderate_wrench(rng))
        if res.success:
            screws[converged] = res.screw
            converged += 1
            residual = max(residual, res.residual)
    screws = screws[:converged]
    err = relative_errors(model.stiffness(screws), model.numerical_stiffness(screws, step=STEP))
    print(f'equilibria under random moderate wrenches: {converged} of {n} converged, '
          f'largest residual |F + W| {residual:.1e} N')
    print(f'K vs central differences of F at those equilibria: mean {err.mean():.2e}, '
          f'max {err.max():.2e} (paper 4.4e-10)')

    rest = model.evaluate(model.initial_screw)
    a2 = model.link2_nodes_in_link1(rest.transform)[model.link2_node_names.index('A')]
    for name, direction in zip('xyz', np.eye(3), strict=True):
        f = 0.01 * direction
        res = solve_equilibrium(model, np.r_[f, np.cross(a2, f)])
        dF = res.wrench - rest.wrench
        predicted = rest.stiffness @ (res.screw - model.initial_screw)
        print(f'load response, 10 mN at node A along {name}: |K dxi - dF| / |dF| = '
              f'{np.linalg.norm(predicted - dF) / np.linalg.norm(dF):.2e} (stable {res.stable})')


if __name__ == '__main__':
    main()
