"""Eigenvalues judged at a floor, as a subscriber judges them: the floor the documentation
promises (``eigenvalues >= output.min_eigenvalue``) checked with ``numpy.linalg.eigvalsh`` of the
values received, with no tolerance (the projection keeps the margin
:data:`~tensegrity_stiffness.mechanics.controller_stiffness.EIGENVALUE_MARGIN` for that), and
eigenvalues compared with a bound derived from the matrix's size (``eigvalsh`` is accurate to a
few ``eps |M|_2``, never to a fraction of a small floor)."""

import numpy as np

from tensegrity_stiffness.mechanics.controller_stiffness import EIGENVALUE_MARGIN

#: ``eigvalsh`` of a symmetric matrix is accurate to this many ``eps |M|_2`` (LAPACK's bound is
#: a small multiple of n eps; at most 15 seen over 20,000 random 6x6 matrices).
ROUNDING_EPS = 64


def eigenvalue_rounding(M: np.ndarray) -> float:
    """The rounding of the eigenvalues computed from ``M``: ``ROUNDING_EPS eps |M|_2``."""
    return ROUNDING_EPS * float(np.finfo(np.float64).eps) * float(np.linalg.norm(M, 2))


def assert_eigenvalues_at_least(M: np.ndarray, floor: float) -> np.ndarray:
    """``eigvalsh(M).min() >= floor`` exactly (the promise as the subscriber checks it);
    returns the eigenvalues (ascending)."""
    eigenvalues = np.linalg.eigvalsh(M)
    assert eigenvalues.min() >= floor, (
        f'smallest eigenvalue {eigenvalues.min()!r} below the floor {floor!r} by '
        f'{floor - eigenvalues.min():.3g} (|M|_2 {np.linalg.norm(M, 2):.3g}): {eigenvalues}')
    return eigenvalues


def assert_eigenvalues_at_floor(M: np.ndarray, floor: float) -> np.ndarray:
    """:func:`assert_eigenvalues_at_least`, and the smallest eigenvalue is the floor itself: no
    higher than the floor plus the projection's margin and the rounding of ``eigvalsh``
    (a projection that clipped too high fails here). Returns the eigenvalues."""
    eigenvalues = assert_eigenvalues_at_least(M, floor)
    norm = float(np.linalg.norm(M, 2))
    ceiling = floor + EIGENVALUE_MARGIN * norm + eigenvalue_rounding(M)
    assert eigenvalues.min() <= ceiling, (
        f'smallest eigenvalue {eigenvalues.min()!r} above the floor {floor!r} by '
        f'{eigenvalues.min() - floor:.3g} (allowed: margin and rounding {ceiling - floor:.3g})')
    return eigenvalues
