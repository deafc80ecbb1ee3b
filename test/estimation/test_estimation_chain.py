"""Spine estimator: a 3-joint spine with per-joint load cells and an unknown tip load (shared by
every joint's equilibrium): NEES of the tip pose and of the tip load in the chi-square band over
1000 seeded trials, errors that shrink as sensors are added, unobservable sets refused."""


import numpy as np
import pytest
from scipy.stats import chi2
from support import REPO
from support.estimation_trials import (
    FOUR_STRINGS,
    POSE_COVARIANCE,
    TENSION_STD,
    WARM_START_SPREAD,
    WRENCH_COVARIANCE,
    nees,
    nees_band,
    perturbed_pose,
)

from tensegrity_stiffness import config
from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.estimators import Measurements, estimate_chain_state
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium

SPINE = REPO / 'config' / 'default_spine.yaml'
N_JOINTS = 3
TRIALS = 1000
#: Distinct true tip loads (each solved once); the trials cycle through them with fresh noise.
TRUTHS = 40
#: Spread of the true tip loads (N, N m).
LOAD_SPREAD = np.array([0.1] * 3 + [0.003] * 3)
ALL_STRINGS = tuple(range(12))


@pytest.fixture(scope='module')
def chain():
    document = config.load_yaml(SPINE)
    config.parameters(document)['chain']['n_joints'] = N_JOINTS
    return JointChain.from_dict(document)


@pytest.fixture(scope='module')
def truths(chain):
    rng = np.random.default_rng(31)
    out = []
    unloaded = chain.unloaded_screws()
    while len(out) < TRUTHS:
        W = rng.normal(scale=LOAD_SPREAD)
        res = solve_chain_equilibrium(chain, W, initial_screws=unloaded)
        assert res.success, res.message
        out.append((W, res.screws, chain.evaluate(res.screws)))
    return out


def joint_tensions(state, strings, rng):
    out = []
    for k in range(N_JOINTS):
        t = np.full(12, np.nan)
        idx = list(strings)
        t[idx] = state.tensions[k][idx] + rng.normal(scale=TENSION_STD, size=len(idx))
        out.append(Measurements(tensions=t, tension_std=TENSION_STD))
    return out


_RUNS: dict = {}


def run(chain, truths, strings, tip_pose=False, trials=TRIALS):
    key = (strings, tip_pose, trials)
    if key in _RUNS:
        return _RUNS[key]
    rng = np.random.default_rng(7)
    pose_errors, nees_pose, nees_load, load_errors, failures = [], [], [], [], []
    for trial in range(trials):
        W, screws, state = truths[trial % len(truths)]
        kwargs = {}
        if tip_pose:
            kwargs = dict(tip_pose=perturbed_pose(state.tip_transform, POSE_COVARIANCE, rng),
                          tip_pose_covariance=POSE_COVARIANCE)
        est = estimate_chain_state(
            chain, joint_tensions(state, strings, rng),
            initial_screws=screws + rng.normal(scale=WARM_START_SPREAD, size=(N_JOINTS, 6)),
            initial_tip_wrench=W + rng.normal(scale=0.1 * LOAD_SPREAD), stiffness_std=False,
            **kwargs)
        if not est.success:
            failures.append(est.message)
            continue
        e = sm.pose_error(est.tip_transform, state.tip_transform)
        pose_errors.append(e)
        nees_pose.append(nees(e, est.tip_pose_covariance))
        load_errors.append(est.tip_wrench - W)
        nees_load.append(nees(est.tip_wrench - W, est.tip_wrench_covariance))
    _RUNS[key] = (np.array(pose_errors), np.array(nees_pose), np.array(load_errors),
                  np.array(nees_load), failures)
    return _RUNS[key]


def test_spine_nees_in_chi2_band(chain, truths):
    """Every joint's 12 load cells, unknown tip load: tip pose and tip load consistent."""
    _, nees_pose, _, nees_load, failures = run(chain, truths, ALL_STRINGS)
    assert not failures, failures[:3]
    low, high = nees_band(TRIALS)
    assert low <= nees_pose.mean() <= high, (nees_pose.mean(), (low, high))
    assert low <= nees_load.mean() <= high, (nees_load.mean(), (low, high))


def rms(errors):
    return np.sqrt(np.mean(np.sum(errors ** 2, axis=1)))


def test_spine_errors_shrink_as_sensors_are_added(chain, truths):
    """4 load cells per joint -> 12 per joint -> 12 per joint and a tip pose (the errors differ
    by factors of 2-10: 200 trials tell them apart)."""
    trials = 200
    previous = None
    for strings, tip_pose in ((FOUR_STRINGS, False), (ALL_STRINGS, False), (ALL_STRINGS, True)):
        pose_errors, _, load_errors, _, failures = run(chain, truths, strings, tip_pose, trials)
        assert len(failures) < 0.01 * trials, failures[:3]
        now = (rms(pose_errors[:, :3]), rms(pose_errors[:, 3:]), rms(load_errors[:, :3]))
        if previous is not None:
            assert all(a < b for a, b in zip(now, previous, strict=True)), (now, previous)
        previous = now


def test_spine_estimate_at_the_truth(chain, truths):
    """Noise-free tensions: the estimate is the truth; the tip stiffness is the library's exact
    one under the true load, with a finite std."""
    W, screws, state = truths[0]
    measurements = []
    for k in range(N_JOINTS):
        measurements.append(Measurements(tensions=state.tensions[k], tension_std=TENSION_STD))
    est = estimate_chain_state(chain, measurements, initial_screws=screws, initial_tip_wrench=W)
    assert est.success, est.message
    np.testing.assert_allclose(est.screws, screws, atol=1e-8)
    np.testing.assert_allclose(est.tip_wrench, W, atol=1e-8)
    np.testing.assert_allclose(est.tip_stiffness, chain.tip_stiffness(screws, W), rtol=1e-6,
                               atol=1e-6 * np.abs(est.tip_stiffness).max())
    assert np.all(np.isfinite(est.tip_stiffness_std)) and est.tip_stiffness_std.max() > 0
    assert est.joint_covariances.shape == (N_JOINTS, 6, 6)
    assert est.chi2 < 1e-10 and est.dof == 12 * N_JOINTS - 6


def test_spine_known_tip_load_and_default_start(chain, truths):
    """A force-torque reading of the tip load and 4 load cells on the first joint only."""
    rng = np.random.default_rng(3)
    W, _, state = truths[1]
    measurements = joint_tensions(state, FOUR_STRINGS, rng)
    measurements[1] = measurements[2] = None
    est = estimate_chain_state(chain, measurements,
                               tip_wrench=W + rng.multivariate_normal(np.zeros(6),
                                                                      WRENCH_COVARIANCE),
                               tip_wrench_covariance=WRENCH_COVARIANCE)
    assert est.success, est.message
    e = sm.pose_error(est.tip_transform, state.tip_transform)
    assert nees(e, est.tip_pose_covariance) < 30.0


@pytest.mark.parametrize(('joints', 'strings', 'words'), [
    ((0, 1, 2), (0,), ['3 measured degrees of freedom', 'tip_wrench']),
    ((0,), FOUR_STRINGS, ['joint 1: 4 tensions', '4 measured degrees of freedom']),
])
def test_spine_unobservable_sets_are_refused(chain, truths, joints, strings, words):
    W, screws, state = truths[0]
    measurements = joint_tensions(state, strings, np.random.default_rng(0))
    measurements = [m if k in joints else None for k, m in enumerate(measurements)]
    est = estimate_chain_state(chain, measurements, initial_screws=screws, initial_tip_wrench=W)
    assert not est.success and not est.observable, est.message
    for word in words:
        assert word in est.message, est.message
    assert np.isnan(est.screws).all() and np.isnan(est.tip_wrench).all()


def test_spine_bad_input(chain):
    with pytest.raises(ValueError, match='one entry per joint'):
        estimate_chain_state(chain, [None])
    with pytest.raises(ValueError, match=r'joint_measurements\[0\].tension_std'):
        estimate_chain_state(chain, [Measurements(tensions=np.ones(12)), None, None])
    with pytest.raises(ValueError, match='tip_wrench'):
        estimate_chain_state(chain, [None] * 3, tip_wrench=np.zeros(6), tip_wrench_covariance=None)
    with pytest.raises(ValueError, match='tip_pose_covariance'):
        estimate_chain_state(chain, [None] * 3, tip_pose=np.eye(4),
                             tip_pose_covariance=np.ones((6, 6)))
    with pytest.raises(ValueError, match='per-joint external_wrench'):
        estimate_chain_state(chain, [Measurements(external_wrench=np.zeros(6),
                                                  wrench_covariance=np.eye(6)), None, None])


def test_a_broken_load_cell_on_a_spine_is_named_and_left_out(chain, truths):
    """12 load cells per joint and an unknown tip load (redundancy 30): a load cell 0.8 N off
    is left out by name, the tip pose within 3 sigma; one at -0.3 N is impossible."""
    rng = np.random.default_rng(12)
    bound = chi2.ppf(0.9973, 6)
    for trial, (fault, joint, string) in enumerate([(0.8, 0, 3), (-0.8, 2, 7), (None, 1, 5)]):
        _, screws, state = truths[trial]
        joints = joint_tensions(state, ALL_STRINGS, rng)
        t = joints[joint].tensions
        t[string] = -0.3 if fault is None else t[string] + fault
        est = estimate_chain_state(chain, joints, initial_screws=screws, stiffness_std=False)
        assert est.success, est.message
        name = f'joint {joint + 1} tension[{chain.joints[joint].string_names[string]}]'
        assert est.outliers == (name,), est.outlier_reasons
        assert est.consistent is True and est.redundancy == 12 * N_JOINTS - 1 - 6
        e = sm.pose_error(est.tip_transform, state.tip_transform)
        assert nees(e, est.tip_pose_covariance) <= bound


def test_a_spine_tracker_that_lost_track_restarts_cold(chain, truths):
    """A warm start from an absurd earlier estimate (after a hostile burst): the estimate is
    the cold start's, not a wrong minimum near the absurd one."""
    rng = np.random.default_rng(13)
    state = truths[0][2]
    joints = joint_tensions(state, ALL_STRINGS, rng)
    cold = estimate_chain_state(chain, joints, stiffness_std=False)
    assert cold.success and cold.consistent
    absurd = chain.unloaded_screws() + rng.normal(scale=[0.8] * 3 + [0.01] * 3,
                                                  size=(N_JOINTS, 6))
    est = estimate_chain_state(chain, joints, initial_screws=absurd,
                               initial_tip_wrench=[5.0, -5.0, 3.0, 0.1, 0.1, 0.1],
                               stiffness_std=False)
    assert est.success and est.consistent, est.message
    np.testing.assert_allclose(est.tip_transform, cold.tip_transform, atol=1e-6)


def test_a_contradicted_tip_pose_is_left_out(chain, truths):
    """12 load cells per joint and a tip pose 5 mm off: ``pose`` left out, the tip pose
    estimated from the load cells within 3 sigma."""
    rng = np.random.default_rng(14)
    _, screws, state = truths[1]
    wrong = perturbed_pose(state.tip_transform, POSE_COVARIANCE, rng)
    wrong[:3, 3] += [0.005, 0.0, 0.0]
    est = estimate_chain_state(chain, joint_tensions(state, ALL_STRINGS, rng), tip_pose=wrong,
                               tip_pose_covariance=POSE_COVARIANCE, initial_screws=screws,
                               stiffness_std=False)
    assert est.success and est.outliers == ('pose',), est.outlier_reasons
    assert est.consistent is True and est.redundancy == 12 * N_JOINTS - 6
    e = sm.pose_error(est.tip_transform, state.tip_transform)
    assert nees(e, est.tip_pose_covariance) <= chi2.ppf(0.9973, 6)
