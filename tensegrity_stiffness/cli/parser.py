"""``tensegrity-stiffness``: the parser (each command group adds its commands) and :func:`main`.

Runs on the library alone (numpy, scipy, PyYAML; matplotlib for plots) -- no node, no rclpy.
Subcommands (``tensegrity-stiffness <command> --help`` for every option):

* ``joint``        wrench, K, K_c, tensions, interpretation at a screw or pose (eqs. 6-11, 19-20)
* ``equilibrium``  the equilibrium under an external wrench (Section VI)
* ``planar-fk``    planar mechanism forward kinematics at (L3, theta1) (eqs. 2-7, 17-30, 42)
* ``planar-ik``    planar mechanism inverse kinematics at D3 = (x, y) (eqs. 8-16, 48-52)
* ``design``       rest lengths that hold a screw under a load within tension limits, with a
  chosen Cartesian stiffness (:mod:`tensegrity_stiffness.mechanics.design`)
* ``plot <figure>`` one PNG: ``joint``, ``extension`` (Monke & Vikas Figs. 4-5),
  ``actuator-workspace``, ``cartesian-workspace`` (Ji, Li & Lin Figs. 2-3), ``theta2``
  (Figs. 4-6), ``actuator-stiffness``, ``cartesian-stiffness`` (Figs. 7-8), ``stiffness-range``
  (reachable diagonal of K_c along a screw sweep)
* ``chain``        a spine of joints: tip pose and exact tip stiffness at screws, or at the chain
  equilibrium under a tip wrench and link weights (``plot spine`` draws it)
* ``figures``      every figure of docs/figures.md into a folder (``docs/figures``)
* ``bag``          what the node would publish, for a whole rosbag2 recording (needs rosbags)
* ``calibrate``    each string's stiffness and rest-length offset from a recording (rosbag2 or
  CSV), with identifiability and std (:mod:`tensegrity_stiffness.cli.calibration_report`)
* ``record``       a rosbag2 of a running node's topics (:mod:`.record_command`; rclpy, in a
  child process)
* ``export-mjcf``  the digital twin's MuJoCo model of the joint, the spine or a structure
* ``new-config``   a starter joint (or spine) config from a template, its unloaded equilibrium
  written as ``initial_screw`` (:mod:`tensegrity_stiffness.mechanics.templates`)
* ``check-config`` a config's unloaded equilibrium, stability, strings, modes and whether its
  ``initial_screw`` is an equilibrium (exit 0 sound, 2 with the reason)
* ``structure``    any structure of bodies and strings: ``check``, ``equilibrium``,
  ``form-find``, ``modes``, ``plot`` (:mod:`tensegrity_stiffness.cli.structure_commands`)
* ``viewers``      the RViz configuration and Foxglove layout of a config in a namespace
  (:mod:`.viewer_commands`)
* ``modes``        natural frequencies, damping ratios and mode shapes at the unloaded
  equilibrium (:mod:`tensegrity_stiffness.mechanics.dynamics`; ``--plot`` draws them)

Numbers accept arithmetic with ``pi`` (``pi/10``, ``-3*pi/4``, ``-1e-3``). ``--json`` prints
machine-readable output (NaN and inf as null). Exit codes: 0 success, 1 no solution (equilibrium
not found, unreachable point), 2 bad input (message on stderr, no traceback), 3 matplotlib
missing. Progress of long computations goes to stderr, only when stderr is a terminal.
"""

from __future__ import annotations

import argparse
import sys
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from tensegrity_stiffness.cli import (
    config_commands,
    dynamics_commands,
    figure_commands,
    joint_commands,
    planar_commands,
    record_command,
    recording_commands,
    spine_commands,
    structure_commands,
    viewer_commands,
)
from tensegrity_stiffness.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_NO_MATPLOTLIB,
    EXIT_NO_SOLUTION,
    PROG,
    protect_negative_numbers,
)
from tensegrity_stiffness.cli.plots import MatplotlibMissingError
from tensegrity_stiffness.mechanics.unloaded import InitialScrewWarning

#: Each command's ``add_parser(subparsers)``, in the order of ``--help``.
COMMANDS: tuple[Callable[[Any], None], ...] = (
    joint_commands.add_joint_parser,
    joint_commands.add_equilibrium_parser,
    planar_commands.add_planar_fk_parser,
    planar_commands.add_planar_ik_parser,
    joint_commands.add_design_parser,
    figure_commands.add_plot_parser,
    recording_commands.add_bag_parser,
    recording_commands.add_calibrate_parser,
    record_command.add_record_parser,
    spine_commands.add_chain_parser,
    recording_commands.add_export_mjcf_parser,
    figure_commands.add_figures_parser,
    dynamics_commands.add_modes_parser,
    config_commands.add_new_config_parser,
    config_commands.add_check_config_parser,
    structure_commands.add_structure_parser,
    viewer_commands.add_viewers_parser,
)


def build_parser() -> argparse.ArgumentParser:
    """The argparse parser of every command."""
    parser = argparse.ArgumentParser(
        prog=PROG, description='Stiffness of tensegrity joints (Monke & Vikas) and of the '
        'planar tensegrity mechanism (Ji, Li & Lin) from the command line. Numbers accept pi '
        'arithmetic (pi/10).',
        epilog='exit codes: 0 ok, 1 no solution, 2 bad input, 3 matplotlib missing')
    sub = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    for add_parser in COMMANDS:
        add_parser(sub)
    return parser


def _silence_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's final flush does not fail again."""
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
    except (OSError, ValueError, AttributeError):  # not a real file (e.g. captured in tests)
        pass


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of ``tensegrity-stiffness``; returns the exit code (see the module docstring).
    """
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    try:
        args = parser.parse_args(protect_negative_numbers(argv))
    except SystemExit as exc:  # --help (0) or a usage error (2, message already printed)
        return int(exc.code) if isinstance(exc.code, int) else EXIT_BAD_INPUT
    # Not warnings.catch_warnings: it would reset which warnings were already shown.
    previous = warnings.showwarning
    warnings.showwarning = _warning_line(previous)
    try:
        # An absurd number (1e308) overflows to inf in a norm or a product before a check
        # refuses it by name: the error line says it, numpy's RuntimeWarning would only add
        # noise before it.
        with np.errstate(over='ignore'):
            return _run(args)
    finally:
        warnings.showwarning = previous


def _warning_line(previous: Callable[..., None]) -> Callable[..., None]:
    """``warnings.showwarning`` that prints a config's :class:`InitialScrewWarning` (an
    ``initial_screw`` that is not an unloaded equilibrium) as one line on stderr and hands any
    other warning to ``previous``."""
    def show(message: Warning | str, category: type[Warning], *args: Any, **kwargs: Any
             ) -> None:
        if issubclass(category, InitialScrewWarning):
            print(f'{PROG}: warning: {message}', file=sys.stderr)
        else:
            previous(message, category, *args, **kwargs)
    return show


def _run(args: argparse.Namespace) -> int:
    """Run the parsed command; errors to exit codes (module docstring)."""
    try:
        return args.handler(args)
    except MatplotlibMissingError as exc:
        print(f'{PROG}: {exc}', file=sys.stderr)
        return EXIT_NO_MATPLOTLIB
    except ValueError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT
    except BrokenPipeError:  # e.g. piped into `head`: stop quietly (Python docs recipe)
        _silence_stdout()
        return EXIT_NO_SOLUTION
    except OSError as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT

