"""Calibration of a structure's strings (:mod:`tensegrity_stiffness.structures`) from a
recording: each string's stiffness ``k_j`` and rest-length offset ``d_j`` (true rest length =
the encoder's + ``d_j``), with the identifiability report (no rclpy).

The joint's method (:mod:`~tensegrity_stiffness.estimation.calibration`) generalised: every
sample's unknown state is eliminated and the parameters are fitted by Gauss-Newton with the
information ``S = sum_i C_i - B_i^T A_i^-1 B_i``. In a structure a string's load cell depends
only on its own length, so the state of sample ``i`` that matters for string ``j`` is its true
length ``l_ij`` (measured by the length sensor, ``noise.length``; not held at the reading: that
would bias the stiffness low, as the joint's docstring says of the pose), and the problem splits
into one small problem per string with the residuals

* ``(l_ij - l_m,ij) / noise.length`` (the length sensor),
* ``(phi(l_ij; k_j, r_ij + d_j) - t_ij) / noise.tension`` (the load cell, the string's law,
  ``r_ij`` the encoder's rest length),

Jacobians ``d phi / d l = phi'``, ``d phi / d k = phi / k`` (both laws are linear in ``k``),
``d phi / d d = d phi / d l0`` (Hooke: ``-k`` taut, the paper's law ``-k / l``; 0 slack or past
the maximum length). The identifiability of the scaled parameters (``(k - k_nom) /
(STIFFNESS_UNIT k_nom)``, ``d / OFFSET_UNIT``, as the joint's) is the joint's
:func:`~tensegrity_stiffness.estimation.calibration.identifiability`: a string slack in every
sample, or never moved, is named; its parameters stay at nominal. Covariance: the inverse of
``S`` on the identifiable subspace (the Cramer-Rao bound of the linearised problem).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation.calibration_model import OFFSET_UNIT, STIFFNESS_UNIT
from tensegrity_stiffness.estimation.calibration_results import identifiability
from tensegrity_stiffness.estimation.calibration_samples import CalibrationNoise
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.joint import string_forces
from tensegrity_stiffness.structures.structure import Structure

__all__ = [
    'StructureCalibration',
    'StructureCalibrationSample',
    'calibrate_structure',
    'tension_parameter_jacobians',
]

FloatArray = NDArray[np.float64]

#: Gauss-Newton iterations and the scaled step below which the fit stops.
MAX_ITERATIONS = 30
STEP_TOLERANCE = 1e-10


@dataclass(frozen=True)
class StructureCalibrationSample:
    """One instant of a recording: ``lengths`` (n,) the length sensors (m), ``tensions`` (n,)
    the load cells (N), ``encoders`` (n,) the commanded rest lengths (m)."""

    lengths: ArrayLike
    tensions: ArrayLike
    encoders: ArrayLike


@dataclass
class StructureCalibration:
    """Outcome of :func:`calibrate_structure`: ``stiffness`` (n,) N/m, ``offsets`` (n,) m and
    their ``stiffness_std`` / ``offset_std`` (NaN where unidentifiable), ``covariance`` (2n, 2n)
    of ``[k; d]``, ``identifiable`` the identifiable parameters' names and ``unidentifiable``
    the words for what the recording cannot determine, ``chi2`` and ``dof``."""

    stiffness: FloatArray
    offsets: FloatArray
    stiffness_std: FloatArray
    offset_std: FloatArray
    covariance: FloatArray
    identifiable: tuple[str, ...]
    unidentifiable: tuple[str, ...]
    chi2: float
    dof: int


def tension_parameter_jacobians(structure: Structure, lengths: FloatArray, rest: FloatArray,
                                k: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray,
                                                        FloatArray]:
    """Tensions (..., n) of strings of ``lengths`` with rest lengths ``rest`` and stiffness
    ``k`` by the structure's law, and their derivatives in the length, the stiffness and the
    rest length (module docstring)."""
    phi, dphi, slack, saturated = string_forces(lengths, rest, k, structure.max_stretch,
                                                structure.force_law)
    taut = ~(slack | saturated)
    d_rest = np.where(taut, -k if structure.force_law == 'hooke' else -k / lengths, 0.0)
    return phi, dphi, phi / k, d_rest


def _samples(structure: Structure, samples: Sequence[StructureCalibrationSample]
             ) -> tuple[FloatArray, FloatArray, FloatArray]:
    n = structure.n_strings
    if not samples:
        raise ValueError('samples: a recording needs at least one sample')
    out = []
    for field in ('lengths', 'tensions', 'encoders'):
        rows = []
        for i, s in enumerate(samples):
            v = finite_array(f'samples[{i}].{field}', getattr(s, field)).reshape(-1)
            if v.shape != (n,):
                raise ValueError(f'samples[{i}].{field} must be {n} values, got {v.size}')
            rows.append(v)
        out.append(np.array(rows))
    if np.any(out[0] <= 0.0) or np.any(out[2] <= 0.0):
        raise ValueError('samples: lengths and encoders must be > 0')
    return out[0], out[1], out[2]


def calibrate_structure(structure: Structure, samples: Sequence[StructureCalibrationSample],
                        noise: CalibrationNoise | None = None) -> StructureCalibration:
    """Each string's stiffness and rest-length offset from ``samples`` (module docstring),
    starting at the structure's stiffness and zero offsets."""
    noise = noise or CalibrationNoise()
    lm, tm, enc = _samples(structure, samples)
    n = structure.n_strings
    k_nom = structure.k.copy()
    k, d = k_nom.copy(), np.zeros(n)
    lengths = lm.copy()
    sl, st = noise.length, noise.tension
    unit = np.concatenate([STIFFNESS_UNIT * k_nom, np.full(n, OFFSET_UNIT)])
    names = [f'stiffness[{s}]' for s in structure.string_names] + [
        f'rest_length_offset[{s}]' for s in structure.string_names]
    basis = None
    for _ in range(MAX_ITERATIONS):
        phi, dphi, dk, dd = tension_parameter_jacobians(structure, lengths, enc + d, k)
        r_l = (lengths - lm) / sl
        r_t = (phi - tm) / st
        # per sample and string: unknown l (a = (1/sl^2 + dphi^2/st^2)), parameters (k, d)
        a = 1.0 / sl ** 2 + (dphi / st) ** 2
        g_l = r_l / sl + dphi * r_t / st
        jp = np.stack([dk, dd], axis=-1) / st * unit.reshape(2, n).T  # (m, n, 2) scaled
        b = (dphi / st)[..., None] * jp  # cross terms l-parameters
        S = np.einsum('min,mio->ino', jp, jp) - np.einsum('min,mio->ino', b / a[..., None], b)
        g = np.einsum('min,mi->in', jp, r_t) - np.einsum('min,mi->in', b / a[..., None], g_l)
        info = np.zeros((2 * n, 2 * n))
        grad = np.zeros(2 * n)
        for j in range(n):
            idx = [j, n + j]
            info[np.ix_(idx, idx)] = S[j]
            grad[idx] = g[j]
        if basis is None:
            ident = identifiability(info, names)
            basis = ident.basis
        reduced = basis.T @ info @ basis
        step_z = -basis @ np.linalg.solve(reduced, basis.T @ grad) if basis.shape[1] else \
            np.zeros(2 * n)
        step = step_z * unit
        k = k + step[:n]
        d = d + step[n:]
        # the lengths at the new parameters: each its own Gauss-Newton step
        phi, dphi, dk, dd = tension_parameter_jacobians(structure, lengths, enc + d, k)
        lengths = lengths + _length_step(lengths, lm, phi, dphi, tm, sl, st)
        if np.max(np.abs(step_z)) < STEP_TOLERANCE:
            break
    phi, dphi, dk, dd = tension_parameter_jacobians(structure, lengths, enc + d, k)
    chi2 = float(np.sum(((lengths - lm) / sl) ** 2) + np.sum(((phi - tm) / st) ** 2))
    cov_z = basis @ np.linalg.solve(basis.T @ info @ basis, basis.T) if basis.shape[1] else \
        np.zeros((2 * n, 2 * n))
    cov = unit[:, None] * cov_z * unit[None, :]
    std = np.sqrt(np.maximum(np.diag(cov), 0.0))
    identified = np.linalg.norm(basis, axis=1) > 1e-9 if basis.shape[1] else np.zeros(2 * n,
                                                                                       bool)
    std = np.where(identified, std, math.nan)
    return StructureCalibration(k, d, std[:n], std[n:], cov,
                                tuple(nm for nm, ok in zip(names, identified, strict=True) if ok),
                                tuple(ident.descriptions), chi2,
                                2 * lm.size - lm.size - int(basis.shape[1]))


def _length_step(lengths: FloatArray, lm: FloatArray, phi: FloatArray, dphi: FloatArray,
                 tm: FloatArray, sl: float, st: float) -> FloatArray:
    """Each sample's length's Gauss-Newton step at the parameters (its own 1-unknown problem)."""
    a = 1.0 / sl ** 2 + (dphi / st) ** 2
    return -((lengths - lm) / sl ** 2 + dphi * (phi - tm) / st ** 2) / a
