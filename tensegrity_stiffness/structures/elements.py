"""The elements of a structure: rigid bodies (bars and general bodies), strings and the ground.

* A **body** has a frame (its ``pose`` in the world: the start of the solvers), named nodes in
  that frame, a mass, a centre of mass and an inertia about it (in the body's axes), and may be
  ``fixed``. A **bar** is a body with the two nodes ``a`` at ``(0, 0, -length/2)`` and ``b`` at
  ``(0, 0, +length/2)`` on its own z axis, its centre of mass at the middle and by default the
  inertia of a solid cylinder of radius ``length * BAR_RADIUS_RATIO`` (nearly the thin rod's
  ``m L^2 / 12``; a small positive moment about the axis, so that the mass matrix is regular).
* A **string** joins a node ``from`` to a node ``to`` (``body.node`` or ``world.node``) with the
  joint's force law (:func:`~tensegrity_stiffness.mechanics.joint.string_forces`): stiffness
  ``k`` (N/m), ``rest_length`` (m), optional ``max_length`` (m) and a viscous ``damping``
  (N s/m, for the modes and the MuJoCo export).
* The **ground** is the half-space ``normal . x >= height`` with Coulomb friction ``friction``;
  every node may touch it.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.inertia import (
    DEFAULT_LINK_MASS,
    LinkInertia,
    default_inertia_moments,
)

FloatArray = NDArray[np.float64]

BAR = 'bar'
BODY = 'body'
BODY_KINDS = (BAR, BODY)
#: The node names of a bar: ``a`` at -length/2, ``b`` at +length/2 on its z axis.
BAR_NODES = ('a', 'b')
#: Default radius of a bar (its inertia about the axis, its capsule in MuJoCo) per unit length.
BAR_RADIUS_RATIO = 0.01
#: The name of the world in a node reference ``world.<node>``: no body may take it.
WORLD = 'world'
#: The identity pose [x y z qx qy qz qw].
IDENTITY_POSE = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)


def _number(name: str, value: Any, minimum: float | None = None, strict: bool = False
            ) -> float:
    """A finite float (``>= minimum``, or ``> minimum`` when ``strict``); ValueError naming
    ``name``."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f'{name} must be a number, got {value!r}')
    x = float(value)
    if not math.isfinite(x):
        raise ValueError(f'{name} must be finite, got {x}')
    if minimum is not None and (x <= minimum if strict else x < minimum):
        raise ValueError(f'{name} must be {">" if strict else ">="} {minimum:g}, got {x:g}')
    return x


@dataclass(frozen=True, eq=False)
class Body:
    """A rigid body of a structure (module docstring); build bars with :meth:`bar` and other
    bodies with :meth:`rigid`. ``nodes`` maps node names to (3,) points in the body frame;
    ``pose`` (4, 4) in the world; ``inertia`` (3, 3) about ``com`` in the body's axes."""

    name: str
    kind: str
    nodes: Mapping[str, FloatArray]
    pose: FloatArray
    mass: float
    com: FloatArray
    inertia: FloatArray
    fixed: bool = False
    length: float | None = None
    radius: float | None = None
    node_names: tuple[str, ...] = field(init=False)
    node_array: FloatArray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, 'node_names', tuple(self.nodes))
        object.__setattr__(self, 'node_array',
                           np.array([self.nodes[k] for k in self.node_names]).reshape(-1, 3))

    @classmethod
    def bar(cls, name: str, length: float, pose: ArrayLike = IDENTITY_POSE,
            mass: float = DEFAULT_LINK_MASS, inertia: ArrayLike | None = None,
            fixed: bool = False, radius: float | None = None) -> Body:
        """A bar of ``length`` (m) with nodes ``a``, ``b`` at ``-+length/2`` on its z axis."""
        length = _number('length', length, 0.0, strict=True)
        r = length * BAR_RADIUS_RATIO if radius is None else _number('radius', radius, 0.0,
                                                                      strict=True)
        m = _number('mass', mass, 0.0)
        if inertia is None:
            transverse = m * (3.0 * r * r + length * length) / 12.0
            inertia = (transverse, transverse, 0.5 * m * r * r)
        nodes = {'a': np.array([0.0, 0.0, -0.5 * length]), 'b': np.array([0.0, 0.0, 0.5 * length])}
        return cls(str(name), BAR, nodes, rigid_transform(pose, 'pose'), m, np.zeros(3),
                   _inertia(m, np.zeros(3), inertia), bool(fixed), length, r)

    @classmethod
    def rigid(cls, name: str, nodes: Mapping[str, ArrayLike], pose: ArrayLike = IDENTITY_POSE,
              mass: float = DEFAULT_LINK_MASS, com: ArrayLike = (0.0, 0.0, 0.0),
              inertia: ArrayLike | None = None, fixed: bool = False) -> Body:
        """A general body with named ``nodes`` in its frame (default inertia: the twin's,
        :func:`~tensegrity_stiffness.mechanics.inertia.default_inertia_moments`)."""
        if not isinstance(nodes, Mapping) or not nodes:
            raise ValueError('nodes must be a non-empty mapping {name: [x, y, z]}')
        points = {}
        for key, value in nodes.items():
            if not str(key) or '.' in str(key):
                raise ValueError(f'nodes: a node name must be non-empty and without ".", got '
                                 f'{key!r}')
            p = finite_array(f'nodes.{key}', value).ravel()
            if p.shape != (3,):
                raise ValueError(f'nodes.{key} must be 3 values [x, y, z], got {p.size}')
            points[str(key)] = p
        m = _number('mass', mass, 0.0)
        c = finite_array('com', com).ravel()
        if c.shape != (3,):
            raise ValueError(f'com must be 3 values [x, y, z], got {c.size}')
        if inertia is None:
            inertia = default_inertia_moments(np.array(list(points.values())), max(m, 0.0), c)
        return cls(str(name), BODY, points, rigid_transform(pose, 'pose'), m, c,
                   _inertia(m, c, inertia), bool(fixed))

    @property
    def link_inertia(self) -> LinkInertia:
        """The body's mass properties as the dynamics'
        :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia` (mass > 0 needed)."""
        return LinkInertia(self.mass, self.com, self.inertia)


def _inertia(mass: float, com: FloatArray, inertia: ArrayLike) -> FloatArray:
    """The (3, 3) inertia of 3 principal moments or 9 values, checked by
    :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia` (symmetric positive definite)
    for a body with mass; zero for a massless body."""
    if mass == 0.0:
        arr = finite_array('inertia', inertia).ravel()
        if arr.size not in (3, 9) or np.any(arr != 0.0):
            raise ValueError('inertia of a massless body must be zero')
        return np.zeros((3, 3))
    return LinkInertia(mass, com, inertia).inertia


@dataclass(frozen=True)
class StringSpec:
    """A string from node ``start`` to node ``end`` (``body.node`` or ``world.node``):
    ``stiffness`` N/m, ``rest_length`` m, ``max_length`` m (inf: no limit), ``damping``
    N s/m."""

    name: str
    start: str
    end: str
    stiffness: float
    rest_length: float
    max_length: float = math.inf
    damping: float = 0.0

    def __post_init__(self) -> None:
        _number('stiffness', self.stiffness, 0.0, strict=True)
        _number('rest_length', self.rest_length, 0.0, strict=True)
        if not (self.max_length > self.rest_length):  # also NaN
            raise ValueError(f'max_length must exceed rest_length ({self.rest_length:g}), got '
                             f'{self.max_length}')
        _number('damping', self.damping, 0.0)


@dataclass(frozen=True)
class Ground:
    """The ground: the half-space ``normal . x >= height`` (``normal`` a unit (3,) vector in
    the world) with Coulomb friction coefficient ``friction`` (>= 0)."""

    normal: FloatArray = field(default_factory=lambda: np.array([0.0, 0.0, 1.0]))
    height: float = 0.0
    friction: float = 0.8

    def __post_init__(self) -> None:
        n = finite_array('normal', self.normal).ravel()
        norm = float(np.linalg.norm(n)) if n.shape == (3,) else 0.0
        if norm == 0.0:
            raise ValueError(f'normal must be a non-zero 3-vector, got {self.normal!r}')
        object.__setattr__(self, 'normal', n / norm)
        object.__setattr__(self, 'height', _number('height', self.height))
        object.__setattr__(self, 'friction', _number('friction', self.friction, 0.0))

    def tangents(self) -> FloatArray:
        """(2, 3) an orthonormal basis of the ground plane (with ``normal`` right-handed)."""
        n = self.normal
        helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        t1 = np.cross(helper, n)
        t1 /= np.linalg.norm(t1)
        return np.array([t1, np.cross(n, t1)])
