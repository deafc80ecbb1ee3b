"""Physical interpretations of the stiffness matrix (Monke & Vikas, Section V, eqs. 19-20)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry import components

FloatArray = NDArray[np.float64]

#: Block names in the order of :attr:`StiffnessInterpretation.block_norms` (eq. 19); column
#: labels of K (screw coordinates) and row labels (wrench components), eq. 20.
BLOCK_NAMES = components.BLOCK_NAMES
COLUMN_NAMES = components.SCREW_NAMES
ROW_NAMES = components.WRENCH_NAMES


@dataclass(frozen=True)
class StiffnessInterpretation:
    """Block, column and row views of ``K = dF/dxi``.

    ``blocks``: the four 3x3 blocks of eq. (19) by name: K_fw (force per rotation), K_fv
    (translational stiffness), K_mw (rotational stiffness), K_mv (moment per translation).
    ``block_norms`` (4,): their Frobenius norms in :data:`BLOCK_NAMES` order;
    ``column_norms`` (6,): |K e_i|, the wrench produced per unit change of screw coordinate i;
    ``row_norms`` (6,): sensitivity of each wrench component (eq. 20).
    """

    blocks: dict[str, FloatArray]
    block_norms: FloatArray
    column_norms: FloatArray
    row_norms: FloatArray


def interpret_stiffness(stiffness: ArrayLike) -> StiffnessInterpretation:
    """Block Frobenius norms, column norms and row norms of a (6, 6) stiffness matrix."""
    K = np.asarray(stiffness, dtype=np.float64)
    if K.shape != (6, 6):
        raise ValueError(f'stiffness must have shape (6, 6), got {K.shape}')
    blocks = {'K_fw': K[:3, :3], 'K_fv': K[:3, 3:], 'K_mw': K[3:, :3], 'K_mv': K[3:, 3:]}
    block_norms = np.array([np.linalg.norm(blocks[name]) for name in BLOCK_NAMES])
    return StiffnessInterpretation(blocks, block_norms, np.linalg.norm(K, axis=0),
                                   np.linalg.norm(K, axis=1))


def principal_stiffnesses(cartesian_stiffness: ArrayLike) -> FloatArray:
    """(6,) principal stiffnesses of a Cartesian stiffness (rows a wrench ``[fx fy fz mx my
    mz]``, columns a twist ``[dx dy dz rx ry rz]``, linear first, as ``K_c`` and a spine's tip
    stiffness): the eigenvalues of the symmetric part of its translational block (force per
    displacement, N/m), then of its rotational block (moment per rotation, N m/rad), each
    ascending. The viewers plot them (``~/stiffness_eigenvalues``)."""
    K = np.asarray(cartesian_stiffness, dtype=np.float64)
    if K.shape != (6, 6):
        raise ValueError(f'cartesian_stiffness must have shape (6, 6), got {K.shape}')
    translational, rotational = K[:3, :3], K[3:, 3:]
    return np.concatenate([np.linalg.eigvalsh(0.5 * (translational + translational.T)),
                           np.linalg.eigvalsh(0.5 * (rotational + rotational.T))])


def _summing_map() -> FloatArray:
    """(36, 16) 0/1 matrix: squared entries of K (row-major) -> the squares of the 16 norms of
    :func:`interpretation_vector`."""
    out = np.zeros((6, 6, 16))
    for r in range(6):
        for c in range(6):
            out[r, c, 2 * (r // 3) + c // 3] = 1.0  # block [fw, fv, mw, mv]
            out[r, c, 4 + c] = 1.0  # column norm
            out[r, c, 10 + r] = 1.0  # row norm
    return out.reshape(36, 16)


_SUMMING_MAP = _summing_map()


def interpretation_vector(stiffness: ArrayLike) -> FloatArray:
    """The 16 numbers of :func:`interpret_stiffness` in one vector, computed in three array
    operations: block Frobenius norms in :data:`BLOCK_NAMES` order (4), column norms (6), row
    norms (6). ``stiffness`` (6, 6) gives (16,); a batch (..., 6, 6) gives (..., 16), each row
    one vector-matrix product as for a single K (a stack of (1, 36) products: no large GEMM,
    whose threading would depend on OPENBLAS_NUM_THREADS and the load)."""
    K = np.asarray(stiffness, dtype=np.float64)
    if K.shape == (6, 6):
        return np.sqrt(np.square(K).reshape(36) @ _SUMMING_MAP)
    if K.ndim < 2 or K.shape[-2:] != (6, 6):
        raise ValueError(f'stiffness must have shape (6, 6) or (..., 6, 6), got {K.shape}')
    squares = np.square(K).reshape(-1, 1, 36)
    return np.sqrt(squares @ _SUMMING_MAP).reshape(*K.shape[:-2], 16)
