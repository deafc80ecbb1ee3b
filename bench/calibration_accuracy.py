"""The accuracy to expect from a calibration: the Cramer-Rao bound of the default joint's
parameters for several sensor sets, motions and sample counts (the table of
``docs/calibration.md``).

Run by hand: ``python3 bench/calibration_accuracy.py [--counts 50 200 1000]``. True parameters
drawn as in the tests (each ``k_j`` within +-20 %, offsets within +-1 mm); states are the
library's equilibria; noise: pose 0.1 mm / 0.1 deg, wrench 0.01 N / 0.0005 N m, tension
0.005 N. Prints a markdown table: median and worst std of a stiffness (% of its value) and of
an offset (mm) over the strings the sensor set determines.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test'))

from support.calibration_recordings import (  # noqa: E402
    FORCE_SPREAD,
    MOMENT_SPREAD,
    configurations,
    measure,
    nominal_model,
    true_parameters,
)

from tensegrity_stiffness.estimation.calibration_samples import CalibrationNoise  # noqa: E402
from tensegrity_stiffness.estimation.joint_calibration import cramer_rao_std  # noqa: E402

SEED = 7
FOUR = (0, 3, 5, 10)
#: (label, motion, measure options, strings determined, common scale held)
CASES = (
    ('pose + wrench', 'loads + rest lengths', {}, None, False),
    ('pose + wrench', 'loads only', {}, None, False),
    ('pose + wrench (10x smaller loads)', 'small loads + rest lengths', {}, None, False),
    ('pose + 12 tensions, load unknown', 'loads + rest lengths',
     {'wrench': False, 'tensions': tuple(range(12))}, None, False),
    ('pose + 4 tensions + wrench', 'loads + rest lengths', {'tensions': FOUR}, None, False),
    ('pose + 4 tensions, load unknown', 'loads + rest lengths',
     {'wrench': False, 'tensions': FOUR}, FOUR, False),
    ('pose only, unloaded (ratios of k)', 'rest lengths (+-6 mm)',
     {'unloaded_disturbance': True}, None, True),
)


def states_for(model, k, d, motion: str, count: int):
    noise = CalibrationNoise()
    if motion == 'loads only':
        return configurations(model, k, d, count, SEED, rest_spread=1e-12, backend='library')
    if motion.startswith('small loads'):
        return configurations(model, k, d, count, SEED, force=FORCE_SPREAD / 10,
                              moment=MOMENT_SPREAD / 10, backend='library')
    if motion.startswith('rest lengths'):
        return configurations(model, k, d, count, SEED, force=noise.force, moment=noise.moment,
                              rest_spread=6e-3, backend='library')
    return configurations(model, k, d, count, SEED, backend='library')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--counts', type=int, nargs='+', default=[50, 200, 1000])
    args = parser.parse_args()
    model = nominal_model()
    n = model.n_strings
    k, d = true_parameters(model, SEED)
    noise = CalibrationNoise()
    print('| sensors | motion | samples | stiffness std, median (worst) | '
          'offset std, median (worst) |')
    print('| --- | --- | ---: | ---: | ---: |')
    for label, motion, options, strings, scale_held in CASES:
        for count in args.counts:
            states = states_for(model, k, d, motion, count)
            samples = measure(model, states, SEED, noise, **options)
            P = 2 * n
            if strings is not None:
                columns = [j for j in range(n) if j in strings] + [n + j for j in strings]
                basis = np.eye(P)[:, columns]
            elif scale_held:
                held = np.zeros(P)
                held[:n] = 1.0 / np.sqrt(n)
                basis = np.linalg.svd(np.eye(P) - np.outer(held, held))[0][:, :P - 1]
            else:
                basis = None
            std = cramer_rao_std(model, k, d, states.screws, samples, noise=noise,
                                     basis=basis)
            idx = np.arange(n) if strings is None else np.array(strings)
            ks = 100 * std[idx] / k[idx]
            ds = 1e3 * std[n + idx]
            print(f'| {label} | {motion} | {count} | {np.median(ks):.2f} % ({ks.max():.2f} %) '
                  f'| {np.median(ds):.3f} mm ({ds.max():.3f} mm) |')


if __name__ == '__main__':
    main()
