"""Structure templates (``tensegrity-stiffness new-config --template prism | six-bar | joint |
spine``; docs/structures.md, "Templates"): the regular p-prism, the 6-bar expanded octahedron,
and a structure from a joint or a spine config.

Each template is a function of its choices that returns the document
(:func:`prism_document`, :func:`six_bar_document`, :func:`config_structure_document`).

* **Regular p-prism** (:func:`prism_layout`): ``p`` bars between two regular p-gons of
  ``radius`` at heights 0 and ``height``, the top one turned by the twist ``alpha`` about +z.
  Nodes ``b<i>`` (bottom, angle ``2 pi i / p``) and ``t<i>`` (top, ``2 pi i / p + alpha``);
  strings ``bottom_<i>`` (``b<i>``-``b<i+1>``), ``top_<i>`` (``t<i>``-``t<i+1>``) and
  ``vertical_<i>`` (``b<i>``-``t<i>``); bars ``bar<i>`` from ``b<i>`` to ``t<i+1>``. In
  equilibrium only at ``alpha = pi/2 - pi/p`` (:func:`prism_twist`; Tibert & Pellegrino 2003,
  Connelly & Terrell 1995), with the force densities of :func:`prism_force_densities`.
* **Expanded octahedron** (:func:`six_bar_layout`): six bars of length ``L`` in three parallel
  pairs along x, y, z, each pair ``L/2`` apart, 24 strings of length ``L sqrt(6)/4`` (strut /
  string ``sqrt(8/3)``); force densities 1 (strings) and -3/2 (bars). Nodes
  ``<bar>.a``/``.b``: bar ``x1`` joins ``(-L/2, 0, +L/4)`` to ``(+L/2, 0, +L/4)``, ``x2`` the
  same at ``z = -L/4``; ``y1``/``y2`` at ``x = +-L/4`` along y; ``z1``/``z2`` at ``y = +-L/4``
  along z.

* **A joint or a spine config** (:func:`config_structure_document`): the joint's two links
  (``link1`` fixed) or the spine's links (``link0`` the base, fixed) as bodies, through
  :meth:`~tensegrity_stiffness.structures.structure.Structure.from_joint` /
  :meth:`~tensegrity_stiffness.structures.structure.Structure.from_chain` at the config's
  ``initial_screw`` (screws).

With ``ground``, the structure gets gravity (-z) and the ground plane through its lowest nodes;
the prism stands on its bottom polygon, the six-bar on a triangle of strings.

A layout becomes a structure document (:func:`structure_document_of_layout`): each bar a body of
the schema at the pose that puts its ``a``/``b`` on the layout's nodes, the tensions those of the
layout's self-stress scaled so that the largest string tension is ``pretension`` (N), the rest
lengths from the strings' force law (``hooke``: ``l0 = l - t/k``; ``paper``: ``l0 = l (1 - t/k)``)
so the layout is an exact equilibrium of the document. Templates refuse a pretension the strings
cannot carry (a rest length <= 0, a maximum length below the length).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.quaternion import (
    quaternion_to_rotation,
    rotation_to_quaternion,
)
from tensegrity_stiffness.geometry.validation import per_string
from tensegrity_stiffness.mechanics.design import rest_from_tensions
from tensegrity_stiffness.structures.analysis import Framework, analyse_framework

FloatArray = NDArray[np.float64]

TEMPLATES = ('prism', 'six-bar', 'from-config')
#: Defaults of the bar templates: node radius (m), string stiffness (N/m), the largest string
#: tension (N), the bars' mass (kg).
DEFAULT_RADIUS = 0.1
DEFAULT_STIFFNESS = 500.0
DEFAULT_PRETENSION = 5.0
DEFAULT_BAR_MASS = 0.1
#: The prism template's default number of bars.
DEFAULT_PRISM_BARS = 3
#: The six-bar's default bar length (m).
DEFAULT_BAR_LENGTH = 0.3
#: Gravity written with ``ground`` (m/s^2, -z).
STANDARD_GRAVITY = 9.80665
#: Friction coefficient of the ground written with ``ground``.
DEFAULT_FRICTION = 0.8


@dataclass(frozen=True)
class Layout:
    """Node positions and members of a bar-and-string template: ``node_names`` (n,),
    ``positions`` (n, 3), ``bars`` {name: (node a, node b)}, ``strings`` {name: (from, to)}."""

    node_names: tuple[str, ...]
    positions: FloatArray
    bars: dict[str, tuple[int, int]]
    strings: dict[str, tuple[int, int]]

    def framework(self, forces: ArrayLike | None = None) -> Framework:
        """The pin-jointed framework: strings first, then bars (their order here)."""
        members = list(self.strings.values()) + list(self.bars.values())
        names = list(self.strings) + list(self.bars)
        is_bar = [False] * len(self.strings) + [True] * len(self.bars)
        return Framework.build(self.node_names, self.positions, members, names, is_bar,
                               forces=forces)


def prism_twist(p: int) -> float:
    """The equilibrium twist ``pi/2 - pi/p`` (rad) of the regular p-prism (Tibert &
    Pellegrino 2003, eq. 4)."""
    return math.pi / 2.0 - math.pi / p


def prism_force_densities(p: int) -> tuple[float, float, float]:
    """Force densities (bottom and top strings, vertical strings, bars) of the regular p-prism
    in equilibrium, scaled to 1 on the polygons: ``(1, 2 sin(pi/p), -2 sin(pi/p))``. From node
    ``b<i>``'s equilibrium: vertically the bar balances the vertical string; horizontally the
    polygon's pull ``-4 sin^2(pi/p) x_i`` balances ``q_v`` times the vertical string's
    horizontal span, ``2 sin(pi/p)`` radially outwards at ``alpha = pi/2 - pi/p`` (Connelly &
    Terrell 1995; for p = 3 the ratios ``1 : sqrt 3 : -sqrt 3`` of Tibert & Pellegrino 2003)."""
    s = 2.0 * math.sin(math.pi / p)
    return 1.0, s, -s


def _check_int(name: str, value: Any, minimum: int) -> int:
    if isinstance(value, bool) or int(value) != value or value < minimum:
        raise ValueError(f'{name} must be an integer >= {minimum}, got {value!r}')
    return int(value)


def _check_positive(name: str, value: Any) -> float:
    x = float(value)
    if not (math.isfinite(x) and x > 0.0):
        raise ValueError(f'{name} must be finite and > 0, got {value!r}')
    return x


def prism_layout(p: int, radius: float = DEFAULT_RADIUS, height: float | None = None,
                 twist: float | None = None) -> Layout:
    """The regular p-prism (module docstring) of ``radius`` and ``height`` (m; default
    ``2 radius``) at ``twist`` (rad; default the equilibrium :func:`prism_twist`)."""
    p = _check_int('bars', p, 3)
    r = _check_positive('radius', radius)
    h = 2.0 * r if height is None else _check_positive('height', height)
    alpha = prism_twist(p) if twist is None else float(twist)
    if not math.isfinite(alpha):
        raise ValueError(f'twist must be finite, got {twist!r}')
    angles = 2.0 * math.pi * np.arange(p) / p
    bottom = np.column_stack([r * np.cos(angles), r * np.sin(angles), np.zeros(p)])
    top = np.column_stack([r * np.cos(angles + alpha), r * np.sin(angles + alpha),
                           np.full(p, h)])
    names = tuple(f'b{i}' for i in range(p)) + tuple(f't{i}' for i in range(p))
    strings: dict[str, tuple[int, int]] = {}
    for i in range(p):
        strings[f'bottom_{i}'] = (i, (i + 1) % p)
    for i in range(p):
        strings[f'top_{i}'] = (p + i, p + (i + 1) % p)
    for i in range(p):
        strings[f'vertical_{i}'] = (i, p + i)
    bars = {f'bar{i}': (i, p + (i + 1) % p) for i in range(p)}
    return Layout(names, np.vstack([bottom, top]), bars, strings)


#: The six-bar's bars: name -> (axis of the bar, axis of the offset, sign of the offset).
_SIX_BARS = (('x1', 0, 2, 1.0), ('x2', 0, 2, -1.0), ('y1', 1, 0, 1.0), ('y2', 1, 0, -1.0),
             ('z1', 2, 1, 1.0), ('z2', 2, 1, -1.0))


def six_bar_layout(bar_length: float = DEFAULT_BAR_LENGTH) -> Layout:
    """The expanded octahedron (module docstring) with bars of ``bar_length`` (m): every node
    joined by strings to the four nearest nodes of the other two pairs."""
    L = _check_positive('bar_length', bar_length)
    names, points, bars = [], [], {}
    for bar, axis, offset_axis, sign in _SIX_BARS:
        for end, along in (('a', -0.5), ('b', 0.5)):
            x = np.zeros(3)
            x[axis] = along * L
            x[offset_axis] = sign * 0.25 * L
            names.append(f'{bar}.{end}')
            points.append(x)
        bars[bar] = (len(names) - 2, len(names) - 1)
    X = np.array(points)
    bar_of = [k // 2 for k in range(len(names))]
    string_length = L * math.sqrt(6.0) / 4.0
    strings = {}
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            if _SIX_BARS[bar_of[i]][1] == _SIX_BARS[bar_of[j]][1]:
                continue  # the same pair: not joined
            if abs(np.linalg.norm(X[i] - X[j]) - string_length) <= 1e-9 * L:
                strings[f'{names[i]}-{names[j]}'.replace('.', '')] = (i, j)
    return Layout(tuple(names), X, bars, strings)


def self_stress_tensions(layout: Layout, pretension: float) -> FloatArray:
    """Member tensions (strings, then bars) of the layout's one self-stress, scaled so the
    largest string tension is ``pretension`` (ValueError when the layout has no self-stress
    with every string pulling, or more than one)."""
    fw = layout.framework()
    a = analyse_framework(fw)
    if a.self_stresses != 1:
        raise ValueError(f'the layout has {a.self_stresses} self-stresses; a template needs '
                         'exactly one (is it at its equilibrium twist?)')
    t = a.self_stress_basis[:, 0]
    n_s = len(layout.strings)
    if t[:n_s].sum() < 0.0:
        t = -t
    if np.any(t[:n_s] <= 0.0) or np.any(t[n_s:] >= 0.0):
        raise ValueError('the layout\'s self-stress does not pull on every string and push on '
                         'every bar')
    return t * (pretension / t[:n_s].max())


def bar_pose(a: ArrayLike, b: ArrayLike) -> tuple[float, list[float]]:
    """Length and pose ``[x, y, z, qx, qy, qz, qw]`` of a bar whose node ``a`` (at
    ``-length/2`` on its z axis) lies at ``a`` and node ``b`` at ``b`` (the rotation turns +z
    onto ``b - a`` about ``z x (b - a)``)."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    d = b - a
    length = float(np.linalg.norm(d))
    z = d / length
    c = float(z[2])
    axis = np.cross([0.0, 0.0, 1.0], z)
    s = float(np.linalg.norm(axis))
    if s < 1e-12:
        R = np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    else:
        k = axis / s
        Kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
        R = np.eye(3) + s * Kx + (1.0 - c) * Kx @ Kx
    q = rotation_to_quaternion(R)
    return length, [float(v) for v in (*(0.5 * (a + b)), *q)]


def rest_lengths_for(lengths: FloatArray, tensions: FloatArray, stiffness: FloatArray,
                     force_law: str) -> FloatArray:
    """Rest lengths that give ``tensions`` at ``lengths`` under ``force_law`` (``hooke``:
    ``t = k (l - l0)``; ``paper``: ``t = k (l - l0) / l``): the joint's inversion,
    :func:`~tensegrity_stiffness.mechanics.design.rest_from_tensions`."""
    law = _Law(force_law, np.asarray(stiffness, dtype=float))
    return rest_from_tensions(law, lengths, tensions)


@dataclass(frozen=True)
class _Law:
    """The two fields of a force law that :func:`rest_from_tensions` reads."""

    force_law: str
    k: FloatArray


def structure_document_of_layout(layout: Layout, stiffness: ArrayLike = DEFAULT_STIFFNESS,
                                 pretension: float = DEFAULT_PRETENSION,
                                 bar_mass: float = DEFAULT_BAR_MASS, force_law: str = 'hooke',
                                 ground: bool = False, max_stretch: float | None = None,
                                 start: Layout | None = None,
                                 tensions: ArrayLike | None = None) -> dict[str, Any]:
    """The ``{'structure': ...}`` document of ``layout`` (module docstring): rest lengths that
    make the layout an equilibrium at ``pretension`` (N, the largest string tension), strings
    of ``stiffness`` (N/m, one or one per string), bars of ``bar_mass`` (kg). ``max_stretch``
    (m): each string's maximum length minus its length at the layout (None: no maximum).
    ``start``: the same topology at other node positions, written as the bodies' poses (the
    solvers' start). ``ground``: gravity (-z) and the ground plane under the lowest node.
    ``tensions``: the member forces (strings, then bars: :meth:`Layout.framework`'s order) in
    equilibrium at the layout, scaled to the pretension (None: the layout's one self-stress).
    ``bar_mass``: one mass or one per bar."""
    pretension = _check_positive('pretension', pretension)
    if force_law not in ('hooke', 'paper'):
        raise ValueError(f"force_law must be 'hooke' or 'paper', got {force_law!r}")
    n_s = len(layout.strings)
    k = per_string('stiffness', stiffness, n_s, repeat_one=True)
    if np.any(k <= 0.0):
        raise ValueError(f'stiffness must be one positive value or {n_s} (one per string)')
    if tensions is None:
        t = self_stress_tensions(layout, pretension)
    else:
        t = np.asarray(tensions, dtype=np.float64).reshape(-1)
        if t.shape != (n_s + len(layout.bars),) or np.any(t[:n_s] <= 0.0):
            raise ValueError(f'tensions must be {n_s + len(layout.bars)} member forces with '
                             'every string pulling')
        t = t * (pretension / t[:n_s].max())
    masses = np.broadcast_to(np.asarray(bar_mass, dtype=np.float64), (len(layout.bars),))
    fw = layout.framework()
    lengths = fw.lengths[:n_s]
    rest = rest_lengths_for(lengths, t[:n_s], k, force_law)
    names = list(layout.strings)
    if np.any(rest <= 0.0):
        j = int(np.argmin(rest))
        raise ValueError(f'pretension {pretension:g} N: string {names[j]} (stiffness '
                         f'{k[j]:g} N/m, length {lengths[j]:.6g} m) would need a rest length '
                         f'<= 0 for its tension {t[j]:.6g} N; lower the pretension or stiffen '
                         'the strings')
    where = layout if start is None else start
    X = where.positions
    bodies = []
    for m, (name, (i, j)) in zip(masses, layout.bars.items(), strict=True):
        length, pose = bar_pose(X[i], X[j])
        bodies.append({'name': name, 'type': 'bar', 'length': length, 'pose': pose,
                       'mass': float(m)})
    node_ref = {}
    for name, (i, j) in layout.bars.items():
        node_ref[i], node_ref[j] = f'{name}.a', f'{name}.b'
    strings = []
    for s, (name, (i, j)) in enumerate(layout.strings.items()):
        entry = {'name': name, 'from': node_ref[i], 'to': node_ref[j],
                 'stiffness': float(k[s]), 'rest_length': float(rest[s])}
        if max_stretch is not None:
            entry['max_length'] = float(lengths[s] + _check_positive('max_stretch',
                                                                     max_stretch))
        strings.append(entry)
    section: dict[str, Any] = {'force_law': force_law, 'bodies': bodies, 'strings': strings}
    if ground:
        section['gravity'] = [0.0, 0.0, -STANDARD_GRAVITY]
        section['ground'] = {'normal': [0.0, 0.0, 1.0], 'height': float(X[:, 2].min()),
                             'friction': DEFAULT_FRICTION}
    return {'structure': section}


def string_triangles(layout: Layout) -> list[tuple[int, int, int]]:
    """The triangles of nodes joined pairwise by strings (the faces a structure can rest on)."""
    pairs = {frozenset(ij) for ij in layout.strings.values()}
    n = len(layout.node_names)
    return [(i, j, k) for i in range(n) for j in range(i + 1, n) for k in range(j + 1, n)
            if {frozenset((i, j)), frozenset((j, k)), frozenset((i, k))} <= pairs]


def face_down(layout: Layout, face: Sequence[int] | None = None) -> Layout:
    """``layout`` turned so that the triangle of nodes ``face`` (default: the first of
    :func:`string_triangles`) lies flat at the bottom, its outward normal onto -z, then lifted
    so that its nodes are at z = 0."""
    if face is None:
        triangles = string_triangles(layout)
        if not triangles:
            raise ValueError('the layout has no triangle of strings to rest on')
        face = triangles[0]
    X = layout.positions
    a, b, c = X[list(face)]
    n = np.cross(b - a, c - a)
    n /= np.linalg.norm(n)
    if n @ (a - X.mean(axis=0)) < 0.0:
        n = -n
    _, pose = bar_pose(np.zeros(3), -n)  # R turns +z onto -n, so R' turns n onto -z
    R = quaternion_to_rotation(np.array(pose[3:]))
    Y = X @ R  # rows R' x
    Y[:, 2] -= Y[list(face), 2].mean()
    return Layout(layout.node_names, Y, layout.bars, layout.strings)


def prism_document(p: int, radius: float = DEFAULT_RADIUS, height: float | None = None,
                   twist: float | None = None, **kwargs: Any) -> dict[str, Any]:
    """The regular p-prism template (module docstring): the rest lengths of the equilibrium
    prism of ``radius`` and ``height`` (m); a ``twist`` (rad) other than the equilibrium's
    writes the bars' start poses at that twist (the solvers turn it back).
    ``kwargs``: :func:`structure_document_of_layout`'s."""
    layout = prism_layout(p, radius, height)
    start = None if twist is None else prism_layout(p, radius, height, twist)
    return structure_document_of_layout(layout, start=start, **kwargs)


def six_bar_document(bar_length: float = DEFAULT_BAR_LENGTH, ground: bool = False,
                     **kwargs: Any) -> dict[str, Any]:
    """The expanded octahedron template (module docstring) with bars of ``bar_length`` (m),
    on a triangle of strings with ``ground``. ``kwargs``: :func:`structure_document_of_layout`'s.
    """
    layout = six_bar_layout(bar_length)
    if ground:
        layout = face_down(layout)
    return structure_document_of_layout(layout, ground=ground, **kwargs)


def config_structure_document(document: Any) -> dict[str, Any]:
    """The structure of a joint or a spine config document (module docstring): a spine when
    the document has a ``chain`` section, a joint otherwise, with the config's dynamics (the
    links' inertias, the strings' damping:
    :meth:`~tensegrity_stiffness.mechanics.joint_dynamics.JointDynamics.from_config`,
    :meth:`~tensegrity_stiffness.mechanics.chain_dynamics.ChainDynamics.from_config`) so that the
    modes have masses."""
    from tensegrity_stiffness import config
    from tensegrity_stiffness.mechanics.chain_dynamics import ChainDynamics
    from tensegrity_stiffness.mechanics.joint_dynamics import JointDynamics
    from tensegrity_stiffness.structures.structure import Structure

    if isinstance(config.parameters(document).get('chain'), dict):
        dynamics = ChainDynamics.from_config(document)
        damping = dynamics.string_damping
        if any(not np.array_equal(c, damping[0]) for c in damping):
            raise ValueError('dynamics.string_damping: a structure of a spine takes one damping '
                             'for every joint')
        structure = Structure.from_chain(dynamics.chain, inertias=dynamics.inertias,
                                         string_damping=damping[0])
    else:
        joint = JointDynamics.from_config(document)
        structure = Structure.from_joint(joint.model, inertia=joint.inertia,
                                         string_damping=joint.string_damping)
    return structure.to_dict()


def layout_of(structure: Any, positions: ArrayLike | None = None) -> Layout:
    """The layout of a free structure of bars (its node names ``bar.a``/``bar.b``, its strings
    and bars) at ``positions`` (n, 3) (None: its start); ValueError for fixed bodies, world
    nodes or general bodies (a layout has bars and strings only)."""
    for body in structure.bodies:
        if body.fixed or body.kind != 'bar':
            raise ValueError(f"bodies: '{body.name}' is {'fixed' if body.fixed else 'not a bar'}"
                             '; form-finding writes free structures of bars')
    if structure.world_nodes:
        raise ValueError('world_nodes: form-finding writes free structures of bars (no '
                         'anchors)')
    X = (structure.node_positions(structure.transforms()) if positions is None
         else np.asarray(positions, dtype=np.float64))
    bars = {name: (structure.node_index(f'{name}.a'), structure.node_index(f'{name}.b'))
            for name in structure.bar_names}
    strings = {name: (int(i), int(j))
               for name, (i, j) in zip(structure.string_names, structure.string_nodes,
                                       strict=True)}
    return Layout(tuple(structure.node_names), X, bars, strings)
