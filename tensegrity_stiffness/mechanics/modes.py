"""Vibration modes of a linear model ``x_dot = A x + B u`` whose state is coordinates and their
rates (``A = [[0, 1], [A21, A22]]``), and its frequency response: the analysis of the joints'
and spines' linear models (:mod:`~tensegrity_stiffness.mechanics.joint_dynamics`,
:mod:`~tensegrity_stiffness.mechanics.chain_dynamics`) and of the structures'
(:mod:`~tensegrity_stiffness.structures.modes`).

* Modes: the eigenvalues ``lambda`` of ``A``, one per conjugate pair: undamped natural frequency
  ``|lambda| / 2 pi`` (Hz), damping ratio ``-Re lambda / |lambda|``; an overdamped pair of real
  eigenvalues ``l1, l2`` gives ``sqrt(l1 l2) / 2 pi`` and ``-(l1 + l2) / (2 sqrt(l1 l2))``.
  Without damping (``A22 = 0``) the eigenvalues are ``+-sqrt(mu)`` with ``mu`` those of ``A21``
  (:func:`undamped_modes`: the half-size problem).
* Frequency response: ``H(f) = C (2 pi i f 1 - A)^-1 B`` (:func:`frequency_response`).

numpy / scipy (LAPACK's ``dgeev``) only.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dgeev

from tensegrity_stiffness.geometry.components import SCREW_NAMES
from tensegrity_stiffness.geometry.validation import finite_array

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: An eigenvalue is real when ``|Im| <= REAL_TOLERANCE |lambda|``.
REAL_TOLERANCE = 1e-9
#: Labels of the screw coordinates and of the modes' frequencies (for messages and reports).
SCREW_LABELS = SCREW_NAMES


@dataclass(frozen=True, eq=False)
class JointModes:
    """Vibration modes of a linear model, ascending in frequency (``m`` = 6 for a joint, 6N for
    a spine).

    ``frequencies`` (m,) Hz: undamped natural frequencies; ``damping_ratios`` (m,);
    ``eigenvalues`` (m,) complex (1/s; the one with ``Im >= 0`` of each pair); ``shapes``
    (m, m) complex: row k the screw-coordinate part of mode k (unit norm, largest component
    real); ``twists`` (m, m): the same as spatial twists ``[dv; dw]`` in {1} (per joint in
    {1}_i for a spine), real part after that normalisation; ``stable``: every eigenvalue has
    ``Re < 0`` (damped), or, without damping, every squared frequency is positive;
    ``screw``: the state (6,) or (N, 6)."""

    frequencies: FloatArray
    damping_ratios: FloatArray
    eigenvalues: ComplexArray
    shapes: ComplexArray
    twists: FloatArray
    stable: bool
    screw: FloatArray

    @property
    def overdamped(self) -> NDArray[np.bool_]:
        """(m,) True for a mode of a pair of real eigenvalues (overdamped, or unstable with
        real growth): it does not oscillate, and its ``frequencies`` entry is
        ``sqrt(l1 l2) / 2 pi`` of the pair, not a frequency of vibration (issue #42)."""
        return np.asarray(self.eigenvalues).imag == 0.0


def _dgeev(A: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """LAPACK's ``dgeev`` of a real square ``A`` (through ``scipy.linalg.lapack``, the routine
    ``np.linalg.eig`` calls, without numpy's per-call wrapping, which costs as much as the
    decomposition at 6x6): the real and imaginary parts of the eigenvalues and the right
    eigenvectors in LAPACK's real storage (a complex pair, ``Im > 0`` first, as its real and
    imaginary parts in two columns). LinAlgError as numpy's for a matrix that is not finite or
    does not converge."""
    if not np.isfinite(A).all():
        raise np.linalg.LinAlgError('Array must not contain infs or NaNs')
    wr, wi, _, vr, info = dgeev(A, compute_vl=0)
    if info != 0:
        raise np.linalg.LinAlgError('Eigenvalues did not converge')
    return wr, wi, vr


def _eigenvectors(vr: FloatArray, wi: FloatArray, columns: NDArray[np.intp]) -> ComplexArray:
    """Columns ``columns`` of the complex eigenvector matrix ``np.linalg.eig`` returns, from
    :func:`_dgeev`'s real storage."""
    out = vr[:, columns].astype(complex)
    first, second = wi[columns] > 0.0, wi[columns] < 0.0
    if first.any():
        out[:, first] += 1j * vr[:, columns[first] + 1]
    if second.any():
        out[:, second] = vr[:, columns[second] - 1] - 1j * vr[:, columns[second]]
    return out


def _eig(A: FloatArray) -> tuple[NDArray[Any], NDArray[Any]]:
    """``np.linalg.eig(A)`` of a real square ``A`` from :func:`_dgeev`: the eigenvalues (real
    when every one is) and the right eigenvectors as columns (unit norm)."""
    wr, wi, vr = _dgeev(A)
    if not wi.any():
        return wr, vr
    return wr + 1j * wi, _eigenvectors(vr, wi, np.arange(wr.size))


def state_matrix_modes(A: FloatArray, twist_map: FloatArray, state: FloatArray,
                       damped: bool) -> JointModes:
    """The modes of a linear model's state matrix ``A`` (2m, 2m) = ``[[0, I], [., .]]``: one per
    conjugate pair, ascending; an overdamped pair of real eigenvalues as one mode (module
    docstring), ``twist_map`` (6k, m) taking the coordinates to twists, ``state`` stored as
    :attr:`JointModes.screw`; ``damped``: the stability test of a damped model (no eigenvalue
    grows) or of an undamped one (every eigenvalue imaginary). The method of the joints' and
    spines' modes, and of the structures' (:mod:`tensegrity_stiffness.structures.modes`)."""
    n = A.shape[0] // 2
    wr, wi, vr = _dgeev(A)
    lam = wr + 1j * wi
    scale = np.abs(lam)
    real = np.abs(wi) <= REAL_TOLERANCE * np.maximum(scale, 1e-300)
    upper = np.flatnonzero(~real & (wi > 0.0))
    w = scale[upper]
    zeta = -wr[upper] / w
    chosen = lam[upper]
    # The first of each complex pair: its eigenvector is columns j + i (j + 1).
    shapes = (vr[:n, upper] + 1j * vr[:n, upper + 1]).T
    if upper.size < n:
        # Real eigenvalues: overdamped (or unstable) pairs, by ascending |lambda|.
        reals = np.flatnonzero(real)
        order = reals[np.argsort(scale[reals])]
        a, b = order[0::2], order[1::2]
        l1, l2 = wr[a], wr[b]
        wo = np.sqrt(np.abs(l1 * l2))
        with np.errstate(divide='ignore', invalid='ignore'):
            zr = np.where(wo > 0.0, -(l1 + l2) / (2.0 * wo), np.inf)
        w, zeta = np.r_[w, wo], np.r_[zeta, zr]
        chosen = np.r_[chosen, l1.astype(complex)]
        shapes = np.vstack([shapes, _eigenvectors(vr, wi, a)[:n].T])
    order = np.argsort(w, kind='stable')[:n]
    w, zeta, chosen, shapes = w[order], zeta[order], chosen[order], shapes[order]
    # Unit norm, largest component real and positive (one scaling of each row).
    size = np.abs(shapes)
    rows = np.arange(order.size)
    largest = size.argmax(axis=1)
    scaling = size[rows, largest] / (shapes[rows, largest] *
                                     np.sqrt(np.einsum('ij,ij->i', size, size)))
    shapes = shapes * scaling[:, None]
    if damped:
        # No eigenvalue grows beyond rounding, none is zero: a mode the strings' damping does
        # not reach (a ring joint's spin about its axis, whose strings keep their lengths to
        # first order) rings on, Re = 0 to rounding, and is not an instability.
        stable = bool(np.all(wr <= REAL_TOLERANCE * scale) and np.all(scale > 0.0))
    else:
        # Undamped: stable when every eigenvalue is +-i w with w > 0 (a constant wrench is not
        # conservative on SE(3), so a loaded joint can also flutter: Re > 0 in a complex pair).
        stable = bool(np.all(np.abs(wr) <= REAL_TOLERANCE * scale) and np.all(scale > 0.0))
    return JointModes(w / (2.0 * math.pi), zeta, chosen, shapes, (twist_map @ shapes.T).real.T,
                      stable, state)


def undamped_modes(A21: FloatArray, twist_map: FloatArray, screw: FloatArray) -> JointModes:
    """The modes of ``A = [[0, I], [A21, 0]]`` (no damping) from the half-size problem: ``A``
    has the eigenvalues ``+-sqrt(mu)`` with ``mu`` those of ``A21`` (same shapes), so a 6x6
    (6N x 6N) eigenproblem replaces the 12x12 one; ``twist_map`` and ``screw`` as
    :func:`state_matrix_modes`. (Kept lean: this is the node's per-input path.)"""
    mu, vec = _eig(A21)
    lam = 1j * np.sqrt(-mu + 0j)  # the root with Im >= 0: i w for mu = -w^2
    w = np.abs(lam)
    order = np.argsort(w)
    lam, w = lam[order], w[order]
    shapes = vec.T[order]  # unit norm from LAPACK
    rows = np.arange(order.size)
    big = shapes[rows, np.abs(shapes).argmax(axis=1)]
    if np.isrealobj(mu):
        shapes = (shapes * np.sign(big)[:, None]).astype(complex)
        stable = bool(mu.max() < 0.0)
    else:
        shapes = shapes * (np.abs(big) / big)[:, None]
        stable = bool((np.abs(mu.imag) <= REAL_TOLERANCE * np.abs(mu)).all() and
                      mu.real.max() < 0.0)
    # + 0.0: a ratio of a conservative mode is 0, not -0 (-lam.real of Re lambda = 0).
    return JointModes(w / (2.0 * math.pi), -lam.real / w + 0.0, lam, shapes,
                      (twist_map @ shapes.T).real.T, stable, screw)


def frequency_response(A: FloatArray, B: FloatArray, C: FloatArray, frequencies_hz: ArrayLike
                       ) -> ComplexArray:
    """(F, p, q) complex ``C (2 pi i f 1 - A)^-1 B`` of the linear model ``(A, B)`` with outputs
    ``C`` at each frequency ``f`` (Hz, >= 0; ValueError otherwise)."""
    f = finite_array('frequencies_hz', frequencies_hz).ravel()
    if np.any(f < 0.0):
        raise ValueError('frequencies_hz must be >= 0')
    n = A.shape[0]
    out = np.empty((f.size,) + (C.shape[0], B.shape[1]), dtype=complex)
    for k, fk in enumerate(f):
        out[k] = C @ np.linalg.solve(2j * math.pi * fk * np.eye(n) - A, B)
    return out
