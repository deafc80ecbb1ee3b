"""A structure of rigid bodies and strings: its wrenches and exact stiffness in body twists.

Conventions (docs/structures.md)
--------------------------------
* Body ``i`` (config order) has the pose ``P_i = (R_i, t_i)`` in the world; a node ``r`` of
  body ``i`` (in its frame) is at ``x = R_i r + t_i``; a world node is fixed at its point.
* String ``j`` runs from node ``A`` (on body ``a``) to node ``B`` (on body ``b``):
  ``s_j = x_B - x_A``, ``l_j = |s_j|``, tension ``phi_j`` by the joint's force law
  (:func:`~tensegrity_stiffness.mechanics.joint.string_forces`, eq. 8 of Monke & Vikas with
  docs/errata.md), ``f_j = phi_j s_j / l_j`` the force on body ``a`` (``-f_j`` on body ``b``).
* ``wrenches`` (N, 6): the strings' wrench on each body, ``[f; m]`` in the world frame about the
  world origin, ``W_a = sum [f_j; x_A x f_j]`` (eq. 9 of the joint, summed over the strings at
  each body).
* ``stiffness`` (6N, 6N) ``K = -dW/d(delta)``, ``delta`` the stacked spatial twists
  ``[dv; dw]`` of the bodies in the world frame, applied as ``P_i -> exp(hat(delta_i)) P_i``
  (so that a node moves by ``dx = dv + dw x x = Z(x)^T delta``, ``Z(x) = [I; hat(x)]``): the
  joint's ``K_c`` convention with {1} the world. With ``A_j = df/ds = gamma s s^T + beta I``
  (``beta = phi / l``, ``gamma = (phi' - beta) / l^2``, the joint's eq. 10 factor) each string
  adds the blocks ::

      K_aa += Z_A A Z_A^T + E(f, x_A),    K_ab -= Z_A A Z_B^T,
      K_bb += Z_B A Z_B^T + E(-f, x_B),   K_ba -= Z_B A Z_A^T,
      E(f, x) = [[0, 0], [hat(f), -hat(f) hat(x)]]   (the moment arm that moves),

  the rows and columns of every body (fixed ones too). For a joint (body 1 fixed at the
  world origin) the block of body 2 is the joint's ``K_c = [H_D, -H_G]`` exactly:
  ``Z_B A Z_B^T + E(-f, x_B) = Z_A A Z_B^T`` because ``hat(s) A = hat(f)``.
* ``bar_forces``: per bar (config order of :attr:`Structure.bar_names`), the compression
  ``((F_b - F_a) . e) / 2`` of the strings' forces ``F_a``, ``F_b`` at its nodes, ``e`` the unit
  vector from ``b`` to ``a`` (strings that pull the ends towards each other compress the bar:
  compression positive; for a bar in equilibrium ``F_a = -F_b`` along the axis).

Two implementations of exactly this computation: the compiled kernel
(``src/structure_kernel.cpp``, :mod:`~tensegrity_stiffness.structures.kernel`) and
:meth:`Structure.evaluate_numpy`, its reference (the tests hold them together to 1e-12).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.screw import exp_se3, hat3
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.joint import FORCE_LAWS, MIN_STRING_LENGTH, string_forces
from tensegrity_stiffness.structures import schema
from tensegrity_stiffness.structures.elements import (
    BAR,
    WORLD,
    Body,
    Ground,
    StringSpec,
)
from tensegrity_stiffness.structures.joint_parts import (
    chain_structure_arguments,
    joint_structure_arguments,
)

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]

#: Default central-difference step of :meth:`Structure.numerical_stiffness` (m and rad).
NUMERICAL_STEP = 1e-6
_EYE3 = np.eye(3)


@dataclass(slots=True)
class StructureState:
    """Everything :meth:`Structure.evaluate` computes at one set of poses (module docstring).

    ``poses`` (N, 4, 4); ``wrenches`` (N, 6) [f; m] in the world about its origin;
    ``stiffness`` (6N, 6N) ``-dW/d(delta)`` (NaN when only the wrenches were asked for);
    ``string_vectors`` (n, 3) ``s = x_to - x_from``; ``lengths``, ``tensions`` (n,);
    ``slack``, ``saturated`` (n,) bool; ``node_positions`` {``body.node``: (3,)} (world nodes
    too); ``bar_forces`` (n_bars,) compression positive; ``node_forces`` (n_nodes, 3) the
    strings' force on each node (order of :attr:`Structure.node_names`)."""

    poses: FloatArray
    wrenches: FloatArray
    stiffness: FloatArray
    string_vectors: FloatArray
    lengths: FloatArray
    tensions: FloatArray
    slack: BoolArray
    saturated: BoolArray
    node_positions: dict[str, FloatArray]
    bar_forces: FloatArray
    node_forces: FloatArray


def cross3(a: FloatArray, b: FloatArray) -> FloatArray:
    """``a x b`` of (..., 3) arrays (as ``np.cross``, a fraction of its overhead on the solvers'
    few vectors)."""
    a0, a1, a2 = a[..., 0], a[..., 1], a[..., 2]
    b0, b1, b2 = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0], axis=-1)


def _z_blocks(x: FloatArray, M: FloatArray) -> FloatArray:
    """``[M; hat(x) M]`` (..., 6, 3) for points (..., 3) and matrices (..., 3, 3)."""
    return np.concatenate([M, hat3(x) @ M], axis=-2)


def _with_transpose_z(ZM: FloatArray, x: FloatArray) -> FloatArray:
    """``ZM Z(x)^T = [ZM, -ZM hat(x)]`` (..., 6, 6)."""
    return np.concatenate([ZM, -(ZM @ hat3(x))], axis=-1)


def geometric_block(f: FloatArray, x: FloatArray) -> FloatArray:
    """``E(f, x) = [[0, 0], [hat(f), -hat(f) hat(x)]]`` (..., 6, 6): minus the derivative of
    the wrench ``[f; x x f]`` of a constant force ``f`` at a point ``x`` that moves with the
    body's twist (module docstring)."""
    hf = hat3(f)
    out = np.zeros(np.broadcast_shapes(f.shape, x.shape)[:-1] + (6, 6))
    out[..., 3:, :3] = hf
    out[..., 3:, 3:] = -(hf @ hat3(x))
    return out


def twist_exp(delta: FloatArray) -> FloatArray:
    """``exp(hat(delta))`` (..., 4, 4) of spatial twists ``[dv; dw]`` (..., 6)."""
    d = np.asarray(delta, dtype=np.float64)
    return exp_se3(np.concatenate([d[..., 3:], d[..., :3]], axis=-1))


class Structure:
    """Rigid bodies joined by strings, with optional world nodes, gravity and ground.

    Parameters
    ----------
    bodies : :class:`~tensegrity_stiffness.structures.elements.Body` (bars and bodies).
    strings : :class:`~tensegrity_stiffness.structures.elements.StringSpec` joining
        ``body.node`` / ``world.node`` references.
    world_nodes : {name: (3,)} anchors on the world.
    gravity : (3,) m/s^2 in the world (None: none).
    ground : :class:`~tensegrity_stiffness.structures.elements.Ground` or None.
    force_law : ``'hooke'`` or ``'paper'`` (the joint's).
    use_kernel : evaluate in the compiled kernel when it is built (default).

    Attributes (arrays in the orders of the config)
    ----------
    body_names, node_names (``body.node``, the world's last), string_names, bar_names;
    node_bodies (n_nodes,) the body of each node (-1: the world), node_points (n_nodes, 3) in
    its body's frame (in the world for world nodes); string_nodes (n, 2) and string_bodies
    (n, 2) the ``from`` / ``to`` node and body of each string, string_points (n, 2, 3) their
    points in their bodies' frames; k, rest_lengths, max_lengths, max_stretch, damping (n,);
    fixed (N,) bool; bar_indices (n_bars,) the bars' body indices and bar_nodes (n_bars, 2) the
    node indices of their ends ``a``, ``b``.
    """

    def __init__(self, bodies: Sequence[Body], strings: Sequence[StringSpec],
                 world_nodes: Mapping[str, ArrayLike] | None = None,
                 gravity: ArrayLike | None = None, ground: Ground | None = None,
                 force_law: str = 'hooke', use_kernel: bool = True) -> None:
        self.bodies = list(bodies)
        if not self.bodies or not all(isinstance(b, Body) for b in self.bodies):
            raise ValueError('bodies must be a non-empty sequence of Body')
        self.body_names = [b.name for b in self.bodies]
        if len(set(self.body_names)) != len(self.body_names) or WORLD in self.body_names:
            raise ValueError(f'body names must be unique and not "{WORLD}"')
        self._index = {name: i for i, name in enumerate(self.body_names)}
        self.world_nodes = {str(k): finite_array(f'world_nodes.{k}', v).reshape(3)
                            for k, v in (world_nodes or {}).items()}
        self.strings = list(strings)
        if not self.strings:
            raise ValueError('a structure needs at least one string')
        if force_law not in FORCE_LAWS:
            raise ValueError(f'force_law must be one of {FORCE_LAWS}, got {force_law!r}')
        self.force_law = force_law
        self.gravity = None if gravity is None else finite_array('gravity', gravity).reshape(3)
        if ground is not None and not isinstance(ground, Ground):
            raise ValueError('ground must be a Ground or None')
        self.ground = ground
        # Nodes: every body's, then the world's, as 'body.node'.
        self.node_names = [f'{b.name}.{k}' for b in self.bodies for k in b.node_names] + [
            f'{WORLD}.{k}' for k in self.world_nodes]
        self._node_index = {name: i for i, name in enumerate(self.node_names)}
        self.node_bodies = np.array([i for i, b in enumerate(self.bodies) for _ in b.node_names]
                                    + [-1] * len(self.world_nodes), dtype=np.intp)
        self.node_points = np.array([p for b in self.bodies for p in b.node_array]
                                    + list(self.world_nodes.values())).reshape(-1, 3)
        ends, nodes = [], []
        for j, s in enumerate(self.strings):
            pair = []
            for ref in (s.start, s.end):
                if ref not in self._node_index:
                    raise ValueError(f'strings[{j}] ({s.name}): no node {ref!r}')
                pair.append(self._node_index[ref])
            nodes.append(pair)
        self.string_nodes = np.array(nodes, dtype=np.intp)  # (n, 2) node indices
        ends = self.node_bodies[self.string_nodes]
        self.string_bodies = ends  # (n, 2) body indices, -1 for the world
        self.string_points = self.node_points[self.string_nodes]  # (n, 2, 3) local coords
        self.string_names = [s.name for s in self.strings]
        # Node-string incidence (n_nodes, n): +1 at a string's from-node, -1 at its to-node.
        self._incidence = np.zeros((len(self.node_names), len(self.strings)))
        rows = np.arange(len(self.strings))
        self._incidence[self.string_nodes[:, 0], rows] += 1.0
        self._incidence[self.string_nodes[:, 1], rows] -= 1.0
        self.k = np.array([s.stiffness for s in self.strings])
        self.rest_lengths = np.array([s.rest_length for s in self.strings])
        self.max_lengths = np.array([s.max_length for s in self.strings])
        self.max_stretch = self.max_lengths - self.rest_lengths
        self.damping = np.array([s.damping for s in self.strings])
        self.fixed = np.array([b.fixed for b in self.bodies], dtype=bool)
        self.bar_indices = np.array([i for i, b in enumerate(self.bodies) if b.kind == BAR],
                                    dtype=np.intp)
        self.bar_names = [self.body_names[i] for i in self.bar_indices]
        self.bar_nodes = np.array([[self._node_index[f'{self.body_names[i]}.{k}']
                                     for k in ('a', 'b')] for i in self.bar_indices],
                                   dtype=np.intp).reshape(-1, 2)
        # The world as body N (identity pose) in the numpy path.
        n_b = len(self.bodies)
        self._ends_world = np.where(ends < 0, n_b, ends)
        self._kernel = None
        if use_kernel:
            from tensegrity_stiffness.structures.kernel import structure_kernel

            self._kernel = structure_kernel(self)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_dict(cls, document: Any, use_kernel: bool = True, strict: bool = True
                  ) -> Structure:
        """From a config document (plain, or a ROS parameter file) with a ``structure``
        section, or that section itself: the schema of
        :mod:`~tensegrity_stiffness.structures.schema` (errors name the entry; unknown keys are
        refused with the nearest name, ``strict=False`` warns)."""
        return cls(**schema.parse_structure(document, strict), use_kernel=use_kernel)

    @classmethod
    def from_yaml(cls, path: str | Path, use_kernel: bool = True, strict: bool = True
                  ) -> Structure:
        """From a YAML file (see :meth:`from_dict`)."""
        return cls.from_dict(config.load_yaml(path), use_kernel=use_kernel, strict=strict)

    def to_dict(self) -> dict[str, Any]:
        """The config document ``{'structure': ...}`` that :meth:`from_dict` reads back to
        this structure (plain floats and lists: YAML- and JSON-ready)."""
        return schema.structure_document(self.bodies, self.strings, self.world_nodes,
                                         self.gravity, self.ground, self.force_law)

    @classmethod
    def from_joint(cls, model: Any, pose: ArrayLike | None = None, inertia: Any = None,
                   string_damping: ArrayLike = 0.0, use_kernel: bool = True) -> Structure:
        """A joint (:class:`~tensegrity_stiffness.mechanics.joint.JointModel`) as a structure
        (:mod:`~tensegrity_stiffness.structures.joints`): ``link1`` fixed at the world origin,
        ``link2`` at ``pose`` (default ``exp(hat(xi0))`` of the model's ``initial_screw``);
        ``inertia``: link 2's :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia`
        (default massless); ``string_damping`` (N s/m, one for all or one per string)."""
        return cls(**joint_structure_arguments(model, pose, inertia, string_damping),
                   use_kernel=use_kernel)

    @classmethod
    def from_chain(cls, chain: Any, screws: ArrayLike | None = None, inertias: Any = None,
                   string_damping: ArrayLike = 0.0, use_kernel: bool = True) -> Structure:
        """A spine (:class:`~tensegrity_stiffness.mechanics.chain.JointChain`) as a structure
        (:mod:`~tensegrity_stiffness.structures.joints`): ``link0`` (the base) fixed at the
        world origin, the links at the frames of ``screws`` (default the unloaded screws);
        ``inertias``, ``string_damping``: :func:`~.joint_parts.chain_structure_arguments`."""
        return cls(**chain_structure_arguments(chain, screws, inertias, string_damping),
                   use_kernel=use_kernel)

    def __getstate__(self) -> dict[str, Any]:
        """Pickled without the compiled kernel's handle (a structure sent to another process
        binds that process's library again, or takes the numpy path without one)."""
        state = self.__dict__.copy()
        state['_kernel'] = self._kernel is not None
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        wanted = state.pop('_kernel')
        self.__dict__.update(state)
        self._kernel = None
        if wanted:
            from tensegrity_stiffness.structures.kernel import structure_kernel

            self._kernel = structure_kernel(self)

    def with_rest_lengths(self, rest_lengths: ArrayLike) -> Structure:
        """A copy with new rest lengths (n,) (each string keeps its maximum stretch)."""
        rest = self.validate_rest_lengths(rest_lengths)
        strings = [replace(s, rest_length=float(r), max_length=float(r + stretch))
                   for s, r, stretch in zip(self.strings, rest, self.max_stretch, strict=True)]
        return self._copy(self.bodies, strings)

    def with_poses(self, poses: ArrayLike) -> Structure:
        """A copy whose bodies start at ``poses`` ((N, 4, 4) or (N, 7)): e.g. an equilibrium,
        to write as a config with :meth:`to_dict`."""
        T = self.transforms(poses)
        return self._copy([replace(b, pose=P) for b, P in zip(self.bodies, T, strict=True)],
                          self.strings)

    def _copy(self, bodies: list[Body], strings: list[StringSpec]) -> Structure:
        return Structure(bodies, strings, self.world_nodes, self.gravity, self.ground,
                         self.force_law, use_kernel=self.uses_kernel)

    # ------------------------------------------------------------------ accessors
    @property
    def n_bodies(self) -> int:
        """Number of bodies N."""
        return len(self.bodies)

    @property
    def n_strings(self) -> int:
        """Number of strings n."""
        return len(self.strings)

    @property
    def compiled_kernel(self) -> Any:
        """The compiled kernel's handle of this structure
        (:class:`~tensegrity_stiffness.structures.kernel.StructureKernel`), None on the numpy
        path."""
        return self._kernel

    @property
    def uses_kernel(self) -> bool:
        """True when evaluations run in the compiled kernel."""
        return self._kernel is not None

    def body(self, name: str) -> Body:
        """The body named ``name`` (ValueError naming it otherwise)."""
        return self.bodies[self.body_index(name)]

    def body_index(self, name: str) -> int:
        """The index of the body named ``name``."""
        if name not in self._index:
            near = schema.nearest_name(name, self.body_names)
            raise ValueError(f'no body {name!r}' + (f' (did you mean {near!r}?)' if near else ''))
        return self._index[name]

    def node_index(self, name: str) -> int:
        """The index of node ``body.node`` in :attr:`node_names`."""
        if name not in self._node_index:
            raise ValueError(f'no node {name!r}')
        return self._node_index[name]

    def start_poses(self) -> FloatArray:
        """(N, 4, 4) the bodies' poses of the config (the solvers' start)."""
        return np.array([b.pose for b in self.bodies])

    def transforms(self, poses: ArrayLike | None = None) -> FloatArray:
        """``poses`` as checked (N, 4, 4) transforms ((N, 4, 4) or (N, 7)
        ``[x y z qx qy qz qw]``, each through
        :func:`~tensegrity_stiffness.geometry.transforms.rigid_transform`); None: the start."""
        if poses is None:
            return self.start_poses()
        arr = np.asarray(poses, dtype=np.float64)
        n = self.n_bodies
        if arr.shape not in ((n, 4, 4), (n, 7)):
            raise ValueError(f'poses must have shape ({n}, 4, 4) or ({n}, 7), got {arr.shape}')
        return np.array([rigid_transform(p, f'poses[{i}] ({self.body_names[i]})')
                         for i, p in enumerate(arr)])

    def node_positions(self, transforms: FloatArray) -> FloatArray:
        """(n_nodes, 3) every node in the world at the (N, 4, 4) ``transforms``."""
        T = np.concatenate([transforms, np.eye(4)[None]], axis=0)
        idx = np.where(self.node_bodies < 0, self.n_bodies, self.node_bodies)
        return np.einsum('nij,nj->ni', T[idx, :3, :3], self.node_points) + T[idx, :3, 3]

    def validate_rest_lengths(self, rest_lengths: ArrayLike | None) -> FloatArray:
        """Rest lengths (n,) finite and > 0 (None: the configured ones)."""
        if rest_lengths is None:
            return self.rest_lengths
        arr = finite_array('rest_lengths', rest_lengths)
        if arr.shape != (self.n_strings,) or np.any(arr <= 0.0):
            raise ValueError(f'rest_lengths must be {self.n_strings} values > 0, got shape '
                             f'{arr.shape}')
        return arr

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, poses: ArrayLike | None = None, rest_lengths: ArrayLike | None = None
                 ) -> StructureState:
        """Wrenches, stiffness, tensions, ... at ``poses`` ((N, 4, 4) or (N, 7); None: the
        start) with ``rest_lengths`` (n,) (None: the configured ones)."""
        return self.evaluate_transforms(self.transforms(poses),
                                        self.validate_rest_lengths(rest_lengths))

    def evaluate_transforms(self, T: FloatArray, rest: FloatArray | None = None,
                            wrench_only: bool = False) -> StructureState:
        """:meth:`evaluate` of checked (N, 4, 4) transforms (the solvers' path): in the
        compiled kernel when it is loaded, else :meth:`evaluate_numpy`."""
        rest = self.rest_lengths if rest is None else rest
        if self._kernel is not None:
            state = self._kernel.evaluate(T, rest, wrench_only)
            if state is not None:
                return state
        return self.evaluate_numpy(T, rest, wrench_only)

    def string_geometry(self, T: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """String ends ``x_A``, ``x_B`` (n, 3) in the world and the lengths (n,) at the
        transforms ``T`` (N, 4, 4); ValueError naming a string of zero length."""
        Tw = np.concatenate([T, np.eye(4)[None]], axis=0)
        ia, ib = self._ends_world[:, 0], self._ends_world[:, 1]
        pa, pb = self.string_points[:, 0], self.string_points[:, 1]
        xa = np.einsum('nij,nj->ni', Tw[ia, :3, :3], pa) + Tw[ia, :3, 3]
        xb = np.einsum('nij,nj->ni', Tw[ib, :3, :3], pb) + Tw[ib, :3, 3]
        lengths = np.sqrt(np.sum((xb - xa) ** 2, axis=1))
        if lengths.min() < MIN_STRING_LENGTH:
            bad = [self.string_names[j] for j in np.flatnonzero(lengths < MIN_STRING_LENGTH)]
            raise ValueError(f'strings {bad} have zero length at these poses')
        return xa, xb, lengths

    def evaluate_numpy(self, T: FloatArray, rest: FloatArray | None = None,
                       wrench_only: bool = False) -> StructureState:
        """The module docstring's equations in numpy (the kernel's reference)."""
        rest = self.rest_lengths if rest is None else rest
        n_b = self.n_bodies
        xa, xb, lengths = self.string_geometry(T)
        s = xb - xa
        phi, dphi, slack, saturated = string_forces(lengths, rest, self.k, self.max_stretch,
                                                    self.force_law)
        beta = phi / lengths
        f = beta[:, None] * s  # on body a; -f on body b
        ia, ib = self._ends_world[:, 0], self._ends_world[:, 1]
        W = np.zeros((n_b + 1, 6))
        np.add.at(W, ia, np.concatenate([f, np.cross(xa, f)], axis=1))
        np.add.at(W, ib, np.concatenate([-f, -np.cross(xb, f)], axis=1))
        if wrench_only:
            K = np.full((6 * n_b, 6 * n_b), np.nan)
        else:
            gamma = (dphi - beta) / (lengths * lengths)
            A = gamma[:, None, None] * s[:, :, None] * s[:, None, :] + beta[:, None, None] * _EYE3
            ZaA, ZbA = _z_blocks(xa, A), _z_blocks(xb, A)
            blocks = np.zeros((n_b + 1, n_b + 1, 6, 6))
            np.add.at(blocks, (ia, ia), _with_transpose_z(ZaA, xa) + geometric_block(f, xa))
            np.add.at(blocks, (ib, ib), _with_transpose_z(ZbA, xb) + geometric_block(-f, xb))
            np.add.at(blocks, (ia, ib), -_with_transpose_z(ZaA, xb))
            np.add.at(blocks, (ib, ia), -_with_transpose_z(ZbA, xa))
            K = blocks[:n_b, :n_b].transpose(0, 2, 1, 3).reshape(6 * n_b, 6 * n_b)
        return self.state(T, W[:n_b], K, s, lengths, phi, slack, saturated, f)

    def state(self, T: FloatArray, W: FloatArray, K: FloatArray, s: FloatArray,
              lengths: FloatArray, phi: FloatArray, slack: BoolArray, saturated: BoolArray,
              f: FloatArray | None = None) -> StructureState:
        """The :class:`StructureState` of evaluated quantities (node positions, node forces
        and bar forces added)."""
        if f is None:
            f = (phi / lengths)[:, None] * s
        x = self.node_positions(T)
        F = self._incidence @ f
        if self.bar_indices.size:
            a, b = self.bar_nodes[:, 0], self.bar_nodes[:, 1]
            e = x[a] - x[b]
            e /= np.linalg.norm(e, axis=1, keepdims=True)
            bars = 0.5 * np.sum((F[b] - F[a]) * e, axis=1)
        else:
            bars = np.zeros(0)
        return StructureState(T, W, K, s, lengths, phi, slack, saturated,
                              dict(zip(self.node_names, x, strict=True)), bars, F)

    # ------------------------------------------------------------------ loads
    def gravity_wrenches(self, T: FloatArray, gravity: FloatArray | None = None
                         ) -> tuple[FloatArray, FloatArray]:
        """The bodies' weights (N, 6) ``[m g; c x m g]`` (world, about its origin; ``c`` the
        centre of mass in the world) and their stiffness ``-dW/d(delta)`` (6N, 6N), block
        diagonal with ``E(m g, c)`` (module docstring)."""
        g = self.gravity if gravity is None else gravity
        n_b = self.n_bodies
        if g is None:
            return np.zeros((n_b, 6)), np.zeros((6 * n_b, 6 * n_b))
        masses = np.array([b.mass for b in self.bodies])
        coms = np.array([b.com for b in self.bodies])
        c = np.einsum('nij,nj->ni', T[:, :3, :3], coms) + T[:, :3, 3]
        G = masses[:, None] * g
        W = np.concatenate([G, cross3(c, G)], axis=1)
        K = np.zeros((6 * n_b, 6 * n_b))
        E = geometric_block(G, c)
        for i in range(n_b):
            K[6 * i:6 * i + 6, 6 * i:6 * i + 6] = E[i]
        return W, K

    def numerical_stiffness(self, poses: ArrayLike | None = None,
                            rest_lengths: ArrayLike | None = None,
                            step: float = NUMERICAL_STEP) -> FloatArray:
        """Central differences ``-dW/d(delta)`` (6N, 6N) of the strings' wrenches, each body
        moved by ``exp(hat(+-step e_k)) P_i`` (the check of the closed form)."""
        if not (math.isfinite(step) and step > 0.0):
            raise ValueError(f'step must be finite and > 0, got {step}')
        T = self.transforms(poses)
        rest = self.validate_rest_lengths(rest_lengths)
        n_b = self.n_bodies
        K = np.empty((6 * n_b, 6 * n_b))
        for i in range(n_b):
            for k in range(6):
                delta = np.zeros(6)
                delta[k] = step
                plus, minus = T.copy(), T.copy()
                plus[i] = twist_exp(delta) @ T[i]
                minus[i] = twist_exp(-delta) @ T[i]
                Wp = self.evaluate_numpy(plus, rest, True).wrenches.ravel()
                Wm = self.evaluate_numpy(minus, rest, True).wrenches.ravel()
                K[:, 6 * i + k] = -(Wp - Wm) / (2.0 * step)
        return K
