"""The spine's command ``chain``: tip pose and exact tip stiffness of a chain of joints at screws,
or at its equilibrium under a tip wrench and the link weights, with the chain options of
``plot spine``."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.common import (
    CELL_WIDTH,
    EXIT_NO_SOLUTION,
    EXIT_OK,
    KC_COLUMN_NAMES,
    PROG,
    FloatArray,
    add_json,
    display,
    matrix_lines,
    num,
    parse_number,
    print_json,
    vector,
    yes,
)
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.mechanics.chain import (
    DEFAULT_SPINE_CONFIG,
    JointChain,
    solve_chain_equilibrium,
)
from tensegrity_stiffness.mechanics.equilibrium import is_stable
from tensegrity_stiffness.mechanics.interpretation import COLUMN_NAMES, ROW_NAMES

#: Tip wrench of the spine figure (docs/figures.md) (N, N m in the base frame): a sideways push.
README_SPINE_TIP_WRENCH = (0.1, 0.0, 0.0, 0.0, 0.0, 0.0)


def chain_configuration(args: argparse.Namespace
                         ) -> tuple[JointChain, Path, FloatArray, FloatArray, Any]:
    """(chain, config path, screws, tip wrench, equilibrium result or None) of --config,
    --screws, --tip-wrench, --gravity: the given screws, else the chain equilibrium."""
    path = Path(args.config) if args.config else config.packaged_config_path(
        DEFAULT_SPINE_CONFIG)
    try:
        chain = JointChain.from_yaml(path)
    except ValueError as exc:
        raise ValueError(f'config {path}: {exc}') from None
    W = np.asarray(args.tip_wrench, dtype=np.float64)
    if args.gravity is not None:
        chain.gravity = chain.resolved_gravity(np.asarray(args.gravity, dtype=np.float64))
    if args.screws is not None:
        values = np.asarray(args.screws, dtype=np.float64)
        if values.size != 6 * chain.n_joints:
            raise ValueError(f'--screws needs 6 N = {6 * chain.n_joints} values (joint-major '
                             f'[wx wy wz vx vy vz]), got {values.size}')
        return chain, path, values.reshape(chain.n_joints, 6), W, None
    result = solve_chain_equilibrium(chain, W, time_budget=args.time_budget)
    return chain, path, result.screws, W, result


def _cmd_chain(args: argparse.Namespace) -> int:
    chain, path, screws, W, result = chain_configuration(args)
    state = chain.evaluate(screws)
    residuals = chain.residuals(screws, W)
    report: dict[str, Any] = {
        'config': str(path), 'n_joints': chain.n_joints, 'tip_wrench': W,
        'gravity': chain.gravity, 'link_masses': chain.link_masses,
        'solved': result is not None,
        'success': True if result is None else result.success,
        'message': 'evaluated at the given screws' if result is None else result.message,
        'iterations': 0 if result is None else result.iterations,
        'residual': float(np.linalg.norm(residuals)), 'screws': screws,
        'joint_wrenches': state.wrenches,
        'slack_strings': [int(np.count_nonzero(s)) for s in state.slack],
        'tip_transform': state.tip_transform, 'tip_position': state.tip_transform[:3, 3],
        'tip_quaternion': rotation_to_quaternion(state.tip_transform[:3, :3]),
        'base_frame': chain.base_frame, 'tool_frame': chain.tool_frame}
    try:
        K = chain.tip_stiffness_from_state(state, W)
        report['tip_stiffness'] = K
        report['tip_stiffness_tool'] = chain.tip_stiffness_from_state(state, W, frame='tool')
        report['stable'] = is_stable(chain.tangent_stiffness(screws, W))
    except np.linalg.LinAlgError:
        report['tip_stiffness'] = report['tip_stiffness_tool'] = None
        report['stable'] = False
    if args.json:
        print_json(report)
    else:
        _print_chain(report)
    if not report['success']:
        print(f'{PROG}: no equilibrium found: {report["message"]}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


def _print_chain(report: dict[str, Any]) -> None:
    print(f"chain: {report['config']} ({report['n_joints']} joints)")
    print(f"tip wrench W (N, N m, base frame): {vector(report['tip_wrench'])}; gravity "
          f"{vector(report['gravity'])} m/s^2, link masses {vector(report['link_masses'])} kg")
    what = 'equilibrium' if report['solved'] else 'configuration'
    print(f"{what}: {report['message']}; residual {num(report['residual'])}, iterations "
          f"{report['iterations']}, stable: {yes(report['stable'])}")
    print()
    print('  joint' + ''.join(c.rjust(CELL_WIDTH) for c in COLUMN_NAMES) + '  slack')
    for i, (xi, slack) in enumerate(zip(display(report['screws']), report['slack_strings'],
                                        strict=True)):
        print(f'  {i + 1:>5}' + ''.join(num(float(v), CELL_WIDTH) for v in xi) + f'  {slack:>5}')
    print()
    print(f"tip pose in {report['base_frame']}: position (m) "
          f"{vector(display(report['tip_position']))}, quaternion [x y z w] "
          f"{vector(display(report['tip_quaternion']))}")
    for key, frame in (('tip_stiffness', f"base frame ({report['base_frame']})"),
                       ('tip_stiffness_tool', f"tool frame ({report['tool_frame']})")):
        print()
        if report[key] is None:
            print(f'tip stiffness in the {frame}: singular')
            continue
        print(f'tip stiffness dW/d[dv; dw] in the {frame}; rows: wrench (N, N m), columns: '
              'tip twist, linear first:')
        print('\n'.join(matrix_lines(np.asarray(report[key]), ROW_NAMES, KC_COLUMN_NAMES)))


def add_chain_options(p: argparse.ArgumentParser, tip_wrench: Sequence[float]) -> None:
    """--config, --screws, --tip-wrench (default ``tip_wrench``), --gravity, --time-budget."""
    g = p.add_argument_group('chain')
    g.add_argument('--config', metavar='YAML',
                   help='spine config (ROS parameter file or plain YAML with "joint" and '
                        '"chain"; default: the packaged config/default_spine.yaml)')
    g.add_argument('--screws', nargs='+', type=parse_number, metavar='XI',
                   help='6 N values, joint-major [wx wy wz vx vy vz] (default: the chain '
                        'equilibrium under --tip-wrench and the weights)')
    g.add_argument('--tip-wrench', nargs=6, type=parse_number, default=list(tip_wrench),
                   metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'),
                   help='wrench on the last link in the base frame about its origin (N, N m; '
                        f'default {" ".join(f"{v:g}" for v in tip_wrench)})')
    g.add_argument('--gravity', nargs=3, type=parse_number, metavar=('GX', 'GY', 'GZ'),
                   help="gravity in the base frame (m/s^2; default: the config's; acts on "
                        'chain.link_masses)')
    g.add_argument('--time-budget', type=parse_number, metavar='S',
                   help='bound on the equilibrium solve (s; default: none)')


def add_chain_parser(sub: Any) -> None:
    """``chain``."""
    p = sub.add_parser('chain', help='a spine of joints: tip pose and tip stiffness',
                       description='Tip pose and exact tip stiffness of a chain of joints at '
                                   '--screws (under the given loads), or at its equilibrium '
                                   'under --tip-wrench and the link weights.')
    add_chain_options(p, (0.0,) * 6)
    add_json(p)
    p.set_defaults(handler=_cmd_chain)
