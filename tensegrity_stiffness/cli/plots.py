"""PNG figures of the joint and of the planar mechanism (the papers' figures, from the library).

matplotlib is an optional dependency (``pip install matplotlib``, pinned in
``scripts/setup_env.sh``): it is imported inside the functions, and only its Agg canvas is used
(no pyplot, no global backend switch). Without it every function raises
:class:`MatplotlibMissingError`. Every function takes the output path and the PNG size in pixels
(``width`` x ``height``, written exactly: ``figsize = size / DPI`` at :data:`DPI`), writes one PNG
and returns its path. Long computations accept ``progress(done, total)``.

Figures (defaults are the papers' parameter sets):

* :func:`plot_joint` -- the six-DOF joint at a screw: both links' nodes, 12 strings coloured by
  tension, slack strings dashed (Monke & Vikas, eqs. 6-9).
* :func:`plot_extension_sweep` -- block Frobenius norms and column norms of K along the
  extensional displacement of :mod:`tensegrity_stiffness.mechanics.sweeps` (Monke & Vikas, Figs.
  4-5).
* :func:`plot_actuator_workspace`, :func:`plot_cartesian_workspace` -- workspaces with the
  singular curves i-vi (Ji, Li & Lin, Figs. 2-3; K1 = 200, K2 = 100 N/m).
* :func:`plot_theta2_curves` -- U, tau and K against theta2 with the actuators locked (Figs. 4-6;
  L = 1 m, L3 = 6 m, K1 = 100, K2 = 10 N/m, theta1 = pi/10).
* :func:`plot_actuator_stiffness`, :func:`plot_cartesian_stiffness` -- stiffness maps over both
  workspaces (Figs. 7-8; K1 = 200, K2 = 100 N/m).
* :func:`plot_stiffness_range` -- the reachable range of each diagonal entry of K_c over the
  admissible tensions along a sweep of one screw coordinate
  (:mod:`tensegrity_stiffness.mechanics.design`).
* :func:`plot_spine` -- a chain of joints (:mod:`tensegrity_stiffness.mechanics.chain`) in the
  base frame, strings coloured by tension.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.components import SCREW_NAMES
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.design import (
    DIAGONAL_NAMES,
    DIAGONAL_UNITS,
    design_rest_lengths,
    stiffness_range,
)
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.planar import SQRT3, PlanarMechanism
from tensegrity_stiffness.mechanics.planar_workspace import (
    actuator_stiffness_map,
    actuator_workspace_boundary,
    actuator_workspace_curves,
    cartesian_stiffness_map,
    cartesian_workspace_boundary,
    cartesian_workspace_curves,
)
from tensegrity_stiffness.mechanics.sweeps import ExtensionSweep, ProgressCallback

FloatArray = NDArray[np.float64]

#: Message of :class:`MatplotlibMissingError` (the CLI prints it and exits with code 3).
MATPLOTLIB_MISSING = 'matplotlib is required for plots: pip install matplotlib'
#: Dots per inch of every PNG (the figure size in inches is the pixel size / DPI).
DPI = 100
#: Accepted PNG sizes (pixels, each side).
MIN_PIXELS = 100
MAX_PIXELS = 8000
#: Default PNG size (width, height) in pixels of each figure.
#: The spine figure's tip-force arrow: its length as a fraction of the spine's largest extent
#: (the force's direction, not its size, is drawn) and its colour (apart from the strings'
#: colour map and the frames' RGB).
TIP_FORCE_ARROW = 0.4
TIP_FORCE_COLOUR = 'deepskyblue'
#: Zoom of a 3D box fitted to a slender body (matplotlib leaves a margin for any rotation).
FIT_ZOOM = 1.1
DEFAULT_SIZES = {
    'joint': (800, 700),
    'extension': (1000, 450),
    'actuator-workspace': (900, 600),
    'cartesian-workspace': (800, 820),
    'theta2': (900, 750),
    'actuator-stiffness': (900, 600),
    'cartesian-stiffness': (800, 700),
    'stiffness-range': (1000, 600),
    'spine': (700, 900),
}
#: Default samples along each curve and per side of each map grid.
DEFAULT_CURVE_SAMPLES = 400
DEFAULT_MAP_RESOLUTION = 300
DEFAULT_THETA2_SAMPLES = 721
#: Grid rows per progress report of the maps.
MAP_CHUNK_ROWS = 16
#: Filled contour levels of the stiffness maps.
MAP_LEVELS = 20
#: Labelled contour lines of the stiffness maps.
MAP_LINES = 10
#: Margin around the Cartesian workspace (fraction of its extent).
CARTESIAN_MARGIN = 0.06
#: Metres -> millimetres (the joint is drawn in mm).
MM = 1000.0
#: Screw entries below this fraction of the largest are written as 0 in the joint's title.
TITLE_ZERO = 1e-12
#: Colour map of string tensions and of the stiffness maps.
TENSION_CMAP = 'plasma'
STIFFNESS_CMAP = 'viridis'

#: Paper's parameter sets (Ji, Li & Lin): Figs. 2-3 and 7-8, and Figs. 4-6.
PLANAR_MAP_PARAMETERS = {'L': 1.0, 'K1': 200.0, 'K2': 100.0}
PLANAR_THETA2_PARAMETERS = {'L': 1.0, 'K1': 100.0, 'K2': 10.0, 'L3': 6.0, 'theta1': math.pi / 10}

#: Legend text and style of each workspace curve (Ji, Li & Lin, Section 4.2 and eq. 31).
CURVE_LABELS = {
    'i': r'i: $L_3 = 0$ (eq. 26)',
    'ii': r'ii: $\sin\theta_1 = 0$ (eq. 27)',
    'iii': r'iii: $\eta_1 = 0$, $\sin\theta_2 = 0$ (eq. 28)',
    'iv': r'iv: $\theta_1 = \theta_2$ (eq. 33)',
    'v': r'v: $\det J = 0$, fold (eq. 30)',
    'vi': r'vi: $L_3 = L_{3,\max}$ (eq. 31)',
}
CURVE_STYLES = {
    'i': {'color': 'tab:blue', 'linestyle': '-'},
    'ii': {'color': 'tab:orange', 'linestyle': '-'},
    'iii': {'color': 'tab:green', 'linestyle': '--'},
    'iv': {'color': 'tab:red', 'linestyle': '-.'},
    'v': {'color': 'tab:purple', 'linestyle': ':'},
    'vi': {'color': 'black', 'linestyle': '-'},
}
BLOCK_LABELS = (r'$K_{f\omega}$ (N/rad)', r'$K_{fv}$ (N/m)', r'$K_{m\omega}$ (N m/rad)',
                r'$K_{mv}$ (N)')
COLUMN_LABELS = (r'$\omega_x$', r'$\omega_y$', r'$\omega_z$', r'$v_x$', r'$v_y$', r'$v_z$')


class MatplotlibMissingError(RuntimeError):
    """matplotlib is not installed (plots need it; the rest of the package does not)."""


def _matplotlib() -> tuple[Any, Any]:
    """(Figure, FigureCanvasAgg), imported lazily; MatplotlibMissingError when not installed."""
    try:
        import matplotlib  # noqa: F401  (a clear error before the submodules)
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise MatplotlibMissingError(MATPLOTLIB_MISSING) from exc
    return Figure, FigureCanvasAgg


def check_size(width: int, height: int) -> tuple[int, int]:
    """Validated PNG size in pixels (integers in [MIN_PIXELS, MAX_PIXELS])."""
    out = []
    for name, value in (('width', width), ('height', height)):
        if isinstance(value, bool) or int(value) != value:
            raise ValueError(f'{name} must be an integer number of pixels, got {value}')
        if not MIN_PIXELS <= int(value) <= MAX_PIXELS:
            raise ValueError(f'{name} must be in [{MIN_PIXELS}, {MAX_PIXELS}] px, got {value}')
        out.append(int(value))
    return out[0], out[1]


def _check_count(name: str, value: int, minimum: int = 2) -> int:
    if isinstance(value, bool) or int(value) != value or value < minimum:
        raise ValueError(f'{name} must be an integer >= {minimum}, got {value}')
    return int(value)


def new_figure(width: int, height: int) -> Any:
    """A Figure of exactly ``width`` x ``height`` px at :data:`DPI` with an Agg canvas."""
    width, height = check_size(width, height)
    Figure, FigureCanvasAgg = _matplotlib()
    fig = Figure(figsize=(width / DPI, height / DPI), dpi=DPI, layout='constrained')
    FigureCanvasAgg(fig)
    return fig


def output_path(path: str | Path) -> Path:
    """The output path; ValueError when its folder does not exist."""
    path = Path(path)
    if not path.parent.is_dir():
        raise ValueError(f'output folder {path.parent} does not exist')
    if path.is_dir():
        raise ValueError(f'output path {path} is a folder, expected a .png file name')
    return path


def save_figure(fig: Any, path: Path) -> Path:
    fig.savefig(path, format='png', dpi=DPI)
    return path


def _finite_rows(curve: FloatArray) -> FloatArray:
    return curve[np.all(np.isfinite(curve), axis=1)]


# ---------------------------------------------------------------------------- six-DOF joint
def _equal_axes_3d(ax: Any, points: FloatArray, span: float, elevation: float,
                   azimuth: float, fit: bool = False) -> None:
    """Equal-scale 3D axes around ``points`` (mm), y of the base frame up: a cube of side 1.1
    ``span``, or with ``fit`` a box of 1.1 times each axis' extent (at least a quarter of
    ``span``), so that a slender body (a spine) fills the figure at the same scale on each
    axis."""
    centre = 0.5 * (points.max(axis=0) + points.min(axis=0))
    extent = np.maximum(np.ptp(points, axis=0), 0.25 * span) if fit else np.full(3, span)
    half = 0.55 * extent
    ax.set_xlim(centre[0] - half[0], centre[0] + half[0])
    ax.set_ylim(centre[1] - half[1], centre[1] + half[1])
    ax.set_zlim(centre[2] - half[2], centre[2] + half[2])
    # The view first: set_box_aspect maps the aspect through the vertical axis in effect.
    ax.view_init(elev=elevation, azim=azimuth, vertical_axis='y')
    ax.set_box_aspect(tuple(extent / extent.max()), zoom=FIT_ZOOM if fit else 1.0)
    if fit:  # narrow axes: fewer ticks, so that their labels do not run into each other
        from matplotlib.ticker import MaxNLocator

        for axis in (ax.xaxis, ax.yaxis, ax.zaxis):
            axis.set_major_locator(MaxNLocator(4))
    ax.set_xlabel('x (mm)')
    ax.set_ylabel('y (mm)')
    ax.set_zlabel('z (mm)')


def plot_joint(model: JointModel, screw: ArrayLike, path: str | Path, *,
               rest_lengths: ArrayLike | None = None,
               width: int = DEFAULT_SIZES['joint'][0], height: int = DEFAULT_SIZES['joint'][1],
               title: str | None = None, elevation: float = 18.0,
               azimuth: float = -50.0) -> Path:
    """The joint at ``screw`` in 3D (in {1}, mm): link-1 nodes (squares) and link-2 nodes
    ``T p2`` (circles), each link drawn as the polyline through its nodes in config order, the
    strings coloured by tension (N, colour bar), slack strings dashed grey, saturated strings
    thick; the frames {1} and {2} as small RGB triads; the joint's y axis vertical."""
    path = output_path(path)
    state = model.evaluate(screw, rest_lengths)
    fig = new_figure(width, height)
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    T = state.transform
    p1 = model.link1_nodes * MM
    p2 = model.link2_nodes_in_link1(T) * MM
    ax = fig.add_subplot(projection='3d')
    top = float(state.tensions.max()) if state.tensions.max() > 0.0 else 1.0
    norm = Normalize(0.0, top)
    cmap = _colormap(TENSION_CMAP)
    for j, (a, b) in enumerate(model.connections):
        seg = np.vstack([p1[a], p2[b]])
        if state.slack[j]:
            style = {'color': '0.55', 'linestyle': '--', 'linewidth': 1.2}
        else:
            style = {'color': cmap(norm(state.tensions[j])), 'linestyle': '-',
                     'linewidth': 3.2 if state.saturated[j] else 2.0}
        ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], **style)
    for nodes, names, marker, colour, label in (
            (p1, model.node_names, 's', 'tab:blue', '1'),
            (p2, model.link2_node_names, 'o', 'tab:green', '2')):
        ax.plot(nodes[:, 0], nodes[:, 1], nodes[:, 2], color=colour, linewidth=4.0, alpha=0.35)
        ax.scatter(nodes[:, 0], nodes[:, 1], nodes[:, 2], marker=marker, s=40, color=colour,
                   depthshade=False)
        for name, p in zip(names, nodes, strict=True):
            ax.text(p[0], p[1], p[2], f' {name}{label}', fontsize=8, color=colour)
    span = float(np.ptp(np.vstack([p1, p2]), axis=0).max())
    for frame, origin, R in (('1', np.zeros(3), np.eye(3)), ('2', T[:3, 3] * MM, T[:3, :3])):
        for k, colour in enumerate(('red', 'green', 'blue')):
            tip = origin + 0.18 * span * R[:, k]
            ax.plot(*np.vstack([origin, tip]).T, color=colour, linewidth=1.2)
        ax.text(*origin, f' {{{frame}}}', fontsize=8)
    _equal_axes_3d(ax, np.vstack([p1, p2]), span, elevation, azimuth)
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.6, pad=0.08,
                 label='string tension (N)')
    n_slack, n_sat = int(state.slack.sum()), int(state.saturated.sum())
    handles = [Line2D([], [], color=cmap(0.7), linewidth=2.0, label='taut string'),
               Line2D([], [], color='0.55', linestyle='--', label=f'slack string ({n_slack})'),
               Line2D([], [], color='tab:blue', marker='s', linestyle='', label='link 1 nodes'),
               Line2D([], [], color='tab:green', marker='o', linestyle='', label='link 2 nodes')]
    if n_sat:
        handles.insert(1, Line2D([], [], color=cmap(1.0), linewidth=3.2,
                                 label=f'saturated string ({n_sat})'))
    ax.legend(handles=handles, loc='upper left', fontsize=8)
    xi = np.asarray(state.screw)
    xi = np.where(np.abs(xi) < TITLE_ZERO * np.abs(xi).max(), 0.0, xi)  # rounding noise -> 0
    ax.set_title(title or ('joint at screw xi = [' + ' '.join(f'{v:.4g}' for v in xi) + ']\n'
                           f'|F| = {np.linalg.norm(state.wrench[:3]):.3g} N, '
                           f'|M| = {np.linalg.norm(state.wrench[3:]):.3g} N m'), fontsize=10)
    return save_figure(fig, path)


def _colormap(name: str) -> Any:
    from matplotlib import colormaps

    return colormaps[name]


def plot_extension_sweep(sweep: ExtensionSweep, path: str | Path, *,
                         width: int = DEFAULT_SIZES['extension'][0],
                         height: int = DEFAULT_SIZES['extension'][1]) -> Path:
    """Monke & Vikas Figs. 4-5: Frobenius norms of the blocks of K (eq. 19, left) and norms of
    its columns (eq. 20, right) against the extension (mm) of :func:`extension_sweep`; log scale
    (the blocks have different units). Dotted lines mark where strings go slack or saturate."""
    path = output_path(path)
    fig = new_figure(width, height)
    s = sweep.displacement * MM
    left, right = fig.subplots(1, 2, sharex=True)
    for k, label in enumerate(BLOCK_LABELS):
        left.plot(s, sweep.block_norms[:, k], label=label, linewidth=1.8)
    for k, label in enumerate(COLUMN_LABELS):
        right.plot(s, sweep.column_norms[:, k], label=label, linewidth=1.8,
                   linestyle='-' if k < 3 else '--')
    events = []
    for counts, what in ((sweep.n_slack, 'slack'), (sweep.n_saturated, 'saturated')):
        change = np.flatnonzero(np.diff(counts) != 0)
        events += [(s[i + 1], f'{counts[i + 1]} {what}') for i in change]
    d = ', '.join(f'{v + 0.0:.3g}' for v in np.round(sweep.direction, 12))
    for ax, name in ((left, 'Fig. 4: block Frobenius norms of K'),
                     (right, 'Fig. 5: column norms of K')):
        ax.set_yscale('log')
        ax.set_xlabel(f'extension s along d = ({d}) in {{1}} (mm)')
        ax.set_title(name, fontsize=10)
        ax.grid(True, which='both', alpha=0.3)
        for x, text in events:
            ax.axvline(x, color='0.4', linestyle=':', linewidth=1.0)
            ax.annotate(text, (x, 1.0), xycoords=('data', 'axes fraction'), fontsize=7,
                        rotation=90, va='top', ha='right', color='0.3')
    left.set_ylabel('Frobenius norm of the block')
    right.set_ylabel(r'$|K e_i|$ (rotation columns N/rad & N m/rad, translation N/m & N)',
                     fontsize=8)
    # Below the axes: inside, every corner of a log-scale panel is crossed by some curve.
    for ax, ncol in ((left, 2), (right, 3)):
        ax.legend(fontsize=8, loc='upper center', bbox_to_anchor=(0.5, -0.16), ncol=ncol,
                  frameon=False)
    return save_figure(fig, path)


# ---------------------------------------------------------------------------- planar mechanism
def _curve_legend(ax: Any, curves: dict[str, FloatArray], point_names: tuple[str, ...] = ()
                  ) -> None:
    """Draw each curve in its style with its label; empty curves are listed as out of range;
    curves in ``point_names`` that collapse to a point are drawn as a marker."""
    for name, curve in curves.items():
        pts = _finite_rows(curve)
        label = CURVE_LABELS[name]
        style = dict(CURVE_STYLES[name])
        if not len(pts):
            ax.plot([], [], label=label + ' (outside the ranges)', **style)
            continue
        if name in point_names and np.ptp(pts, axis=0).max() < 1e-9:
            ax.plot(pts[:1, 0], pts[:1, 1], marker='o', markersize=7, linestyle='',
                    color=style['color'], label=label + ' (a point)')
            continue
        ax.plot(curve[:, 0], curve[:, 1], linewidth=2.0, label=label, **style)
        mid = pts[len(pts) // 2]
        ax.annotate(name, mid, textcoords='offset points', xytext=(4, 4), fontsize=9,
                    color=style['color'], fontweight='bold')


def plot_actuator_workspace(mech: PlanarMechanism, path: str | Path, *,
                            samples: int = DEFAULT_CURVE_SAMPLES,
                            width: int = DEFAULT_SIZES['actuator-workspace'][0],
                            height: int = DEFAULT_SIZES['actuator-workspace'][1]) -> Path:
    """Ji, Li & Lin Fig. 2: the actuator workspace (theta1, L3) with the singular curves i-v
    and the actuator limit vi
    (:func:`~tensegrity_stiffness.mechanics.planar_workspace.actuator_workspace_curves`), shaded
    inside the ranges."""
    path = output_path(path)
    samples = _check_count('samples', samples)
    fig = new_figure(width, height)
    ax = fig.add_subplot()
    outline = actuator_workspace_boundary(mech, samples)
    ax.fill(outline[:, 0], outline[:, 1], color='tab:blue', alpha=0.08,
            label='actuator workspace')
    _curve_legend(ax, actuator_workspace_curves(mech, samples))
    ax.set_xlabel(r'$\theta_1$ (rad)')
    ax.set_ylabel(r'$L_3$ (m)')
    pad_t = 0.04 * (mech.theta1_max - mech.theta1_min)
    pad_l = 0.06 * (mech.L3_max - mech.L3_min)
    ax.set_xlim(mech.theta1_min - pad_t, mech.theta1_max + pad_t)
    ax.set_ylim(mech.L3_min - pad_l, mech.L3_max + pad_l)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8, loc='center right', framealpha=0.9)
    ax.set_title(f'Fig. 2: actuator workspace and singular curves '
                 f'(L = {mech.L:g} m, K1 = {mech.K1:g} N/m, K2 = {mech.K2:g} N/m)', fontsize=10)
    return save_figure(fig, path)


def _cartesian_box(mech: PlanarMechanism, samples: int) -> tuple[float, float, float, float]:
    """(xmin, xmax, ymin, ymax) of the Cartesian workspace with a margin (m)."""
    pts = _finite_rows(cartesian_workspace_boundary(mech, samples))
    lo, hi = pts.min(axis=0), pts.max(axis=0)
    pad = CARTESIAN_MARGIN * float((hi - lo).max())
    return lo[0] - pad, hi[0] + pad, lo[1] - pad, hi[1] + pad


def _draw_base(ax: Any, mech: PlanarMechanism) -> None:
    """The fixed base triangle C1 C2 C3 (eq. 1), for orientation."""
    L = mech.L
    base = np.array([[0.0, 0.0], [-L, -SQRT3 * L], [L, -SQRT3 * L], [0.0, 0.0]])
    ax.plot(base[:, 0], base[:, 1], color='0.5', linewidth=1.0, linestyle='--',
            label=r'base $C_1C_2C_3$')
    for name, p in zip(('C1', 'C2', 'C3'), base[:3], strict=True):
        ax.annotate(name, p, textcoords='offset points', xytext=(3, 3), fontsize=8, color='0.4')


def plot_cartesian_workspace(mech: PlanarMechanism, path: str | Path, *,
                             samples: int = DEFAULT_CURVE_SAMPLES,
                             resolution: int = DEFAULT_MAP_RESOLUTION,
                             width: int = DEFAULT_SIZES['cartesian-workspace'][0],
                             height: int = DEFAULT_SIZES['cartesian-workspace'][1],
                             progress: ProgressCallback | None = None) -> Path:
    """Ji, Li & Lin Fig. 3: the Cartesian workspace of D3 (shaded: points with a stable
    equilibrium inside the actuator ranges, on a ``resolution`` x ``resolution`` grid) and the
    images of the curves i-vi
    (:func:`~tensegrity_stiffness.mechanics.planar_workspace.cartesian_workspace_curves`; curve i
    is a single point on the stable branch)."""
    path = output_path(path)
    samples = _check_count('samples', samples)
    resolution = _check_count('resolution', resolution)
    fig = new_figure(width, height)
    ax = fig.add_subplot()
    x0, x1, y0, y1 = _cartesian_box(mech, samples)
    X, Y = np.meshgrid(np.linspace(x0, x1, resolution), np.linspace(y0, y1, resolution))
    inside = _rows(lambda sl: mech.in_cartesian_workspace(X[sl], Y[sl]), resolution,
                   progress).astype(float)
    from matplotlib.colors import ListedColormap

    ax.pcolormesh(X, Y, np.ma.masked_equal(inside, 0.0), cmap=ListedColormap(['tab:blue']),
                  alpha=0.15, shading='auto', rasterized=True)
    ax.fill([], [], color='tab:blue', alpha=0.15, label='Cartesian workspace (D3)')
    _draw_base(ax, mech)
    _curve_legend(ax, cartesian_workspace_curves(mech, samples), point_names=('i',))
    ax.set_aspect('equal')
    ax.set_xlim(min(x0, -mech.L) - 0.05, max(x1, mech.L) + 0.05)
    ax.set_ylim(min(y0, -SQRT3 * mech.L) - 0.05, y1)
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.grid(True, alpha=0.3)
    # Below the axes: inside, it covered the base triangle and the singular curves.
    fig.legend(fontsize=8, loc='outside lower center', ncol=2, frameon=False)
    ax.set_title(f'Fig. 3: Cartesian workspace and singular curves '
                 f'(K1 = {mech.K1:g}, K2 = {mech.K2:g} N/m)', fontsize=10)
    return save_figure(fig, path)


def _rows(compute: Any, n_rows: int, progress: ProgressCallback | None) -> FloatArray:
    """``compute(slice)`` over row chunks of a grid, stacked; reports progress per chunk."""
    parts = []
    for start in range(0, n_rows, MAP_CHUNK_ROWS):
        parts.append(np.asarray(compute(slice(start, min(start + MAP_CHUNK_ROWS, n_rows)))))
        if progress is not None:
            progress(min(start + MAP_CHUNK_ROWS, n_rows), n_rows)
    return np.concatenate(parts, axis=0)


def theta2_curves(mech: PlanarMechanism, L3: float, theta1: float, theta2: FloatArray
                  ) -> dict[str, Any]:
    """U (eq. 4, J), tau (eq. 41, N m) and K (eq. 42, N m/rad) at ``theta2`` with the actuators
    locked at (L3, theta1); ``theta2_m`` the stable equilibrium (tau = 0, K maximal) and
    ``theta2_0`` the two angles with K = 0 (theta2_m +- pi/2), all in rad."""
    U = mech.energy(L3, theta1, theta2)
    tau = mech.torque(L3, theta1, theta2)
    K = mech.stiffness(L3, theta1, theta2)
    stable, _ = mech.equilibrium_angles(L3, theta1)
    t_m = float(stable)
    return {'U': U, 'tau': tau, 'K': K, 'theta2_m': t_m,
            'theta2_0': (t_m - 0.5 * math.pi, t_m + 0.5 * math.pi)}


def plot_theta2_curves(mech: PlanarMechanism, path: str | Path, *,
                       L3: float = PLANAR_THETA2_PARAMETERS['L3'],
                       theta1: float = PLANAR_THETA2_PARAMETERS['theta1'],
                       theta2_min: float = 0.0, theta2_max: float = math.pi,
                       samples: int = DEFAULT_THETA2_SAMPLES,
                       width: int = DEFAULT_SIZES['theta2'][0],
                       height: int = DEFAULT_SIZES['theta2'][1]) -> Path:
    """Ji, Li & Lin Figs. 4-6: U, tau = dU/dtheta2 and K = d2U/dtheta2^2 against theta2 (rad)
    with the actuators locked at (L3, theta1) (the captions' "theta2 = pi/10" is theta1, see
    docs/errata.md). Vertical lines: theta2_m (stable equilibrium) and theta2_0 (K = 0) in
    range."""
    path = output_path(path)
    samples = _check_count('samples', samples)
    if not (math.isfinite(theta2_min) and math.isfinite(theta2_max) and theta2_max > theta2_min):
        raise ValueError(f'theta2 range must be finite with max > min, got '
                         f'[{theta2_min}, {theta2_max}]')
    fig = new_figure(width, height)
    t2 = np.linspace(theta2_min, theta2_max, samples)
    c = theta2_curves(mech, L3, theta1, t2)
    axes = fig.subplots(3, 1, sharex=True)
    rows = (('U', 'U (J)', 'Fig. 4: potential energy U (eq. 4)'),
            ('tau', r'$\tau$ (N m)', r'Fig. 5: external torque $\tau = \partial U/'
                                     r'\partial\theta_2$ (eq. 41)'),
            ('K', 'K (N m/rad)', r'Fig. 6: stiffness $K = \partial^2 U/\partial\theta_2^2$ '
                                 '(eq. 42)'))
    period = 2.0 * math.pi
    marks = [(c['theta2_m'], r'$\theta_{2,m}$', 'tab:green')]
    marks += [(t, r'$\theta_{2,0}$', 'tab:red') for t in c['theta2_0']]
    for ax, (key, ylabel, title) in zip(axes, rows, strict=True):
        ax.plot(t2, c[key], linewidth=1.8, color='tab:blue')
        if key != 'U':
            ax.axhline(0.0, color='0.5', linewidth=0.8)
        y_text, va = (0.03, 'bottom') if key == 'K' else (0.97, 'top')
        ax.set_ylabel(ylabel)
        ax.set_title(title, fontsize=10, loc='left')
        ax.grid(True, alpha=0.3)
        for t, label, colour in marks:
            for shift in range(-2, 3):
                x = t + shift * period
                if theta2_min <= x <= theta2_max:
                    ax.axvline(x, color=colour, linestyle=':', linewidth=1.2)
                    ax.annotate(f'{label} = {x:.3f}', (x, y_text),
                                xycoords=('data', 'axes fraction'), fontsize=8, va=va,
                                ha='left', color=colour, xytext=(3, 0),
                                textcoords='offset points')
    axes[-1].set_xlabel(r'$\theta_2$ (rad)')
    fig.suptitle(f'Actuators locked: L = {mech.L:g} m, L3 = {L3:g} m, theta1 = {theta1:.4g} '
                 f'rad, K1 = {mech.K1:g} N/m, K2 = {mech.K2:g} N/m', fontsize=10)
    return save_figure(fig, path)


def _map_axes(fig: Any, X: FloatArray, Y: FloatArray, K: FloatArray, label: str,
              shrink: float = 1.0) -> Any:
    """Filled contours of K (masked where NaN) with labelled contour lines and a colour bar."""
    ax = fig.add_subplot()
    Km = np.ma.masked_invalid(K)
    if Km.count() == 0:
        raise ValueError('the stiffness map is empty: no point of the grid has a stable '
                         'equilibrium inside the ranges')
    filled = ax.contourf(X, Y, Km, levels=MAP_LEVELS, cmap=STIFFNESS_CMAP)
    if float(Km.max() - Km.min()) > 0.0:
        lines = ax.contour(X, Y, Km, levels=MAP_LINES, colors='k', linewidths=0.6)
        ax.clabel(lines, fontsize=7, fmt='%.0f')
    fig.colorbar(filled, ax=ax, label=label, shrink=shrink)
    ax.grid(True, alpha=0.3)
    return ax


def plot_actuator_stiffness(mech: PlanarMechanism, path: str | Path, *,
                            resolution: int = DEFAULT_MAP_RESOLUTION,
                            width: int = DEFAULT_SIZES['actuator-stiffness'][0],
                            height: int = DEFAULT_SIZES['actuator-stiffness'][1],
                            progress: ProgressCallback | None = None) -> Path:
    """Ji, Li & Lin Fig. 7: stiffness K (N m/rad) at the stable equilibrium over the actuator
    workspace (theta1, L3), eq. 47 on the stable branch
    (:func:`~tensegrity_stiffness.mechanics.planar_workspace.actuator_stiffness_map`)."""
    path = output_path(path)
    resolution = _check_count('resolution', resolution)
    fig = new_figure(width, height)
    T1, L3 = np.meshgrid(np.linspace(mech.theta1_min, mech.theta1_max, resolution),
                         np.linspace(mech.L3_min, mech.L3_max, resolution))
    K = _rows(lambda sl: actuator_stiffness_map(mech, L3[sl], T1[sl]), resolution, progress)
    ax = _map_axes(fig, T1, L3, K, 'K (N m/rad)')
    ax.set_xlabel(r'$\theta_1$ (rad)')
    ax.set_ylabel(r'$L_3$ (m)')
    ax.set_title(f'Fig. 7: stiffness in the actuator workspace '
                 f'(L = {mech.L:g} m, K1 = {mech.K1:g}, K2 = {mech.K2:g} N/m)', fontsize=10)
    return save_figure(fig, path)


def plot_cartesian_stiffness(mech: PlanarMechanism, path: str | Path, *,
                             resolution: int = DEFAULT_MAP_RESOLUTION,
                             samples: int = DEFAULT_CURVE_SAMPLES,
                             width: int = DEFAULT_SIZES['cartesian-stiffness'][0],
                             height: int = DEFAULT_SIZES['cartesian-stiffness'][1],
                             progress: ProgressCallback | None = None) -> Path:
    """Ji, Li & Lin Fig. 8: stiffness K (N m/rad) over the Cartesian workspace of D3 by exact
    inverse kinematics
    (:func:`~tensegrity_stiffness.mechanics.planar_workspace.cartesian_stiffness_map`); where two
    stable in-range equilibria put D3 at a point, the stiffer one is shown."""
    path = output_path(path)
    resolution = _check_count('resolution', resolution)
    samples = _check_count('samples', samples)
    fig = new_figure(width, height)
    x0, x1, y0, y1 = _cartesian_box(mech, samples)
    X, Y = np.meshgrid(np.linspace(x0, x1, resolution), np.linspace(y0, y1, resolution))

    def stiffest(sl: slice) -> FloatArray:
        both = cartesian_stiffness_map(mech, X[sl], Y[sl])
        return np.fmax(both[..., 0], both[..., 1])  # NaN only where neither exists

    K = _rows(stiffest, resolution, progress)
    ax = _map_axes(fig, X, Y, K, 'K (N m/rad), stiffest solution', shrink=0.8)
    outline = cartesian_workspace_boundary(mech, samples)
    ax.plot(outline[:, 0], outline[:, 1], color='k', linewidth=1.0)
    ax.set_aspect('equal')
    ax.set_xlabel('x (m)')
    ax.set_ylabel('y (m)')
    ax.set_title(f'Fig. 8: stiffness in the Cartesian workspace '
                 f'(K1 = {mech.K1:g}, K2 = {mech.K2:g} N/m)', fontsize=10)
    return save_figure(fig, path)


# ---------------------------------------------------------------------------- stiffness design
#: Screw coordinates a stiffness-range sweep can move along, and their units.
SCREW_COORDINATES = SCREW_NAMES
SCREW_COORDINATE_UNITS = ('rad', 'rad', 'rad', 'm', 'm', 'm')
DEFAULT_RANGE_SAMPLES = 31


def stiffness_range_curves(model: JointModel, screw: ArrayLike, coordinate: str,
                           offsets: ArrayLike, external_wrench: ArrayLike | None = None,
                           tension_min: float = 0.1, tension_max: float = 1.5,
                           progress: ProgressCallback | None = None
                           ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Along ``screw + offset e_coordinate``: (minimum, maximum, design) (N, 6) of the diagonal of
    K_c (:func:`~tensegrity_stiffness.mechanics.design.stiffness_range`; ``design`` = the tensions
    closest to the middle of the limits); NaN where the request is infeasible."""
    if coordinate not in SCREW_COORDINATES:
        raise ValueError(f'coordinate must be one of {SCREW_COORDINATES}, got {coordinate!r}')
    offsets = np.asarray(offsets, dtype=np.float64)
    axis = np.eye(6)[SCREW_COORDINATES.index(coordinate)]
    out = np.full((3, offsets.size, 6), np.nan)
    for i, s in enumerate(offsets):
        xi = np.asarray(screw, dtype=np.float64) + s * axis
        rng = stiffness_range(model, xi, external_wrench, tension_min, tension_max)
        if rng.success:
            out[0, i], out[1, i] = rng.minimum, rng.maximum
            design = design_rest_lengths(model, xi, external_wrench, tension_min, tension_max)
            if design.success:
                out[2, i] = np.diag(design.cartesian_stiffness)
        if progress is not None:
            progress(i + 1, offsets.size)
    return out[0], out[1], out[2]


def plot_stiffness_range(model: JointModel, screw: ArrayLike, path: str | Path, *,
                         coordinate: str = 'wx', extent: float = 0.3,
                         samples: int = DEFAULT_RANGE_SAMPLES,
                         external_wrench: ArrayLike | None = None, tension_min: float = 0.1,
                         tension_max: float = 1.5,
                         width: int = DEFAULT_SIZES['stiffness-range'][0],
                         height: int = DEFAULT_SIZES['stiffness-range'][1],
                         progress: ProgressCallback | None = None) -> Path:
    """Reachable range (shaded) of each diagonal entry of K_c over every admissible tension set,
    and the entry of the mid-limit design (line), for a sweep of one screw coordinate in
    ``[-extent, extent]`` about ``screw``; blank where no tensions hold the load."""
    path = output_path(path)
    samples = _check_count('samples', samples)
    offsets = np.linspace(-extent, extent, samples)
    lo, hi, mid = stiffness_range_curves(model, screw, coordinate, offsets, external_wrench,
                                         tension_min, tension_max, progress)
    fig = new_figure(width, height)
    axes = fig.subplots(2, 3, sharex=True)
    unit = SCREW_COORDINATE_UNITS[SCREW_COORDINATES.index(coordinate)]
    for i, ax in enumerate(axes.ravel()):
        ax.fill_between(offsets, lo[:, i], hi[:, i], color='tab:blue', alpha=0.3,
                        label='reachable')
        ax.plot(offsets, mid[:, i], color='tab:blue', linewidth=1.6, label='mid-limit design')
        ax.set_title(f'$K_c$ {DIAGONAL_NAMES[i]}-{DIAGONAL_NAMES[i]} ({DIAGONAL_UNITS[i]})',
                     fontsize=10)
        ax.grid(True, alpha=0.3)
        if i >= 3:
            ax.set_xlabel(f'offset of {coordinate} from the centre screw ({unit})')
    axes[0, 0].legend(fontsize=8)
    fig.suptitle(f'diagonal of $K_c$ reachable with tensions in [{tension_min:g}, '
                 f'{tension_max:g}] N', fontsize=11)
    return save_figure(fig, path)


# ---------------------------------------------------------------------------- spine
def plot_spine(chain: JointChain, screws: ArrayLike, path: str | Path, *,
               rest_lengths: Any = None, width: int = DEFAULT_SIZES['spine'][0],
               height: int = DEFAULT_SIZES['spine'][1], title: str | None = None,
               elevation: float = 12.0, azimuth: float = -60.0,
               tip_wrench: ArrayLike | None = None) -> Path:
    """The chain at ``screws`` in 3D (base frame, mm): each link's nodes (link i = link 2 of joint
    i and link 1 of joint i+1, one colour per link, joined by a polyline per node set), every
    joint's strings coloured by tension (one colour bar), slack strings dashed grey, saturated
    thick; the base and tool frames as RGB triads; the tip wrench's force as an arrow."""
    path = output_path(path)
    state = chain.evaluate(screws, rest_lengths)
    fig = new_figure(width, height)
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    ax = fig.add_subplot(projection='3d')
    tensions = [np.asarray(t) for t in state.tensions]
    top = max(float(t.max()) for t in tensions)
    norm = Normalize(0.0, top if top > 0.0 else 1.0)
    cmap = _colormap(TENSION_CMAP)
    links = _colormap('tab10')
    points = []
    n_slack = 0
    for i, model in enumerate(chain.joints):
        P, L = state.joint_frames[i], state.link_transforms[i]
        p1 = (model.link1_nodes @ P[:3, :3].T + P[:3, 3]) * MM
        p2 = model.link2_nodes_in_link1(L) * MM
        points += [p1, p2]
        slack, saturated = np.asarray(state.slack[i]), np.asarray(state.saturated[i])
        n_slack += int(slack.sum())
        for j, (a, b) in enumerate(model.connections):
            seg = np.vstack([p1[a], p2[b]])
            if slack[j]:
                style = {'color': '0.55', 'linestyle': '--', 'linewidth': 0.9}
            else:
                style = {'color': cmap(norm(tensions[i][j])), 'linestyle': '-',
                         'linewidth': 2.4 if saturated[j] else 1.4}
            ax.plot(seg[:, 0], seg[:, 1], seg[:, 2], **style)
        for nodes, link in ((p1, i), (p2, i + 1)):
            colour = '0.3' if link == 0 else links((link - 1) % 10)
            ax.plot(nodes[:, 0], nodes[:, 1], nodes[:, 2], color=colour, linewidth=3.0,
                    alpha=0.6)
            ax.scatter(nodes[:, 0], nodes[:, 1], nodes[:, 2], s=12, color=colour,
                       depthshade=False)
    cloud = np.vstack(points)
    span = float(np.ptp(cloud, axis=0).max())
    for name, T in (('base', np.eye(4)), ('tool', state.tip_transform)):
        origin = T[:3, 3] * MM
        for k, colour in enumerate(('red', 'green', 'blue')):
            tip = origin + 0.08 * span * T[:3, k]
            ax.plot(*np.vstack([origin, tip]).T, color=colour, linewidth=1.5)
        ax.text(*origin, f' {name}', fontsize=8)
    handles = [Line2D([], [], color=cmap(0.7), linewidth=1.4, label='taut string'),
               Line2D([], [], color='0.55', linestyle='--', label=f'slack string ({n_slack})')]
    W = None if tip_wrench is None else np.asarray(tip_wrench, dtype=np.float64)
    if W is not None and np.linalg.norm(W[:3]) > 0.0:
        origin = state.tip_transform[:3, 3] * MM
        arrow = TIP_FORCE_ARROW * span * W[:3] / np.linalg.norm(W[:3])
        ax.quiver(*origin, *arrow, color=TIP_FORCE_COLOUR, linewidth=3.0,
                  arrow_length_ratio=0.25)
        cloud = np.vstack([cloud, origin + arrow])
        handles.append(Line2D([], [], color=TIP_FORCE_COLOUR, linewidth=3.0,
                              label=f'tip force {np.linalg.norm(W[:3]):.3g} N (direction)'))
    _equal_axes_3d(ax, cloud, span, elevation, azimuth, fit=True)
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.5, pad=0.08,
                 label='string tension (N)')
    # Below the axes: inside, it covered the top of the spine.
    fig.legend(handles=handles, loc='outside lower center', ncol=len(handles), fontsize=8,
               frameon=False)
    p = np.round(state.tip_transform[:3, 3] * MM, 1) + 0.0  # no '-0.0'
    ax.set_title(title or (f'spine of {chain.n_joints} joints, tip at '
                           f'({p[0]:.1f}, {p[1]:.1f}, {p[2]:.1f}) mm'), fontsize=10)
    return save_figure(fig, path)
