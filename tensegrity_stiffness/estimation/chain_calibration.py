"""The spine's calibration (:func:`calibrate_chain`): each joint calibrated from the spine's
samples (:class:`ChainCalibrationSample`) with the loads the joints above it carry.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation.calibration_results import CalibrationResult
from tensegrity_stiffness.estimation.calibration_samples import (
    RECORDED_ROTATION_TOLERANCE,
    CalibrationNoise,
    CalibrationSample,
)
from tensegrity_stiffness.estimation.joint_calibration import calibrate_joint
from tensegrity_stiffness.geometry.transforms import adjoint, rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array

FloatArray = NDArray[np.float64]

# ------------------------------------------------------------------------------ spines
@dataclass(frozen=True)
class ChainCalibrationSample:
    """One quasi-static instant of a spine (N joints, n strings each).

    ``rest_lengths`` (N, n) commanded per joint; ``link_poses`` (N, 4, 4) or (N, 7): the
    measured pose of every link {2}_i in the base; ``tip_wrench`` (6,) the load on link N in the
    base about its origin (None when unknown, zeros when unloaded); ``tensions`` (N, n) N, NaN
    where none.
    """

    rest_lengths: ArrayLike
    link_poses: ArrayLike
    tip_wrench: ArrayLike | None = None
    tensions: ArrayLike | None = None


def _chain_joint_samples(chain: Any, samples: Sequence[ChainCalibrationSample], noise:
                         CalibrationNoise) -> tuple[list[list[CalibrationSample]],
                                                    list[CalibrationNoise]]:
    """Per joint: samples in the joint's own frames (relative pose, load moved into {1}_i) and
    the relative pose's noise."""

    N = chain.n_joints
    per_joint: list[list[CalibrationSample]] = [[] for _ in range(N)]
    spans = np.zeros(N)
    arms = np.zeros(N)
    g = chain.gravity
    weights = chain.has_weights(g)
    for s_index, s in enumerate(samples):
        where = f'samples[{s_index}]'
        raw = finite_array(f'{where}.link_poses', s.link_poses)
        if raw.shape not in ((N, 4, 4), (N, 7)):
            raise ValueError(f'{where}.link_poses must have shape ({N}, 4, 4) or ({N}, 7), got '
                             f'{raw.shape}')
        L = np.array([rigid_transform(p, f'{where}.link_poses[{i}]', RECORDED_ROTATION_TOLERANCE)
                      for i, p in enumerate(raw)])
        P = np.empty_like(L)
        P[0] = np.eye(4)
        for i in range(1, N):
            P[i] = L[i - 1] @ chain.link_offsets[i - 1]
        rest = finite_array(f'{where}.rest_lengths', s.rest_lengths)
        if rest.ndim != 2 or rest.shape[0] != N:
            raise ValueError(f'{where}.rest_lengths must have one row per joint ({N}), got '
                             f'shape {rest.shape}')
        tensions = None if s.tensions is None else np.asarray(s.tensions, dtype=np.float64)
        loads = None
        if s.tip_wrench is not None:
            W = finite_array(f'{where}.tip_wrench', s.tip_wrench)
            if W.shape != (6,):
                raise ValueError(f'{where}.tip_wrench must have shape (6,), got {W.shape}')
            B = np.broadcast_to(W, (N, 6))
            if weights:
                w, _ = chain.link_weights(L, g)
                B = W + np.cumsum(w[::-1], axis=0)[::-1]
            loads = (np.swapaxes(adjoint(P), 1, 2) @ B[:, :, None])[:, :, 0]
        for i in range(N):
            T = np.linalg.solve(P[i], L[i])
            spans[i] = max(spans[i], float(np.linalg.norm(L[i][:3, 3] - P[i][:3, 3])))
            arms[i] = max(arms[i], float(np.linalg.norm(P[i][:3, 3])))
            per_joint[i].append(CalibrationSample(
                rest[i], pose=T, tensions=None if tensions is None else tensions[i],
                external_wrench=None if loads is None else loads[i]))
    noises = [noise]
    for i in range(1, N):
        # Two measured poses: sqrt(2) their noise, plus link i-1's rotation noise acting on
        # the distance between the frames; the load's force noise acting on the arm from the
        # base origin to {1}_i (isotropic, first order).
        position = math.sqrt(2.0 * noise.position ** 2
                             + (2.0 / 3.0) * (spans[i] * noise.rotation) ** 2)
        moment = math.sqrt(noise.moment ** 2 + (2.0 / 3.0) * (arms[i] * noise.force) ** 2)
        noises.append(CalibrationNoise(position=position, rotation=math.sqrt(2.0) * noise.rotation,
                                       force=noise.force, moment=moment,
                                       tension=noise.tension, length=noise.length))
    return per_joint, noises


def calibrate_chain(chain: Any, samples: Sequence[ChainCalibrationSample],
                    fit: Sequence[str] | str = ('stiffness', 'rest_length_offsets'),
                    noise: CalibrationNoise | Mapping[str, float] | None = None,
                    loss: str = 'soft_l1') -> list[CalibrationResult]:
    """Calibrate every joint of a spine
    (:class:`~tensegrity_stiffness.mechanics.chain.JointChain`) from
    recordings with every link's pose: joint i is fitted by :func:`calibrate_joint` to the
    pose of {2}_i in {1}_i (``P_i^-1 L_i``, ``P_i = L_{i-1} O_{i-1}``) and to the load it
    carries moved into {1}_i, ``Ad_{P_i}^T (W + sum_{k >= i} w_k)`` (the chain's link weights
    ``w_k`` at the measured poses; :mod:`tensegrity_stiffness.mechanics.chain`). A relative pose
    carries
    the noise of two measured poses: its std is taken as ``sqrt(2)`` times the rotation noise
    and ``sqrt(2 sp^2 + 2/3 (d sr)^2)`` in position (``d`` the largest distance between the two
    frames), and the moved load's moment noise as ``sqrt(sm^2 + 2/3 (a sf)^2)`` (``a`` the
    largest distance of {1}_i from the base origin); the correlation between neighbouring joints
    (they share a link's pose) is left out. One :class:`CalibrationResult` per joint."""
    noise = CalibrationNoise.of(noise)
    per_joint, noises = _chain_joint_samples(chain, samples, noise)
    return [calibrate_joint(model, joint_samples, fit=fit, noise=joint_noise, loss=loss)
            for model, joint_samples, joint_noise in zip(chain.joints, per_joint, noises,
                                                         strict=True)]
