"""The twin's sensors: the IMU of the last link (:class:`ImuReading`), the noise model of every
simulated sensor (:class:`SensorNoise`) and one noisy reading of them all (:func:`measure`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

if TYPE_CHECKING:  # types only: the twin returns these readings (no import circle)
    from tensegrity_stiffness.simulation.twin import ChainSimulation, JointSimulation

FloatArray = NDArray[np.float64]

@dataclass(frozen=True)
class ImuReading:
    """An IMU on a link at the origin of its frame, in that frame: ``angular_velocity``
    (rad/s) and ``specific_force`` (m/s^2, acceleration minus gravity: +g up at rest)."""

    angular_velocity: FloatArray
    specific_force: FloatArray


@dataclass(frozen=True)
class SensorNoise:
    """Standard deviations of the simulated sensors (white Gaussian noise; 0: exact):
    ``lengths`` (m), ``tensions`` (N), ``gyro`` (rad/s), ``accelerometer`` (m/s^2), and of a
    structure twin's ``encoders`` (m, the rest lengths in force) and ``markers`` (m, each
    coordinate of a node position). The one home of the twins' noise model (the sim nodes'
    parameters fill it)."""

    lengths: float = 0.0
    tensions: float = 0.0
    gyro: float = 0.0
    accelerometer: float = 0.0
    encoders: float = 0.0
    markers: float = 0.0

    def __post_init__(self) -> None:
        for name in ('lengths', 'tensions', 'gyro', 'accelerometer', 'encoders', 'markers'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ValueError(f'noise {name} must be a finite standard deviation >= 0, got '
                                 f'{value!r}')

    def add(self, values: ArrayLike, kind: str, rng: np.random.Generator) -> FloatArray:
        """``values`` plus noise of the sensor ``kind`` (a field name), drawn from ``rng``."""
        std = getattr(self, kind)
        arr = np.array(values, dtype=np.float64)
        return arr + rng.normal(0.0, std, arr.shape) if std > 0.0 else arr


@dataclass(frozen=True)
class Measurements:
    """One reading of every simulated sensor (with noise): ``lengths``, ``tensions`` (the
    simulation's shapes), ``imu`` (:class:`ImuReading`), ``time`` (s)."""

    lengths: FloatArray
    tensions: FloatArray
    imu: ImuReading
    time: float


def measure(simulation: JointSimulation | ChainSimulation, noise: SensorNoise,
            rng: np.random.Generator) -> Measurements:
    """Read the twin's sensors (string lengths, tensions, the IMU of link 2 / link N) and add
    ``noise`` drawn from ``rng`` (seeded by the caller: reproducible)."""
    imu = simulation.imu()
    return Measurements(
        noise.add(simulation.string_lengths(), 'lengths', rng),
        noise.add(simulation.tensions(), 'tensions', rng),
        ImuReading(noise.add(imu.angular_velocity, 'gyro', rng),
                   noise.add(imu.specific_force, 'accelerometer', rng)),
        simulation.time)
