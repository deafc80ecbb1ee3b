"""The pin-jointed analysis of a structure: self-stresses, mechanisms, force densities, the stress
matrix, prestress stability and super stability (docs/structures.md, "Analysis").

The structure is read as a pin-jointed framework (:class:`Framework`): its nodes, and as members
its strings and its bars (a bar joins its nodes ``a`` and ``b``); the nodes of fixed bodies and
the world's nodes are supports. Member forces ``t`` are tensions (a bar's is minus its
compression).

* **Equilibrium matrix** (Pellegrino & Calladine 1986, eq. 1): ``A t = f`` with column ``k`` of
  member ``(i, j)`` holding ``(x_i - x_j) / l_k`` at node ``i`` and ``(x_j - x_i) / l_k`` at node
  ``j`` (rows of the free nodes only); its transpose is the compatibility matrix (``e = A' d``).
  With ``r = rank A`` (the SVD), ``b`` members and ``D`` free coordinates: ``s = b - r``
  self-stresses and ``m = D - r - R`` mechanisms, ``R`` the rigid motions of a free framework
  (6 in general position, 5 for collinear nodes: the count ``m - s = 3j - b - 6`` of
  Pellegrino & Calladine); with supports ``R = 0`` (``m - s = 3j - c - b``, ``c`` the fixed
  coordinates): a motion of the whole that the supports allow is a mechanism.
* **Force densities** ``q_k = t_k / l_k`` (Schek 1974), bars negative; the **stress matrix**
  ``Omega`` (nodes x nodes): ``Omega_ij = -q_k`` for member ``k = (i, j)``,
  ``Omega_ii = sum_k q_k`` over the members at ``i`` (Connelly 1982). A self-stress has
  ``Omega X = 0`` for the (n, 3) node positions ``X``.
* **Prestress stability** (Pellegrino 1990; Guest 2011, "The stiffness of prestressed
  frameworks: a unifying approach"): the geometric stiffness ``K_G = Omega (x) I_3`` of the
  stress, on the free coordinates, is positive definite on the internal mechanisms (the
  mechanisms orthogonal to the rigid motions): every mechanism is stiffened by the prestress.
  (The product-force test of Pellegrino & Calladine is this test for one mechanism.)
* **Bodies of any kind** (:func:`body_counts`): the same counts on the rigid-body model,
  the equilibrium matrix the (6F, n) wrenches of unit string tensions on the F free bodies
  (:func:`string_wrench_matrix`): ``s = n - r``
  string self-stresses, ``m = 6F - r - g`` mechanisms with ``g`` the gauge motions (the rigid
  motions when nothing holds the structure, and each free bar's spin about its axis). For bars
  it equals the pin-jointed count (a bar's balance makes its force axial).
* **Super stability** (Connelly 1982; Zhang & Ohsaki 2007, "Stability conditions for
  tensegrity structures", Int. J. Solids Struct. 44): for a free framework in 3D whose strings
  pull and bars push, ``Omega`` positive semi-definite with nullity ``d + 1 = 4``, and the
  directions of the stressed members not on a conic at infinity (no symmetric 3x3
  ``Q != 0`` with ``d_k' Q d_k = 0`` for all of them: the (b, 6) matrix of the
  ``d_k d_k'`` has rank 6). Super stable frameworks are stable for any positive member
  stiffnesses and any stress level.

Ranks and signs are judged with relative tolerances (:data:`RANK_RTOL`,
:data:`EIGENVALUE_RTOL`) that lie far above the rounding of the SVD and the eigenvalues
(``n eps |M|``) and far below the smallest non-zero values of the structures here.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
IntArray = NDArray[np.intp]

#: Singular values below ``RANK_RTOL * s_max`` count as zero (ranks, null spaces).
RANK_RTOL = 1e-9
#: Eigenvalues of the stress matrix and of the reduced geometric stiffness within
#: ``EIGENVALUE_RTOL * max|eig|`` of zero count as zero.
EIGENVALUE_RTOL = 1e-9
#: Space dimension d (the nullity of a super stable stress matrix is d + 1).
DIMENSION = 3
#: Member kinds.
BAR = 'bar'
STRING = 'string'


@dataclass(frozen=True)
class Framework:
    """A pin-jointed framework: ``positions`` (n, 3) of the nodes ``node_names``; ``members``
    (b, 2) node indices with ``member_names`` and ``is_bar`` (b,); ``fixed`` (n,) the supports;
    ``forces`` (b,) member tensions (bars negative; None: none known)."""

    node_names: tuple[str, ...]
    positions: FloatArray
    members: IntArray
    member_names: tuple[str, ...]
    is_bar: BoolArray
    fixed: BoolArray
    forces: FloatArray | None = None

    @classmethod
    def build(cls, node_names: Sequence[str], positions: ArrayLike,
              members: Sequence[tuple[int, int]], member_names: Sequence[str],
              is_bar: Sequence[bool], fixed: Sequence[bool] | None = None,
              forces: ArrayLike | None = None) -> Framework:
        """A checked framework (ValueError naming the field)."""
        X = np.asarray(positions, dtype=np.float64)
        n = len(node_names)
        if X.shape != (n, 3) or not np.all(np.isfinite(X)):
            raise ValueError(f'positions must be finite with shape ({n}, 3), got {X.shape}')
        M = np.asarray(members, dtype=np.intp).reshape(-1, 2)
        b = M.shape[0]
        if len(member_names) != b or len(is_bar) != b:
            raise ValueError(f'member_names and is_bar need {b} entries (one per member)')
        if b and (M.min() < 0 or M.max() >= n):
            raise ValueError(f'members must join nodes 0..{n - 1}')
        for k, (i, j) in enumerate(M):
            if i == j or np.linalg.norm(X[i] - X[j]) == 0.0:
                raise ValueError(f'member {member_names[k]} has zero length')
        F = np.zeros(n, dtype=bool) if fixed is None else np.asarray(fixed, dtype=bool)
        if F.shape != (n,):
            raise ValueError(f'fixed must have {n} entries, got {F.shape}')
        t = None
        if forces is not None:
            t = np.asarray(forces, dtype=np.float64).reshape(-1)
            if t.shape != (b,) or not np.all(np.isfinite(t)):
                raise ValueError(f'forces must be {b} finite member tensions')
        return cls(tuple(node_names), X, M, tuple(member_names),
                   np.asarray(is_bar, dtype=bool), F, t)

    @property
    def lengths(self) -> FloatArray:
        """(b,) member lengths."""
        i, j = self.members.T
        return np.linalg.norm(self.positions[i] - self.positions[j], axis=1)

    def with_forces(self, forces: ArrayLike) -> Framework:
        """The same framework with member tensions ``forces`` (b,)."""
        return Framework.build(self.node_names, self.positions, self.members.tolist(),
                               self.member_names, self.is_bar.tolist(), self.fixed.tolist(),
                               forces)

    def with_positions(self, positions: ArrayLike) -> Framework:
        """The same members at new node ``positions`` (n, 3) (forces dropped)."""
        return Framework.build(self.node_names, positions, self.members.tolist(),
                               self.member_names, self.is_bar.tolist(), self.fixed.tolist())


def equilibrium_matrix(positions: FloatArray, members: IntArray) -> FloatArray:
    """(3n, b) ``A`` of ``A t = f`` (module docstring; Pellegrino & Calladine 1986) over all
    nodes, rows ``3i..3i+2`` of node ``i``."""
    n, b = positions.shape[0], members.shape[0]
    A = np.zeros((3 * n, b))
    i, j = members.T
    d = positions[i] - positions[j]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    cols = np.arange(b)
    for c in range(3):
        A[3 * i + c, cols] += u[:, c]
        A[3 * j + c, cols] -= u[:, c]
    return A


def stress_matrix(n_nodes: int, members: IntArray, densities: FloatArray) -> FloatArray:
    """(n, n) stress matrix ``Omega`` of force densities ``q`` (module docstring)."""
    Omega = np.zeros((n_nodes, n_nodes))
    i, j = members.T
    np.add.at(Omega, (i, j), -densities)
    np.add.at(Omega, (j, i), -densities)
    np.add.at(Omega, (i, i), densities)
    np.add.at(Omega, (j, j), densities)
    return Omega


def rigid_motion_basis(positions: FloatArray) -> FloatArray:
    """(3n, 6) the infinitesimal rigid motions ``u_i = v + w x x_i`` (three translations, three
    rotations about the centroid), columns not orthonormalised."""
    n = positions.shape[0]
    R = np.zeros((3 * n, 6))
    x = positions - positions.mean(axis=0)
    for c in range(3):
        R[c::3, c] = 1.0
        w = np.zeros(3)
        w[c] = 1.0
        R[:, 3 + c] = np.cross(w, x).reshape(-1)
    return R


def null_space(M: FloatArray, rtol: float = RANK_RTOL) -> tuple[FloatArray, int]:
    """Orthonormal basis (columns) of the null space of ``M`` and its rank, singular values
    below ``rtol * s_max`` counting as zero."""
    if M.size == 0:
        return np.eye(M.shape[1]), 0
    _, s, Vt = np.linalg.svd(M)
    rank = int(np.sum(s > rtol * s[0])) if s.size and s[0] > 0.0 else 0
    return Vt[rank:].T.copy(), rank


def column_space(M: FloatArray, rtol: float = RANK_RTOL) -> FloatArray:
    """Orthonormal basis of the column space of ``M``."""
    if M.size == 0:
        return np.zeros((M.shape[0], 0))
    U, s, _ = np.linalg.svd(M, full_matrices=False)
    rank = int(np.sum(s > rtol * s[0])) if s.size and s[0] > 0.0 else 0
    return U[:, :rank]


def free_coordinates(fixed: BoolArray) -> IntArray:
    """The coordinate indices (into 3n) of the free nodes."""
    return (3 * np.flatnonzero(~fixed)[:, None] + np.arange(3)).reshape(-1)


def remaining_rigid_motions(positions: FloatArray, fixed: BoolArray) -> FloatArray:
    """Orthonormal basis, on the free coordinates, of the rigid motions that leave every
    support in place (all 6, or fewer for collinear nodes, when nothing is fixed)."""
    R = rigid_motion_basis(positions)
    rows = free_coordinates(fixed)
    if fixed.any():
        fixed_rows = free_coordinates(~fixed)
        keep, _ = null_space(R[fixed_rows])
        R = R @ keep
    return column_space(R[rows])


def directions_on_conic_at_infinity(directions: FloatArray, rtol: float = RANK_RTOL) -> bool:
    """True when the (b, 3) ``directions`` lie on a conic at infinity: some symmetric
    ``Q != 0`` has ``d' Q d = 0`` for all (Connelly; Zhang & Ohsaki 2007, Theorem 2)."""
    d = directions / np.linalg.norm(directions, axis=1)[:, None]
    x, y, z = d.T
    rows = np.column_stack([x * x, y * y, z * z, 2 * x * y, 2 * y * z, 2 * x * z])
    _, rank = null_space(rows, rtol)
    return rank < 6


@dataclass
class Analysis:
    """What :func:`analyse_framework` finds (module docstring).

    Counts: ``rank`` of the equilibrium matrix, ``self_stresses`` s, ``mechanisms`` m (rigid
    motions removed), ``rigid_motions`` (removed: those of a free framework, none with supports).
    ``self_stress_basis`` (b, s) orthonormal; ``mechanism_basis`` (D, m) orthonormal on the free
    coordinates, orthogonal to the rigid motions. With member forces: ``force_densities`` {member:
    q} (N/m, bars negative) and ``density_vector`` (b,) the same in member order, ``stress_matrix``
    (n, n) and its ascending ``stress_eigenvalues``, ``stress_nullity``, ``stress_psd``,
    ``residual`` ``|A t|`` on the free nodes (N; zero for a self-stress), ``strings_pull`` (every
    string tension >= 0 and bar force <= 0), ``prestress_stiffness`` (m,) the ascending eigenvalues
    of the geometric stiffness on the mechanisms (N/m), ``prestress_stable``, ``super_stable``
    (None with supports: Connelly's test is for free frameworks) and ``conic_at_infinity``."""

    framework: Framework
    rank: int
    self_stresses: int
    mechanisms: int
    rigid_motions: int
    self_stress_basis: FloatArray
    mechanism_basis: FloatArray
    density_vector: FloatArray | None = None
    stress_matrix: FloatArray | None = None
    stress_eigenvalues: FloatArray | None = None
    stress_nullity: int | None = None
    stress_psd: bool | None = None
    residual: float | None = None
    strings_pull: bool | None = None
    prestress_stiffness: FloatArray | None = None
    prestress_stable: bool | None = None
    super_stable: bool | None = None
    conic_at_infinity: bool | None = None

    @property
    def force_densities(self) -> dict[str, float] | None:
        """{member name: force density t / l (N/m)}, bars negative (None without forces)."""
        if self.density_vector is None:
            return None
        return dict(zip(self.framework.member_names, map(float, self.density_vector),
                        strict=True))


def _zero_tolerance(values: FloatArray, rtol: float) -> float:
    return rtol * max(float(np.max(np.abs(values))) if values.size else 0.0, 1e-300)


def analyse_framework(framework: Framework, rtol: float = RANK_RTOL,
                      eigenvalue_rtol: float = EIGENVALUE_RTOL) -> Analysis:
    """Self-stresses and mechanisms of ``framework`` and, when it carries forces, the force
    densities, the stress matrix, prestress and super stability (module docstring)."""
    fw = framework
    X, members = fw.positions, fw.members
    rows = free_coordinates(fw.fixed)
    A = equilibrium_matrix(X, members)[rows]
    stresses, rank = null_space(A, rtol)
    kinematic, _ = null_space(A.T, rtol)  # inextensional displacements (D, D - r)
    # Rigid motions are the gauge of a free framework only: with supports, a motion of the
    # whole that leaves them in place (a swing about two anchors) is a mechanism.
    rigid = (np.zeros((rows.size, 0)) if fw.fixed.any()
             else remaining_rigid_motions(X, fw.fixed))
    # Internal mechanisms: the inextensional motions orthogonal to the rigid ones.
    internal = kinematic - rigid @ (rigid.T @ kinematic)
    mechanism_basis = column_space(internal, rtol) if internal.size else internal
    n_mech = kinematic.shape[1] - rigid.shape[1]
    out = Analysis(fw, rank, members.shape[0] - rank, n_mech, rigid.shape[1], stresses,
                   mechanism_basis)
    if fw.forces is None:
        return out
    t = fw.forces
    q = t / fw.lengths
    Omega = stress_matrix(X.shape[0], members, q)
    eig = np.linalg.eigvalsh(Omega)
    zero = _zero_tolerance(eig, eigenvalue_rtol)
    out.density_vector = q
    out.stress_matrix = Omega
    out.stress_eigenvalues = eig
    out.stress_nullity = int(np.sum(np.abs(eig) <= zero))
    out.stress_psd = bool(eig[0] >= -zero)
    out.residual = float(np.linalg.norm(A @ t))
    out.strings_pull = bool(np.all(t[~fw.is_bar] >= 0.0) and np.all(t[fw.is_bar] <= 0.0))
    KG = np.kron(Omega, np.eye(3))[np.ix_(rows, rows)]
    if mechanism_basis.shape[1]:
        Q = mechanism_basis.T @ KG @ mechanism_basis
        mu = np.linalg.eigvalsh(0.5 * (Q + Q.T))
        stable = bool(mu[0] > _zero_tolerance(np.linalg.eigvalsh(KG), eigenvalue_rtol))
    else:
        mu, stable = np.zeros(0), True
    out.prestress_stiffness = mu
    out.prestress_stable = stable and out.strings_pull
    stressed = np.abs(q) > _zero_tolerance(q, eigenvalue_rtol)
    i, j = members[stressed].T
    out.conic_at_infinity = directions_on_conic_at_infinity(X[i] - X[j], rtol)
    if fw.fixed.any():
        out.super_stable = None
    else:
        out.super_stable = bool(out.strings_pull and out.stress_psd
                                and out.stress_nullity == DIMENSION + 1
                                and not out.conic_at_infinity)
    return out


def product_forces(analysis: Analysis) -> FloatArray:
    """(D, m) the product forces ``K_G M`` of the self-stress and each mechanism (Pellegrino &
    Calladine 1986, Section 5): the loads that the stress exerts when the framework moves along
    a mechanism. A mechanism is first-order stiffened when its product forces are not in the
    column space of the equilibrium matrix (the bar and string forces cannot balance them);
    ``M' K_G M`` is their component along the mechanisms (the prestress stiffness)."""
    a = analysis
    if a.stress_matrix is None:
        raise ValueError('product forces need member forces (a framework with forces)')
    rows = free_coordinates(a.framework.fixed)
    KG = np.kron(a.stress_matrix, np.eye(3))[np.ix_(rows, rows)]
    return KG @ a.mechanism_basis


def framework_of(structure: Any, poses: ArrayLike | None = None) -> Framework:
    """The pin-jointed framework of a :class:`~tensegrity_stiffness.structures.structure.Structure`
    at ``poses`` (None: its start), with the member forces of its evaluation (strings' tensions,
    minus the bars' compressions). The nodes of fixed bodies and of the world are supports; every
    free body must be a bar (ValueError naming the first that is not: a body of more nodes is no
    pin-jointed member)."""
    for body in structure.bodies:
        if not body.fixed and body.kind != BAR:
            raise ValueError(f"bodies: '{body.name}' is a free {body.kind} of "
                             f'{len(body.node_names)} nodes; the pin-jointed analysis takes '
                             'bars (and fixed bodies, whose nodes are supports)')
    T = structure.transforms(poses)
    state = structure.evaluate(T)
    X = structure.node_positions(T)
    members = [tuple(map(int, pair)) for pair in structure.string_nodes]
    names = list(structure.string_names)
    forces = list(state.tensions)
    for k, i in enumerate(structure.bar_indices):
        name = structure.body_names[int(i)]
        members.append((structure.node_index(f'{name}.a'), structure.node_index(f'{name}.b')))
        names.append(name)
        forces.append(-float(state.bar_forces[k]))
    is_bar = [False] * structure.n_strings + [True] * len(structure.bar_indices)
    fixed = [b < 0 or bool(structure.fixed[b]) for b in structure.node_bodies]
    return Framework.build(structure.node_names, X, members, names, is_bar, fixed, forces)


def analyse(structure: Any, poses: ArrayLike | None = None) -> Analysis:
    """:func:`analyse_framework` of :func:`framework_of` ``(structure, poses)``: the counts,
    force densities, stress matrix, prestress and super stability of the structure's
    pin-jointed framework at ``poses`` (None: its start)."""
    return analyse_framework(framework_of(structure, poses))


def string_wrench_matrix(structure: Any, T: FloatArray) -> FloatArray:
    """(6N, n) ``G``: column ``k`` the wrenches ``[f; x x f]`` (world, about its origin) on
    the bodies of a unit tension in string ``k`` at the (N, 4, 4) poses ``T``; the strings'
    wrenches are ``G t`` (the rows of the world's nodes dropped)."""
    X = structure.node_positions(T)
    a, b = structure.string_nodes.T
    d = X[b] - X[a]
    u = d / np.linalg.norm(d, axis=1)[:, None]
    G = np.zeros((6 * structure.n_bodies, structure.n_strings))
    cols = np.arange(structure.n_strings)
    for ends, sign in ((a, 1.0), (b, -1.0)):
        bodies = structure.node_bodies[ends]
        f = sign * u
        m = np.cross(X[ends], f)
        on = bodies >= 0
        for c in range(3):
            G[6 * bodies[on] + c, cols[on]] += f[on, c]
            G[6 * bodies[on] + 3 + c, cols[on]] += m[on, c]
    return G


@dataclass(frozen=True)
class BodyCounts:
    """:func:`body_counts`: ``rank`` of the bodies' equilibrium matrix, ``self_stresses``,
    ``mechanisms``, ``rigid_motions`` (6 or 0) and ``spins`` (free bars) removed."""

    rank: int
    self_stresses: int
    mechanisms: int
    rigid_motions: int
    spins: int


def body_counts(structure: Any, poses: ArrayLike | None = None,
                rtol: float = RANK_RTOL) -> BodyCounts:
    """Self-stresses and mechanisms of ``structure``'s rigid-body model at ``poses`` (None:
    its start; module docstring), for bodies of any kind."""
    T = structure.transforms(poses)
    free = np.flatnonzero(~structure.fixed)
    rows = (6 * free[:, None] + np.arange(6)).reshape(-1)
    G = string_wrench_matrix(structure, T)[rows]
    _, rank = null_space(G.T, rtol) if G.size else (None, 0)
    held = bool(structure.fixed.any() or structure.world_nodes)
    gauge = []
    if not held:
        for c in range(6):  # a twist [v at the origin; omega] of every free body
            twist = np.zeros(6)
            twist[c] = 1.0
            gauge.append(np.tile(twist, free.size))
    spins = 0
    for i in structure.bar_indices:
        k = int(np.searchsorted(free, i))
        if k < free.size and free[k] == i:
            Ti = T[int(i)]
            axis, centre = Ti[:3, 2], Ti[:3, 3]
            twist = np.zeros(6 * free.size)
            twist[6 * k:6 * k + 3] = np.cross(centre, axis)  # v at the origin of a spin
            twist[6 * k + 3:6 * k + 6] = axis
            gauge.append(twist)
            spins += 1
    g = int(np.linalg.matrix_rank(np.array(gauge))) if gauge else 0
    n = structure.n_strings
    return BodyCounts(rank, n - rank, 6 * free.size - rank - g, 0 if held else 6, spins)
