"""What a calibration reads: its samples (:class:`CalibrationSample`: rest lengths and any of a
pose or screw, a wrench, tensions and lengths), the noise of each reading
(:class:`CalibrationNoise`) and the samples checked once into arrays
(:class:`CalibrationData`). The method is in :mod:`~tensegrity_stiffness.estimation.calibration`.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.special import chdtri

from tensegrity_stiffness.geometry.screw import (
    exp_se3,
    single_screw,
)
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array, finite_scalar, per_string
from tensegrity_stiffness.mechanics.joint import JointModel

FloatArray = NDArray[np.float64]

#: Known loads measure a force when their chi-square has this upper-tail probability or less.
SCALE_TEST_PROBABILITY = 1e-3
#: Largest max-abs deviation of R^T R from I accepted in a recorded (4, 4) pose (poses read
#: from recordings carry the rounding of their source).
RECORDED_ROTATION_TOLERANCE = 1e-6
#: Residual kinds (rows of a sample: pose 6, wrench 6, tensions n, lengths n) and their units.
RESIDUAL_KINDS = ('position', 'rotation', 'force', 'moment', 'tension', 'length')
RESIDUAL_UNITS = {'position': 'm', 'rotation': 'rad', 'force': 'N', 'moment': 'N m',
                  'tension': 'N', 'length': 'm'}


@dataclass(frozen=True)
class CalibrationNoise:
    """Standard deviation of each measurement kind (the defaults: a motion-capture system, a
    six-axis force-torque sensor, inline load cells, string encoders)."""

    position: float = 1e-4          # m (0.1 mm)
    rotation: float = math.radians(0.1)  # rad (0.1 deg)
    force: float = 0.01             # N
    moment: float = 5e-4            # N m
    tension: float = 0.005          # N
    length: float = 1e-4            # m

    def __post_init__(self) -> None:
        for kind in RESIDUAL_KINDS:
            value = finite_scalar(f'noise.{kind}', getattr(self, kind))
            if value < 0.0 or (value == 0.0 and kind not in ('force', 'moment')):
                raise ValueError(f'noise.{kind} must be > 0, got {value}')
        if (self.force == 0.0) != (self.moment == 0.0):
            raise ValueError('noise.force and noise.moment must both be 0 (the known loads are '
                             f'exact) or both > 0, got {self.force} and {self.moment}')

    @property
    def exact_loads(self) -> bool:
        """Whether the known loads are exact (force and moment noise 0): each is a constraint
        on its sample's screw, not a reading."""
        return self.force == 0.0

    @classmethod
    def of(cls, noise: CalibrationNoise | Mapping[str, float] | None) -> CalibrationNoise:
        """``noise`` as a :class:`CalibrationNoise` (a mapping overrides the defaults it
        names; ``pose`` sets position (m) and ``wrench`` force (N) for short)."""
        if noise is None:
            return cls()
        if isinstance(noise, CalibrationNoise):
            return noise
        values = dict(noise)
        if 'pose' in values:
            values.setdefault('position', values.pop('pose'))
        if 'wrench' in values:
            values.setdefault('force', values.pop('wrench'))
        unknown = sorted(set(values) - set(RESIDUAL_KINDS))
        if unknown:
            raise ValueError(f'noise: unknown kinds {unknown} '
                             f'(known: {", ".join(RESIDUAL_KINDS)})')
        return cls(**{k: float(v) for k, v in values.items()})

    def row_std(self, n: int) -> FloatArray:
        """Std of every residual row of a sample: pose (6), wrench (6), tensions (n),
        lengths (n)."""
        return np.concatenate([np.full(3, self.position), np.full(3, self.rotation),
                               np.full(3, self.force), np.full(3, self.moment),
                               np.full(n, self.tension), np.full(n, self.length)])


@dataclass(frozen=True)
class CalibrationSample:
    """One quasi-static instant of a recording.

    ``rest_lengths`` (n,) m: the commanded values (encoders); ``pose``: link 2 in {1} measured by
    motion capture, (4, 4) or ``[x y z qx qy qz qw]``; ``screw`` (6,): the same as a screw (give
    one of the two); ``tensions`` (n,) N from load cells, NaN where none; ``lengths`` (n,) m
    measured string lengths, NaN where none; ``external_wrench`` (6,) a force-torque reading on
    link 2 in the library's convention ([N; N m], in {1} about its origin): None when unknown,
    zeros when unloaded.
    """

    rest_lengths: ArrayLike
    pose: ArrayLike | None = None
    screw: ArrayLike | None = None
    tensions: ArrayLike | None = None
    lengths: ArrayLike | None = None
    external_wrench: ArrayLike | None = None


@dataclass
class CalibrationData:
    """The samples as arrays (N samples, n strings); absent measurements NaN / masked."""

    rest: FloatArray            # (N, n) commanded
    poses: FloatArray           # (N, 4, 4), NaN where no pose
    has_pose: NDArray[np.bool_]
    wrench: FloatArray          # (N, 6), 0 where unknown
    has_wrench: NDArray[np.bool_]
    tensions: FloatArray        # (N, n) NaN where none
    lengths: FloatArray         # (N, n) NaN where none

    @property
    def n_samples(self) -> int:
        return self.rest.shape[0]

    def mask(self) -> NDArray[np.bool_]:
        """(N, 12 + 2n) rows that carry a measurement."""
        return np.hstack([np.repeat(self.has_pose[:, None], 6, axis=1),
                          np.repeat(self.has_wrench[:, None], 6, axis=1),
                          np.isfinite(self.tensions), np.isfinite(self.lengths)])


def samples_data(model: JointModel, samples: Sequence[CalibrationSample]) -> CalibrationData:
    """Validate the samples (ValueError naming ``samples[i].field``) into arrays."""
    n = model.n_strings
    N = len(samples)
    rest = np.empty((N, n))
    poses = np.full((N, 4, 4), np.nan)
    has_pose = np.zeros(N, bool)
    wrench = np.zeros((N, 6))
    has_wrench = np.zeros(N, bool)
    tensions = np.full((N, n), np.nan)
    lengths = np.full((N, n), np.nan)
    for i, s in enumerate(samples):
        where = f'samples[{i}]'
        if not isinstance(s, CalibrationSample):
            raise ValueError(f'{where} is not a CalibrationSample')
        rest[i] = per_string(f'{where}.rest_lengths', s.rest_lengths, n)
        if np.any(rest[i] <= 0.0):
            raise ValueError(f'{where}.rest_lengths must be > 0')
        if s.pose is not None and s.screw is not None:
            raise ValueError(f'{where}: give pose or screw, not both')
        if s.pose is not None:
            poses[i] = rigid_transform(s.pose, f'{where}.pose', RECORDED_ROTATION_TOLERANCE)
            has_pose[i] = True
        elif s.screw is not None:
            poses[i] = exp_se3(single_screw(s.screw, f'{where}.screw', in_chart=False))
            has_pose[i] = True
        tensions[i] = per_string(f'{where}.tensions', s.tensions, n, not_measured=True)
        lengths[i] = per_string(f'{where}.lengths', s.lengths, n, not_measured=True)
        if s.external_wrench is not None:
            w = finite_array(f'{where}.external_wrench', s.external_wrench)
            if w.shape != (6,):
                raise ValueError(f'{where}.external_wrench must have shape (6,), got {w.shape}')
            wrench[i] = w
            has_wrench[i] = True
    return CalibrationData(rest, poses, has_pose, wrench, has_wrench, tensions, lengths)


# ------------------------------------------------------------------------------ the fit
def measures_force(data: CalibrationData, noise: CalibrationNoise,
                   probability: float = SCALE_TEST_PROBABILITY) -> bool:
    """Whether the samples measure a force: a load cell, an exact load other than zero, or
    noisy known loads that differ from zero beyond their noise (their whitened chi-square
    exceeds its ``1 - probability`` quantile; zeros are exact, "unloaded"). Without one, the
    common scale of the stiffnesses is unidentifiable: ``F(c k) = c F(k)`` and ``F = -W = 0`` at
    every sample, whatever ``c``."""
    if np.isfinite(data.tensions).any():
        return True
    loads = data.wrench[data.has_wrench]
    loads = loads[np.any(loads != 0.0, axis=1)]
    if loads.size == 0:
        return False
    if noise.exact_loads:
        return True
    std = np.concatenate([np.full(3, noise.force), np.full(3, noise.moment)])
    return float(np.sum((loads / std) ** 2)) > chdtri(loads.size, probability)
