"""Equilibria of a structure under loads, gravity and the ground, with unilateral contact and
Coulomb friction; their stability on the tangent space without the gauge (docs/structures.md).

Unknowns and residuals
----------------------
Each free body's pose is an increment from its start, ``T_i = exp(hat(xi_i)) P_i`` (screw
coordinates as the joint's, re-charted as the spine's when ``|omega|`` nears 2 pi; a rigid
motion of the start moves the increments linearly); the residual of body ``i`` is the sum of the
wrenches on it: strings, its weight ``[m g; c x m g]``, the external load (constant, world frame
about its origin) and its contact forces ``[lambda; x_c x lambda]``, its moment taken about the
body's start position so that the norm Newton minimises does not depend on the world frame.
Fixed bodies stay at their poses (their residual is a reaction). A node on the ground is

* **sticking**: pinned at its anchor ``a_c`` (where it touched), ``x_c = a_c`` (3 equations,
  the force ``lambda_c`` (3) unknown): the tangential forces of a statically indeterminate
  contact set follow from the structure's elasticity, from the start;
* **sliding** (its force left the friction cone): ``normal . x_c = height`` and the tangential
  force ``-mu lambda_n d / |d|`` against its slip ``d`` (the tangential part of ``x_c - a_c``):
  Coulomb's law on the straight path from the anchor (3 equations, ``lambda_c`` (3) unknown);
  at ``mu = 0`` every contact slides with no tangential force.

Newton (:func:`~tensegrity_stiffness.mechanics.newton.damped_newton`) solves the square system
with its exact Jacobian (:meth:`_Problem.residual_jacobian`): ``-K_total`` (the strings'
:attr:`~.structure.StructureState.stiffness`, the weights' and the contact forces' ``E(f, x)``
blocks) times ``Pi J(xi_i)`` per body, the contact columns ``Z(x_c)``, the constraint rows
``Z(x_c)^T`` and the sliding law's derivatives. Around it, an active set on the contacts: a free
structure under gravity is first translated along the normal so that its lowest node is on the
ground, then tipped over by its weight as a rigid body about one or two contacts until it stands
on three (:func:`tipped_onto_the_ground`); nodes on the ground stick; then, one change at a time
until none is due, a contact with a pulling normal force is released, the deepest node below the
ground becomes a sticking contact at its projection, and a sticking contact whose force left the
cone slides (its anchor moved by :data:`SLIP_START` mean rest lengths along its tangential
force, so that it starts slipping against it; once solved, its law is taken again from where it
touched).

The gauge
---------
Motions that change no residual are not determined by the equilibrium: each bar's spin about its
own axis (its nodes lie on the axis, so no string or contact force has a moment about it), the six
rigid motions of a structure with no fixed body, no world node and no contact, and, on a
frictionless ground, the motions in the ground plane (two translations and the turn about the
normal). Newton's matrix is bordered with them, ``A + s N_l M``: ``N_l`` the gauge twists
(:func:`gauge_twists`, which the residual wrenches do no work on) and ``M`` the gauge conditions
(:func:`gauge_conditions`: no spin of a bar about its axis, no mean displacement and no mean turn
of the nodes about their centroid), so every step has no gauge component and the solver returns
the equilibrium nearest the start in that sense. Stability is judged on the tangent space that
removes the gauge and the contact constraints: the symmetric part of ``B^T K_total B`` positive
definite, ``B`` a basis of the free twists with no gauge component that keep the contacts in
place (with friction: a small disturbance meets static friction, also at a contact that slid to
the edge of its cone) or on the ground (frictionless). A structure balanced, not stable, on a
node or an edge of two is rolled over it (:func:`rolled_over`: the way of its unstable mode that
reaches the ground first) until another node touches, and solved again.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import (
    BLOCK_SWAP,
    ScrewKinematics,
    exp_se3,
    exp_so3,
    hat3,
    log_se3,
)
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.equilibrium import (
    MAX_NEWTON_ITERATIONS,
    MAX_ROTATION_STEP,
    MAX_TRANSLATION_STEP,
    RECHART_ANGLE,
    STABILITY_TOLERANCE,
)
from tensegrity_stiffness.mechanics.newton import damped_newton, solve_deadline
from tensegrity_stiffness.structures.structure import (
    Structure,
    StructureState,
    cross3,
    geometric_block,
)

FloatArray = NDArray[np.float64]

#: Converged when the norm of the residuals (N, N m; constraints scaled by the mean string
#: stiffness to N) is at most this.
STRUCTURE_TOLERANCE = 1e-9
#: A node at most this far above the ground (m) touches it; a node deeper than this below it
#: penetrates.
CONTACT_DISTANCE = 1e-9
#: Contact-set changes before the solver gives up.
MAX_CONTACT_UPDATES = 60
#: Newton steps of a solve (over its contact sets) that a time budget does not cut short: the
#: examples' ground equilibria converge in 4 (5-8 ms of CPU), so a node starved of CPU by a
#: busy machine still answers them (a CI run beside three workers ran out of a 5 s budget
#: before the first step).
MIN_NEWTON_ITERATIONS = 4
#: Relative slack of the friction cone and of the sign of a normal force.
CONE_TOLERANCE = 1e-9
#: The first slip of a contact that starts sliding, in mean rest lengths.
SLIP_START = 1e-6
#: Roll-overs of a structure balanced on a node or an edge before the solver returns it.
MAX_ROLLS = 4
#: Steps of the scan for the angle of a roll-over (then bisection).
ROLL_SCAN = 180
STICK, SLIDE = 'stick', 'slide'


@dataclass
class Contact:
    """A node on the ground: its index in ``Structure.node_names``, its body, its ``anchor``
    (3,) and ``mode`` (:data:`STICK` or :data:`SLIDE`); its force (3,) is unknown."""

    node: int
    body: int
    anchor: FloatArray
    mode: str = STICK
    #: Where the node touched the ground (the anchor of a sliding contact's law, once it has
    #: started slipping from a moved anchor).
    touch: FloatArray | None = None


@dataclass(frozen=True)
class StructureEquilibrium:
    """Outcome of :func:`solve_structure_equilibrium`.

    ``poses`` (N, 4, 4) the equilibrium (or the last iterate); ``state`` the strings' state
    there; ``contacts`` {``body.node``: force (3,) of the ground on it}; ``residual`` the norm
    of the residuals; ``stable`` and ``stability_margin`` (smallest eigenvalue of the reduced
    tangent stiffness over its largest); ``tangent_stiffness`` (6N, 6N) ``K_total`` (strings,
    weights, contact forces); ``gauge`` (6N, m) the gauge twists at the solution (module
    docstring); ``sliding``: the names of the sliding contacts; ``constraints`` (c, 6N) the
    contacts' constraints on small motions (3 rows per contact with friction, the normal row on
    a frictionless ground)."""

    success: bool
    message: str
    poses: FloatArray
    state: StructureState | None
    stable: bool
    contacts: dict[str, FloatArray]
    residual: float
    iterations: int
    stability_margin: float = -math.inf
    tangent_stiffness: FloatArray | None = field(default=None, repr=False)
    gauge: FloatArray | None = field(default=None, repr=False)
    sliding: tuple[str, ...] = ()
    constraints: FloatArray | None = field(default=None, repr=False)


def structure_loads(structure: Structure, loads: Any) -> FloatArray:
    """External wrenches (N, 6) ``[f; m]`` (world, about its origin, constant) from None, a
    mapping {body name: (6,)} or an (N, 6) array; ValueError naming the entry. A load on a fixed
    body goes into its reaction (no equation)."""
    n = structure.n_bodies
    out = np.zeros((n, 6))
    if loads is None:
        return out
    if isinstance(loads, Mapping):
        for name, value in loads.items():
            w = finite_array(f'loads[{name!r}]', value).ravel()
            if w.shape != (6,):
                raise ValueError(f'loads[{name!r}] must be 6 values [f; m], got {w.size}')
            out[structure.body_index(str(name))] += w
        return out
    arr = finite_array('loads', loads)
    if arr.shape != (n, 6):
        raise ValueError(f'loads must have shape ({n}, 6) or be a mapping by body name, got '
                         f'{arr.shape}')
    return arr.copy()


def gauge_kind(structure: Structure, has_contacts: bool) -> str | None:
    """Which motions besides the bars' spins are a gauge: ``'rigid'`` (no fixed body, no world
    node, no contact), ``'plane'`` (no fixed body or world node, contacts on a frictionless
    ground) or None."""
    if structure.fixed.any() or structure.world_nodes:
        return None
    if not has_contacts:
        return 'rigid'
    if structure.ground is not None and structure.ground.friction == 0.0:
        return 'plane'
    return None


def _plane_motions(structure: Structure) -> tuple[FloatArray, FloatArray, FloatArray]:
    t1, t2 = structure.ground.tangents()
    return t1, t2, structure.ground.normal


def gauge_twists(structure: Structure, T: FloatArray, contacts: list[Contact]) -> FloatArray:
    """The gauge twists (6N, m) at the poses ``T`` with this contact set (module docstring),
    orthonormal, rows of fixed bodies zero: the free bars' spins, then the rigid motions or the
    ground plane's motions (:func:`gauge_kind`)."""
    n = structure.n_bodies
    columns = []
    for i in structure.bar_indices:
        if structure.fixed[i]:
            continue
        e = T[i, :3, 2]
        col = np.zeros(6 * n)
        col[6 * i:6 * i + 3] = cross3(T[i, :3, 3], e)
        col[6 * i + 3:6 * i + 6] = e
        columns.append(col)
    kind = gauge_kind(structure, bool(contacts))
    motions: list[FloatArray] = []
    if kind == 'rigid':
        motions = list(np.eye(6))
    elif kind == 'plane':
        t1, t2, normal = _plane_motions(structure)
        motions = [np.r_[t1, 0, 0, 0], np.r_[t2, 0, 0, 0], np.r_[0, 0, 0, normal]]
    columns += [np.tile(twist, n) for twist in motions]
    if not columns:
        return np.zeros((6 * n, 0))
    return np.linalg.qr(np.array(columns).T)[0]


def gauge_conditions(structure: Structure, T: FloatArray, contacts: list[Contact]
                     ) -> FloatArray:
    """The conditions (m, 6N) that fix the gauge of a step ``delta``, one per gauge twist of
    :func:`gauge_twists` (unit rows): no spin of a free bar about its axis, and no mean motion
    of the free bodies' nodes (their mean displacement and mean turn about their centroid,
    ``sum dx_n = 0`` and ``sum (x_n - c) x dx_n = 0``; in the ground plane: the two tangential
    components and the turn about the normal). Geometric, so a rigidly moved start gives the
    rigidly moved equilibrium."""
    n = structure.n_bodies
    rows = []
    for i in structure.bar_indices:
        if not structure.fixed[i]:
            row = np.zeros(6 * n)
            row[6 * i + 3:6 * i + 6] = T[i, :3, 2]
            rows.append(row)
    kind = gauge_kind(structure, bool(contacts))
    if kind is not None:
        x = structure.node_positions(T)
        nodes = np.flatnonzero(structure.node_bodies >= 0)
        c = x[nodes].mean(axis=0)
        move = np.zeros((3, 6 * n))
        turn = np.zeros((3, 6 * n))
        for j in nodes:
            b = structure.node_bodies[j]
            ZT = np.hstack([np.eye(3), -hat3(x[j])])
            move[:, 6 * b:6 * b + 6] += ZT
            turn[:, 6 * b:6 * b + 6] += hat3(x[j] - c) @ ZT
        if kind == 'rigid':
            rows += list(move) + list(turn)
        else:
            t1, t2, normal = _plane_motions(structure)
            rows += [t1 @ move, t2 @ move, normal @ turn]
    if not rows:
        return np.zeros((0, 6 * n))
    M = np.array(rows)
    return M / np.linalg.norm(M, axis=1, keepdims=True)


class _Problem:
    """One contact set's equilibrium equations in the unknowns ``[xi of the free bodies;
    contact forces]`` (module docstring)."""

    def __init__(self, structure: Structure, loads: FloatArray, rest: FloatArray,
                 reference: FloatArray, contacts: list[Contact]) -> None:
        self.s, self.loads, self.rest, self.reference = structure, loads, rest, reference
        # Each body's residual moment is taken about its reference centre (rows X_i): the norm
        # Newton minimises does not depend on the world frame.
        self.centres = reference[:, :3, 3].copy()
        self.contacts = contacts
        self.free = np.flatnonzero(~structure.fixed)
        self.nf = self.free.size
        self.n_forces = 3 * len(contacts)
        self.scale = float(np.mean(structure.k))  # N/m: constraints in N
        self.length = float(np.mean(structure.rest_lengths))
        ground = structure.ground
        self.normal = ground.normal if ground is not None else np.zeros(3)
        self.height = ground.height if ground is not None else 0.0
        self.friction = ground.friction if ground is not None else 0.0
        self.plane = ground.tangents() if ground is not None else np.zeros((2, 3))

    # -------------------------------------------------------------- packing
    def start(self, forces: list[FloatArray]) -> FloatArray:
        """The unknowns at the reference poses (zero increments) with these contact forces."""
        return np.concatenate([np.zeros(6 * self.nf), *forces])

    def transforms(self, x: FloatArray) -> FloatArray:
        """The poses ``exp(hat(xi_i)) P_i`` of the increments ``xi_i`` ([omega; v], a spatial
        twist's screw) from the reference poses ``P_i``: a rigid motion of the reference moves
        the increments linearly (by its adjoint)."""
        return self.kinematics(x)[0]

    def kinematics(self, x: FloatArray) -> tuple[FloatArray, FloatArray]:
        """The poses (:meth:`transforms`) and ``Pi J(xi_i)`` (nf, 6, 6), the map from the
        increments' changes to the spatial twists ``[dv; dw]`` (one screw at a time: the
        scalar path of :class:`~tensegrity_stiffness.geometry.screw.ScrewKinematics` is faster
        than its batch at a structure's few bodies)."""
        T = self.reference.copy()
        PJ = np.empty((self.nf, 6, 6))
        for k, i in enumerate(self.free):
            kin = ScrewKinematics(x[6 * k:6 * k + 6])
            T[i] = kin.T @ self.reference[i]
            PJ[k] = kin.J[BLOCK_SWAP]
        return T, PJ

    def moment_rows(self, size: int) -> FloatArray:
        """``D`` (size, size): the residual wrench of body i about its reference centre,
        ``[f; m - c_i x f]``, the constraint rows unchanged."""
        D = np.eye(size)
        for k, i in enumerate(self.free):
            D[6 * k + 3:6 * k + 6, 6 * k:6 * k + 3] = -hat3(self.centres[i])
        return D

    def forces(self, x: FloatArray) -> list[FloatArray]:
        """Each contact's force (3,) on its node."""
        k = 6 * self.nf
        return [x[k + 3 * m:k + 3 * m + 3] for m in range(len(self.contacts))]

    def slip(self, c: Contact, p: FloatArray) -> tuple[FloatArray, float]:
        """The unit slip direction (3,) of a sliding contact at ``p`` and the slip's length."""
        d = p - c.anchor
        d -= (d @ self.normal) * self.normal
        size = float(np.linalg.norm(d))
        return (d / size if size > 0.0 else d), size

    def sliding_rows(self, c: Contact, p: FloatArray, f: FloatArray) -> FloatArray:
        """The 3 equations of a sliding contact (module docstring), in N."""
        tangential = f.copy()
        if self.friction > 0.0:
            tangential += self.friction * (f @ self.normal) * self.slip(c, p)[0]
        return np.r_[self.scale * (self.normal @ p - self.height), self.plane @ tangential]

    def contact_points(self, T: FloatArray) -> FloatArray:
        s = self.s
        out = np.empty((len(self.contacts), 3))
        for m, c in enumerate(self.contacts):
            out[m] = T[c.body, :3, :3] @ s.node_points[c.node] + T[c.body, :3, 3]
        return out

    # -------------------------------------------------------------- equations
    def evaluate(self, x: FloatArray, tangent: bool = True) -> tuple[FloatArray, Any] | None:
        """(residuals, context) at ``x``, or None where a string has zero length."""
        T, PJ = self.kinematics(x)
        try:
            state = self.s.evaluate_transforms(T, self.rest)
        except ValueError:
            return None
        Wg, Kg = self.s.gravity_wrenches(T)
        W = state.wrenches + Wg + self.loads
        points = self.contact_points(T)
        forces = self.forces(x)
        g = []
        for c, p, f in zip(self.contacts, points, forces, strict=True):
            W[c.body, :3] += f
            W[c.body, 3:] += cross3(p, f)
            g.append(self.scale * (p - c.anchor) if c.mode == STICK
                     else self.sliding_rows(c, p, f))
        W = W[self.free]
        W[:, 3:] -= cross3(self.centres[self.free], W[:, :3])
        r = np.concatenate([W.ravel(), *g])
        if not np.all(np.isfinite(r)):
            return None
        return r, (T, state, Kg, points, forces, PJ)

    def total_stiffness(self, context: Any) -> FloatArray:
        """``K_total`` (6N, 6N): strings, weights and the contact forces' ``E`` blocks."""
        _, state, Kg, points, forces, _ = context
        K = state.stiffness + Kg
        for c, p, f in zip(self.contacts, points, forces, strict=True):
            b = slice(6 * c.body, 6 * c.body + 6)
            K[b, b] += geometric_block(f, p)
        return K

    def constraint_rows(self, points: FloatArray) -> FloatArray:
        """The contacts' constraints on small motions about the equilibrium, d/d(delta)
        (c, 6N) with ``dx = Z(x)^T delta``: on a ground with friction 3 rows per contact (a
        small disturbance meets static friction, also at a contact that slid to the edge of its
        cone), on a frictionless ground the normal row."""
        n = self.s.n_bodies
        rows = []
        for c, p in zip(self.contacts, points, strict=True):
            ZT = np.hstack([np.eye(3), -hat3(p)])
            row = np.zeros((3, 6 * n))
            row[:, 6 * c.body:6 * c.body + 6] = ZT
            rows.append(row if self.friction > 0.0 else self.normal @ row[None])
        return np.vstack(rows) if rows else np.zeros((0, 6 * n))

    def contact_blocks(self, c: Contact, p: FloatArray, f: FloatArray
                       ) -> tuple[FloatArray, FloatArray]:
        """A contact's 3 rows of the Jacobian: d/d(delta of its body) (3, 6) and d/d(force)
        (3, 3), scaled as :meth:`evaluate`'s residuals."""
        ZT = np.hstack([np.eye(3), -hat3(p)])
        if c.mode == STICK:
            return self.scale * ZT, np.zeros((3, 3))
        n, mu = self.normal, self.friction
        dx = np.zeros((3, 6))
        dx[0] = self.scale * (n @ ZT)
        dforce = np.zeros((3, 3))
        dforce[1:] = self.plane
        if mu > 0.0:
            u, size = self.slip(c, p)
            projector = np.eye(3) - np.outer(n, n)
            dforce[1:] += mu * np.outer(self.plane @ u, n)
            if size > 0.0:
                du = (projector - np.outer(u, u)) / size @ projector @ ZT
                dx[1:] = mu * (f @ n) * (self.plane @ du)
        return dx, dforce

    def residual_jacobian(self, x: FloatArray, context: Any) -> FloatArray:
        """d(residuals)/d(unknowns) at ``x`` (``context`` from :meth:`evaluate`), exact: the
        tests hold it to central differences of :meth:`evaluate`."""
        points = context[3]
        nf = self.nf
        cols = (6 * self.free[:, None] + np.arange(6)).ravel()
        K = self.total_stiffness(context)
        size = 6 * nf + self.n_forces
        A = np.zeros((size, size))
        A[:6 * nf, :6 * nf] = -K[np.ix_(cols, cols)]
        forces = context[4]
        for m, (c, p, f) in enumerate(zip(self.contacts, points, forces, strict=True)):
            k = 6 * nf + 3 * m
            rows = np.flatnonzero(self.free == c.body)
            dx, dforce = self.contact_blocks(c, p, f)
            A[k:k + 3, k:k + 3] = dforce
            if rows.size:
                b = 6 * int(rows[0])
                A[b:b + 6, k:k + 3] = np.vstack([np.eye(3), hat3(p)])
                A[k:k + 3, b:b + 6] = dx
        # Columns: delta_i = Pi J(xi_i) dxi_i.
        PJ = context[5]
        A[:, :6 * nf] = np.einsum('ajb,jbc->ajc', A[:, :6 * nf].reshape(size, nf, 6),
                                  PJ).reshape(size, 6 * nf)
        return self.moment_rows(size) @ A

    def jacobian(self, x: FloatArray, context: Any) -> FloatArray:
        """:meth:`residual_jacobian` bordered with the gauge (module docstring)."""
        A = self.residual_jacobian(x, context)
        T, PJ, s, nf = context[0], context[5], self.s, self.nf
        size = A.shape[0]
        cols = (6 * self.free[:, None] + np.arange(6)).ravel()
        D = self.moment_rows(size)
        N = gauge_twists(s, T, self.contacts)[cols]
        if N.shape[1]:
            # Bordered: left null vectors (the gauge twists paired with the residual wrenches,
            # moved by D^-T) times the gauge conditions in the unknowns (delta_i = Pi J_i dxi_i).
            m = N.shape[1]
            left = np.zeros((size, m))
            left[:6 * nf] = N
            left = np.linalg.solve(D.T, left)
            L = gauge_conditions(s, T, self.contacts)[:, cols]
            right = np.zeros((m, size))
            right[:, :6 * nf] = np.einsum('mjb,jbc->mjc', L.reshape(m, nf, 6), PJ).reshape(
                m, 6 * nf)
            A += max(1.0, float(np.abs(A).max())) * left @ right
        return A

    def clip(self, step: FloatArray) -> FloatArray:
        """Scale the step so that no body turns by more than MAX_ROTATION_STEP or moves its
        reference centre by more than MAX_TRANSLATION_STEP mean rest lengths."""
        xi = step[:6 * self.nf].reshape(self.nf, 6)
        rot = np.linalg.norm(xi[:, :3], axis=1).max(initial=0.0) / MAX_ROTATION_STEP
        moved = xi[:, 3:] + cross3(xi[:, :3], self.centres[self.free])
        tra = np.linalg.norm(moved, axis=1).max(initial=0.0) / (MAX_TRANSLATION_STEP *
                                                                 self.length)
        return step / max(rot, tra, 1.0)

    def rechart(self, x: FloatArray) -> FloatArray:
        xi = x[:6 * self.nf].reshape(self.nf, 6)
        theta = np.linalg.norm(xi[:, :3], axis=1)
        if np.all(theta < RECHART_ANGLE):
            return x
        x = x.copy()
        for i in np.flatnonzero(theta >= RECHART_ANGLE):
            x[6 * i:6 * i + 6] = log_se3(exp_se3(xi[i]))
        return x


# ---------------------------------------------------------------------------- contact set
def _initial_contacts(structure: Structure, T: FloatArray) -> tuple[FloatArray, list[Contact]]:
    """The start on the ground: a free structure (nothing anchored) under gravity towards the
    ground translated along the normal so that its lowest node is on it (down onto it, or up
    out of it); the nodes on or below the ground stick at their projections."""
    ground = structure.ground
    if ground is None:
        return T, []
    x = structure.node_positions(T)
    movable = structure.node_bodies >= 0
    movable[movable] = ~structure.fixed[structure.node_bodies[movable]]
    heights = x @ ground.normal - ground.height
    anchored = structure.fixed.any() or bool(structure.world_nodes)
    g = structure.gravity
    if (not anchored and g is not None and g @ ground.normal < 0.0 and movable.any()
            and abs(heights[movable].min()) > CONTACT_DISTANCE):
        drop = heights[movable].min()
        T = T.copy()
        T[~structure.fixed, :3, 3] -= drop * ground.normal
        x = structure.node_positions(T)
        heights = x @ ground.normal - ground.height
    contacts = [_new_contact(structure, T, j) for j in np.flatnonzero(
        movable & (heights <= CONTACT_DISTANCE))]
    return T, contacts


def _new_contact(structure: Structure, T: FloatArray, node: int) -> Contact:
    ground = structure.ground
    x = structure.node_positions(T)[node]
    anchor = x - (x @ ground.normal - ground.height) * ground.normal
    contact = Contact(int(node), int(structure.node_bodies[node]), anchor)
    if ground.friction == 0.0:
        contact.mode = SLIDE
    return contact


def _update_contacts(problem: _Problem, x: FloatArray) -> str | None:
    """One change of the contact set at a converged ``x`` (module docstring), as a sentence,
    or None when the set is consistent."""
    s, contacts = problem.s, problem.contacts
    T = problem.transforms(x)
    forces = problem.forces(x)
    n, mu = problem.normal, problem.friction
    scale = max(1.0, float(np.max(np.abs(s.evaluate_transforms(T, problem.rest).tensions))))
    normal = np.array([f @ n for f in forces])
    if normal.size and normal.min() < -CONE_TOLERANCE * scale:
        m = int(np.argmin(normal))
        gone = contacts.pop(m)
        return f'released {s.node_names[gone.node]}'
    heights = s.node_positions(T) @ n - problem.height
    heights[[c.node for c in contacts]] = np.inf
    movable = s.node_bodies >= 0
    movable[movable] = ~s.fixed[s.node_bodies[movable]]
    heights[~movable] = np.inf
    if heights.size and heights.min() < -CONTACT_DISTANCE:
        j = int(np.argmin(heights))
        contacts.append(_new_contact(s, T, j))
        return f'{s.node_names[j]} touched the ground'
    points = problem.contact_points(T)
    for c, f, p in zip(contacts, forces, points, strict=True):
        tangential = f - (f @ n) * n
        size = float(np.linalg.norm(tangential))
        if c.mode == STICK and size > mu * (f @ n) + CONE_TOLERANCE * scale:
            c.mode = SLIDE
            c.touch = c.anchor
            c.anchor = p + SLIP_START * problem.length * tangential / size
            return f'{s.node_names[c.node]} slides'
    for c in contacts:
        if c.touch is not None:  # slipping: its law from where it touched
            c.anchor, c.touch = c.touch, None
            return f'{s.node_names[c.node]} slips from where it touched'
    return None


def _contact_guess(contacts: list[Contact], old: list[Contact], old_forces: list[FloatArray],
                   normal: FloatArray) -> list[FloatArray]:
    """Start values of the contact unknowns: the last forces of the contacts kept."""
    by_node = {c.node: f for c, f in zip(old, old_forces, strict=True)}
    return [by_node.get(c.node, np.zeros(3)).copy() for c in contacts]


# ---------------------------------------------------------------------------- the solver
def solve_structure_equilibrium(structure: Structure, loads: Any = None,
                                start: ArrayLike | None = None, *,
                                rest_lengths: ArrayLike | None = None,
                                tolerance: float = STRUCTURE_TOLERANCE,
                                max_iterations: int = MAX_NEWTON_ITERATIONS,
                                time_budget: float | None = None,
                                roll: bool = True) -> StructureEquilibrium:
    """The equilibrium of ``structure`` under ``loads`` (None, {body: (6,)} or (N, 6): constant
    wrenches ``[f; m]`` in the world about its origin), its gravity and its ground, from
    ``start`` ((N, 4, 4) or (N, 7); default the config's poses), with ``rest_lengths`` (n,)
    (module docstring). ``roll``: a structure found balanced, not stable, on one or two ground
    contacts is rolled over (:func:`rolled_over`) and solved again, up to :data:`MAX_ROLLS`
    times. Bad input raises ValueError naming it; an equilibrium that is not found returns
    ``success=False`` with the reason."""
    W = structure_loads(structure, loads)
    rest = structure.validate_rest_lengths(rest_lengths)
    T0 = structure.transforms(start)
    deadline = solve_deadline(tolerance, max_iterations, time_budget)
    T0, contacts = _initial_contacts(structure, T0)
    held = structure.fixed.any() or bool(structure.world_nodes) or bool(contacts)
    if not held and structure.gravity is not None and np.any(
            [b.mass > 0.0 for b in structure.bodies]) and np.any(structure.gravity != 0.0):
        return StructureEquilibrium(False, 'no equilibrium: the structure falls (gravity and '
                                    'no ground under it, no fixed body, no world node)', T0,
                                    None, False, {}, math.inf, 0)
    try:
        structure.evaluate_transforms(T0, rest, wrench_only=True)
    except ValueError as exc:
        return StructureEquilibrium(False, f'start is not admissible: {exc}', T0, None, False,
                                    {}, math.inf, 0)
    iterations, rolls = 0, 0
    if roll:
        T0, contacts = tipped_onto_the_ground(structure, T0, contacts)
    while True:
        result = _settle(structure, W, rest, T0, contacts, tolerance, max_iterations, deadline,
                         iterations)
        iterations = result.iterations
        if not (roll and result.success and not result.stable and rolls < MAX_ROLLS):
            break
        T1 = rolled_over(structure, result)
        if T1 is None:
            break
        rolls += 1
        T0, contacts = _initial_contacts(structure, T1)
    if rolls:
        result = replace(result, message=result.message + ' (rolled over ' + (
            'once)' if rolls == 1 else f'{rolls} times)'))
    return result


def resting_poses(structure: Structure) -> FloatArray:
    """Where a structure rests: its equilibrium with its gravity and ground
    (:func:`solve_structure_equilibrium`), or its configured poses when it has none. The
    structure twin starts there, and the structure estimator's first estimate."""
    result = solve_structure_equilibrium(structure)
    return result.poses if result.success else structure.start_poses()


def _settle(structure: Structure, W: FloatArray, rest: FloatArray, T0: FloatArray,
            contacts: list[Contact], tolerance: float, max_iterations: int, deadline: float,
            iterations: int) -> StructureEquilibrium:
    """Newton and the contact set's changes from ``T0`` with ``contacts`` (module docstring);
    ``iterations`` so far."""
    problem = _Problem(structure, W, rest, T0, contacts)
    x = problem.start(_contact_guess(contacts, [], [], problem.normal))
    norm, changes = math.inf, []
    for _ in range(MAX_CONTACT_UPDATES):
        x, norm, used = damped_newton(x, problem.evaluate, problem.jacobian, problem.clip,
                                      problem.rechart, tolerance, max_iterations, deadline,
                                      max(0, MIN_NEWTON_ITERATIONS - iterations))
        iterations += used
        if norm > tolerance:
            break
        old, old_forces = list(problem.contacts), problem.forces(x)
        change = _update_contacts(problem, x)
        if change is None:
            break
        changes.append(change)
        T = problem.transforms(x)
        problem = _Problem(structure, W, rest, T, problem.contacts)
        x = problem.start(_contact_guess(problem.contacts, old, old_forces, problem.normal))
    else:
        return _result(problem, x, norm, iterations, False,
                       f'the contact set did not settle after {MAX_CONTACT_UPDATES} changes')
    if norm > tolerance:
        reason = 'time budget exhausted' if time.perf_counter() >= deadline else 'no convergence'
        return _result(problem, x, norm, iterations, False,
                       f'{reason}: residual {norm:.3e} after {iterations} iterations')
    return _result(problem, x, norm, iterations, True, 'converged' + (
        f' ({len(changes)} contact changes)' if changes else ''))


def _roll_angle(structure: Structure, x: FloatArray, movable: NDArray[np.bool_],
                pivot: FloatArray, axis: FloatArray) -> float:
    """The smallest angle in (0, pi] by which turning the movable nodes ``x`` about the line
    (``pivot``, unit ``axis``) brings one of them onto the ground (inf: none). With Rodrigues'
    formula a node's height is ``h0 + b sin t + c (1 - cos t)``: scanned, then bisected."""
    ground = structure.ground
    r = x[movable] - pivot
    K = hat3(axis)
    n = ground.normal
    h0 = r @ n + pivot @ n - ground.height
    b = (r @ K.T) @ n
    c = (r @ (K @ K).T) @ n

    def lowest(angle: float) -> float:
        return float(np.min(h0 + b * math.sin(angle) + c * (1.0 - math.cos(angle))))

    angles = np.linspace(0.0, math.pi, ROLL_SCAN + 1)[1:]
    heights = (h0[None] + np.sin(angles)[:, None] * b[None]
               + (1.0 - np.cos(angles))[:, None] * c[None]).min(axis=1)
    below = np.flatnonzero(heights < 0.0)
    if not below.size:
        return math.inf
    hi = float(angles[below[0]])
    lo = hi - math.pi / ROLL_SCAN
    for _ in range(60):  # bisection to rounding
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if lowest(mid) < 0.0 else (mid, hi)
    return lo


def _turned(structure: Structure, T: FloatArray, pivot: FloatArray, axis: FloatArray,
            angle: float) -> FloatArray:
    """The free bodies of ``T`` turned rigidly by ``angle`` about the line (pivot, axis)."""
    G = np.eye(4)
    G[:3, :3] = exp_so3(axis * angle)
    G[:3, 3] = pivot - G[:3, :3] @ pivot
    return np.array([P if fixed else G @ P for P, fixed in zip(T, structure.fixed,
                                                                strict=True)])


def tipped_onto_the_ground(structure: Structure, T: FloatArray, contacts: list[Contact]
                           ) -> tuple[FloatArray, list[Contact]]:
    """A rigid structure resting on one ground contact or two tipped over by its weight: turned
    about that node (about the axis of the weight's moment) or that edge (the way the weight
    turns it) until another node touches, until it stands on three (or the weight has no moment
    about its contacts); the poses and the new contacts. Free structures under gravity only
    (no fixed body, no world node)."""
    ground, g = structure.ground, structure.gravity
    if ground is None or g is None or structure.fixed.any() or structure.world_nodes:
        return T, contacts
    masses = np.array([b.mass for b in structure.bodies])
    weight = masses.sum() * g
    for _ in range(2 * MAX_ROLLS):
        if not 1 <= len(contacts) <= 2:
            break
        coms = np.einsum('nij,nj->ni', T[:, :3, :3], np.array([b.com for b in structure.bodies]))
        centre = (masses @ (coms + T[:, :3, 3])) / masses.sum()
        x = structure.node_positions(T)
        nodes = [c.node for c in contacts]
        pivot = x[nodes[0]]
        moment = np.cross(centre - pivot, weight)
        if len(nodes) == 2:
            edge = x[nodes[1]] - pivot
            edge /= np.linalg.norm(edge)
            moment = (moment @ edge) * edge
        size = float(np.linalg.norm(moment))
        if size <= 1e-12 * float(np.linalg.norm(weight)) * float(np.linalg.norm(centre - pivot)):
            break
        movable = structure.node_bodies >= 0
        movable[nodes] = False
        angle = _roll_angle(structure, x, movable, pivot, moment / size)
        if not math.isfinite(angle):
            break
        T, contacts = _initial_contacts(structure, _turned(structure, T, pivot, moment / size,
                                                           angle))
    return T, contacts


def rolled_over(structure: Structure, result: StructureEquilibrium) -> FloatArray | None:
    """The poses of a structure balanced (not stable) on one ground contact or an edge of two,
    turned rigidly about that node (about the horizontal axis of its unstable mode's turn) or
    that edge, the way that reaches the ground first, until another node touches it; None when
    that does not apply (no ground or gravity, three or more contacts, a fixed body or world
    node, no node to touch)."""
    ground = structure.ground
    names = list(result.contacts)
    if (ground is None or structure.gravity is None or not 1 <= len(names) <= 2
            or structure.fixed.any() or structure.world_nodes):
        return None
    T = result.poses
    x = structure.node_positions(T)
    contact_nodes = [structure.node_index(name) for name in names]
    pivot = x[contact_nodes].mean(axis=0)
    movable = structure.node_bodies >= 0
    movable[contact_nodes] = False
    if len(names) == 2:
        axis = x[contact_nodes[1]] - x[contact_nodes[0]]
    else:
        B = tangent_basis(result.constraints, result.gauge, structure.fixed)
        H = B.T @ result.tangent_stiffness @ B
        mode = B @ np.linalg.eigh(0.5 * (H + H.T))[1][:, 0]
        turn = mode.reshape(-1, 6)[:, 3:].mean(axis=0)  # the bodies' mean angular part
        axis = turn - (turn @ ground.normal) * ground.normal
    size = float(np.linalg.norm(axis))
    if size == 0.0:
        return None
    axis = axis / size
    options = [(_roll_angle(structure, x, movable, pivot, sign * axis), sign)
               for sign in (1.0, -1.0)]
    angle, sign = min(options)
    if not math.isfinite(angle):
        return None
    return _turned(structure, T, pivot, sign * axis, angle)


def _result(problem: _Problem, x: FloatArray, norm: float, iterations: int, success: bool,
            message: str) -> StructureEquilibrium:
    """The result at ``x``: state, contacts, stability (successful solves) and message."""
    s = problem.s
    got = problem.evaluate(x)
    T = problem.transforms(x)
    if got is None:
        return StructureEquilibrium(False, 'no usable equilibrium: the last iterate cannot be '
                                    'evaluated', T, None, False, {}, math.inf, iterations)
    _, context = got
    state = context[1]
    forces = problem.forces(x)
    contacts = {s.node_names[c.node]: f.copy()
                for c, f in zip(problem.contacts, forces, strict=True)}
    sliding = tuple(s.node_names[c.node] for c in problem.contacts if c.mode == SLIDE)
    K = problem.total_stiffness(context)
    gauge = gauge_twists(s, T, problem.contacts)
    margin = -math.inf
    constraints = problem.constraint_rows(context[3])
    if success:
        margin = reduced_stability_margin(K, constraints, gauge, s.fixed)
        slack = int(np.count_nonzero(state.slack))
        if slack:
            message += f' ({slack} slack strings)'
        if not margin > STABILITY_TOLERANCE:
            message += '; equilibrium is not stable'
    return StructureEquilibrium(success, message, T, state, success and
                                margin > STABILITY_TOLERANCE, contacts, norm, iterations,
                                margin, K, gauge, sliding, constraints)


def tangent_basis(constraints: FloatArray, gauge: FloatArray, fixed: NDArray[np.bool_]
                  ) -> FloatArray:
    """An orthonormal basis (6N, d) of the twists of the free bodies that satisfy the contact
    constraints (rows (c, 6N)) and have no gauge component."""
    n = fixed.size
    free_cols = np.repeat(~fixed, 6)
    rows = [constraints, gauge.T, np.eye(6 * n)[~free_cols]]
    return scipy.linalg.null_space(np.vstack(rows))


def reduced_stability_margin(K: FloatArray, constraints: FloatArray, gauge: FloatArray,
                             fixed: NDArray[np.bool_]) -> float:
    """The smallest eigenvalue of the symmetric part of ``B^T K B`` over the largest modulus
    (``B``: :func:`tangent_basis`): > 0 for a stable equilibrium; inf when no twist is left."""
    B = tangent_basis(constraints, gauge, fixed)
    if B.shape[1] == 0:
        return math.inf
    H = B.T @ K @ B
    eig = np.linalg.eigvalsh(0.5 * (H + H.T))
    top = float(np.max(np.abs(eig)))
    return float(eig[0]) / top if top > 0.0 else -math.inf


def body_stiffness(K: FloatArray, fixed: NDArray[np.bool_], body: int) -> FloatArray:
    """The stiffness (6, 6) that a wrench on ``body`` meets when the other free bodies are in
    equilibrium: ``inv((K_ff^-1)_bb)`` of the tangent stiffness ``K`` (6N, 6N) restricted to the
    free bodies (a spine's tip stiffness for its last link; a joint's ``K_c``)."""
    free = np.flatnonzero(~fixed)
    if body not in free:
        raise ValueError(f'body {body} is fixed')
    cols = (6 * free[:, None] + np.arange(6)).ravel()
    C = np.linalg.inv(K[np.ix_(cols, cols)])
    k = int(np.flatnonzero(free == body)[0])
    return np.linalg.inv(C[6 * k:6 * k + 6, 6 * k:6 * k + 6])
