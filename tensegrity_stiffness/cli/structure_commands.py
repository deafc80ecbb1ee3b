"""``tensegrity-stiffness structure``: any structure of bodies and strings (docs/structures.md).

* ``structure check FILE`` the equilibrium with the file's gravity and ground, its stability,
  slack and saturated strings, bar and contact forces and the pin-jointed analysis
  (:func:`~tensegrity_stiffness.structures.report.check_structure`); exit 0 sound, 2 with the
  reason on stderr.
* ``structure equilibrium FILE`` the equilibrium under loads (``--load BODY FX FY FZ MX MY
  MZ``): poses, tensions, contacts; ``--out`` writes the file with the bodies at it.
* ``structure form-find FILE --method force-density | kinematic | design`` the forms of
  :mod:`~tensegrity_stiffness.structures.form_finding`, written with ``--out``.
* ``structure modes FILE`` the natural frequencies, damping ratios and the named zero modes
  at the equilibrium (:func:`~tensegrity_stiffness.structures.modes.structure_modes`).
* ``structure plot FILE`` the 3D figure (:mod:`.structure_plots`) at the equilibrium or the
  start.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.common import (
    EXIT_BAD_INPUT,
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
from tensegrity_stiffness.mechanics.templates import pose_vector
from tensegrity_stiffness.structures import form_finding, templates
from tensegrity_stiffness.structures.analysis import framework_of
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.modes import structure_modes
from tensegrity_stiffness.structures.report import check_structure
from tensegrity_stiffness.structures.structure import Structure

METHODS = ('force-density', 'kinematic', 'design')
#: Damping ratios up to this are rounding of an undamped structure's (not printed).
DAMPING_RATIO_ZERO = 1e-12


def _structure_path(args: argparse.Namespace) -> Path:
    if (args.file is None) == (getattr(args, 'example', None) is None):
        raise ValueError('give a structure FILE or --example NAME (one of them)')
    return Path(args.file) if args.file else config.example_config_path(args.example)


def _loads(structure: Structure, given: list[list[str]] | None) -> dict[str, Any] | None:
    """{body: (6,)} of the ``--load BODY FX FY FZ MX MY MZ`` options (summed per body)."""
    if not given:
        return None
    loads: dict[str, Any] = {}
    for entry in given:
        name = entry[0]
        structure.body_index(name)  # ValueError naming it
        values = np.array([parse_number(v) for v in entry[1:]])
        loads[name] = loads.get(name, np.zeros(6)) + values
    return loads


def _print_check(path: Path, r: dict[str, Any]) -> None:
    eq = r['equilibrium']
    print(f"structure: {path} ({r['n_bodies']} bodies, {r['n_bars']} bars, "
          f"{r['n_strings']} strings; gravity {'yes' if r['gravity'] else 'no'}, ground "
          f"{yes(r['ground'])})")
    print(f"equilibrium: {eq['message']}, residual {num(eq['residual'])} (N, N m), "
          f"{eq['iterations']} iterations")
    print(f"  stable (tangent stiffness positive definite): {yes(eq['stable'])}, margin "
          f"{num(eq['stability_margin'])}")
    if 'tensions' in r:
        t = np.array(list(r['tensions'].values()))
        slack, saturated = ', '.join(r['slack']) or 'none', ', '.join(r['saturated']) or 'none'
        print(f'  tensions (N): {num(t.min())} .. {num(t.max())}; slack: {slack}; saturated: '
              f'{saturated}')
        if r['bar_forces']:
            f = np.array(list(r['bar_forces'].values()))
            print(f'  bar compressions (N): {num(f.min())} .. {num(f.max())}')
    for node, force in r['contacts'].items():
        slide = ' (sliding)' if node in r['sliding'] else ''
        print(f'  contact {node}: {vector(force)} N{slide}')
    if r['modes'] is not None:
        counts = ', '.join(f'{v} {k}' for k, v in r['modes']['counts'].items())
        print(f"modes (Hz): {vector(r['modes']['frequencies_hz'])}; zero modes: {counts}")
    b = r['body_counts']
    if b is not None:
        print(f"bodies: {b['self_stresses']} string self-stress(es), {b['mechanisms']} "
              f"mechanism(s) ({b['rigid_motions']} rigid motions and {b['spins']} bar spins "
              'removed)')
    a = r['analysis']
    if a is not None:
        print(f"analysis: {a['self_stresses']} self-stress(es), {a['mechanisms']} mechanism(s) "
              f"({a['n_nodes']} nodes, {a['n_members']} members, {a['rigid_motions']} rigid "
              'motions removed)')
        if 'stress_nullity' in a:
            print(f"  stress matrix: nullity {a['stress_nullity']}, positive semi-definite "
                  f"{yes(a['stress_psd'])}; prestress stable {yes(a['prestress_stable'])}; "
                  f"super stable {'n/a' if a['super_stable'] is None else yes(a['super_stable'])}")
    for note in r['notes']:
        print(f'note: {note}')
    print(f"sound: {yes(r['sound'])}")


def _cmd_check(args: argparse.Namespace) -> int:
    path = _structure_path(args)
    structure = Structure.from_yaml(path)
    report = check_structure(structure)
    report['file'] = str(path)
    if args.plot:
        _plot_equilibrium(structure, args.plot, None)
    if args.json:
        print_json(report)
    else:
        _print_check(path, report)
    for problem in report['problems']:
        print(f'{PROG}: error: {problem}', file=sys.stderr)
    return EXIT_BAD_INPUT if report['problems'] else EXIT_OK


def _with_poses(structure: Structure, poses: np.ndarray) -> dict[str, Any]:
    """The structure's document with its bodies at ``poses`` (N, 4, 4)."""
    document = structure.to_dict()
    for body, T in zip(document['structure']['bodies'], poses, strict=True):
        body['pose'] = pose_vector(T)
    return document


def _write(path: str, document: dict[str, Any], header: list[str]) -> None:
    written = config.write_yaml(path, document, header)
    print(f'{PROG}: wrote {written}', file=sys.stderr)


def _cmd_equilibrium(args: argparse.Namespace) -> int:
    path = _structure_path(args)
    structure = Structure.from_yaml(path)
    eq = solve_structure_equilibrium(structure, _loads(structure, args.load))
    out: dict[str, Any] = {'file': str(path), 'success': eq.success, 'message': eq.message,
                           'residual': eq.residual, 'stable': eq.stable,
                           'stability_margin': eq.stability_margin,
                           'poses': dict(zip(structure.body_names,
                                             [pose_vector(T) for T in eq.poses], strict=True)),
                           'contacts': {k: list(map(float, v)) for k, v in eq.contacts.items()}}
    if eq.state is not None:
        out['tensions'] = dict(zip(structure.string_names, map(float, eq.state.tensions),
                                   strict=True))
        out['bar_forces'] = dict(zip(structure.bar_names, map(float, eq.state.bar_forces),
                                     strict=True))
    if args.json:
        print_json(out)
    else:
        print(f'equilibrium: {eq.message}, residual {num(eq.residual)}; stable {yes(eq.stable)}')
        print('poses [x y z qx qy qz qw] (m):')
        for name, pose in out['poses'].items():
            print(f'  {name}: {vector(pose)}')
        for name, t in out.get('tensions', {}).items():
            print(f'  tension {name}: {num(t)} N')
        for node, force in out['contacts'].items():
            print(f'  contact {node}: {vector(force)} N')
    if not eq.success:
        return EXIT_NO_SOLUTION
    if args.out:
        _write(args.out, _with_poses(structure, eq.poses),
               [f'{path} at its equilibrium ({PROG} structure equilibrium).'])
    if args.plot:
        _plot_equilibrium(structure, args.plot, eq)
    return EXIT_OK


def _densities(framework: Any, given: list[str] | None) -> np.ndarray:
    """Force densities of ``--density PREFIX=Q`` (each member takes the longest prefix of its
    name given); ValueError naming a member without one."""
    if not given:
        raise ValueError('--method force-density needs --density PREFIX=Q for every member '
                         '(e.g. --density bottom=1 --density top=1 --density vertical=1.732 '
                         '--density bar=-1.732)')
    table = {}
    for item in given:
        prefix, sep, value = item.partition('=')
        if not sep or not prefix:
            raise ValueError(f'--density must be PREFIX=Q, got {item!r}')
        table[prefix] = parse_number(value)
    q = []
    for name in framework.member_names:
        matches = [p for p in table if name.startswith(p)]
        if not matches:
            raise ValueError(f'--density: no prefix matches member {name!r}')
        q.append(table[max(matches, key=len)])
    return np.array(q)


def _form_document(structure: Structure, framework: Any, pretension: float | None
                   ) -> dict[str, Any]:
    """The document of a free structure of bars at a found form (its member forces, scaled to
    ``pretension``, None: the file's largest tension at its start)."""
    layout = templates.layout_of(structure, framework.positions)
    if pretension is None:
        top = float(structure.evaluate().tensions.max())
        pretension = top if top > 0.0 else templates.DEFAULT_PRETENSION
    document = templates.structure_document_of_layout(
        layout, stiffness=structure.k, pretension=pretension,
        bar_mass=[b.mass for b in structure.bodies], force_law=structure.force_law,
        tensions=framework.forces)
    original = structure.to_dict()['structure']
    for key in ('gravity', 'ground'):
        if key in original:
            document['structure'][key] = original[key]
    return document


def _cmd_form_find(args: argparse.Namespace) -> int:
    path = _structure_path(args)
    structure = Structure.from_yaml(path)
    info: dict[str, Any] = {'file': str(path), 'method': args.method}
    if args.method == 'design':
        design = form_finding.design_rest_lengths_for_shape(structure, None, args.t_min,
                                                            args.t_max)
        info.update(success=design.success, message=design.message,
                    rest_lengths=dict(zip(structure.string_names, design.rest_lengths,
                                          strict=True)),
                    tensions=dict(zip(structure.string_names, design.tensions, strict=True)))
        document = structure.to_dict()
        for entry, rest in zip(document['structure']['strings'], design.rest_lengths,
                               strict=True):
            entry['rest_length'] = float(rest)
        success = design.success
    else:
        templates.layout_of(structure)  # refuses supports and general bodies by name
        fw = framework_of(structure)
        if args.method == 'force-density':
            result = form_finding.force_density_form(fw, _densities(fw, args.density),
                                                     start=fw.positions)
        else:
            result = form_finding.kinematic_form(fw, args.lengthen)
        success = result.success
        info.update(success=success, message=result.message, **result.info)
        if success and result.framework.forces is None:
            success = False
            info['message'] += '; the form has no self-stress'
        document = _form_document(structure, result.framework, args.pretension) if success \
            else None
        if document is not None:
            found = Structure.from_dict(document)
            info['bar_lengths'] = {b.name: float(b.length) for b in found.bodies}
            info['rest_lengths'] = dict(zip(found.string_names, map(float, found.rest_lengths),
                                            strict=True))
    if args.json:
        print_json(info)
    else:
        print(f"form-finding ({args.method}) of {path}: {info['message']}")
        for key in ('bar_lengths', 'rest_lengths', 'tensions'):
            for name, value in info.get(key, {}).items():
                print(f"  {key.replace('_', ' ')[:-1]} {name}: {num(value)}")
    if not success:
        return EXIT_NO_SOLUTION
    if args.out:
        _write(args.out, document, [f'{path} form-found ({PROG} structure form-find --method '
                                    f'{args.method}).'])
    return EXIT_OK


def _cmd_modes(args: argparse.Namespace) -> int:
    path = _structure_path(args)
    structure = Structure.from_yaml(path)
    eq = solve_structure_equilibrium(structure)
    if not eq.success:
        print(f'{PROG}: error: no equilibrium: {eq.message}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    modes = structure_modes(structure, eq)
    out = {'file': str(path), 'frequencies_hz': modes.frequencies,
           'damping_ratios': modes.damping_ratios, 'zero_modes': list(modes.zero_modes),
           'counts': modes.counts, 'stable': modes.stable}
    if args.json:
        print_json(out)
        return EXIT_OK
    print(f'modes of {path} at its equilibrium ({eq.message}); stable {yes(modes.stable)}')
    print(f'  {len(modes.frequencies)} modes with stiffness, frequencies (Hz): '
          f'{vector(modes.frequencies)}')
    if np.max(np.abs(modes.damping_ratios), initial=0.0) > DAMPING_RATIO_ZERO:
        print(f'  damping ratios: {vector(modes.damping_ratios)}')
    counts = ', '.join(f'{v} {k}' for k, v in modes.counts.items())
    print(f'  {len(modes.zero_modes)} zero modes ({counts})')
    return EXIT_OK


def _plot_equilibrium(structure: Structure, png: str, eq: Any) -> None:
    from tensegrity_stiffness.cli.structure_plots import plot_structure

    if eq is None:
        eq = solve_structure_equilibrium(structure)
    if eq.state is None:
        raise ValueError(f'no equilibrium to draw: {eq.message}')
    written = plot_structure(structure, eq.state, png, contacts=eq.contacts,
                             title=f'{structure.n_bodies} bodies, {structure.n_strings} '
                                   f'strings at equilibrium ({eq.message})')
    print(f'{PROG}: wrote {written}', file=sys.stderr)


def _cmd_plot(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.cli.structure_plots import plot_structure

    path = _structure_path(args)
    structure = Structure.from_yaml(path)
    if args.start:
        written = plot_structure(structure, structure.evaluate(), args.out,
                                 width=args.width, height=args.height,
                                 title=f'{path.name} at its start')
        print(f'{PROG}: wrote {written}', file=sys.stderr)
        return EXIT_OK
    eq = solve_structure_equilibrium(structure)
    if not eq.success:
        print(f'{PROG}: error: no equilibrium: {eq.message}', file=sys.stderr)
        return EXIT_NO_SOLUTION
    written = plot_structure(structure, eq.state, args.out, contacts=eq.contacts,
                             width=args.width, height=args.height,
                             title=f'{path.name} at equilibrium')
    print(f'{PROG}: wrote {written}', file=sys.stderr)
    return EXIT_OK


def _add_file(p: argparse.ArgumentParser) -> None:
    p.add_argument('file', nargs='?', metavar='FILE', help='the structure (YAML)')
    p.add_argument('--example', metavar='NAME',
                   help='a packaged example of config/examples instead of FILE, e.g. '
                        'six_bar.yaml')


def add_structure_parser(sub: Any) -> None:
    """``structure`` and its subcommands."""
    p = sub.add_parser('structure', help='any structure of bodies and strings: check, '
                                         'equilibrium, form-find, modes, plot',
                       description='Structures of rigid bodies and strings (docs/structures.md)'
                                   ': check a file, its equilibrium, form-finding, a 3D '
                                   'figure.')
    cmds = p.add_subparsers(dest='structure_command', required=True, metavar='SUBCOMMAND')
    c = cmds.add_parser('check', help='equilibrium, stability, strings, contacts, analysis',
                        description='The equilibrium with the file\'s gravity and ground, its '
                                    'stability, slack and saturated strings, bar and contact '
                                    'forces, and the pin-jointed analysis (self-stresses, '
                                    'mechanisms, prestress and super stability). Exit 0 when '
                                    'sound, 2 with the reason on stderr.')
    _add_file(c)
    c.add_argument('--plot', metavar='PNG', help='also draw the equilibrium here')
    add_json(c)
    c.set_defaults(handler=_cmd_check)
    e = cmds.add_parser('equilibrium', help='the equilibrium under loads',
                        description='The equilibrium under constant loads (with the file\'s '
                                    'gravity and ground): poses, tensions, contact forces. Exit '
                                    '1 when none is found.')
    _add_file(e)
    e.add_argument('--load', nargs=7, action='append', metavar=('BODY', 'FX', 'FY', 'FZ', 'MX',
                                                                'MY', 'MZ'),
                   help='a wrench on BODY in the world about its origin (N, N m); repeatable')
    e.add_argument('--out', metavar='FILE', help='write the structure at the equilibrium')
    e.add_argument('--plot', metavar='PNG', help='draw the equilibrium here')
    add_json(e)
    e.set_defaults(handler=_cmd_equilibrium)
    f = cmds.add_parser('form-find', help='force density, kinematic, rest-length design',
                        description='force-density: node positions of the member force '
                                    'densities (--density PREFIX=Q), nearest the file\'s start '
                                    '(the affine gauge); kinematic: the bars (--lengthen, '
                                    'default all) lengthened to their maximum at the strings\' '
                                    'start lengths; design: rest lengths that hold the start '
                                    'with tensions in [--t-min, --t-max]. Exit 1 when the '
                                    'method finds nothing.')
    _add_file(f)
    f.add_argument('--method', choices=METHODS, required=True, help='the method')
    f.add_argument('--density', action='append', metavar='PREFIX=Q',
                   help='force-density: members whose names start with PREFIX take Q (N/m; '
                        'bars negative); the longest prefix wins; repeatable')
    f.add_argument('--lengthen', nargs='+', metavar='BAR', help='kinematic: the bars to lengthen')
    f.add_argument('--pretension', type=parse_number, metavar='N',
                   help='force-density, kinematic: the largest string tension of the written '
                        "rest lengths (default: the file's at its start)")
    f.add_argument('--t-min', type=parse_number, default=1.0, metavar='N',
                   help='design: the least string tension (default 1)')
    f.add_argument('--t-max', type=parse_number, default=100.0, metavar='N',
                   help='design: the largest string tension (default 100)')
    f.add_argument('--out', metavar='FILE', help='write the form-found structure')
    add_json(f)
    f.set_defaults(handler=_cmd_form_find)
    m = cmds.add_parser('modes', help='frequencies and the named zero modes',
                        description='Natural frequencies (Hz), damping ratios and the zero '
                                    'modes (rigid or plane motions, bar spins, mechanisms) at '
                                    'the equilibrium with the file\'s gravity and ground. Exit '
                                    '1 when no equilibrium is found.')
    _add_file(m)
    add_json(m)
    m.set_defaults(handler=_cmd_modes)
    g = cmds.add_parser('plot', help='the 3D figure',
                        description='Bodies, strings coloured by tension, contact forces, at '
                                    'the equilibrium (or --start).')
    _add_file(g)
    g.add_argument('--out', required=True, metavar='PNG', help='the PNG to write')
    g.add_argument('--start', action='store_true', help="at the file's poses, not solved")
    g.add_argument('--width', type=int, default=900, metavar='PX', help='width (px)')
    g.add_argument('--height', type=int, default=700, metavar='PX', help='height (px)')
    g.set_defaults(handler=_cmd_plot)
