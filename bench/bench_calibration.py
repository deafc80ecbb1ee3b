"""Timing and accuracy of the calibration (``tensegrity_stiffness.estimation.calibration``).

Run by hand: ``python3 bench/bench_calibration.py [--samples 1000] [--repeats 3]``. A joint with
true parameters drawn away from the nominal (each ``k_j`` within +-20 %, each offset within
+-1 mm) is measured at ``--samples`` quasi-static states (the library's equilibria under random
commanded rest lengths and loads; pose 0.1 mm / 0.1 deg, wrench 0.01 N / 0.0005 N m), and all 24
parameters (12 stiffnesses, 12 offsets) are fitted: the wall time of ``calibrate_joint`` with the
robust loss (robust stage, outlier test, final stage) and with plain least squares, next to the
issue's target (<= 5 s for 1,000 samples); for scale, 200 samples. Accuracy printed beside:
the largest error in reported std, and the range of reported std / Cramer-Rao bound. No
assertions: numbers only. Beside them, the same plain least-squares problem solved by
``scipy.optimize.least_squares`` (sparse Jacobian, LSMR) for ``--scipy-samples`` samples.
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

from support.calibration_recordings import (  # noqa: E402
    configurations,
    measure,
    nominal_model,
    true_parameters,
)

from tensegrity_stiffness.estimation.calibration_model import CalibrationProblem  # noqa: E402
from tensegrity_stiffness.estimation.calibration_results import CalibrationResult  # noqa: E402
from tensegrity_stiffness.estimation.calibration_samples import (  # noqa: E402
    CalibrationNoise,
    samples_data,
)
from tensegrity_stiffness.estimation.joint_calibration import (  # noqa: E402
    calibrate_joint,
    cramer_rao_std,
    initial_screws,
)

TARGET_S = 5.0
SEED = 3


def accuracy(result: CalibrationResult, k: np.ndarray, d: np.ndarray,
             crb: np.ndarray) -> str:
    truth = np.concatenate([k, d])
    fitted = np.array([result.parameters[name] for name in result.names])
    std = np.array([result.std[name] for name in result.names])
    ratio = std / crb
    return (f'max |error| / std {np.max(np.abs(fitted - truth) / std):.2f}, std / CRB '
            f'{ratio.min():.3f}-{ratio.max():.3f}, median stiffness std '
            f'{100 * np.median(std[:12] / k):.2f} %, median offset std '
            f'{1e3 * np.median(std[12:]):.3f} mm')


def scipy_reference(model, samples) -> tuple[float, np.ndarray, int]:
    """The same plain least-squares problem through ``scipy.optimize.least_squares`` (trust
    region, sparse Jacobian: 24 parameters + one screw per sample, LSMR), from the same start:
    (seconds, fitted parameters, function evaluations). The library's choice is measured
    against it."""
    from scipy import sparse
    from scipy.optimize import least_squares

    t0 = time.perf_counter()
    data = samples_data(model, samples)
    problem = CalibrationProblem(model, data, CalibrationNoise())
    n2 = 2 * model.n_strings
    xi0 = problem.refine_screws(np.zeros(n2), initial_screws(model, data))
    N = len(samples)
    sample_of_row, row_of = np.nonzero(problem.mask)
    M, width = sample_of_row.size, n2 + 6
    indices = np.empty((M, width), dtype=np.int64)
    indices[:, :n2] = np.arange(n2)
    indices[:, n2:] = n2 + 6 * sample_of_row[:, None] + np.arange(6)
    indptr = np.arange(M + 1) * width

    def fun(x):
        return problem.evaluate(x[:n2], x[n2:].reshape(N, 6), False).residuals[problem.mask]

    def jac(x):
        ev = problem.evaluate(x[:n2], x[n2:].reshape(N, 6))
        values = np.hstack([ev.jac_parameters[sample_of_row, row_of],
                            ev.jac_screw[sample_of_row, row_of]])
        return sparse.csr_matrix((values.ravel(), indices.ravel(), indptr),
                                 shape=(M, n2 + 6 * N))

    res = least_squares(fun, np.concatenate([np.zeros(n2), xi0.ravel()]), jac=jac,
                        method='trf', tr_solver='lsmr', x_scale='jac', ftol=1e-10, xtol=1e-10,
                        gtol=1e-10, max_nfev=200)
    k, dd = problem.parameters(res.x[:n2])
    return time.perf_counter() - t0, np.concatenate([k, dd]), res.nfev


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--samples', type=int, default=1000)
    parser.add_argument('--repeats', type=int, default=3)
    parser.add_argument('--scipy-samples', type=int, default=200,
                        help='samples of the scipy least_squares reference (0: skip)')
    args = parser.parse_args()
    model = nominal_model()
    k, d = true_parameters(model, SEED)
    started = time.perf_counter()
    states = configurations(model, k, d, args.samples, SEED, backend='library')
    samples = measure(model, states, SEED, CalibrationNoise())
    print(f'{args.samples} samples (library equilibria, made in '
          f'{time.perf_counter() - started:.1f} s), 24 parameters; kernel: '
          f'{model.uses_kernel}; machine shared: timings are noisy')
    for count in (200, args.samples):
        crb = cramer_rao_std(model, k, d, states.screws[:count], samples[:count])
        for loss in ('soft_l1', 'linear'):
            times = []
            for _ in range(args.repeats):
                t0 = time.perf_counter()
                result = calibrate_joint(model, samples[:count], loss=loss)
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
    if args.scipy_samples:
        count = args.scipy_samples
        t0 = time.perf_counter()
        ours = calibrate_joint(model, samples[:count], loss='linear')
        mine = time.perf_counter() - t0
        seconds, fitted, nfev = scipy_reference(model, samples[:count])
        values = np.array([ours.parameters[name] for name in ours.names])
        std = np.array([ours.std[name] for name in ours.names])
        print(f'  {count} samples, plain least squares: this library {mine:.2f} s, scipy '
              f'least_squares (sparse, LSMR) {seconds:.2f} s ({nfev} evaluations): ratio '
              f'{seconds / mine:.1f}x; largest difference of the estimates '
              f'{np.max(np.abs(fitted - values) / std):.3f} std')


if __name__ == '__main__':
    main()
