"""The dynamics' command ``modes``: the vibration modes of a joint (or, ``--spine``, a spine)
at its unloaded equilibrium (:mod:`tensegrity_stiffness.mechanics.mode_reports`), and a figure of
each mode's shape (:mod:`tensegrity_stiffness.cli.dynamics_plots`, needs matplotlib)."""

from __future__ import annotations

import argparse
import sys
from typing import Any

from tensegrity_stiffness.cli.common import EXIT_OK, PROG, add_json, parse_number, print_json
from tensegrity_stiffness.mechanics.joint_dynamics import DEFAULT_STRING_DAMPING


def _cmd_modes(args: argparse.Namespace) -> int:
    from tensegrity_stiffness.mechanics import mode_reports

    dyn, modes, report = mode_reports.modes_from_config(args.config, args.spine,
                                                        args.string_damping)
    if args.json:
        print_json(report)
    else:
        print(mode_reports.format_modes(modes))
    if args.plot:
        from tensegrity_stiffness.cli.dynamics_plots import plot_joint_modes, plot_spine_modes
        from tensegrity_stiffness.cli.figure_commands import png_size

        if args.spine:
            path = plot_spine_modes(dyn.chain, modes, args.plot)
        else:
            path = plot_joint_modes(dyn.model, modes, args.plot)
        width, height = png_size(path)
        print(f'{PROG}: wrote {path} ({width}x{height} px)', file=sys.stderr)
    return EXIT_OK


def add_modes_parser(sub: Any) -> None:
    """``modes``."""
    p = sub.add_parser('modes', help='natural frequencies, damping ratios and mode shapes',
                       description='Vibration modes of the joint (or, with --spine, the spine) '
                                   'at its unloaded equilibrium: frequency, damping ratio and '
                                   'dominant twist component of each, slowest first; --plot '
                                   'draws each mode shape (needs matplotlib).')
    p.add_argument('--config', metavar='YAML',
                   help='config file (default: the packaged default_joint.yaml, or '
                        'default_spine.yaml with --spine); the link inertias are its '
                        'joint.link2_mass, link2_com, link2_inertia (spine: chain.link_masses, '
                        "link_coms, link_inertias), missing ones the digital twin's")
    p.add_argument('--spine', action='store_true', help='the spine (a chain config)')
    p.add_argument('--string-damping', type=parse_number, metavar='C',
                   help="damping of every string (N s/m; default: the config's "
                        "dynamics.string_damping, else the twin's "
                        f'{DEFAULT_STRING_DAMPING:g})')
    p.add_argument('--plot', metavar='PNG', help='write the mode shapes here (matplotlib)')
    add_json(p)
    p.set_defaults(handler=_cmd_modes)
