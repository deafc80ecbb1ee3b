"""Seeded Monte Carlo trials of the estimator: true configurations, simulated sensors with the
issue's typical noise, and the NEES of the pose. Shared by the estimation tests (the forward
model's sensors) and the twin tests (the MuJoCo twin's)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import chi2

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.estimators import Measurements, estimate_joint_state
from tensegrity_stiffness.geometry.screw import exp_so3

#: Typical sensor noise (issue 23): load cells (N), string lengths (m), gravity direction (unit
#: vector components), motion capture (m, rad), force-torque (N, N m).
TENSION_STD = 0.005
LENGTH_STD = 1e-4
GRAVITY_STD = 0.01
POSE_POSITION_STD = 1e-4
POSE_ANGLE_STD = math.radians(0.1)
FORCE_STD = 0.01
MOMENT_STD = 0.0005
POSE_COVARIANCE = np.diag([POSE_POSITION_STD ** 2] * 3 + [POSE_ANGLE_STD ** 2] * 3)
WRENCH_COVARIANCE = np.diag([FORCE_STD ** 2] * 3 + [MOMENT_STD ** 2] * 3)
#: Four load cells well spread over the default joint (cross_AA, cross_DA, straight_BA,
#: straight_DC): with gravity along -y of {1} the best-conditioned four of the 495 choices.
FOUR_STRINGS = (0, 2, 6, 11)
#: Four that leave a direction undetermined even with gravity along -y: every string from
#: link-1 node A (cross_AA, cross_AD, straight_AB, straight_AC).
SINGULAR_FOUR = (0, 1, 4, 5)
GRAVITY_BASE = np.array([0.0, -1.0, 0.0])
#: The sensor sets of the issue, by name: (tensions, lengths, imu, pose, wrench).
SENSOR_SETS = {
    '12 tensions': ('all', None, False, False, False),
    '4 tensions + IMU': (FOUR_STRINGS, None, True, False, False),
    '12 lengths': (None, 'all', False, False, False),
    'motion capture': (None, None, False, True, False),
    'force-torque + 4 tensions': (FOUR_STRINGS, None, False, False, True),
}
#: Truth spread around the unloaded equilibrium (rad, m) and a tracker's warm-start offset.
TRUTH_SPREAD = np.array([0.02] * 3 + [5e-4] * 3)
WARM_START_SPREAD = np.array([0.005] * 3 + [1e-4] * 3)


def nees_band(trials: int, dof: int = 6, level: float = 0.95) -> tuple[float, float]:
    """Two-sided ``level`` band of the mean of ``trials`` independent chi-square(dof) values."""
    tail = 0.5 * (1.0 - level)
    return (chi2.ppf(tail, dof * trials) / trials, chi2.ppf(1.0 - tail, dof * trials) / trials)


def nees(error: np.ndarray, covariance: np.ndarray) -> float:
    return float(error @ np.linalg.solve(covariance, error))


@dataclass
class Truth:
    """What the sensors see: screw, transform, tensions, lengths, wrench of the strings on link
    2, the direction of gravity in link 2 (an accelerometer at rest) and the external load."""

    screw: np.ndarray
    transform: np.ndarray
    tensions: np.ndarray
    lengths: np.ndarray
    string_wrench: np.ndarray
    gravity: np.ndarray
    external_wrench: np.ndarray


def truth_from_model(model, xi) -> Truth:
    """The forward model's sensors at ``xi`` (the quasi-static load ``-F``)."""
    state = model.evaluate(xi)
    return Truth(np.array(xi), state.transform.copy(), state.tensions.copy(),
                 state.lengths.copy(), state.wrench.copy(),
                 state.transform[:3, :3].T @ GRAVITY_BASE, -state.wrench)


def truth_from_twin(simulation) -> Truth:
    """The MuJoCo twin's sensors (a settled :class:`JointSimulation`): its tendon tensions and
    lengths, its IMU's specific force (gravity = its opposite) and its applied load."""
    a = simulation.imu().specific_force
    return Truth(simulation.screw(), simulation.pose(), simulation.tensions(),
                 simulation.string_lengths(), simulation.string_wrench(),
                 -a / np.linalg.norm(a), simulation.external_wrench)


def perturbed_pose(transform, covariance, rng) -> np.ndarray:
    """A motion-capture reading: ``p + dp``, ``exp(hat(dtheta)) R`` with ``[dp; dtheta]`` drawn
    from ``covariance`` (the PoseWithCovariance convention)."""
    d = rng.multivariate_normal(np.zeros(6), covariance)
    out = np.array(transform, dtype=float)
    out[:3, 3] += d[:3]
    out[:3, :3] = exp_so3(d[3:]) @ out[:3, :3]
    return out


def measure(truth: Truth, sensor_set, rng, n_strings: int = 12) -> Measurements:
    """Noisy readings of ``truth`` by ``sensor_set`` (a value of :data:`SENSOR_SETS`)."""
    tensions, lengths, imu, pose, wrench = sensor_set
    kw: dict = {}
    if tensions is not None:
        idx = np.arange(n_strings) if tensions == 'all' else np.array(tensions)
        t = np.full(n_strings, np.nan)
        t[idx] = truth.tensions[idx] + rng.normal(scale=TENSION_STD, size=idx.size)
        kw.update(tensions=t, tension_std=TENSION_STD)
    if lengths is not None:
        idx = np.arange(n_strings) if lengths == 'all' else np.array(lengths)
        ln = np.full(n_strings, np.nan)
        ln[idx] = truth.lengths[idx] + rng.normal(scale=LENGTH_STD, size=idx.size)
        kw.update(lengths=ln, length_std=LENGTH_STD)
    if imu:
        kw.update(gravity=truth.gravity + rng.normal(scale=GRAVITY_STD, size=3),
                  gravity_std=GRAVITY_STD, gravity_base=GRAVITY_BASE)
    if pose:
        kw.update(pose=perturbed_pose(truth.transform, POSE_COVARIANCE, rng),
                  pose_covariance=POSE_COVARIANCE)
    if wrench:
        kw.update(external_wrench=truth.external_wrench + rng.multivariate_normal(
            np.zeros(6), WRENCH_COVARIANCE), wrench_covariance=WRENCH_COVARIANCE)
    return Measurements(**kw)


def tracked_estimate(model, truth: Truth, sensor_set, rng):
    """One estimate of ``truth`` from a noisy reading of ``sensor_set``, warm-started in the
    truth's neighbourhood as a tracker's previous estimate would be (no std of K_c)."""
    return estimate_joint_state(model, measure(truth, sensor_set, rng),
                                initial_screw=truth.screw + rng.normal(scale=WARM_START_SPREAD),
                                stiffness_std=False)


def pose_error(estimate, truth: Truth) -> np.ndarray:
    return sm.pose_error(estimate.transform, truth.transform)
