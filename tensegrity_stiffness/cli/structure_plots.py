"""The 3D figure of a structure (``tensegrity-stiffness structure plot``, ``structure check
--plot``): bars as thick dark segments, general bodies as the polyline through their nodes
(fixed ones blue), strings coloured by tension (slack ones dashed grey, saturated ones thick),
world nodes as squares, contact forces as arrows at the nodes on the ground, and the ground as
a grey outline; z up, equal scale on the three axes (mm). Built as the joint's figure of
:mod:`.plots`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.cli.plots import (
    MM,
    TENSION_CMAP,
    new_figure,
    output_path,
    save_figure,
)

FloatArray = NDArray[np.float64]

#: Default figure size (px).
STRUCTURE_FIGURE_SIZE = (900, 700)
#: Longest contact-force arrow as a fraction of the structure's size.
CONTACT_ARROW = 0.3
CONTACT_COLOUR = 'deepskyblue'
BAR_COLOUR = '0.15'
BODY_COLOUR = 'tab:green'
WORLD_COLOUR = 'tab:blue'


def _axes_box(ax: Any, points: FloatArray, elevation: float, azimuth: float) -> None:
    """Equal-scale axes around ``points`` (mm), z up."""
    lo, hi = points.min(axis=0), points.max(axis=0)
    centre = 0.5 * (lo + hi)
    half = 0.55 * max(float(np.max(hi - lo)), 1e-9)
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.view_init(elev=elevation, azim=azimuth)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.set_xlabel('x (mm)')
    ax.set_ylabel('y (mm)')
    ax.set_zlabel('z (mm)')


def plot_structure(structure: Any, state: Any, path: str | Path, *,
                   contacts: dict[str, FloatArray] | None = None,
                   width: int = STRUCTURE_FIGURE_SIZE[0],
                   height: int = STRUCTURE_FIGURE_SIZE[1], title: str | None = None,
                   elevation: float = 22.0, azimuth: float = -60.0) -> Path:
    """The structure at ``state`` (a
    :class:`~tensegrity_stiffness.structures.structure.StructureState`, e.g. of an equilibrium)
    with its ``contacts`` {node: force (3,)} (module docstring) as a PNG at ``path``."""
    path = output_path(path)
    fig = new_figure(width, height)
    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.lines import Line2D

    s = structure
    X = s.node_positions(state.poses) * MM
    ax = fig.add_subplot(projection='3d')
    top = float(state.tensions.max()) if state.tensions.max() > 0.0 else 1.0
    norm = Normalize(0.0, top)
    cmap = colormaps[TENSION_CMAP]
    for j, (a, b) in enumerate(s.string_nodes):
        seg = X[[a, b]]
        if state.slack[j]:
            style = {'color': '0.55', 'linestyle': '--', 'linewidth': 1.2}
        else:
            style = {'color': cmap(norm(state.tensions[j])), 'linestyle': '-',
                     'linewidth': 3.2 if state.saturated[j] else 1.8}
        ax.plot(*seg.T, **style)
    for i, body in enumerate(s.bodies):
        nodes = X[s.node_bodies == i]
        if body.kind == 'bar':
            ax.plot(*nodes.T, color=BAR_COLOUR, linewidth=5.0, solid_capstyle='round')
        else:
            colour = WORLD_COLOUR if body.fixed else BODY_COLOUR
            ax.plot(*nodes.T, color=colour, linewidth=4.0, alpha=0.5)
            ax.scatter(*nodes.T, color=colour, s=30, depthshade=False)
        ax.text(*nodes.mean(axis=0), f' {body.name}', fontsize=7, color=BAR_COLOUR)
    world = X[s.node_bodies < 0]
    if world.size:
        ax.scatter(*world.T, marker='s', color=WORLD_COLOUR, s=40, depthshade=False)
    span = float(np.ptp(X, axis=0).max())
    contacts = contacts or {}
    if contacts:
        forces = np.array(list(contacts.values()))
        scale = CONTACT_ARROW * span / max(float(np.linalg.norm(forces, axis=1).max()), 1e-300)
        for name, f in contacts.items():
            p = X[s.node_index(name)]
            ax.quiver(*p, *(np.asarray(f) * scale), color=CONTACT_COLOUR, linewidth=1.5)
    if s.ground is not None:
        n = s.ground.normal
        t1, t2 = s.ground.tangents()
        c = X.mean(axis=0)
        c = c - (n @ c - s.ground.height * MM) * n
        g = np.array([c + 0.6 * span * (u * t1 + v * t2)
                      for u, v in ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))])
        ax.plot(*g.T, color='0.6', linewidth=1.0)
        X = np.vstack([X, g])
    _axes_box(ax, X, elevation, azimuth)
    fig.colorbar(ScalarMappable(norm=norm, cmap=cmap), ax=ax, shrink=0.6, pad=0.08,
                 label='string tension (N)')
    kinds = {('bar' if b.kind == 'bar' else 'fixed body' if b.fixed else 'body')
             for b in s.bodies}
    handles = [Line2D([], [], color=colour, linewidth=width, label=label)
               for label, colour, width in (('bar', BAR_COLOUR, 5.0), ('body', BODY_COLOUR, 4.0),
                                            ('fixed body', WORLD_COLOUR, 4.0))
               if label in kinds]
    handles += [Line2D([], [], color=cmap(0.7), linewidth=1.8, label='taut string'),
               Line2D([], [], color='0.55', linestyle='--',
                      label=f'slack string ({int(state.slack.sum())})')]
    if contacts:
        handles.append(Line2D([], [], color=CONTACT_COLOUR, label=f'contact force '
                                                                  f'({len(contacts)})'))
    ax.legend(handles=handles, loc='upper left', fontsize=8)
    ax.set_title(title or f'{s.n_bodies} bodies, {s.n_strings} strings', fontsize=10)
    return save_figure(fig, path)
