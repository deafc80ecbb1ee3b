#!/usr/bin/env python3
"""Six-DOF core benchmark, run by hand:
``python3 bench/bench_joint.py [--quick] [--previous DIR [--previous-kernel LIB]]``.

Prints, measured side by side in one run on the default joint:
* the compiled kernel (``tensegrity_stiffness_kernel``, when built) and the numpy path
  (``use_kernel=False``, the readable implementation): per-call ``evaluate`` and ``stiffness``,
  batched ``evaluate`` at N = 10^4 and 10^5 and ``interpretation_vector`` (against
  ``interpret_stiffness``); with ``--previous DIR`` also the same figures of an earlier checkout
  (e.g. ``mkdir DIR && git archive 5525cc4 | tar -x -C DIR``), imported in this process from
  DIR with its own kernel (compiled here from DIR's sources with the CMakeLists' flags, or
  ``--previous-kernel LIB``), and the ratios new / previous. All are timed in alternation (best
  of each), so that load on a shared machine falls on all alike;
* per-call analytic K (eq. 10) vs central-difference K (eq. 21), and their ratio; the
  central-difference baseline is given two ways (one vectorised wrench-only pass over the 12
  perturbed screws, and a loop of 12 single wrench calls) and the faster one is used;
* dT/dxi alone (closed form vs central differences);
* batched K throughput (configs/s) for N = 10^4 and 10^5 vs single calls;
* equilibrium solve time (median, p99) over random moderate wrenches.
Targets (issues 2 and 12): evaluate <= 40 us, K <= 25 us, >= 15x faster than central
differences, batched >= 500,000 configs/s at N = 10^4, equilibrium median <= 2 ms.
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
import timeit
from pathlib import Path
from types import ModuleType

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tensegrity_stiffness.geometry.screw import dexp_se3, exp_se3  # noqa: E402
from tensegrity_stiffness.mechanics import kernel  # noqa: E402
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium  # noqa: E402
from tensegrity_stiffness.mechanics.interpretation import (  # noqa: E402
    interpret_stiffness,
    interpretation_vector,
)
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402


def per_call_us(fn, repeat: int = 7, number: int = 2000) -> float:
    """Best-of-``repeat`` mean time per call, microseconds."""
    return min(timeit.repeat(fn, repeat=repeat, number=number)) / number * 1e6


def side_by_side(*fns, repeat: int, number: int) -> list[float]:
    """Best per-call time (us) of each of ``fns``, timed in alternation."""
    best = [math.inf] * len(fns)
    for _ in range(repeat):
        for i, fn in enumerate(fns):
            best[i] = min(best[i], timeit.timeit(fn, number=number) / number * 1e6)
    return best


def old_interpretation(K: np.ndarray) -> np.ndarray:
    """The 16 numbers from the readable :func:`interpret_stiffness`."""
    it = interpret_stiffness(K)
    return np.concatenate([it.block_norms, it.column_norms, it.row_norms])


def numpy_path(model) -> JointModel:
    """``model`` on the numpy path (``use_kernel=False``), of the model's own package."""
    return type(model)(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                       link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
                       force_law=model.force_law, initial_screw=model.initial_screw,
                       use_kernel=False)


def build_previous_kernel(root: Path, out_dir: Path) -> Path:
    """The kernel of the checkout ``root`` compiled with its CMakeLists' flags (g++)."""
    folder = root / 'tensegrity_stiffness_kernel'
    sources = sorted(str(p) for p in (folder / 'src').glob('*.cpp'))
    includes = [f'-I{folder / "include"}'] if (folder / 'include').is_dir() else []
    library = out_dir / kernel.LIBRARY_NAME
    subprocess.run(['g++', '-std=c++17', '-O2', '-ffp-contract=off', '-fno-fast-math', '-fPIC',
                    '-shared', *includes, *sources, '-o', str(library)], check=True)
    return library


def import_previous(root: Path, library: Path) -> tuple[ModuleType, ModuleType]:
    """``tensegrity_stiffness.mechanics.joint`` and ``.kernel`` of the checkout ``root``, imported
    beside this package (its modules swapped out of ``sys.modules`` meanwhile), bound to
    ``library``."""
    prefix = 'tensegrity_stiffness'
    ours = {k: v for k, v in sys.modules.items() if k == prefix or k.startswith(prefix + '.')}
    for name in ours:
        del sys.modules[name]
    setting = os.environ.get(kernel.KERNEL_ENV)
    os.environ[kernel.KERNEL_ENV] = str(library)
    sys.path.insert(0, str(root))
    try:
        joint = importlib.import_module(f'{prefix}.joint')
        previous_kernel = importlib.import_module(f'{prefix}.kernel')
        previous_kernel.status()  # loads the library now, under the setting above
        assert Path(joint.__file__).resolve().is_relative_to(root.resolve()), joint.__file__
    finally:
        sys.path.remove(str(root))
        for name in [k for k in sys.modules if k == prefix or k.startswith(prefix + '.')]:
            del sys.modules[name]
        sys.modules.update(ours)
        if setting is None:
            del os.environ[kernel.KERNEL_ENV]
        else:
            os.environ[kernel.KERNEL_ENV] = setting
    return joint, previous_kernel


def compare_with_previous(model: JointModel, xi: np.ndarray, rng: np.random.Generator,
                          number: int, previous: ModuleType | None) -> None:
    """The compiled kernel and the numpy path (and those of the previous checkout), side by
    side."""
    paths = [('kernel', model), ('numpy', numpy_path(model))]
    print(f'joint kernel: {kernel.status()}')
    if previous is not None:
        joint, previous_kernel = previous
        old = joint.JointModel.from_yaml(ROOT / 'config' / 'default_joint.yaml')
        paths += [('prev kernel', old), ('prev numpy', numpy_path(old))]
        print(f'previous: {Path(joint.__file__).parents[1]}, {previous_kernel.status()}')
    assert [m.uses_kernel for _, m in paths] == [True, False] * (len(paths) // 2), \
        'the kernel is not loaded (build it: bash scripts/setup_env.sh)'
    K = model.stiffness(xi)
    rows = [
        ('evaluate (us per call)', side_by_side(*(lambda m=m: m.evaluate(xi) for _, m in paths),
                                                repeat=7, number=number)),
        ('stiffness K (us per call)', side_by_side(*(lambda m=m: m.stiffness(xi)
                                                     for _, m in paths),
                                                   repeat=7, number=number)),
    ]
    print(f'  {"":<34}' + ''.join(f'{name:>13}' for name, _ in paths)
          + ('  time new/prev: kernel  numpy' if previous else ''))

    def line(name: str, values: list[float], fmt: str, ratios: list[float]) -> None:
        print(f'  {name:<34}' + ''.join(f'{v:{fmt}}' for v in values)
              + ''.join(f'{r:7.3f}' if i else f'{r:24.3f}' for i, r in enumerate(ratios)))

    for name, times in rows:
        ratios = [times[0] / times[2], times[1] / times[3]] if previous else []
        line(name, times, '13.1f', ratios)
    for n in (10_000, 100_000):
        xs = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3, size=(n, 6))
        for _, m in paths:
            m.evaluate(xs[:1000])  # warm up
        # Kernels with kernels, numpy with numpy: a large numpy run between two kernel runs
        # changes malloc's state (its mmap threshold) for the next one.
        times = [math.inf] * len(paths)
        for group in (paths[0::2], paths[1::2]):
            best = side_by_side(*(lambda m=m, xs=xs: m.evaluate(xs) for _, m in group),
                                repeat=5, number=1)
            for (name, _), t in zip(group, best, strict=True):
                times[[p[0] for p in paths].index(name)] = t
        ratios = [times[0] / times[2], times[1] / times[3]] if previous else []
        line(f'batched evaluate, N = {n:,} (cfg/s)', [n / t * 1e6 for t in times], '13,.0f',
             ratios)
    t_new, t_old = side_by_side(lambda: interpretation_vector(K), lambda: old_interpretation(K),
                                repeat=7, number=number)
    print(f'  interpretation_vector {t_new:.1f} us, interpret_stiffness {t_old:.1f} us')
    ref = paths[1][1].evaluate(xi)
    for label, m in paths[:1] + paths[2:]:
        state = m.evaluate(xi)
        worst = max(float(np.max(np.abs(getattr(state, f) - getattr(ref, f)))
                          / np.max(np.abs(getattr(ref, f))))
                    for f in ('wrench', 'stiffness', 'cartesian_stiffness', 'tensions',
                              'lengths'))
        print(f'  largest difference {label} - numpy (relative to the largest entry): '
              f'{worst:.1e}')
    print()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='fewer repetitions')
    parser.add_argument('--previous', type=Path, metavar='DIR',
                        help='a checkout of an earlier commit to measure side by side')
    parser.add_argument('--previous-kernel', type=Path, metavar='LIB',
                        help="its compiled kernel (default: compiled here from DIR's sources)")
    args = parser.parse_args()
    previous = None
    if args.previous is not None:
        with tempfile.TemporaryDirectory() as tmp:
            library = args.previous_kernel or build_previous_kernel(args.previous, Path(tmp))
            previous = import_previous(args.previous, library)
    number = 300 if args.quick else 2000
    model = JointModel.from_yaml(ROOT / 'config' / 'default_joint.yaml')
    rng = np.random.default_rng(0)
    xi = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3)
    step = 1e-6
    compare_with_previous(model, xi, rng, number, previous)

    def cd_loop() -> np.ndarray:
        cols = []
        for i in range(6):
            e = np.zeros(6)
            e[i] = step
            cols.append((model.wrench(xi + e) - model.wrench(xi - e)) / (2 * step))
        return np.stack(cols, axis=1)

    def dexp_cd() -> np.ndarray:
        e = np.eye(6) * step
        return (exp_se3(xi + e) - exp_se3(xi - e)) / (2 * step)

    t_k = per_call_us(lambda: model.stiffness(xi), number=number)
    t_eval = per_call_us(lambda: model.evaluate(xi), number=number)
    t_cd_vec = per_call_us(lambda: model.numerical_stiffness(xi), number=number)
    t_cd_loop = per_call_us(cd_loop, number=max(number // 4, 50))
    t_cd = min(t_cd_vec, t_cd_loop)
    t_dexp = per_call_us(lambda: dexp_se3(xi), number=number)
    t_dexp_cd = per_call_us(dexp_cd, number=number)
    err = np.linalg.norm(model.stiffness(xi) - model.numerical_stiffness(xi)) / np.linalg.norm(
        model.stiffness(xi))

    print('per call (default joint, 12 strings)             time         ratio')
    print(f'  analytic K (eq. 10)                       {t_k:9.1f} us')
    print(f'  full evaluation (F, K, K_c, tensions)     {t_eval:9.1f} us')
    print(f'  central-difference K, vectorised           {t_cd_vec:9.1f} us   '
          f'{t_cd_vec / t_k:5.1f}x')
    print(f'  central-difference K, loop of 12 wrenches  {t_cd_loop:9.1f} us   '
          f'{t_cd_loop / t_k:5.1f}x')
    print(f'  analytic vs best central difference                      {t_cd / t_k:5.1f}x '
          f'(rel. difference {err:.1e})')
    print(f'  dT/dxi closed form (eqs. 12-18)           {t_dexp:9.1f} us')
    print(f'  dT/dxi central differences (vectorised)   {t_dexp_cd:9.1f} us   '
          f'{t_dexp_cd / t_dexp:5.1f}x')

    print('\nbatched K (full evaluation)                   configs/s    vs single')
    single_rate = 1e6 / t_eval
    print(f'  single calls                             {single_rate:12,.0f}')
    for n in (10_000, 100_000):
        xs = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3, size=(n, 6))
        model.evaluate(xs[:1000])  # warm up
        best = min(timeit.repeat(lambda xs=xs: model.evaluate(xs), repeat=3, number=1))
        print(f'  N = {n:>7,}                              {n / best:12,.0f}   '
              f'{n / best / single_rate:6.1f}x')

    solves = 300 if args.quick else 2000
    times = []
    iterations = []
    failures = 0
    for _ in range(solves):
        W = np.r_[rng.normal(scale=0.1, size=3), rng.normal(scale=0.002, size=3)]
        start = time.perf_counter()
        res = solve_equilibrium(model, W)
        times.append(time.perf_counter() - start)
        iterations.append(res.iterations)
        failures += not res.success
    times.sort()
    print(f'\nequilibrium ({solves} random moderate wrenches): median '
          f'{statistics.median(times) * 1e3:.3f} ms, p99 {times[int(0.99 * solves)] * 1e3:.3f} '
          f'ms, median iterations {statistics.median(iterations):.0f}, failures {failures}')


if __name__ == '__main__':
    main()
