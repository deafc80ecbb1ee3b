"""The estimator on the MuJoCo twin's sensors (tensegrity_stiffness.simulation.twin): the twin
settles
under seeded loads, its tendons' tensions and lengths, its IMU and its applied load are read
with the issue's typical noise; the pose NEES lies in the chi-square band over 1000 trials per
sensor set, errors shrink as sensors are added, and forward statics match the settled twin."""


import numpy as np
import pytest
from support.estimation_trials import (
    SENSOR_SETS,
    nees,
    nees_band,
    pose_error,
    tracked_estimate,
    truth_from_twin,
)

from tensegrity_stiffness.estimation.estimators import Measurements, estimate_joint_state
from tensegrity_stiffness.mechanics.joint import JointModel

pytest.importorskip('mujoco')
from support import REPO

from tensegrity_stiffness.simulation.twin import JointSimulation

CONFIG = REPO / 'config' / 'default_joint.yaml'
TRIALS = 1000
#: Settled twin configurations (each under its own seeded load); trials cycle through them.
CONFIGURATIONS = 50
#: Spread of the applied loads (N, N m) and the twin's settling tolerance (N, N m).
LOAD_SPREAD = np.array([0.05] * 3 + [0.001] * 3)
SETTLE_TOLERANCE = 1e-9


@pytest.fixture(scope='module')
def model():
    return JointModel.from_yaml(CONFIG)


@pytest.fixture(scope='module')
def twin_truths(model):
    rng = np.random.default_rng(21)
    sim = JointSimulation(model)
    truths = []
    for _ in range(CONFIGURATIONS):
        sim.apply_wrench(rng.normal(scale=LOAD_SPREAD))
        assert sim.settle(SETTLE_TOLERANCE, max_time=20.0)
        truths.append(truth_from_twin(sim))
    return truths


_RUNS: dict = {}


def run(model, truths, name, sensor_set, trials=TRIALS):
    key = (name, trials)
    if key not in _RUNS:
        rng = np.random.default_rng(5)
        errors, values, failures = [], [], []
        for trial in range(trials):
            truth = truths[trial % len(truths)]
            est = tracked_estimate(model, truth, sensor_set, rng)
            if not est.success:
                failures.append(est.message)
                continue
            e = pose_error(est, truth)
            errors.append(e)
            values.append(nees(e, est.covariance))
        _RUNS[key] = np.array(errors), np.array(values), failures
    return _RUNS[key]


@pytest.mark.parametrize('name', list(SENSOR_SETS))
def test_twin_nees_in_chi2_band(model, twin_truths, name):
    _, values, failures = run(model, twin_truths, name, SENSOR_SETS[name])
    assert not failures, failures[:3]
    low, high = nees_band(TRIALS)
    assert low <= values.mean() <= high, (name, values.mean(), (low, high))


#: Sets of growing information on the twin, each containing the one before it.
NESTED_SETS = {
    '4 tensions + IMU': SENSOR_SETS['4 tensions + IMU'],
    '12 tensions + IMU': ('all', None, True, False, False),
    '12 tensions + IMU + 12 lengths': ('all', 'all', True, False, False),
    '12 tensions + IMU + 12 lengths + force-torque': ('all', 'all', True, False, True),
}


def test_twin_errors_shrink_as_sensors_are_added(model, twin_truths):
    trials = 300
    previous = None
    for name, sensor_set in NESTED_SETS.items():
        errors, _, failures = run(model, twin_truths, name, sensor_set, trials)
        assert not failures
        now = tuple(np.sqrt(np.mean(np.sum(errors[:, block] ** 2, axis=1)))
                    for block in (slice(0, 3), slice(3, 6)))
        if previous is not None:
            assert now[0] < previous[0] and now[1] < previous[1], (name, now, previous)
        previous = now


def test_twin_forward_statics(model, twin_truths):
    """Rest lengths alone and the twin's applied load (known exactly): the twin's screw."""
    covariance = np.diag([1e-12] * 3 + [1e-14] * 3)
    for truth in twin_truths[:5]:
        est = estimate_joint_state(model, Measurements(
            external_wrench=truth.external_wrench, wrench_covariance=covariance))
        assert est.success, est.message
        # the twin settles to 1e-9 N: its screw is the equilibrium to about 1e-9 / K
        np.testing.assert_allclose(est.screw, truth.screw, atol=1e-7)
