"""Modes and the linear model of a structure at an equilibrium (docs/structures.md).

The dynamics' method (:mod:`~tensegrity_stiffness.mechanics.dynamics`) in the structures'
coordinates, the stacked spatial twists ``delta`` ([dv; dw] in the world) of the bodies:

* Mass matrix ``M = blockdiag(Ad_i^-T G_i Ad_i^-1)``: ``G_i`` the body's spatial inertia about
  its origin in its frame
  (:meth:`~tensegrity_stiffness.mechanics.inertia.LinkInertia.spatial_inertia`, in [v; w] order
  here) and ``Ad_i`` the adjoint of its pose, so that the kinetic energy is
  ``1/2 delta_dot^T M delta_dot``.
* Stiffness: the equilibrium's tangent stiffness ``K_total`` (strings, weights, contact forces;
  :attr:`~tensegrity_stiffness.structures.equilibrium.StructureEquilibrium.tangent_stiffness`).
* String damping ``C = L^T diag(c) L`` with ``L = dl/d(delta)`` (n, 6N), a force ``-c_j dl_j/dt``
  along every string, slack or taut, as MuJoCo's tendon damping and the joint's dynamics.
* Coordinates: the twists ``delta = B y`` that keep the fixed bodies fixed and the contacts
  in place (on a frictionless ground: on the ground; ``B`` orthonormal); the linear model is
  ``M_r y_ddot + C_r y_dot + K_r y = B^T w`` (``w`` (6N,) external wrenches), i.e. the state
  matrix ``A = [[0, I], [-M_r^-1 K_r, -M_r^-1 C_r]]`` and input ``[0; M_r^-1 B^T]``.
* Modes: the eigenvalues ``mu`` of ``M_r^-1 K_r`` (``omega^2``); ``|mu|`` at most
  :data:`ZERO_MODE_TOLERANCE` times the largest are the zero modes, counted and named: the rigid
  motions and the frictionless ground's plane motions (the gauge of
  :func:`~tensegrity_stiffness.structures.equilibrium.gauge_twists`), each free bar's spin about
  its axis, and the rest, mechanisms (motions that change no string length to first order and
  that no prestress stiffens). The other modes, in the zero modes' M-orthogonal complement,
  by the dynamics' method (:func:`~tensegrity_stiffness.mechanics.modes.state_matrix_modes`:
  one mode per conjugate pair of the state matrix, natural frequency ``|lambda| / 2 pi``,
  damping ratio ``-Re lambda / |lambda|``), so that a joint's modes are its dynamics' exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg
from numpy.typing import NDArray

from tensegrity_stiffness.geometry.screw import BLOCK_SWAP
from tensegrity_stiffness.geometry.transforms import adjoint, inverse_transform
from tensegrity_stiffness.mechanics.modes import state_matrix_modes
from tensegrity_stiffness.structures.equilibrium import StructureEquilibrium, gauge_kind
from tensegrity_stiffness.structures.structure import Structure

FloatArray = NDArray[np.float64]

#: An eigenvalue of M^-1 K is a zero mode when its modulus is at most this times the largest.
ZERO_MODE_TOLERANCE = 1e-8


def mass_matrix(structure: Structure, T: FloatArray) -> FloatArray:
    """``M`` (6N, 6N) at the poses ``T`` (module docstring); massless bodies have zero
    blocks."""
    n = structure.n_bodies
    M = np.zeros((6 * n, 6 * n))
    for i, body in enumerate(structure.bodies):
        if body.mass == 0.0:
            continue
        G = body.link_inertia.spatial_inertia(body.node_array)[np.ix_(BLOCK_SWAP, BLOCK_SWAP)]
        inverse = adjoint(inverse_transform(T[i]))
        M[6 * i:6 * i + 6, 6 * i:6 * i + 6] = inverse.T @ G @ inverse
    return M


def length_jacobian(structure: Structure, T: FloatArray) -> FloatArray:
    """``L = dl/d(delta)`` (n, 6N): ``dl_j = u_j . (dx_B - dx_A)`` with ``dx = Z(x)^T delta``
    (``u_j`` the unit vector from its ``from`` end to its ``to`` end)."""
    xa, xb, lengths = structure.string_geometry(T)
    u = (xb - xa) / lengths[:, None]
    n = structure.n_bodies
    L = np.zeros((structure.n_strings, 6 * n + 6))  # the world as a last, dropped block
    ends = np.where(structure.string_bodies < 0, n, structure.string_bodies)
    for j in range(structure.n_strings):
        for end, x, sign in ((ends[j, 0], xa[j], -1.0), (ends[j, 1], xb[j], 1.0)):
            L[j, 6 * end:6 * end + 3] += sign * u[j]
            L[j, 6 * end + 3:6 * end + 6] += sign * np.cross(x, u[j])
    return L[:, :6 * n]


def damping_matrix(structure: Structure, T: FloatArray) -> FloatArray:
    """``C = L^T diag(c) L`` (6N, 6N) of the strings' damping ``c`` (N s/m)."""
    L = length_jacobian(structure, T)
    return L.T @ (structure.damping[:, None] * L)


def motion_basis(structure: Structure, constraints: FloatArray) -> FloatArray:
    """An orthonormal basis (6N, d) of the twists that keep the fixed bodies fixed and satisfy
    the contact ``constraints`` (c, 6N)."""
    n = structure.n_bodies
    fixed_rows = np.eye(6 * n)[np.repeat(structure.fixed, 6)]
    return scipy.linalg.null_space(np.vstack([constraints, fixed_rows]))


@dataclass(frozen=True)
class StructureModes:
    """The modes of a structure at an equilibrium (module docstring).

    ``frequencies`` (k,) Hz of the modes with stiffness, ascending, with ``damping_ratios``
    (k,) and ``shapes`` (k, 6N) as twists (unit norm); ``zero_modes``: a name per zero mode
    (``'rigid motion'``, ``'plane motion'``, ``'spin of <bar>'``, ``'mechanism'``) and
    ``zero_shapes`` (z, 6N) a basis of them in that order; ``counts`` {``rigid``, ``spins``,
    ``mechanisms``}; ``stable``: no mode with negative stiffness (nor, damped, a growing one);
    ``A`` (2d, 2d) and ``B`` (2d, 6N) the linear model in the coordinates ``basis`` (6N, d)."""

    frequencies: FloatArray
    damping_ratios: FloatArray
    shapes: FloatArray
    zero_modes: tuple[str, ...]
    zero_shapes: FloatArray
    counts: dict[str, int]
    stable: bool
    A: FloatArray
    B: FloatArray
    basis: FloatArray


def _named_zero_modes(structure: Structure, result: StructureEquilibrium, basis: FloatArray,
                      zero: FloatArray) -> tuple[list[str], FloatArray, dict[str, int]]:
    """Names and a basis (z, 6N) of the zero modes: the gauge twists first (rigid or plane
    motions, bar spins), then the mechanisms (the rest of the zero space)."""
    names, shapes = [], []
    kind = gauge_kind(structure, bool(result.contacts))
    gauge = result.gauge
    spins = [structure.body_names[i] for i in structure.bar_indices if not structure.fixed[i]]
    n_motions = gauge.shape[1] - len(spins)
    label = 'rigid motion' if kind == 'rigid' else 'plane motion'
    # gauge_twists orders the spins first, then the motions.
    for k in range(gauge.shape[1]):
        names.append(f'spin of {spins[k]}' if k < len(spins) else label)
        shapes.append(gauge[:, k])
    zero_twists = basis @ zero  # (6N, z), orthonormal
    rest = zero_twists - gauge @ (gauge.T @ zero_twists)
    count = max(zero.shape[1] - gauge.shape[1], 0)
    if count:
        mechanisms = np.linalg.svd(rest, full_matrices=False)[0][:, :count]
    else:
        mechanisms = np.zeros((basis.shape[0], 0))
    names += ['mechanism'] * mechanisms.shape[1]
    shapes += list(mechanisms.T)
    counts = {'rigid': n_motions, 'spins': len(spins), 'mechanisms': mechanisms.shape[1]}
    return names, np.array(shapes).reshape(-1, basis.shape[0]), counts


def structure_modes(structure: Structure, result: StructureEquilibrium) -> StructureModes:
    """The modes and linear model of ``structure`` at the equilibrium ``result`` of
    :func:`~tensegrity_stiffness.structures.equilibrium.solve_structure_equilibrium` (module
    docstring). ValueError when a free body has no mass."""
    if not result.success:
        raise ValueError(f'modes need an equilibrium: {result.message}')
    massless = [b.name for b, fixed in zip(structure.bodies, structure.fixed, strict=True)
                if not fixed and b.mass == 0.0]
    if massless:
        raise ValueError(f'modes need a mass for every free body: {massless} have none')
    T = result.poses
    basis = motion_basis(structure, result.constraints)
    M = basis.T @ mass_matrix(structure, T) @ basis
    K = basis.T @ result.tangent_stiffness @ basis
    C = basis.T @ damping_matrix(structure, T) @ basis
    d = basis.shape[1]
    MK = np.linalg.solve(M, K)
    MC = np.linalg.solve(M, C)
    mu = np.linalg.eigvals(MK)
    top = float(np.max(np.abs(mu), initial=0.0))
    n_zero = int(np.count_nonzero(np.abs(mu) <= ZERO_MODE_TOLERANCE * max(top, 1e-300)))
    # The zero space from the singular vectors of K_r (robust where eig's vectors of a
    # degenerate zero eigenvalue are not), the rest in its M-orthogonal complement Q.
    zero = np.linalg.svd(K)[2][d - n_zero:].T
    names, zero_shapes, counts = _named_zero_modes(structure, result, basis, zero)
    Q = scipy.linalg.null_space(zero.T @ M) if n_zero else np.eye(d)
    m = Q.shape[1]
    Mq, Kq, Cq = (Q.T @ X @ Q for X in (M, K, C))
    Aq = np.block([[np.zeros((m, m)), np.eye(m)],
                   [-np.linalg.solve(Mq, Kq), -np.linalg.solve(Mq, Cq)]])
    damped = bool(np.any(structure.damping > 0.0))
    modes = state_matrix_modes(Aq, basis @ Q, T, damped) if m else None
    A = np.block([[np.zeros((d, d)), np.eye(d)], [-MK, -MC]])
    B_in = np.vstack([np.zeros((d, basis.shape[0])), np.linalg.solve(M, basis.T)])
    if modes is None:
        return StructureModes(np.zeros(0), np.zeros(0), np.zeros((0, basis.shape[0])),
                              tuple(names), zero_shapes, counts, True, A, B_in, basis)
    shapes = modes.twists / np.maximum(np.linalg.norm(modes.twists, axis=1, keepdims=True),
                                       1e-300)
    return StructureModes(modes.frequencies, modes.damping_ratios, shapes, tuple(names),
                          zero_shapes, counts, modes.stable, A, B_in, basis)
