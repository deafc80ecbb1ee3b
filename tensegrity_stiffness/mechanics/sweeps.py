"""Stiffness along an extensional displacement of the joint (Monke & Vikas, Figs. 4-5).

The paper plots the block Frobenius norms (eq. 19) and the column norms (eq. 20) of ``K`` "during
an extensional displacement of the tensegrity joint" from its unloaded equilibrium, without
defining the displacement. Here it is defined as follows:

* start: the unloaded equilibrium ``xi_0`` (``F(xi_0) = 0``, solved from the config's
  ``initial_screw`` with the given rest lengths), ``T_0 = exp(hat(xi_0)) = (R_0, p_0)``;
* direction: the unit vector ``d = p_0 / |p_0|`` from the origin of {1} to the origin of {2},
  i.e. the joint's axis (for the default sub-vertebra ``d = -y`` of {1}, the axis of the paper's
  compression test, Fig. 6). Moving along ``+d`` pulls the links apart and stretches the strings;
* path: link 2 translates by ``s d`` in {1} with its orientation held fixed,
  ``T(s) = (R_0, p_0 + s d)``, ``0 <= s <= extent`` (m).

Since ``v = G(omega)^-1 p`` (eq. 4), the path is the straight line
``xi(s) = xi_0 + s [0; G(omega_0)^-1 d]`` in screw coordinates, so the whole sweep is one batched
:meth:`~tensegrity_stiffness.mechanics.joint.JointModel.evaluate` (in chunks, to report progress).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import exp_se3, left_jacobian_so3_inverse
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel, JointState

FloatArray = NDArray[np.float64]
#: ``progress(done, total)``: called while a long computation runs.
ProgressCallback = Callable[[int, int], None]

#: Default number of samples along the sweep.
DEFAULT_SWEEP_SAMPLES = 201
#: Screws per progress report of the sweep.
SWEEP_CHUNK = 256
#: Default extent when the strings have no maximum length: this fraction of the mean rest length.
DEFAULT_EXTENT_FRACTION = 0.5
#: |p_0| (m) below which the origin of {2} gives no direction; the node centroids are used then.
MIN_AXIS_LENGTH = 1e-9


@dataclass(frozen=True, eq=False)
class ExtensionSweep:
    """Result of :func:`extension_sweep` (N samples).

    ``displacement`` (N,) m along ``direction`` (3,) (unit, in {1}); ``screws`` (N, 6);
    ``state`` the batched :class:`JointState`; ``block_norms`` (N, 4) Frobenius norms of
    [K_fw, K_fv, K_mw, K_mv] (eq. 19; N/rad, N/m, N m/rad, N); ``column_norms`` (N, 6) and
    ``row_norms`` (N, 6) (eq. 20); ``n_slack``, ``n_saturated`` (N,) string counts;
    ``rest_lengths`` (n,) m used.
    """

    displacement: FloatArray
    direction: FloatArray
    screws: FloatArray
    state: JointState
    block_norms: FloatArray
    column_norms: FloatArray
    row_norms: FloatArray
    n_slack: NDArray[np.int64]
    n_saturated: NDArray[np.int64]
    rest_lengths: FloatArray


def batched_interpretation(stiffness: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Block Frobenius norms (N, 4), column norms (N, 6) and row norms (N, 6) of (N, 6, 6) K.

    The same numbers as :func:`~tensegrity_stiffness.mechanics.interpretation.interpret_stiffness`
    (eqs. 19-20), for a whole batch in three array operations.
    """
    K = np.asarray(stiffness, dtype=np.float64)
    if K.ndim != 3 or K.shape[1:] != (6, 6):
        raise ValueError(f'stiffness must have shape (N, 6, 6), got {K.shape}')
    K2 = K * K
    blocks = np.sqrt(K2.reshape(-1, 2, 3, 2, 3).sum(axis=(2, 4)).reshape(-1, 4))
    return blocks, np.sqrt(K2.sum(axis=1)), np.sqrt(K2.sum(axis=2))


def extension_direction(model: JointModel, screw: ArrayLike) -> FloatArray:
    """Unit vector (3,) in {1} from the origin of {1} to the origin of {2} at ``screw``.

    If the origins coincide (within :data:`MIN_AXIS_LENGTH`), the direction from the centroid of
    the link-1 nodes to the centroid of the link-2 nodes is used instead.
    """
    T = exp_se3(screw)
    axis = T[:3, 3]
    if np.linalg.norm(axis) < MIN_AXIS_LENGTH:
        axis = (model.link2_nodes_in_link1(T).mean(axis=0) - model.link1_nodes.mean(axis=0))
    norm = float(np.linalg.norm(axis))
    if norm < MIN_AXIS_LENGTH:
        raise ValueError('the links have coincident origins and node centroids at the unloaded '
                         'equilibrium: the extension direction is undefined')
    return axis / norm


def default_extent(model: JointModel, rest_lengths: ArrayLike | None = None) -> float:
    """Default sweep extent (m): the smallest maximum stretch ``lmax - l0`` of the strings, or
    :data:`DEFAULT_EXTENT_FRACTION` of the mean rest length when no string has a maximum."""
    stretch = model.max_stretch[np.isfinite(model.max_stretch)]
    if stretch.size:
        return float(stretch.min())
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    return DEFAULT_EXTENT_FRACTION * float(rest.mean())


def extension_sweep(model: JointModel, extent: float | None = None,
                    samples: int = DEFAULT_SWEEP_SAMPLES,
                    rest_lengths: ArrayLike | None = None,
                    progress: ProgressCallback | None = None) -> ExtensionSweep:
    """K along the extensional displacement of the module docstring (Figs. 4-5).

    ``extent`` (m, > 0; default :func:`default_extent`), ``samples`` >= 2 evenly spaced
    displacements including 0 and ``extent``. Raises ValueError for bad input, when the unloaded
    equilibrium cannot be found, or when a string collapses to zero length on the path.
    """
    if isinstance(samples, bool) or int(samples) != samples or samples < 2:
        raise ValueError(f'samples must be an integer >= 2, got {samples}')
    samples = int(samples)
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    if extent is None:
        extent = default_extent(model, rest)
    extent = float(extent)
    if not (math.isfinite(extent) and extent > 0.0):
        raise ValueError(f'extent must be finite and > 0 m, got {extent}')
    eq = solve_equilibrium(model, np.zeros(6), rest)
    if not eq.success:
        raise ValueError(f'no unloaded equilibrium found from the initial screw: {eq.message}')
    x0 = eq.screw
    d = extension_direction(model, x0)
    rate = np.concatenate([np.zeros(3), left_jacobian_so3_inverse(x0[:3]) @ d])
    s = np.linspace(0.0, extent, samples)
    screws = x0 + s[:, None] * rate
    states = []
    for start in range(0, samples, SWEEP_CHUNK):
        states.append(model.evaluate(screws[start:start + SWEEP_CHUNK], rest))
        if progress is not None:
            progress(min(start + SWEEP_CHUNK, samples), samples)
    state = JointState(*(np.concatenate([getattr(st, f) for st in states])
                         for f in JointState.__dataclass_fields__))
    blocks, cols, rows = batched_interpretation(state.stiffness)
    return ExtensionSweep(s, d, screws, state, blocks, cols, rows,
                          state.slack.sum(axis=1), state.saturated.sum(axis=1), rest)
