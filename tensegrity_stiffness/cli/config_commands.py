"""The config commands: ``new-config`` (a starter joint or spine config from a template, with its
unloaded equilibrium solved and written as ``initial_screw``;
:mod:`tensegrity_stiffness.mechanics.templates`; or a structure: the p-prism, the six-bar, a
joint or spine config as a structure, :mod:`tensegrity_stiffness.structures.templates`) and
``check-config`` (a config's unloaded equilibrium, stability, slack and saturated strings, modes
and whether its ``initial_screw`` is an equilibrium;
:func:`~tensegrity_stiffness.mechanics.templates.check_config`)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_OK,
    PROG,
    add_json,
    num,
    parse_number,
    positive_int,
    print_json,
    vector,
    yes,
)
from tensegrity_stiffness.cli.sensor_sets import (
    SENSORS,
    estimator_settings,
    parse_sensor_set,
    report_line,
    sensor_set_report,
)
from tensegrity_stiffness.mechanics import templates
from tensegrity_stiffness.mechanics.chain import MAX_JOINTS
from tensegrity_stiffness.mechanics.joint import MAX_STRINGS
from tensegrity_stiffness.nodes.registry import unknown_config_parameters
from tensegrity_stiffness.structures import templates as structure_templates


def _choices(args: argparse.Namespace) -> templates.JointChoices:
    """The template choices of the parsed options (None: the template's default)."""
    given = {name: getattr(args, name) for name in (
        'radius', 'pretension', 'rest_lengths', 'height', 'gap', 'link2_com', 'link2_inertia')
        if getattr(args, name) is not None}
    for name in ('stiffness', 'max_stretch', 'link2_mass'):
        if getattr(args, name) is not None:
            given[name] = getattr(args, name)
    return templates.JointChoices(template=args.template, n_strings=args.strings, **given)


#: The options each kind of template takes (the others are refused when given).
JOINT_OPTIONS = ('radius', 'height', 'gap', 'stiffness', 'pretension', 'rest_lengths',
                 'max_stretch', 'link2_mass', 'link2_com', 'link2_inertia', 'spine', 'spacing')
STRUCTURE_OPTIONS = {
    'prism': ('bars', 'radius', 'height', 'twist', 'stiffness', 'pretension', 'bar_mass',
              'force_law', 'ground', 'max_stretch'),
    'six-bar': ('bar_length', 'stiffness', 'pretension', 'bar_mass', 'force_law', 'ground',
                'max_stretch'),
    'from-config': ('config',),
}


def _refuse_foreign_options(args: argparse.Namespace) -> None:
    """ValueError naming an option given that the chosen template does not take."""
    every = set(JOINT_OPTIONS).union(*STRUCTURE_OPTIONS.values())
    takes = STRUCTURE_OPTIONS.get(args.template, JOINT_OPTIONS)
    for name in sorted(every - set(takes)):
        if getattr(args, name) not in (None, False):
            raise ValueError(f"--{name.replace('_', '-')} does not apply to --template "
                             f'{args.template}')


def _structure_document(args: argparse.Namespace) -> tuple[dict[str, Any], str]:
    """The structure template's document and its header's first line."""
    if args.template == 'from-config':
        if args.config is None:
            raise ValueError('--template from-config needs --config FILE (a joint or spine '
                             'config)')
        document = structure_templates.config_structure_document(config.load_yaml(args.config))
        return document, f'the structure of {args.config}'
    options: dict[str, Any] = {'ground': args.ground, 'force_law': args.force_law or 'hooke'}
    for name in ('stiffness', 'pretension', 'bar_mass', 'max_stretch'):
        if getattr(args, name) is not None:
            options[name] = getattr(args, name)
    if args.template == 'prism':
        for name in ('radius', 'height', 'twist'):
            if getattr(args, name) is not None:
                options[name] = getattr(args, name)
        bars = args.bars or structure_templates.DEFAULT_PRISM_BARS
        return structure_templates.prism_document(bars, **options), f'a regular {bars}-prism'

    if args.bar_length is not None:
        options['bar_length'] = args.bar_length
    return structure_templates.six_bar_document(**options), 'the 6-bar expanded octahedron'


def _cmd_new_structure(args: argparse.Namespace) -> int:
    document, what = _structure_document(args)
    made = ('the links at the config\'s screws' if args.template == 'from-config' else
            'rest lengths: an exact equilibrium at the pretension')
    return _write_document(args.out, document, [
        f'Structure written by {PROG} new-config --template {args.template}: {what}.',
        f'docs/structures.md; {made}.', f'Check it with: {PROG} structure check FILE'])


def _write_document(out: str | None, document: dict[str, Any], header: list[str]) -> int:
    """``document`` with ``header`` to the file ``out``, or to standard output."""
    if out:
        path = config.write_yaml(out, document, header)
        print(f'{PROG}: wrote {path}', file=sys.stderr)
    else:
        sys.stdout.write(config.yaml_text(document, header))
    return EXIT_OK


def _cmd_new_config(args: argparse.Namespace) -> int:
    _refuse_foreign_options(args)
    if args.template in structure_templates.TEMPLATES:
        return _cmd_new_structure(args)
    document = templates.starter_config(_choices(args), args.spine or 0, args.spacing)
    joint = config.parameters(document)['joint']
    return _write_document(args.out, document, [
        f'Starter config written by {PROG} new-config (template {args.template}).',
        f"Template {args.template}, {len(joint['string_names'])} strings; initial_screw: "
        'its unloaded equilibrium (docs/your_joint.md).',
        f'Check it with: {PROG} check-config FILE'])


def _print_check(path: Path, report: dict[str, Any]) -> None:
    screw_info = report['initial_screw']
    print(f"config: {path} ({report['n_strings']} strings)")
    print(f"unloaded equilibrium xi [wx wy wz vx vy vz] (rad, m): {vector(report['screw'])}")
    print(f"  residual |F| {num(report['residual'])} (N, N m); {report['message']}")
    print(f"  stable (K_c positive definite): {yes(report['stable'])}, margin "
          f"{num(report.get('stability_margin', float('nan')))}")
    print(f"  slack strings: {', '.join(report.get('slack', [])) or 'none'}; saturated: "
          f"{', '.join(report.get('saturated', [])) or 'none'}")
    if screw_info['given']:
        print(f"initial_screw: given, residual |F| {num(screw_info['residual'])}: "
              f"{'an' if screw_info['equilibrium'] else 'NOT an'} unloaded equilibrium")
    else:
        print('initial_screw: missing (solved from the documented starts)')
    if 'modes' in report:
        print(f"modes (Hz): {vector(report['modes']['frequencies_hz'])}")
    if 'chain' in report:
        print(f"spine: {report['chain']['n_joints']} joints, unloaded screws:")
        for i, xi in enumerate(report['chain']['unloaded_screws'], 1):
            print(f'  joint {i}: {vector(xi)}')
    for note in report['notes']:
        print(f'note: {note}')
    print(f"sound: {yes(report['sound'])}")


def _cmd_check_config(args: argparse.Namespace) -> int:
    if (args.file is None) == (args.example is None):
        raise ValueError('give a config FILE or --example NAME (one of them)')
    path = Path(args.file) if args.file else config.example_config_path(args.example)
    sensor_sets = [parse_sensor_set(text) for text in args.sensors or []]
    document = config.load_yaml(path)
    report = templates.check_config(document)
    report['config'] = str(path)
    # The node sections (limits.*, estimation.*, sim.*, ...) as the nodes judge them: a key
    # no node has makes a node refuse to start (strict_parameters: false, warn and run).
    unknown, strict = unknown_config_parameters(document)
    if strict:
        report['problems'] += unknown
    else:
        report['notes'] += [f'{line}: ignored (strict_parameters: false)' for line in unknown]
    report['sound'] = not report['problems']
    if sensor_sets and report['converged'] and not (strict and unknown):
        settings = estimator_settings(path)
        report['sensor_sets'] = [sensor_set_report(settings, report['screw'], sensors)
                                 for sensors in sensor_sets]
    if args.json:
        print_json(report)
    else:
        _print_check(path, report)
        for item in report.get('sensor_sets', []):
            print(report_line(item))
    if report['problems']:
        for problem in report['problems']:
            print(f'{PROG}: error: {problem}', file=sys.stderr)
        return EXIT_BAD_INPUT
    return EXIT_OK


def add_new_config_parser(sub: Any) -> None:
    """``new-config``."""
    p = sub.add_parser('new-config', help='a starter joint (or spine) config from a template',
                       description='Write a starter config (a ROS parameter file that every '
                                   'reader takes) from a template, with the unloaded '
                                   'equilibrium solved and written as joint.initial_screw. '
                                   'Templates: vertebra (the default sub-vertebra, scaled to '
                                   '--radius), ring (--strings strings between two rings of '
                                   'nodes with an apex on a mast). docs/your_joint.md. '
                                   'Structures (docs/structures.md): prism (--bars p, a '
                                   'regular p-prism), six-bar (the expanded octahedron), '
                                   'from-config (--config: a joint or spine config as a '
                                   'structure).')
    p.add_argument('--template', choices=templates.TEMPLATES + structure_templates.TEMPLATES,
                   default='vertebra', help='the template (default: vertebra)')
    p.add_argument('--strings', type=positive_int, metavar='N',
                   help=f'ring: number of strings (even, 6 to {MAX_STRINGS}; default '
                        f'{templates.DEFAULT_RING_STRINGS})')
    p.add_argument('--radius', type=parse_number, metavar='M',
                   help='node radius, m (vertebra: of nodes A and D, default 0.030162; ring: '
                        f'of the ring, default {templates.DEFAULT_RING_RADIUS}; prism: of its '
                        f'polygons, default {structure_templates.DEFAULT_RADIUS})')
    p.add_argument('--height', type=parse_number, metavar='M',
                   help='ring: mast height of the apex, m (default: the radius); prism: '
                        'height, m (default: twice the radius)')
    p.add_argument('--gap', type=parse_number, metavar='M',
                   help='ring: design height of link 2 over link 1, m (default: half the mast)')
    p.add_argument('--stiffness', type=parse_number, nargs='+', metavar='K',
                   help=f'string stiffness, N/m (one for all or one per string; default '
                        f'{templates.DEFAULT_STIFFNESS:g})')
    tension = p.add_mutually_exclusive_group()
    tension.add_argument('--pretension', type=parse_number, metavar='N',
                         help='string tension at the design pose, N (ring: of the apex '
                              f'strings, default {templates.DEFAULT_PRETENSION:g}; vertebra: of '
                              'every string; prism, six-bar: the largest string tension, '
                              f'default {structure_templates.DEFAULT_PRETENSION:g}); sets the '
                              'rest lengths')
    tension.add_argument('--rest-lengths', type=parse_number, nargs='+', metavar='L0',
                         help='rest lengths, m (one for all or one per string)')
    p.add_argument('--max-stretch', type=parse_number, metavar='M',
                   help=f'maximum length minus rest length, m (default '
                        f'{templates.DEFAULT_MAX_STRETCH:g}; prism, six-bar: maximum length '
                        'minus the length, default none)')
    p.add_argument('--link2-mass', type=parse_number, metavar='KG',
                   help="link 2's mass, kg (dynamics and the twin)")
    p.add_argument('--link2-com', type=parse_number, nargs=3, metavar=('X', 'Y', 'Z'),
                   help="link 2's centre of mass in {2}, m")
    p.add_argument('--link2-inertia', type=parse_number, nargs='+', metavar='I',
                   help="link 2's inertia about its centre of mass, kg m^2 (3 principal moments "
                        'or 9 values)')
    p.add_argument('--spine', type=positive_int, metavar='N',
                   help=f'write a spine of N joints (at most {MAX_JOINTS}) of this one, stacked '
                        'upright (chain section)')
    p.add_argument('--spacing', type=parse_number, metavar='M',
                   help="spine: distance between vertebrae along the template's axis, m "
                        '(default: the unloaded height, the vertebra: 0.040003 scaled)')
    structure = p.add_argument_group('structure templates (prism, six-bar, from-config)')
    structure.add_argument('--bars', type=positive_int, metavar='P',
                           help='prism: number of bars p (>= 3; default '
                                f'{structure_templates.DEFAULT_PRISM_BARS})')
    structure.add_argument('--twist', type=parse_number, metavar='RAD',
                           help='prism: the start twist of the top polygon, rad (default: the '
                                'equilibrium pi/2 - pi/p; the rest lengths are always those '
                                'of the equilibrium prism)')
    structure.add_argument('--bar-length', type=parse_number, metavar='M',
                           help='six-bar: bar length, m (default '
                                f'{structure_templates.DEFAULT_BAR_LENGTH:g})')
    structure.add_argument('--bar-mass', type=parse_number, metavar='KG',
                           help=f'mass of each bar, kg (default '
                                f'{structure_templates.DEFAULT_BAR_MASS:g})')
    structure.add_argument('--force-law', choices=('hooke', 'paper'),
                           help="the strings' force law (default hooke)")
    structure.add_argument('--ground', action='store_true',
                           help='add gravity (-z) and the ground under the structure')
    structure.add_argument('--config', metavar='FILE',
                           help='from-config: the joint or spine config')
    p.add_argument('--out', metavar='FILE', help='write here (default: stdout)')
    p.set_defaults(handler=_cmd_new_config)


def add_check_config_parser(sub: Any) -> None:
    """``check-config``."""
    p = sub.add_parser('check-config', help="a config's unloaded equilibrium, stability, "
                                            'strings, modes and initial_screw',
                       description='Validate a joint (or spine) config and report its unloaded '
                                   'equilibrium (residual), stability (K_c positive definite), '
                                   'slack and saturated strings, the modes, and whether the '
                                   'written joint.initial_screw is an equilibrium; a key of a '
                                   "node's section (limits, sensors, sim, ...) that no node has "
                                   'is named with the nearest. Exit 0 when the file is sound, 2 '
                                   'with the reason on stderr.')
    p.add_argument('file', nargs='?', metavar='FILE', help='the config (YAML)')
    p.add_argument('--example', metavar='NAME',
                   help='a packaged example of config/examples instead of FILE (its path is '
                        'printed), e.g. ring8_joint.yaml')
    p.add_argument('--sensors', nargs='+', metavar='SET',
                   help='also report what each sensor set determines at the unloaded '
                        f'equilibrium; a set is comma-separated from {", ".join(SENSORS)} '
                        '(e.g. --sensors tensions tensions,imu lengths); stds and the load mode '
                        "from the config's estimator_node parameters (sensors.*)")
    add_json(p)
    p.set_defaults(handler=_cmd_check_config)


