"""Figures of vibration modes (:mod:`~tensegrity_stiffness.mechanics.dynamics`): each mode drawn as
the joint (or spine) displaced along its shape, next to the equilibrium, for ``tensegrity-stiffness
modes --plot``. matplotlib only (no rclpy)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from tensegrity_stiffness.cli.plots import MM, MatplotlibMissingError, check_size
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.modes import JointModes

#: Default figure size (pixels).
DEFAULT_SIZE = (1500, 1000)
#: The drawn displacement: the largest node displacement is this fraction of the drawing's span.
DISPLACEMENT_FRACTION = 0.15
#: Modes drawn for a spine by default (its slowest).
DEFAULT_SPINE_MODES = 6
DPI = 100


def _pyplot():
    try:
        import matplotlib

        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError as exc:  # pragma: no cover - the setup installs matplotlib
        raise MatplotlibMissingError('matplotlib is required for plots: pip install matplotlib'
                                     ) from exc
    return plt


def _grid(count: int) -> tuple[int, int]:
    cols = min(3, count)
    return (count + cols - 1) // cols, cols


def _equal_axes(ax, points: np.ndarray) -> None:
    centre = 0.5 * (points.max(axis=0) + points.min(axis=0))
    half = 0.55 * float(np.ptp(points, axis=0).max())
    ax.set_xlim(centre[0] - half, centre[0] + half)
    ax.set_ylim(centre[1] - half, centre[1] + half)
    ax.set_zlim(centre[2] - half, centre[2] + half)
    ax.set_xlabel('x (mm)', fontsize=7)
    ax.set_ylabel('y (mm)', fontsize=7)
    ax.set_zlabel('z (mm)', fontsize=7)
    ax.tick_params(labelsize=6)


#: Damping ratios below this are drawn as 0 (rounding noise of an undamped model).
ZETA_ZERO = 1e-9


def _label(modes: JointModes, k: int) -> str:
    zeta = float(modes.damping_ratios[k])
    return (f'mode {k + 1}: {modes.frequencies[k]:.3g} Hz, '
            f'zeta = {0.0 if abs(zeta) < ZETA_ZERO else zeta:.3g}')


def vertical_axis(lower: ArrayLike, upper: ArrayLike) -> str:
    """The axis ('x', 'y' or 'z') drawn up: the one along which the ``upper`` points (link 2's
    nodes, a spine's tip) stand farthest from the ``lower`` ones (link 1's, the base), so a
    +z ring joint stands upright as the +y vertebra does."""
    rise = np.mean(np.atleast_2d(upper), axis=0) - np.mean(np.atleast_2d(lower), axis=0)
    return 'xyz'[int(np.argmax(np.abs(rise)))]


def _scale(points: np.ndarray, displaced: np.ndarray) -> float:
    """Factor that makes the largest node displacement DISPLACEMENT_FRACTION of the span."""
    span = float(np.ptp(points, axis=0).max())
    move = float(np.max(np.linalg.norm(displaced - points, axis=1)))
    return DISPLACEMENT_FRACTION * span / move if move > 0.0 else 0.0


def plot_joint_modes(model: JointModel, modes: JointModes, path: str | Path, *,
                     width: int = DEFAULT_SIZE[0], height: int = DEFAULT_SIZE[1],
                     title: str | None = None, elevation: float = 18.0,
                     azimuth: float = -50.0) -> Path:
    """One 3D panel per mode (in {1}, mm): link 1's nodes (squares), link 2 at the equilibrium
    (grey) and displaced along the mode's shape (green, strings drawn), the displacement scaled
    so that the largest node moves :data:`DISPLACEMENT_FRACTION` of the joint's span (a linear
    mode has no amplitude of its own); the frequency and damping ratio in each title."""
    w, h = check_size(width, height)
    plt = _pyplot()
    xi = np.asarray(modes.screw, dtype=np.float64)
    if xi.shape != (6,):
        raise ValueError(f'modes must be a joint\'s (screw of shape (6,)), got {xi.shape}')
    path = Path(path)
    fig = plt.figure(figsize=(w / DPI, h / DPI), dpi=DPI)
    p1 = model.link1_nodes * MM
    rest = model.link2_nodes_in_link1(_transform(xi)) * MM
    rows, cols = _grid(len(modes.frequencies))
    up = vertical_axis(p1, rest)
    for k in range(len(modes.frequencies)):
        shape = modes.shapes[k].real
        probe = model.link2_nodes_in_link1(_transform(xi + 1e-4 * shape)) * MM
        a = 1e-4 * _scale(rest, probe)
        moved = model.link2_nodes_in_link1(_transform(xi + a * shape)) * MM
        ax = fig.add_subplot(rows, cols, k + 1, projection='3d')
        for i, j in model.connections:
            seg = np.vstack([p1[i], moved[j]])
            ax.plot(*seg.T, color='0.35', linewidth=0.8)
        for nodes, colour, marker, alpha in ((p1, 'tab:blue', 's', 0.9),
                                             (rest, '0.6', 'o', 0.6),
                                             (moved, 'tab:green', 'o', 0.9)):
            ax.plot(*nodes.T, color=colour, linewidth=3.0, alpha=0.4 * alpha)
            ax.scatter(*nodes.T, color=colour, marker=marker, s=18, alpha=alpha,
                       depthshade=False)
        _equal_axes(ax, np.vstack([p1, rest, moved]))
        ax.view_init(elev=elevation, azim=azimuth, vertical_axis=up)
        ax.set_title(_label(modes, k), fontsize=9)
    fig.suptitle(title or ('joint modes at xi = [' + ' '.join(f'{v:.3g}' for v in xi) +
                           ']; grey: equilibrium, green: displaced along the mode'
                           + ('' if modes.stable else ' (UNSTABLE)')), fontsize=10)
    fig.savefig(path)
    plt.close(fig)
    return path


def _transform(xi: ArrayLike) -> np.ndarray:
    from tensegrity_stiffness.geometry.screw import exp_se3

    return exp_se3(np.asarray(xi, dtype=np.float64))


def _spine_points(chain: JointChain, screws: np.ndarray) -> list[tuple[int, np.ndarray]]:
    """(link, nodes in the base, mm) of every node set: link i-1's upper set, link i's lower."""
    L = chain.link_transforms(screws)
    out = []
    current = np.eye(4)
    for i, model in enumerate(chain.joints):
        out.append((i, (model.link1_nodes @ current[:3, :3].T + current[:3, 3]) * MM))
        out.append((i + 1, model.link2_nodes_in_link1(L[i]) * MM))
        if i < chain.n_joints - 1:
            current = L[i] @ chain.link_offsets[i]
    return out


def plot_spine_modes(chain: JointChain, modes: JointModes, path: str | Path, *,
                     count: int = DEFAULT_SPINE_MODES, width: int = DEFAULT_SIZE[0],
                     height: int = DEFAULT_SIZE[1], title: str | None = None,
                     elevation: float = 12.0, azimuth: float = -60.0) -> Path:
    """The spine's ``count`` slowest modes, one 3D panel each (base frame, mm): every link's
    node sets at the equilibrium (grey) and displaced along the mode (one colour per link),
    scaled as :func:`plot_joint_modes`."""
    w, h = check_size(width, height)
    if isinstance(count, bool) or not isinstance(count, int) or count < 1:
        raise ValueError(f'count must be an integer >= 1, got {count!r}')
    plt = _pyplot()
    xi = np.asarray(modes.screw, dtype=np.float64).reshape(chain.n_joints, 6)
    path = Path(path)
    count = min(count, len(modes.frequencies))
    fig = plt.figure(figsize=(w / DPI, h / DPI), dpi=DPI)
    rest = _spine_points(chain, xi)
    rest_all = np.vstack([p for _, p in rest])
    colours = plt.get_cmap('tab10')
    rows, cols = _grid(count)
    up = vertical_axis(rest[0][1], rest[-1][1])
    for k in range(count):
        shape = modes.shapes[k].real.reshape(chain.n_joints, 6)
        probe = np.vstack([p for _, p in _spine_points(chain, xi + 1e-4 * shape)])
        a = 1e-4 * _scale(rest_all, probe)
        moved = _spine_points(chain, xi + a * shape)
        ax = fig.add_subplot(rows, cols, k + 1, projection='3d')
        for (link, p0), (_, p) in zip(rest, moved, strict=True):
            ax.plot(*p0.T, color='0.7', linewidth=2.0)
            colour = '0.3' if link == 0 else colours((link - 1) % 10)
            ax.plot(*p.T, color=colour, linewidth=2.5)
            ax.scatter(*p.T, color=colour, s=8, depthshade=False)
        _equal_axes(ax, np.vstack([rest_all] + [p for _, p in moved]))
        ax.view_init(elev=elevation, azim=azimuth, vertical_axis=up)
        ax.set_title(_label(modes, k), fontsize=9)
    fig.suptitle(title or (f'spine of {chain.n_joints} joints: {count} slowest modes; grey: '
                           'equilibrium' + ('' if modes.stable else ' (UNSTABLE)')),
                 fontsize=10)
    fig.savefig(path)
    plt.close(fig)
    return path
