"""The planar mechanism's commands: ``planar-fk`` (forward kinematics at (L3, theta1)) and
``planar-ik`` (inverse kinematics at D3 = (x, y)), with the mechanism options the figures share."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.common import (
    EXIT_NO_SOLUTION,
    EXIT_OK,
    PROG,
    add_json,
    num,
    parse_number,
    print_json,
    vector,
    yes,
)
from tensegrity_stiffness.mechanics.planar import SINGULARITY_DESCRIPTIONS, PlanarMechanism
from tensegrity_stiffness.nodes.stiffness_node import PLANAR_PARAMETERS

#: Keys of the planar mechanism (the node's ``planar.*`` parameters without the prefix).
PLANAR_KEYS = tuple(spec.name[len('planar.'):] for spec in PLANAR_PARAMETERS)
#: Defaults of the commands' mechanism options (the help text).
CONFIG_DEFAULTS = "the config's planar section (L = 1, K1 = 100, K2 = 10)"


def planar_mechanism(args: argparse.Namespace, base: dict[str, float]) -> PlanarMechanism:
    """PlanarMechanism from ``base`` overridden by the --L, --K1, ... options that were given."""
    params = dict(base)
    for key in PLANAR_KEYS:
        value = getattr(args, f'planar_{key}', None)
        if value is not None:
            params[key] = value
    return PlanarMechanism(**{k: params[k] for k in PLANAR_KEYS if k in params})


def planar_config(args: argparse.Namespace) -> dict[str, float]:
    """The node's planar parameters: the ``planar`` section of --config (default: the packaged
    config), missing keys from the node's parameter table."""
    path = Path(args.config) if args.config else config.packaged_config_path()
    section = config.load_section(path, 'planar', required=False)
    params = {}
    for spec in PLANAR_PARAMETERS:
        key = spec.name[len('planar.'):]
        try:
            params[key] = spec.check(section.get(key, spec.default))
        except ValueError as exc:
            raise ValueError(f'config {path}: {exc}') from None
    return params


def _mech_line(mech: PlanarMechanism) -> str:
    """The mechanism's parameters in one line."""
    return (f'L = {num(mech.L)} m, K1 = {num(mech.K1)} N/m, K2 = {num(mech.K2)} N/m, '
            f'L3 in [{num(mech.L3_min)}, {num(mech.L3_max)}] m, theta1 in '
            f'[{num(mech.theta1_min)}, {num(mech.theta1_max)}], theta2 in '
            f'[{num(mech.theta2_min)}, {num(mech.theta2_max)}] rad')


def _singularity_lines(names: Sequence[str]) -> list[str]:
    """The singular conditions ``names``, described."""
    if not names:
        return ['  singular conditions: none']
    return ['  singular conditions:'] + [f'    {n}: {SINGULARITY_DESCRIPTIONS[n]}'
                                         for n in names]


def _cmd_planar_fk(args: argparse.Namespace) -> int:
    mech = planar_mechanism(args, planar_config(args))
    r = mech.forward(args.L3, args.theta1)
    report = {name: getattr(r, name) for name in r.__dataclass_fields__}
    report['mechanism'] = {k: getattr(mech, k) for k in PLANAR_KEYS}
    if args.json:
        print_json(report)
        return EXIT_OK
    print(f'planar forward kinematics ({_mech_line(mech)})')
    print(f'  actuator        L3 = {num(r.L3)} m, theta1 = {num(r.theta1)} rad '
          f'(in range: {yes(r.actuator_in_range)})')
    print(f'  D3              x = {num(r.x)} m, y = {num(r.y)} m')
    print(f'  theta2          {num(r.theta2)} rad (stable root of eq. 5; in range: '
          f'{yes(r.theta2_in_range)})')
    print(f'  stiffness K     {num(r.stiffness)} N m/rad (eq. 42)')
    print(f'  energy U        {num(r.energy)} J (eq. 4)')
    print(f'  stable          {yes(r.stable)}')
    print(f'  unstable root   theta2 = {num(r.theta2_unstable)} rad, D3 = ({num(r.x_unstable)}'
          f', {num(r.y_unstable)}) m, K = {num(r.stiffness_unstable)} N m/rad')
    print(f'  Jacobian d(x, y)/d(L3, theta1) (eqs. 17-22): {vector(r.jacobian[0])} '
          f'{vector(r.jacobian[1])}, det J = {num(r.jacobian_determinant)} m')
    print('\n'.join(_singularity_lines(r.singularities)))
    return EXIT_OK


def _cmd_planar_ik(args: argparse.Namespace) -> int:
    mech = planar_mechanism(args, planar_config(args))
    result = mech.inverse(args.x, args.y, include_unstable=args.include_unstable,
                          require_theta2_in_range=args.require_theta2_in_range)
    solutions = [{name: getattr(s, name) for name in s.__dataclass_fields__} for s in result]
    report = {'x': result.x, 'y': result.y, 'solutions': solutions, 'reason': result.reason,
              'mechanism': {k: getattr(mech, k) for k in PLANAR_KEYS}}
    if args.json:
        print_json(report)
    else:
        print(f'planar inverse kinematics of D3 = ({num(result.x)}, {num(result.y)}) m '
              f'({_mech_line(mech)})')
        if not solutions:
            print(f'  no solution: {result.reason}')
        else:
            print(f"  {'#':<3}{'L3 (m)':>11}{'theta1':>11}{'theta2':>11}{'K (N m/rad)':>13}"
                  f"{'U (J)':>11}{'det J (m)':>11}  stable  theta2 in range  singular")
            for k, s in enumerate(result):
                print(f'  {k:<3}{num(s.L3, 11)}{num(s.theta1, 11)}{num(s.theta2, 11)}'
                      f'{num(s.stiffness, 13)}{num(s.energy, 11)}'
                      f'{num(s.jacobian_determinant, 11)}  {yes(s.stable):<6}  '
                      f'{yes(s.theta2_in_range):<14}  {",".join(s.singularities) or "-"}')
    if not solutions:
        print(f'{PROG}: no solution: {result.reason}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    return EXIT_OK


def add_planar_options(p: argparse.ArgumentParser, defaults: str, config: bool) -> None:
    """--L, --K1, ... (one per :data:`PLANAR_KEYS`) and (``config``) --config."""
    g = p.add_argument_group('planar mechanism', f'defaults: {defaults}')
    if config:
        g.add_argument('--config', metavar='YAML',
                       help='read the "planar" section of this config (default: the packaged '
                            'config/default_joint.yaml)')
    units = {'L': 'm', 'K1': 'N/m', 'K2': 'N/m', 'L3_min': 'm', 'L3_max': 'm',
             'theta1_min': 'rad', 'theta1_max': 'rad', 'theta2_min': 'rad', 'theta2_max': 'rad'}
    for key in PLANAR_KEYS:
        g.add_argument('--' + key.replace('_', '-'), dest=f'planar_{key}', type=parse_number,
                       metavar='VALUE',
                       help=f'{key} ({units[key]})')


def add_planar_fk_parser(sub: Any) -> None:
    """``planar-fk``."""
    p = sub.add_parser('planar-fk', help='planar mechanism forward kinematics',
                       description='Stable equilibrium, stiffness, Jacobian and singular '
                                   'conditions at actuator (L3, theta1).')
    p.add_argument('L3', type=parse_number, help='actuator length (m)')
    p.add_argument('theta1', type=parse_number, help='actuator angle (rad), e.g. pi/10')
    add_planar_options(p, CONFIG_DEFAULTS, True)
    add_json(p)
    p.set_defaults(handler=_cmd_planar_fk)


def add_planar_ik_parser(sub: Any) -> None:
    """``planar-ik``."""
    p = sub.add_parser('planar-ik', help='planar mechanism inverse kinematics',
                       description='Actuator states (L3, theta1) holding D3 at (x, y) in '
                                   'stable equilibrium, stiffest first.')
    p.add_argument('x', type=parse_number, help='D3 x (m)')
    p.add_argument('y', type=parse_number, help='D3 y (m)')
    p.add_argument('--include-unstable', action='store_true',
                   help='also list unstable equilibria')
    p.add_argument('--require-theta2-in-range', action='store_true',
                   help='drop solutions with theta2 outside its range')
    add_planar_options(p, CONFIG_DEFAULTS, True)
    add_json(p)
    p.set_defaults(handler=_cmd_planar_ik)
