"""The joint's commands: ``joint`` (wrench, K, K_c, tensions, interpretation at a screw or pose),
``equilibrium`` (under an external wrench) and ``design`` (rest lengths for a pose, a load,
tension limits and a stiffness), with the joint options the figures share."""

from __future__ import annotations

import argparse
import sys
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
from tensegrity_stiffness.geometry.quaternion import quaternion_to_rotation, rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import CHART_LIMIT, log_se3
from tensegrity_stiffness.mechanics import design
from tensegrity_stiffness.mechanics.equilibrium import is_stable, solve_equilibrium
from tensegrity_stiffness.mechanics.interpretation import (
    BLOCK_NAMES,
    COLUMN_NAMES,
    ROW_NAMES,
    interpret_stiffness,
)
from tensegrity_stiffness.mechanics.joint import FORCE_LAWS, JointModel, JointState


# ------------------------------------------------------------------------------ joint inputs
def load_joint(args: argparse.Namespace) -> tuple[JointModel, Path, FloatArray]:
    """Joint model, config path and rest lengths (n,) from --config, --force-law,
    --rest-lengths."""
    path = Path(args.config) if args.config else config.packaged_config_path()
    try:
        section = dict(config.load_section(path, 'joint'))
    except ValueError as exc:
        raise ValueError(f'config {path}: {exc}') from None
    if args.force_law:
        section['force_law'] = args.force_law
    model = JointModel.from_dict(section)
    rest = model.rest_lengths
    if args.rest_lengths:
        values = np.asarray(args.rest_lengths, dtype=np.float64)
        if values.size == 1:
            values = np.full(model.n_strings, values[0])
        if values.size != model.n_strings:
            raise ValueError(f'--rest-lengths needs 1 or {model.n_strings} values (one per '
                             f'string), got {values.size}')
        rest = model.validate_rest_lengths(values, batched=False)
    return model, path, rest


def joint_screw(args: argparse.Namespace, model: JointModel) -> FloatArray:
    """The screw of --screw, or of --pose (on the branch nearest the config's initial screw, as
    the node does), or the config's initial screw (the unloaded equilibrium)."""
    if args.screw is not None:
        xi = np.asarray(args.screw, dtype=np.float64)
        if np.linalg.norm(xi[:3]) >= CHART_LIMIT:
            raise ValueError('--screw must have |omega| = |(wx, wy, wz)| < 2 pi')
        return xi
    if args.pose is not None:
        T = np.eye(4)
        try:  # the node's rule: unit within QUATERNION_UNIT_TOLERANCE, renormalised
            T[:3, :3] = quaternion_to_rotation(args.pose[3:])
        except ValueError as exc:
            raise ValueError(f'--pose [x y z qx qy qz qw]: {exc}') from None
        T[:3, 3] = args.pose[:3]
        return log_se3(T, reference=model.initial_screw)
    return model.initial_screw.copy()


def joint_report(model: JointModel, state: JointState, rest: FloatArray,
                 config: Path | str) -> dict[str, Any]:
    """Everything ``joint`` prints, as a JSON-ready dict (orderings as in docs/conventions.md)."""
    interp = interpret_stiffness(state.stiffness)
    T = state.transform
    strings = [
        {'name': name, 'link1_node': model.node_names[a], 'link2_node': model.link2_node_names[b],
         'length': float(length), 'rest_length': float(l0), 'tension': float(t),
         'state': 'slack' if sl else ('saturated' if sat else 'taut')}
        for name, (a, b), length, l0, t, sl, sat in zip(
            model.string_names, model.connections, state.lengths, rest, state.tensions,
            state.slack, state.saturated, strict=True)]
    return {
        'config': str(config),
        'force_law': model.force_law,
        'screw': state.screw,
        'transform': T,
        'position': T[:3, 3],
        'quaternion': rotation_to_quaternion(T[:3, :3]),
        'wrench': state.wrench,
        'energy': float(model.energy(state.screw, rest)),
        'stiffness': state.stiffness,
        'cartesian_stiffness': state.cartesian_stiffness,
        'cartesian_stiffness_positive_definite': is_stable(state.cartesian_stiffness),
        'tensions': state.tensions,
        'strings': strings,
        'interpretation': {
            'block_norms': dict(zip(BLOCK_NAMES, interp.block_norms, strict=True)),
            'column_norms': dict(zip(COLUMN_NAMES, interp.column_norms, strict=True)),
            'row_norms': dict(zip(ROW_NAMES, interp.row_norms, strict=True)),
        },
    }


def _print_joint(report: dict[str, Any]) -> None:
    n = len(report['strings'])
    print(f"joint: {report['config']} ({n} strings, force law {report['force_law']})")
    print(f"screw xi [wx wy wz vx vy vz] (rad, m): {vector(display(report['screw']))}")
    print(f"pose of link 2 in {{1}}: position (m) {vector(display(report['position']))}, "
          f"quaternion [x y z w] {vector(display(report['quaternion']))}")
    print(f"elastic energy U: {num(report['energy'])} J")
    print()
    print('string wrench F on link 2, in {1} about its origin (N, N m), eq. 9:')
    print('      ' + ''.join(c.rjust(CELL_WIDTH) for c in ROW_NAMES))
    print('      ' + ''.join(num(float(v), CELL_WIDTH) for v in display(report['wrench'])))
    print()
    print('strings (eq. 8):')
    print(f"  {'name':<14}{'nodes':>8}{'length (m)':>13}{'rest (m)':>11}{'tension (N)':>13}"
          '  state')
    for s in report['strings']:
        nodes = f"{s['link1_node']}-{s['link2_node']}"
        print(f"  {s['name']:<14}{nodes:>8}{num(s['length'], 13)}{num(s['rest_length'], 11)}"
              f"{num(s['tension'], 13)}  {s['state']}")
    print()
    print('stiffness K = dF/dxi (eq. 10); rows: wrench (N, N m), columns: screw (rad, m):')
    print('\n'.join(matrix_lines(np.asarray(report['stiffness']), ROW_NAMES, COLUMN_NAMES)))
    print()
    print('Cartesian stiffness K_c = -dF/d[dv; dw]; columns: spatial twist in {1}, linear first:')
    print('\n'.join(matrix_lines(np.asarray(report['cartesian_stiffness']), ROW_NAMES,
                                  KC_COLUMN_NAMES)))
    print(f"  symmetric part positive definite: "
          f"{yes(report['cartesian_stiffness_positive_definite'])}")
    print()
    interp = report['interpretation']
    print('interpretation (eqs. 19-20):')
    for title, key in (('block Frobenius norms', 'block_norms'),
                       ('column norms', 'column_norms'), ('row norms', 'row_norms')):
        cells = '  '.join(f'{k} {num(v)}' for k, v in interp[key].items())
        print(f'  {title:<22} {cells}')


def _cmd_joint(args: argparse.Namespace) -> int:
    model, path, rest = load_joint(args)
    state = model.evaluate(joint_screw(args, model), rest)
    report = joint_report(model, state, rest, path)
    if args.json:
        print_json(report)
    else:
        _print_joint(report)
    return EXIT_OK


def _cmd_equilibrium(args: argparse.Namespace) -> int:
    model, path, rest = load_joint(args)
    x0 = None if args.initial_screw is None else np.asarray(args.initial_screw)
    result = solve_equilibrium(model, np.asarray(args.wrench), rest, x0,
                               time_budget=args.time_budget)
    report: dict[str, Any] = {
        'external_wrench': np.asarray(args.wrench), 'success': result.success,
        'message': result.message, 'residual': result.residual,
        'iterations': result.iterations, 'stable': result.stable, 'screw': result.screw}
    if result.state is not None:
        report['joint'] = joint_report(model, result.state, rest, path)
    if args.json:
        print_json(report)
    else:
        print(f"equilibrium under W = {vector(report['external_wrench'])} (N, N m): "
              f'{result.message}')
        print(f'  residual |F + W| = {num(result.residual)}, iterations {result.iterations}, '
              f'stable: {yes(result.stable)}')
        print()
        if result.state is not None:
            _print_joint(report['joint'])
    if not result.success:
        print(f'{PROG}: no equilibrium found: {result.message}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


def tension_limits(args: argparse.Namespace) -> tuple[float, float]:
    """(MIN, MAX) of --tension-limits, checked: 0 < MIN < MAX."""
    t_min, t_max = args.tension_limits
    if not t_min > 0.0:
        raise ValueError(f'--tension-limits: MIN must be > 0 N, got {t_min:g}')
    if not t_max > t_min:
        raise ValueError(f'--tension-limits: MAX must exceed MIN, got {t_min:g} {t_max:g}')
    return t_min, t_max


def read_target_stiffness(path: str | Path) -> FloatArray:
    """The target K_c (6, 6) of a YAML file: key ``cartesian_stiffness`` with 6 rows of 6
    values or 36 values row-major (rows [fx fy fz mx my mz], columns [dx dy dz rx ry rz])."""
    document = config.load_yaml(path)
    if not isinstance(document, dict) or 'cartesian_stiffness' not in document:
        raise ValueError(f'--target-stiffness {path}: needs a "cartesian_stiffness" key '
                         '(6 rows of 6 values or 36 values, row-major)')
    try:
        values = np.asarray(document['cartesian_stiffness'], dtype=np.float64)
    except (TypeError, ValueError):
        raise ValueError(f'--target-stiffness {path}: cartesian_stiffness must be 36 numbers '
                         '(6 rows of 6 or flat, row-major)') from None
    if values.size != 36 or values.shape not in ((36,), (6, 6)):
        raise ValueError(f'--target-stiffness {path}: cartesian_stiffness must be 6x6 or 36 '
                         f'values, got shape {values.shape}')
    if not np.all(np.isfinite(values)):
        raise ValueError(f'--target-stiffness {path}: cartesian_stiffness must be finite')
    return values.reshape(6, 6)


def _cmd_design(args: argparse.Namespace) -> int:
    model, path, _ = load_joint(args)
    xi = joint_screw(args, model)
    W = np.asarray(args.wrench, dtype=np.float64)
    t_min, t_max = tension_limits(args)
    target = None
    if args.target_stiffness is not None:
        target = read_target_stiffness(args.target_stiffness)
    elif args.scale_stiffness is not None:
        if not args.scale_stiffness > 0.0:
            raise ValueError(f'--scale-stiffness must be > 0, got {args.scale_stiffness:g}')
        base = design.design_rest_lengths(model, xi, W, t_min, t_max,
                                          length_scale=args.length_scale)
        if base.success:
            target = args.scale_stiffness * base.cartesian_stiffness
    result = design.design_rest_lengths(model, xi, W, t_min, t_max, target,
                                        args.length_scale)
    strings = [{'name': name, 'length': float(length), 'rest_length': float(l0),
                'tension': float(t)}
               for name, length, l0, t in zip(
                   model.string_names, model.lengths(xi), result.rest_lengths, result.tensions,
                   strict=True)]
    report: dict[str, Any] = {
        'config': str(path), 'force_law': model.force_law, 'screw': xi, 'external_wrench': W,
        'tension_limits': [t_min, t_max], 'success': result.success,
        'message': result.message, 'rest_lengths': result.rest_lengths,
        'tensions': result.tensions, 'strings': strings,
        'cartesian_stiffness': result.cartesian_stiffness, 'stiffness': result.stiffness,
        'target_stiffness': target, 'stiffness_error': result.stiffness_error,
        'length_scale': result.length_scale, 'stable': result.stable}
    if args.json:
        print_json(report)
    else:
        print(f"design at screw {vector(display(xi))} under W = {vector(W)} (N, N m), "
              f'tensions in [{t_min:g}, {t_max:g}] N: {result.message}')
        if result.success:
            print()
            print(f"  {'name':<14}{'length (m)':>13}{'rest (m)':>13}{'tension (N)':>13}")
            for s in strings:
                print(f"  {s['name']:<14}{num(s['length'], 13)}{num(s['rest_length'], 13)}"
                      f"{num(s['tension'], 13)}")
            print()
            print('achieved Cartesian stiffness K_c; columns: spatial twist in {1}, linear '
                  'first:')
            print('\n'.join(matrix_lines(result.cartesian_stiffness, ROW_NAMES,
                                          KC_COLUMN_NAMES)))
            if target is not None:
                print(f'  stiffness error |S (K_c - K*) S| / |S K* S| = '
                      f'{num(result.stiffness_error)} (L = {num(result.length_scale)} m)')
            print(f'  stable: {yes(result.stable)}')
    if not result.success:
        print(f'{PROG}: no design: {result.message}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


def add_joint_options(p: argparse.ArgumentParser, screw: bool = True) -> None:
    """--config, --rest-lengths, --force-law and (``screw``) --screw or --pose."""
    g = p.add_argument_group('joint')
    g.add_argument('--config', metavar='YAML',
                   help='joint config: plain YAML with a "joint" mapping or a ROS parameter '
                        'file (default: the packaged config/default_joint.yaml)')
    g.add_argument('--rest-lengths', nargs='+', type=parse_number, metavar='L0',
                   help='rest lengths (m): one for all strings or one per string, config order')
    g.add_argument('--force-law', choices=FORCE_LAWS,
                   help="string force law (default: the config's; 'paper' = the authors' code)")
    if screw:
        _add_screw_or_pose(g, "screw xi = [omega; v] (rad, m); default: the config's "
                              'initial_screw (unloaded equilibrium)',
                           'pose of link 2 in {1}: position (m) and unit quaternion (ROS '
                           'order); turned into the screw nearest the initial screw')


def _add_screw_or_pose(g: Any, screw_help: str, pose_help: str) -> None:
    """The mutually exclusive --screw (6 values) and --pose (7 values) of a joint command."""
    s = g.add_mutually_exclusive_group()
    s.add_argument('--screw', nargs=6, type=parse_number,
                   metavar=('WX', 'WY', 'WZ', 'VX', 'VY', 'VZ'), help=screw_help)
    s.add_argument('--pose', nargs=7, type=parse_number,
                   metavar=('X', 'Y', 'Z', 'QX', 'QY', 'QZ', 'QW'), help=pose_help)


def add_design_options(p: argparse.ArgumentParser, limits_required: bool) -> None:
    """--config, --force-law, --screw or --pose, --wrench and --tension-limits."""
    g = p.add_argument_group('joint')
    g.add_argument('--config', metavar='YAML',
                   help='joint config (default: the packaged config/default_joint.yaml)')
    g.add_argument('--force-law', choices=FORCE_LAWS,
                   help="string force law (default: the config's)")
    _add_screw_or_pose(g, "target screw xi = [omega; v] (rad, m); default: the config's "
                          'initial_screw',
                       'target pose of link 2 in {1}: position (m) and unit quaternion '
                       '(ROS order), on the branch nearest the initial screw')
    p.add_argument('--wrench', nargs=6, type=parse_number, default=[0.0] * 6,
                   metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'),
                   help='external wrench on link 2 in {1} about its origin (N, N m; default 0)')
    p.add_argument('--tension-limits', nargs=2, type=parse_number, metavar=('MIN', 'MAX'),
                   required=limits_required,
                   default=None if limits_required else [design.DEFAULT_TENSION_MIN,
                                                         design.DEFAULT_TENSION_MAX],
                   help='string tension limits (N), 0 < MIN < MAX'
                        + ('' if limits_required else ' (default 0.1 1.5)'))
    p.set_defaults(rest_lengths=None)


# ------------------------------------------------------------------------------ parsers
def add_joint_parser(sub: Any) -> None:
    """``joint``."""
    p = sub.add_parser('joint', help='wrench, K, K_c, tensions, interpretation at a screw/pose',
                       description='Evaluate the joint at a screw or pose (eqs. 6-11, 19-20).')
    add_joint_options(p)
    add_json(p)
    p.set_defaults(handler=_cmd_joint)


def add_equilibrium_parser(sub: Any) -> None:
    """``equilibrium``."""
    p = sub.add_parser('equilibrium', help='equilibrium under an external wrench',
                       description='Solve F(xi) + W = 0 for the external wrench W on link 2 '
                                   '(in {1} about its origin) and report the joint there.')
    p.add_argument('--wrench', nargs=6, type=parse_number, required=True,
                   metavar=('FX', 'FY', 'FZ', 'MX', 'MY', 'MZ'), help='W (N, N m)')
    add_joint_options(p, screw=False)
    p.add_argument('--initial-screw', nargs=6, type=parse_number, metavar='XI',
                   help="start of the solve (default: the config's initial_screw)")
    p.add_argument('--time-budget', type=parse_number, metavar='S',
                   help='bound on the solve time (s; default: none)')
    add_json(p)
    p.set_defaults(handler=_cmd_equilibrium)


def add_design_parser(sub: Any) -> None:
    """``design``."""
    p = sub.add_parser('design', help='rest lengths for a pose, load, tension limits and '
                       'stiffness', description='Rest lengths that hold the target screw or pose '
                       'in equilibrium under the external wrench with every tension within the '
                       'limits and K_c closest to a target (exact convex QP).')
    add_design_options(p, limits_required=True)
    t = p.add_mutually_exclusive_group()
    t.add_argument('--target-stiffness', metavar='FILE.yaml',
                   help='target K_c: YAML with "cartesian_stiffness", 6 rows of 6 or 36 values '
                        '(row-major; N/m, N, N m/m, N m/rad)')
    t.add_argument('--scale-stiffness', type=parse_number, metavar='F',
                   help='target K_c = F times the K_c of the mid-limit design (no target)')
    p.add_argument('--length-scale', type=parse_number, metavar='M',
                   help='L of S = diag(1, 1, 1, 1/L, 1/L, 1/L) (m; default: the largest '
                        'distance of a link-1 node from the origin of {1})')
    add_json(p)
    p.set_defaults(handler=_cmd_design)
