"""A Cartesian stiffness in the form a controller takes: its frame, symmetric, positive definite,
bounded, smooth, and laid out as the controller reads it. numpy only (no ROS import).

``K_c`` of a joint (``JointModel``: ``K_c = -dF/d[dv; dw]``, rows ``[f; m]`` about the origin of
{1}, columns a spatial twist of {1}, linear first) or of a spine's tip (``~/tip_stiffness``) is
symmetric only at an unloaded equilibrium, and indefinite where the configuration is unstable.
An impedance or admittance controller needs a symmetric positive definite matrix in its own frame
that changes smoothly. The steps, in the order :class:`Conditioner` applies them:

1. :func:`transform_cartesian_stiffness`: into the controller's frame C,
   ``K_C = Ad_T^T K Ad_T`` (a congruence: symmetry and definiteness are kept);
2. :func:`symmetric_part`, then :func:`nearest_positive_definite` (eigenvalues clipped to a floor:
   the nearest such matrix in the Frobenius norm, Higham 1988);
3. a scale, then :func:`clamp` (eigenvalues of the two diagonal 3x3 blocks);
4. :class:`LowPass` (first order, per entry: a convex combination of positive definite matrices
   is positive definite) and, in the node, a rate limit;
5. :func:`to_layout`: ``row_major_36``, ``column_major_36`` or ``diagonal_6``.

Nothing here hides an unstable joint: :class:`Conditioned` reports the input's smallest eigenvalue
of the symmetric part and how far the projection moved the matrix.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.transforms import adjoint, rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array

FloatArray = NDArray[np.float64]

__all__ = [
    'EIGENVALUE_MARGIN',
    'LAYOUTS',
    'LAYOUT_SIZES',
    'Conditioned',
    'Conditioner',
    'LowPass',
    'clamp',
    'diagonal',
    'from_layout',
    'moved_beyond',
    'nearest_positive_definite',
    'stiffness_matrix',
    'symmetric_part',
    'to_layout',
    'transform_cartesian_stiffness',
]

#: The layouts controllers read: 36 values row-major (crisp_controllers' full form), 36 values
#: column-major (Franka stacks: Eigen's default storage), the 6 diagonal values.
LAYOUTS = ('row_major_36', 'column_major_36', 'diagonal_6')
LAYOUT_SIZES = {'row_major_36': 36, 'column_major_36': 36, 'diagonal_6': 6}

#: Margin of the eigenvalue floor, relative to the result's size ``|X|_2``: the projection clips
#: at ``floor + EIGENVALUE_MARGIN |X|_2`` (and keeps a matrix whose smallest eigenvalue is at least
#: half that margin above the floor), so that the eigenvalues a subscriber computes from the values
#: sent (``numpy.linalg.eigvalsh``: accurate to a few ``eps |X|_2``; the reconstruction
#: ``V diag V^T`` and its symmetrisation add as much; at most 15 eps |X|_2 seen over 20,000 random
#: matrices) are ``>= floor``, as documented. 64 n eps with n = 6: ``8.5e-14 |X|_2``, 3.5e-10 for
#: a stiffness of 4e3, far below any floor a controller uses.
EIGENVALUE_MARGIN = 64 * 6 * float(np.finfo(np.float64).eps)


def stiffness_matrix(K: ArrayLike, name: str = 'K') -> FloatArray:
    """``K`` as a finite (6, 6) float array (a copy); ValueError naming ``name`` otherwise."""
    arr = finite_array(name, K)
    if arr.shape != (6, 6):
        raise ValueError(f'{name} must be a 6x6 matrix, got shape {arr.shape}')
    return np.array(arr, dtype=np.float64)


def symmetric_part(K: ArrayLike) -> FloatArray:
    """``(K + K^T) / 2``: the part of ``K`` a potential (a spring) has; the rest, the skew
    part, is the circulatory stiffness of a loaded or non-conservative configuration."""
    K = stiffness_matrix(K)
    return 0.5 * (K + K.T)


def nearest_positive_definite(K: ArrayLike, min_eigenvalue: float = 0.0
                              ) -> tuple[FloatArray, float]:
    """The nearest symmetric matrix to ``K`` (Frobenius norm) whose eigenvalues are all
    ``>= min_eigenvalue``, and the Frobenius norm of the change from ``K``.
    The eigenvalues are clipped at ``min_eigenvalue`` plus the rounding margin
    :data:`EIGENVALUE_MARGIN` ``|X|_2``, so that they are ``>= min_eigenvalue`` also as computed
    from the result.

    Proof of minimality (Higham, Linear Algebra Appl. 103, 1988): symmetric and skew matrices are
    orthogonal, so for symmetric X ``|X - K|^2 = |X - S|^2 + |K - S|^2`` with ``S`` the symmetric
    part; ``X - m I`` is positive semidefinite, and the nearest such matrix to ``S - m I`` clips
    its eigenvalues at 0. So ``X = V max(lambda, m) V^T`` with ``S = V diag(lambda) V^T``. A
    matrix whose eigenvalues are already above the floor (by half the margin) is returned as its
    symmetric part (idempotent: a result passes again unchanged).
    """
    K = stiffness_matrix(K)
    m = float(min_eigenvalue)
    if not math.isfinite(m) or m < 0.0:
        raise ValueError(f'min_eigenvalue must be finite and >= 0, got {min_eigenvalue}')
    S = 0.5 * (K + K.T)
    eigenvalues, vectors = np.linalg.eigh(S)
    X = _eigenvalues_clipped(S, eigenvalues, vectors, m)
    return X, float(np.linalg.norm(X - K))


def _eigenvalues_clipped(S: FloatArray, eigenvalues: FloatArray, vectors: FloatArray,
                         floor: float) -> FloatArray:
    """``S`` (symmetric, ``S = V diag(eigenvalues) V^T``, ascending) with its eigenvalues clipped
    below at ``floor + EIGENVALUE_MARGIN |X|_2`` (``|X|_2 = max(largest eigenvalue, floor)``,
    the size of the result, which sets the rounding of its eigenvalues); ``S`` itself when none
    is below ``floor`` plus half that margin (so that a result, whose eigenvalues come out within
    rounding of the clip, passes a second time unchanged)."""
    margin = EIGENVALUE_MARGIN * max(float(eigenvalues[-1]), floor)  # |result|_2
    if eigenvalues[0] >= floor + 0.5 * margin:
        return S
    X = (vectors * np.maximum(eigenvalues, floor + margin)) @ vectors.T
    return 0.5 * (X + X.T)


def transform_cartesian_stiffness(K_c: ArrayLike, T: ArrayLike) -> FloatArray:
    """``K_c`` (rows ``[f; m]`` about the origin of frame A, columns ``[dv; dw]`` a spatial
    twist of A) expressed in frame C whose pose in A is ``T`` ((4, 4) or ``[x y z qx qy qz qw]``):
    rows the wrench in C's coordinates about C's origin, columns a twist in C's coordinates.

    A twist ``d_C`` of C is the twist ``Ad_T d_C`` of A (``Ad_T = [[R, hat(p) R], [0, R]]``),
    a wrench ``W_A`` is ``Ad_T^T W_A`` in C, so ``K_C = Ad_T^T K_c Ad_T``: a congruence, which
    keeps symmetry and the signs of the eigenvalues (Sylvester's law of inertia). C is a fixed
    frame (its pose does not move with the displacement).
    """
    K = stiffness_matrix(K_c, 'K_c')
    Ad = adjoint(rigid_transform(T, 'pose'))
    return Ad.T @ K @ Ad


def diagonal(K: ArrayLike) -> FloatArray:
    """The 6 diagonal values ``[kx ky kz krx kry krz]`` (what a diagonal controller reads)."""
    return np.diag(stiffness_matrix(K)).copy()


def _clamped_block(B: FloatArray, bounds: tuple[float, float]) -> tuple[FloatArray, bool]:
    eigenvalues, vectors = np.linalg.eigh(0.5 * (B + B.T))
    clipped = np.clip(eigenvalues, bounds[0], bounds[1])
    if np.array_equal(clipped, eigenvalues):
        return B, False
    out = (vectors * clipped) @ vectors.T
    return 0.5 * (out + out.T), True


def _normalised_coupling(A: FloatArray, B: FloatArray, C: FloatArray) -> float:
    """``|A^-1/2 C B^-1/2|_2`` for positive definite A, B (< 1 iff [[A, C], [C^T, B]] is
    positive definite); 1.0 when A or B is not positive definite."""
    a, Va = np.linalg.eigh(A)
    b, Vb = np.linalg.eigh(B)
    if a[0] <= 0.0 or b[0] <= 0.0:
        return 1.0
    Ai = (Va / np.sqrt(a)) @ Va.T
    Bi = (Vb / np.sqrt(b)) @ Vb.T
    return float(np.linalg.norm(Ai @ C @ Bi, 2))


def _bounds(name: str, value: tuple[float, float] | None) -> tuple[float, float] | None:
    if value is None:
        return None
    if len(value) != 2:
        raise ValueError(f'{name} must be (min, max), got {value!r}')
    lo, hi = float(value[0]), float(value[1])
    if not (math.isfinite(lo) and lo >= 0.0 and hi >= lo) or math.isnan(hi):
        raise ValueError(f'{name} must be (min, max) with 0 <= min <= max, got {value!r}')
    return lo, hi


def clamp(K: ArrayLike, translational: tuple[float, float] | None = None,
          rotational: tuple[float, float] | None = None
          ) -> tuple[FloatArray, dict[str, bool]]:
    """``K`` (symmetric) with the eigenvalues of its translational block ``K[:3, :3]`` clipped
    to ``translational = (min, max)`` and of its rotational block ``K[3:, 3:]`` to
    ``rotational`` (None: that block is left alone), and which clamps acted.

    Clamping acts on the blocks' eigenvalues, not on entries, so it does not depend on the
    orientation of the frame; it bounds every diagonal entry of the block too (a Rayleigh
    quotient). The coupling block ``K[:3, 3:]`` is scaled down when needed so that its
    normalised size ``|A^-1/2 C B^-1/2|_2`` does not grow: a positive definite ``K`` stays
    positive definite (``coupling_scaled`` says when it acted).
    """
    K = stiffness_matrix(K)
    translational = _bounds('translational', translational)
    rotational = _bounds('rotational', rotational)
    A, B, C = K[:3, :3], K[3:, 3:], K[:3, 3:]
    hit = {'translational': False, 'rotational': False, 'coupling_scaled': False}
    A2, B2 = A, B
    if translational is not None:
        A2, hit['translational'] = _clamped_block(A, translational)
    if rotational is not None:
        B2, hit['rotational'] = _clamped_block(B, rotational)
    if not (hit['translational'] or hit['rotational']):
        return K, hit
    before = _normalised_coupling(A, B, C)
    after = _normalised_coupling(A2, B2, C)
    C2 = C
    if after > before:
        C2 = C * (before / after)
        hit['coupling_scaled'] = True
    out = np.block([[A2, C2], [C2.T, B2]])
    return out, hit


def to_layout(K: ArrayLike, layout: str) -> FloatArray:
    """The values a controller reads: ``row_major_36`` (``K[i, j]`` at ``6 i + j``),
    ``column_major_36`` (at ``i + 6 j``) or ``diagonal_6``."""
    K = stiffness_matrix(K)
    if layout == 'row_major_36':
        return K.ravel(order='C')
    if layout == 'column_major_36':
        return K.ravel(order='F')
    if layout == 'diagonal_6':
        return np.diag(K).copy()
    raise ValueError(f'layout must be one of {" | ".join(LAYOUTS)}, got {layout!r}')


def from_layout(values: ArrayLike, layout: str) -> FloatArray:
    """The (6, 6) matrix of values in ``layout`` (``diagonal_6``: a diagonal matrix)."""
    if layout not in LAYOUTS:
        raise ValueError(f'layout must be one of {" | ".join(LAYOUTS)}, got {layout!r}')
    v = finite_array('values', values).ravel()
    if v.size != LAYOUT_SIZES[layout]:
        raise ValueError(f'{layout} takes {LAYOUT_SIZES[layout]} values, got {v.size}')
    if layout == 'diagonal_6':
        return np.diag(v)
    return v.reshape(6, 6, order='C' if layout == 'row_major_36' else 'F').copy()


def moved_beyond(new: ArrayLike, sent: ArrayLike | None, deadband: float) -> bool:
    """True when a value of ``new`` differs from ``sent`` by more than ``deadband`` relative to
    the larger of the two magnitudes (always true with nothing sent yet)."""
    if sent is None:
        return True
    new = np.asarray(new, dtype=np.float64)
    sent = np.asarray(sent, dtype=np.float64)
    if new.shape != sent.shape:
        return True
    scale = np.maximum(np.abs(new), np.abs(sent))
    return bool(np.any(np.abs(new - sent) > deadband * scale))


@dataclass(frozen=True)
class Conditioned:
    """One conditioned stiffness: ``matrix`` (6, 6, symmetric positive definite in the
    controller's frame, scaled and clamped), ``projection_distance`` (Frobenius norm of the change
    the projection made, after the frame change), ``relative_projection`` (that over ``|K|``),
    ``input_min_eigenvalue`` (smallest eigenvalue of the symmetric part of the input in the
    controller's frame: < 0 means the joint is unstable there), ``asymmetry`` (``|K - K^T| /
    |K|``), ``clamps`` (which clamps acted)."""

    matrix: FloatArray
    projection_distance: float
    relative_projection: float
    input_min_eigenvalue: float
    asymmetry: float
    clamps: dict[str, bool] = field(default_factory=dict)

    @property
    def input_positive_definite(self) -> bool:
        return self.input_min_eigenvalue > 0.0


@dataclass(frozen=True)
class Conditioner:
    """Steps 1-3 of the module docstring with fixed settings: ``pose`` of the controller's frame
    in the input's frame (None: the same frame), ``min_eigenvalue`` floor, ``scale`` (> 0),
    ``translational`` / ``rotational`` eigenvalue bounds (None: no clamp)."""

    pose: FloatArray | None = None
    min_eigenvalue: float = 0.0
    scale: float = 1.0
    translational: tuple[float, float] | None = None
    rotational: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.pose is not None:
            object.__setattr__(self, 'pose', rigid_transform(self.pose, 'pose'))
        if not (math.isfinite(self.scale) and self.scale > 0.0):
            raise ValueError(f'scale must be finite and > 0, got {self.scale}')
        if not (math.isfinite(self.min_eigenvalue) and self.min_eigenvalue >= 0.0):
            raise ValueError(f'min_eigenvalue must be finite and >= 0, got {self.min_eigenvalue}')
        object.__setattr__(self, 'translational', _bounds('translational', self.translational))
        object.__setattr__(self, 'rotational', _bounds('rotational', self.rotational))
        # Ad_T once: apply() is on a 1 kHz path
        object.__setattr__(self, '_adjoint', None if self.pose is None else adjoint(self.pose))

    def apply(self, K: ArrayLike) -> Conditioned:
        """The conditioned stiffness of the input ``K`` (ValueError: not 6x6, not finite, or so
        large that its conditioning overflows).
        The steps of :func:`transform_cartesian_stiffness` and
        :func:`nearest_positive_definite`, with one eigen-decomposition for the projection and
        the report."""
        K = stiffness_matrix(K)
        largest = float(np.abs(K).max())
        with np.errstate(over='ignore', invalid='ignore'):  # overflow: refused below
            Ad = self._adjoint
            if Ad is not None:
                K = Ad.T @ K @ Ad
            S = 0.5 * (K + K.T)
            norm = math.sqrt(float(np.vdot(K, K)))
            if not math.isfinite(norm):
                raise ValueError(f'K is too large to condition: its norm overflows (largest '
                                 f'|entry| {largest:.3g})')
            eigenvalues, vectors = np.linalg.eigh(S)
            projected = _eigenvalues_clipped(S, eigenvalues, vectors, self.min_eigenvalue)
            D = projected - K
            distance = math.sqrt(float(np.vdot(D, D)))
            A = K - K.T
            asymmetry = math.sqrt(float(np.vdot(A, A)))
            out = projected * self.scale if self.scale != 1.0 else projected
            if not (np.all(np.isfinite(out)) and math.isfinite(distance)):
                raise ValueError(f'K is too large to condition: the result overflows (largest '
                                 f'|entry| {largest:.3g}, output.scale {self.scale:g})')
        clamps = {'translational': False, 'rotational': False, 'coupling_scaled': False}
        if self.translational is not None or self.rotational is not None:
            out, clamps = clamp(out, self.translational, self.rotational)
        return Conditioned(
            matrix=out, projection_distance=distance,
            relative_projection=distance / norm if norm > 0.0 else 0.0,
            input_min_eigenvalue=float(eigenvalues[0]),
            asymmetry=asymmetry / norm if norm > 0.0 else 0.0, clamps=clamps)


class LowPass:
    """First-order low-pass of matrices, ``tau dy/dt = x - y``, each input ``x`` held from its
    arrival until the next one (the exact solution: ``y <- x_held + (y - x_held) exp(-dt /
    tau)`` up to each update, then the new input is held; ``tau = 0``: ``y = x``). Each output is
    a convex combination of the inputs so far, so it stays symmetric positive definite when they
    are."""

    def __init__(self, time_constant: float) -> None:
        self.time_constant = float(time_constant)
        if not (math.isfinite(self.time_constant) and self.time_constant >= 0.0):
            raise ValueError(f'time_constant must be finite and >= 0, got {time_constant}')
        self.value: FloatArray | None = None
        self.target: FloatArray | None = None
        self._time: float | None = None

    def update(self, x: ArrayLike | None, now: float) -> FloatArray:
        """The output at time ``now`` (s, monotonic); then ``x`` (None: no new input) is held
        from ``now`` on. The first input is taken as it is."""
        new = None if x is None else np.array(x, dtype=np.float64)
        if self.value is None or self._time is None or self.time_constant == 0.0:
            if new is None and self.target is None:
                raise ValueError('the low-pass has no input yet')
            if new is not None:
                self.target = new
            self.value = self.target.copy()
        else:
            dt = max(0.0, now - self._time)
            self.value = self.target + (self.value - self.target) * math.exp(
                -dt / self.time_constant)
            if new is not None:
                self.target = new
        self._time = now
        return self.value

    def settled(self, relative: float = 1e-9) -> bool:
        """True when the output equals the held input within ``relative`` of its size."""
        if self.value is None or self.target is None:
            return True
        scale = float(np.abs(self.target).max()) or 1.0
        return float(np.abs(self.value - self.target).max()) <= relative * scale

    def reset(self) -> None:
        self.value = self.target = self._time = None
