#!/usr/bin/env python3
"""Dynamics benchmark (issues 28, 37), run by hand:
``python3 bench/bench_dynamics.py [--quick] [--previous DIR]``.

Prints, measured side by side in one run on the default joint and the default 5-joint spine
(twin default inertia, string damping 0.5 N s/m):
* per call: ``mass_matrix``, ``acceleration`` (with a velocity: the Coriolis terms' 12x12 block
  exponential), ``linearize`` and ``modes`` at the unloaded equilibrium (with damping: 12x12
  eigenproblem; without: the 6x6 one), ``linearize`` at a state off equilibrium (the 21 block
  exponentials of the derivatives of J and M), and numpy's ``eig`` alone for scale;
* against them, a central-difference linear model from the same run (12 + 12 + n + 6 pairs of
  ``acceleration`` calls) and its eigen-decomposition;
* the spine's ``mass_matrix``, ``modes`` and its central-difference linear model.
Then, side by side in alternation, the joint's ``modes`` (damped, undamped) and ``linearize``
with the compiled linear model (``tsk_joint_linear_model``), on the numpy path (the same model
with ``use_kernel=False``) and, with ``--previous DIR``, of an earlier checkout (``git archive
<commit> | tar -x -C DIR``; its kernel compiled from DIR's sources), with the ratios.
Targets: joint mass matrix <= 20 us (issue 28), joint modes <= 100 us damped and undamped
(issues 28, 37).
"""

from __future__ import annotations

import argparse
import sys
import timeit
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from previous_checkout import build_kernel, import_modules  # noqa: E402

from tensegrity_stiffness.mechanics import kernel  # noqa: E402
from tensegrity_stiffness.mechanics.chain import JointChain  # noqa: E402
from tensegrity_stiffness.mechanics.chain_dynamics import ChainDynamics  # noqa: E402
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.mechanics.joint_dynamics import JointDynamics  # noqa: E402

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


def numpy_model(model: JointModel, joint_module=None) -> JointModel:
    """``model`` on the numpy path (``use_kernel=False``)."""
    cls = JointModel if joint_module is None else joint_module.JointModel
    return cls(model.link1_nodes, model.connections, model.k, model.rest_lengths,
               link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
               force_law=model.force_law, initial_screw=model.initial_screw, use_kernel=False)


def compare_part(model: JointModel, xi: np.ndarray, repeat: int, number: int,
                 previous: dict | None) -> None:
    """modes (damped, undamped) and linearize: kernel, numpy path, previous checkout."""
    plain = numpy_model(model)
    columns = [('kernel', model, JointDynamics), ('numpy path', plain, JointDynamics)]
    if previous is not None:
        prev_dynamics = previous['tensegrity_stiffness.mechanics.dynamics']
        prev_joint = previous['tensegrity_stiffness.mechanics.joint']
        prev_model = prev_joint.JointModel(
            model.link1_nodes, model.connections, model.k, model.rest_lengths,
            link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
            force_law=model.force_law, initial_screw=model.initial_screw)
        columns.append(('previous', prev_model, prev_dynamics.JointDynamics))
    print('\nside by side (alternated, best mean per call, us):')
    if previous is not None:
        print(f'  previous: {previous["root"]}, {previous["kernel"].status()}')
    print(f'  {"call":30s}' + ''.join(f'{name:>13s}' for name, _, _ in columns)
          + ('   kernel / previous' if previous else '') + '   target')
    for label, damping, call, target in (
            ('modes, damped (0.5 N s/m)', DAMPING, 'modes', 100.0),
            ('modes, undamped', 0.0, 'modes', 100.0),
            ('linearize, damped', DAMPING, 'linearize', None)):
        fns = []
        for _, m, cls in columns:
            method = getattr(cls(m, string_damping=damping), call)
            fns.append(lambda fn=method: fn(xi))
        times = side_by_side(fns, repeat, number)
        ratio = f'   {times[0] / times[2]:17.2f}' if previous else ''
        goal = '' if target is None else (f'   <= {target:g} us '
                                           f'{"met" if times[0] <= target else "NOT met"}')
        print(f'  {label:30s}' + ''.join(f'{t:13.1f}' for t in times) + ratio + goal)


def load_previous(root: Path, out_dir: Path) -> dict:
    """The dynamics and joint modules of the checkout ``root`` with its own kernel."""
    library = build_kernel(root, out_dir)
    modules = import_modules(root, ['tensegrity_stiffness.mechanics.dynamics',
                                    'tensegrity_stiffness.mechanics.joint'], library)
    modules['root'] = root
    return modules


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--quick', action='store_true', help='fewer repetitions')
    parser.add_argument('--previous', type=Path, metavar='DIR',
                        help='also time an earlier checkout (git archive C | tar -x -C DIR)')
    args = parser.parse_args()
    repeat, number = (3, 200) if args.quick else (7, 2000)
    previous = None
    if args.previous is not None:
        import tempfile
        previous = load_previous(args.previous.resolve(), Path(tempfile.mkdtemp()))
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
    compare_part(model, xi, max(repeat, 5) * 3, max(number // 20, 20), previous)

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
