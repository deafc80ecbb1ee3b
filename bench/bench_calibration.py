"""Timing and accuracy of the calibration (``tensegrity_stiffness.calibration``).

Run by hand: ``python3 bench/bench_calibration.py [--samples 1000] [--repeats 3]``. A joint with
true parameters drawn away from the nominal (each ``k_j`` within +-20 %, each offset within
+-1 mm) is measured at ``--samples`` quasi-static states (the library's equilibria under random
commanded rest lengths and loads; pose 0.1 mm / 0.1 deg, wrench 0.01 N / 0.0005 N m), and all 24
parameters (12 stiffnesses, 12 offsets) are fitted: the wall time of ``calibrate_joint`` with the
robust loss (robust stage, outlier test, final stage) and with plain least squares, next to the
issue's target (<= 5 s for 1,000 samples); for scale, 200 samples. Accuracy printed beside:
the largest error in reported std, and the range of reported std / Cramer-Rao bound. No
assertions: numbers only.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / 'test'))

from calibration_recordings import (  # noqa: E402
    configurations,
    measure,
    nominal_model,
    true_parameters,
)

from tensegrity_stiffness import calibration as cal  # noqa: E402

TARGET_S = 5.0
SEED = 3


def accuracy(result: cal.CalibrationResult, k: np.ndarray, d: np.ndarray,
             crb: np.ndarray) -> str:
    truth = np.concatenate([k, d])
    fitted = np.array([result.parameters[name] for name in result.names])
    std = np.array([result.std[name] for name in result.names])
    ratio = std / crb
    return (f'max |error| / std {np.max(np.abs(fitted - truth) / std):.2f}, std / CRB '
            f'{ratio.min():.3f}-{ratio.max():.3f}, median stiffness std '
            f'{100 * np.median(std[:12] / k):.2f} %, median offset std '
            f'{1e3 * np.median(std[12:]):.3f} mm')


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=1000)
    parser.add_argument('--repeats', type=int, default=3)
    args = parser.parse_args()
    model = nominal_model()
    k, d = true_parameters(model, SEED)
    started = time.perf_counter()
    states = configurations(model, k, d, args.samples, SEED, backend='library')
    samples = measure(model, states, SEED, cal.CalibrationNoise())
    print(f'{args.samples} samples (library equilibria, made in '
          f'{time.perf_counter() - started:.1f} s), 24 parameters; kernel: '
          f'{model.uses_kernel}; machine shared: timings are noisy')
    for count in (200, args.samples):
        crb = cal.cramer_rao_std(model, k, d, states.screws[:count], samples[:count])
        for loss in ('soft_l1', 'linear'):
            times = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                result = cal.calibrate_joint(model, samples[:count], loss=loss)
                times.append(time.perf_counter() - t0)
            best, median = min(times), float(np.median(times))
            verdict = ''
            if count == args.samples:
                met = 'met' if median <= TARGET_S else 'NOT met'
                verdict = f'  (target <= {TARGET_S:g} s: {met})'
            print(f'  {count:5d} samples, loss {loss:<8} median {median:6.2f} s  best '
                  f'{best:6.2f} s  ({result.iterations} iterations, {len(result.outliers)} '
                  f'outliers){verdict}')
            print(f'        {accuracy(result, k, d, crb)}')


if __name__ == '__main__':
    main()
