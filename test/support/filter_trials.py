"""Seeded runs of the recursive filter on the MuJoCo twin: the joint driven by rest lengths
swept +-2 mm at 1-5 Hz and a swinging load, sensed every millisecond by 12 load cells and an
IMU (accelerometer and gyro) with the issue's noise; the truth (pose and twist) read from
MuJoCo. Shared by the twin tests of the filter and its bench."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from support.estimation_trials import TENSION_STD
from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.estimators import Measurements
from tensegrity_stiffness.estimation.joint_filter import JointFilter

#: Accelerometer (m/s^2) and gyro (rad/s) noise of a small MEMS IMU.
ACCELEROMETER_STD = 0.05
GYRO_STD = 0.005
#: The twin's step and the sensors' rate (s).
TIMESTEP = 1e-3
#: Rest lengths swept by at most this much (m), at frequencies drawn in this band (Hz).
SWEEP_AMPLITUDE = 2e-3
SWEEP_BAND = (1.0, 5.0)
#: The load swing: a force of this amplitude (N) turning at this frequency (Hz) plus a moment.
LOAD_FORCE = 0.05
LOAD_MOMENT = 0.001
LOAD_FREQUENCY = 0.5
#: Start of the samples (s, after the filter's start-up from the static estimator) and the
#: spacing of the NEES samples (s): longer than the filter's error correlation time.
BURN_IN = 0.3
SAMPLE_SPACING = 0.05


@dataclass
class Sample:
    """One sampled update: the pose and twist errors with their covariances' NEES."""

    time: float
    pose_nees: float
    twist_nees: float


@dataclass
class Run:
    """What one run gave: the samples, every update's ``consistent`` (clean updates), the
    outliers of each update and the updates that restarted."""

    samples: list[Sample] = field(default_factory=list)
    consistent: list[bool | None] = field(default_factory=list)
    outliers: list[tuple[float, tuple[str, ...]]] = field(default_factory=list)
    restarts: int = 0
    restart_times: list[float] = field(default_factory=list)


def twin_twist(simulation) -> np.ndarray:
    """The twin's twist of link 2 as the filter reports it, ``[dp/dt; w]`` in {1} (MuJoCo's
    free joint: linear velocity in the world, angular velocity in the body)."""
    qvel = np.asarray(simulation.mj_data.qvel)
    R = simulation.pose()[:3, :3]
    return np.concatenate([qvel[:3], R @ qvel[3:6]])


def readings(simulation, rng, fault: str | None = None, cell: int = 0) -> Measurements:
    """12 load cells and the IMU of the twin with noise; ``fault``: ``'load cell at -0.3 N'``,
    ``'load cell 0.8 N off'`` (load cell ``cell``) or ``'IMU flipped'``."""
    t = simulation.tensions() + rng.normal(scale=TENSION_STD, size=12)
    imu = simulation.imu()
    f = imu.specific_force + rng.normal(scale=ACCELEROMETER_STD, size=3)
    w = imu.angular_velocity + rng.normal(scale=GYRO_STD, size=3)
    if fault == 'load cell at -0.3 N':
        t[cell] = -0.3
    elif fault == 'load cell 0.8 N off':
        t[cell] += 0.8
    elif fault == 'IMU flipped':
        f = -f
    return Measurements(tensions=t, tension_std=TENSION_STD, specific_force=f,
                        specific_force_std=ACCELEROMETER_STD, angular_velocity=w,
                        angular_velocity_std=GYRO_STD)


def nees(error: np.ndarray, covariance: np.ndarray) -> float:
    return float(error @ np.linalg.solve(covariance, error))


def drive(model, seed: int, duration: float, fault: str | None = None,
          fault_time: float = math.inf, cell: int = 0, filter_kwargs: dict | None = None,
          joint_damping: float | None = None) -> Run:
    """One seeded run of ``duration`` s on a fresh twin: rest lengths swept (each string its
    own frequency in :data:`SWEEP_BAND`, amplitude up to :data:`SWEEP_AMPLITUDE`, from the
    rest lengths at rest under the initial load), the load swinging; ``fault`` from
    ``fault_time`` on. Samples every :data:`SAMPLE_SPACING` s after :data:`BURN_IN`.
    ``joint_damping``: the twin's damping of link 2 against the world (N s/m, N m s/rad),
    default the twin's (1e-3; JointDynamics has none: a model error the process noise
    covers)."""
    from tensegrity_stiffness.simulation.twin import (
        DEFAULT_TENDON_DAMPING,
        JointSimulation,
        SimulationOptions,
    )

    rng = np.random.default_rng(seed)
    sim = JointSimulation(model, None if joint_damping is None else
                          SimulationOptions(joint_damping=joint_damping))
    rest0 = model.rest_lengths.copy()
    n = rest0.size
    freq = rng.uniform(*SWEEP_BAND, size=n)
    sign = rng.choice([-1.0, 1.0], size=n)
    amp = rng.uniform(0.3, 1.0, size=n) * SWEEP_AMPLITUDE * sign
    load_phase = rng.uniform(0.0, 2.0 * math.pi)
    # the run starts at rest under its initial load (the sweep starts at the rest lengths)
    sim.apply_wrench([LOAD_FORCE * math.cos(load_phase), LOAD_FORCE * math.sin(load_phase),
                      0.0, 0.0, 0.0, LOAD_MOMENT * math.sin(load_phase)])
    assert sim.settle(1e-9, max_time=20.0)
    kwargs = {'string_damping': DEFAULT_TENDON_DAMPING, 'stiffness_std': False}
    kwargs.update(filter_kwargs or {})
    flt = JointFilter(model, **kwargs)
    run = Run()
    steps = round(duration / TIMESTEP)
    every = round(SAMPLE_SPACING / TIMESTEP)
    first = round(BURN_IN / TIMESTEP)
    for k in range(steps):
        t0 = k * TIMESTEP
        rest = rest0 + amp * np.sin(2.0 * math.pi * freq * t0)
        a = 2.0 * math.pi * LOAD_FREQUENCY * t0 + load_phase
        sim.set_rest_lengths(rest)
        sim.apply_wrench([LOAD_FORCE * math.cos(a), LOAD_FORCE * math.sin(a), 0.0,
                          0.0, 0.0, LOAD_MOMENT * math.sin(a)])
        sim.step(1)
        t = (k + 1) * TIMESTEP
        faulty = fault if t >= fault_time else None
        est = flt.step(t, readings(sim, rng, faulty, cell), rest)
        assert est.success, est.message
        if est.restarted:
            run.restarts += 1
            run.restart_times.append(t)
        if faulty is None:
            run.consistent.append(est.consistent)
        run.outliers.append((t, est.outliers))
        if k >= first and (k - first) % every == 0 and faulty is None:
            e = sm.pose_error(est.transform, sim.pose())
            d = est.twist - twin_twist(sim)
            run.samples.append(Sample(t, nees(e, est.covariance),
                                      nees(d, est.twist_covariance)))
    return run
