"""The figure commands: ``plot <figure>`` (one PNG) and ``figures`` (every figure of
docs/figures.md into a folder); both need matplotlib, the PNG facts are read with Pillow."""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from tensegrity_stiffness.cli import plots
from tensegrity_stiffness.cli.common import EXIT_OK, parse_number, positive_int
from tensegrity_stiffness.cli.joint_commands import (
    add_design_options,
    add_joint_options,
    joint_screw,
    load_joint,
    tension_limits,
)
from tensegrity_stiffness.cli.planar_commands import (
    PLANAR_KEYS,
    add_planar_options,
    planar_mechanism,
)
from tensegrity_stiffness.cli.progress import ProgressBar
from tensegrity_stiffness.cli.spine_commands import (
    README_SPINE_TIP_WRENCH,
    add_chain_options,
    chain_configuration,
)
from tensegrity_stiffness.mechanics import sweeps

#: Screw of the joint figure (docs/figures.md): the default joint's unloaded equilibrium bent by
#: 0.4 rad about the x axis of {1} (two strings go slack).
README_JOINT_SCREW = (2.3963, 0.4857, -2.3963, 0.0198, -0.0033, 0.0161)
#: PNG file of each figure (``plot`` default output name and ``figures`` file name).
FIGURE_FILES = {
    'joint': 'joint_3d.png',
    'extension': 'extension_sweep.png',
    'actuator-workspace': 'planar_actuator_workspace.png',
    'cartesian-workspace': 'planar_cartesian_workspace.png',
    'theta2': 'planar_theta2.png',
    'actuator-stiffness': 'planar_stiffness_actuator.png',
    'cartesian-stiffness': 'planar_stiffness_cartesian.png',
    'stiffness-range': 'stiffness_range.png',
    'spine': 'spine.png',
}
#: Accepted range of ``figures --scale``.
SCALE_RANGE = (0.1, 4.0)


def _out_path(args: argparse.Namespace, figure: str) -> Path:
    return Path(args.out) if args.out else Path(FIGURE_FILES[figure])


def _report_png(path: Path, started: float) -> None:
    size = png_size(path)
    print(f'wrote {path} ({size[0]}x{size[1]} px, {time.perf_counter() - started:.2f} s)')


def png_size(path: str | Path) -> tuple[int, int]:
    """(width, height) in pixels of a PNG file (read by Pillow); ValueError if it is none."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as image:
            if image.format == 'PNG':
                return image.size
    except UnidentifiedImageError:
        pass
    raise ValueError(f'{path} is not a PNG file')


def _draw(figure: str, args: argparse.Namespace, path: Path, size: tuple[int, int],
          progress: Callable[[int, int], None] | None) -> Path:
    """Compute and write one figure (the plots module is imported here: it needs matplotlib)."""
    w, h = size
    if figure == 'joint':
        model, _, rest = load_joint(args)
        return plots.plot_joint(model, joint_screw(args, model), path, rest_lengths=rest,
                                width=w, height=h, elevation=args.elevation,
                                azimuth=args.azimuth)
    if figure == 'extension':
        model, _, rest = load_joint(args)
        sweep = sweeps.extension_sweep(model, args.extent, args.samples, rest, progress=progress)
        return plots.plot_extension_sweep(sweep, path, width=w, height=h)
    if figure == 'spine':
        chain, _, screws, W, _ = chain_configuration(args)
        return plots.plot_spine(chain, screws, path, width=w, height=h, tip_wrench=W,
                                elevation=args.elevation, azimuth=args.azimuth)
    if figure == 'theta2':
        mech = planar_mechanism(args, {k: v for k, v in plots.PLANAR_THETA2_PARAMETERS.items()
                                       if k in PLANAR_KEYS})
        return plots.plot_theta2_curves(mech, path, L3=args.L3, theta1=args.theta1,
                                        theta2_min=mech.theta2_min, theta2_max=mech.theta2_max,
                                        samples=args.samples, width=w, height=h)
    mech = planar_mechanism(args, plots.PLANAR_MAP_PARAMETERS)
    if figure == 'actuator-workspace':
        return plots.plot_actuator_workspace(mech, path, samples=args.samples, width=w,
                                             height=h)
    if figure == 'cartesian-workspace':
        return plots.plot_cartesian_workspace(mech, path, samples=args.samples,
                                              resolution=args.resolution, width=w, height=h,
                                              progress=progress)
    if figure == 'actuator-stiffness':
        return plots.plot_actuator_stiffness(mech, path, resolution=args.resolution, width=w,
                                             height=h, progress=progress)
    if figure == 'cartesian-stiffness':
        return plots.plot_cartesian_stiffness(mech, path, resolution=args.resolution,
                                              samples=args.samples, width=w, height=h,
                                              progress=progress)
    if figure == 'stiffness-range':
        model, _, _ = load_joint(args)
        t_min, t_max = tension_limits(args)
        return plots.plot_stiffness_range(model, joint_screw(args, model), path,
                                          coordinate=args.coordinate, extent=args.extent,
                                          samples=args.samples, external_wrench=args.wrench,
                                          tension_min=t_min, tension_max=t_max, width=w,
                                          height=h, progress=progress)
    raise ValueError(f'unknown figure {figure!r}')  # unreachable: argparse checks the choice


def _cmd_plot(args: argparse.Namespace) -> int:
    started = time.perf_counter()
    path = _out_path(args, args.figure)
    progress = ProgressBar(args.figure)
    _draw(args.figure, args, path, tuple(args.size), progress)
    progress.finish()
    _report_png(path, started)
    return EXIT_OK


def _figure_defaults(figure: str) -> argparse.Namespace:
    """The options of ``plot <figure>`` with their defaults (as if typed without options)."""
    parser = argparse.ArgumentParser()
    add_plot_parser(parser.add_subparsers(dest='command'))
    return parser.parse_args(['plot', figure])


def _cmd_figures(args: argparse.Namespace) -> int:
    lo, hi = SCALE_RANGE
    if not lo <= args.scale <= hi:
        raise ValueError(f'--scale must be in [{lo:g}, {hi:g}], got {args.scale:g}')
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    names = list(FIGURE_FILES)
    for k, figure in enumerate(names):
        started = time.perf_counter()
        options = _figure_defaults(figure)
        if figure == 'joint':
            options.screw = list(README_JOINT_SCREW)
        if args.resolution is not None:
            for attr in ('resolution', 'samples'):
                if hasattr(options, attr):
                    setattr(options, attr, max(args.resolution, 2))
        w, h = plots.DEFAULT_SIZES[figure]
        size = (round(w * args.scale), round(h * args.scale))
        path = out / FIGURE_FILES[figure]
        progress = ProgressBar(f'[{k + 1}/{len(names)}] {figure}')
        _draw(figure, options, path, size, progress)
        progress.finish()
        _report_png(path, started)
    return EXIT_OK


def _add_plot_common(p: argparse.ArgumentParser, figure: str) -> None:
    from_sizes = plots.DEFAULT_SIZES[figure]
    p.add_argument('--out', metavar='PNG',
                   help=f'output file (default: ./{FIGURE_FILES[figure]})')
    p.add_argument('--size', nargs=2, type=positive_int, default=list(from_sizes),
                   metavar=('W', 'H'),
                   help=f'PNG size in pixels (default: {from_sizes[0]} {from_sizes[1]})')


PLOT_HELP = {
    'joint': 'the joint in 3D at a screw or pose: nodes, strings coloured by tension, slack '
             'dashed',
    'extension': 'block Frobenius norms and column norms of K along an extensional '
                 'displacement from the unloaded equilibrium (Monke & Vikas Figs. 4-5)',
    'actuator-workspace': 'actuator workspace with the singular curves i-vi (Ji, Li & Lin '
                          'Fig. 2)',
    'cartesian-workspace': 'Cartesian workspace with the singular curves i-vi (Fig. 3)',
    'theta2': 'U, tau and K against theta2 with the actuators locked (Figs. 4-6)',
    'actuator-stiffness': 'stiffness map over the actuator workspace (Fig. 7)',
    'cartesian-stiffness': 'stiffness map over the Cartesian workspace (Fig. 8)',
    'stiffness-range': 'reachable range of each diagonal entry of K_c over the admissible '
                       'tensions along a sweep of one screw coordinate',
    'spine': 'a spine of joints in 3D at screws or at its equilibrium under a tip wrench: '
             'strings coloured by tension',
}


def _view_options(f: argparse.ArgumentParser, elevation: float, azimuth: float) -> None:
    f.add_argument('--elevation', type=parse_number, default=elevation, metavar='DEG',
                   help=f'view elevation (degrees, default {elevation:g})')
    f.add_argument('--azimuth', type=parse_number, default=azimuth, metavar='DEG',
                   help=f'view azimuth (degrees, default {azimuth:g})')


def _joint_figure_options(f: argparse.ArgumentParser) -> None:
    add_joint_options(f)
    _view_options(f, 18.0, -50.0)


def _extension_options(f: argparse.ArgumentParser) -> None:
    add_joint_options(f, screw=False)
    f.add_argument('--extent', type=parse_number, metavar='M',
                   help='largest extension (m; default: the smallest maximum stretch '
                        'lmax - l0 of the strings)')
    f.add_argument('--samples', type=positive_int,
                   default=sweeps.DEFAULT_SWEEP_SAMPLES,
                   help=f'points along the sweep (default '
                        f'{sweeps.DEFAULT_SWEEP_SAMPLES})')


def _spine_options(f: argparse.ArgumentParser) -> None:
    add_chain_options(f, README_SPINE_TIP_WRENCH)
    _view_options(f, 12.0, -60.0)


def _theta2_options(f: argparse.ArgumentParser) -> None:
    add_planar_options(f, 'L = 1, K1 = 100, K2 = 10, theta2 in [0, pi] (Figs. 4-6)', False)
    f.add_argument('--L3', type=parse_number, default=6.0, metavar='M',
                   help='locked actuator length (m, default 6)')
    f.add_argument('--theta1', type=parse_number, default=math.pi / 10, metavar='RAD',
                   help='locked actuator angle (rad, default pi/10)')
    f.add_argument('--samples', type=positive_int,
                   default=plots.DEFAULT_THETA2_SAMPLES,
                   help=f'theta2 samples (default {plots.DEFAULT_THETA2_SAMPLES})')


def _stiffness_range_options(f: argparse.ArgumentParser) -> None:
    add_design_options(f, limits_required=False)
    f.add_argument('--coordinate', choices=plots.SCREW_COORDINATES, default='wx',
                   help='screw coordinate swept about the screw (default wx)')
    f.add_argument('--extent', type=parse_number, default=0.3, metavar='OFFSET',
                   help='sweep from -OFFSET to +OFFSET (rad or m; default 0.3)')
    f.add_argument('--samples', type=positive_int, default=plots.DEFAULT_RANGE_SAMPLES,
                   help=f'points along the sweep (default '
                        f'{plots.DEFAULT_RANGE_SAMPLES})')


def _planar_map_options(f: argparse.ArgumentParser, figure: str) -> None:
    add_planar_options(f, 'L = 1, K1 = 200, K2 = 100, L3 in [0, 2L], theta1 in '
                          '[0, pi] (Figs. 2-3, 7-8)', False)
    if figure != 'actuator-stiffness':
        f.add_argument('--samples', type=positive_int,
                       default=plots.DEFAULT_CURVE_SAMPLES,
                       help=f'samples per curve (default '
                            f'{plots.DEFAULT_CURVE_SAMPLES})')
    if figure != 'actuator-workspace':
        f.add_argument('--resolution', type=positive_int,
                       default=plots.DEFAULT_MAP_RESOLUTION,
                       help=f'grid points per side (default '
                            f'{plots.DEFAULT_MAP_RESOLUTION})')


#: The options of each figure but the planar maps' (:func:`_planar_map_options`).
FIGURE_OPTIONS: dict[str, Callable[[argparse.ArgumentParser], None]] = {
    'joint': _joint_figure_options,
    'extension': _extension_options,
    'spine': _spine_options,
    'theta2': _theta2_options,
    'stiffness-range': _stiffness_range_options,
}


def add_plot_parser(sub: Any) -> None:
    """``plot <figure>``."""
    p = sub.add_parser('plot', help='write one figure as PNG (needs matplotlib)',
                       description='Write one figure as PNG (needs matplotlib).')
    figures = p.add_subparsers(dest='figure', required=True, metavar='FIGURE')
    for figure, text in PLOT_HELP.items():
        f = figures.add_parser(figure, help=text, description=text + '.')
        _add_plot_common(f, figure)
        if figure in FIGURE_OPTIONS:
            FIGURE_OPTIONS[figure](f)
        else:
            _planar_map_options(f, figure)
    p.set_defaults(handler=_cmd_plot)


def add_figures_parser(sub: Any) -> None:
    """``figures``."""
    p = sub.add_parser('figures', help="regenerate every figure of docs/figures.md into a folder",
                       description='Write every figure at its default parameters (the '
                                   "papers' sets) into a folder (needs matplotlib).")
    p.add_argument('--out', default='docs/figures', metavar='DIR',
                   help='output folder (created if missing; default docs/figures)')
    p.add_argument('--scale', type=parse_number, default=1.0,
                   help='scale of the pixel sizes (default 1)')
    p.add_argument('--resolution', type=positive_int, metavar='N',
                   help='override every grid resolution and sample count (quick previews)')
    p.set_defaults(handler=_cmd_figures)
