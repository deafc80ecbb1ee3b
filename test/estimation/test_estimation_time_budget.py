"""The static estimators' time budget (issue #42 item 2): with a budget of 0 s an easy estimate
(a warm start, a cold start from a measured load, a start near the optimum) still succeeds within
the iterations a budget never cuts short, and a hard one (a far start) fails with 'time budget
exhausted' naming the iterations. No timing: a budget of 0 s has always passed."""

import numpy as np
import pytest
from support import REPO
from support.estimation_trials import (
    SENSOR_SETS,
    TENSION_STD,
    WARM_START_SPREAD,
    measure,
    truth_from_model,
)
from test_structure_estimator import example, perturbed, sensor_readings

from tensegrity_stiffness import config
from tensegrity_stiffness.estimation import structure_estimator
from tensegrity_stiffness.estimation.estimators import (
    Measurements,
    estimate_chain_state,
    estimate_joint_state,
)
from tensegrity_stiffness.estimation.least_squares import MIN_FIT_ITERATIONS
from tensegrity_stiffness.estimation.structure_estimator import estimate_structure_poses
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel

EXHAUSTED = f'time budget exhausted after {MIN_FIT_ITERATIONS} iterations ('


@pytest.fixture(scope='module')
def joint():
    model = JointModel.from_yaml(REPO / 'config' / 'default_joint.yaml')
    xi = model.initial_screw + np.array([0.02] * 3 + [5e-4] * 3)
    return model, xi, truth_from_model(model, xi)


@pytest.mark.parametrize('sensor_set', ['12 tensions', '12 lengths',
                                        'force-torque + 4 tensions'])
def test_a_warm_started_joint_estimate_is_not_cut_short(joint, sensor_set):
    model, xi, truth = joint
    rng = np.random.default_rng(11)
    m = measure(truth, SENSOR_SETS[sensor_set], rng)
    est = estimate_joint_state(model, m, initial_screw=xi + rng.normal(scale=WARM_START_SPREAD),
                               time_budget=0.0)
    assert est.success, est.message
    assert est.iterations <= MIN_FIT_ITERATIONS


def test_a_cold_start_from_a_measured_load_is_not_cut_short(joint):
    """No pose, no last estimate, a load reading: the start is the equilibrium under the load
    (solved within the time left: its own minimum of Newton steps), then one fit."""
    model, _, truth = joint
    m = measure(truth, SENSOR_SETS['force-torque + 4 tensions'], np.random.default_rng(12))
    est = estimate_joint_state(model, m, time_budget=0.0)
    assert est.success, est.message
    assert est.iterations <= MIN_FIT_ITERATIONS


def test_a_far_joint_start_runs_out_of_time_by_name(joint):
    model, _, truth = joint
    m = measure(truth, SENSOR_SETS['force-torque + 4 tensions'], np.random.default_rng(1))
    far = model.initial_screw + np.array([0.3, -0.3, 0.3, 0.05, -0.05, 0.05])
    unbounded = estimate_joint_state(model, m, initial_screw=far)
    assert unbounded.success and unbounded.iterations > MIN_FIT_ITERATIONS
    est = estimate_joint_state(model, m, initial_screw=far, time_budget=0.0)
    assert not est.success
    assert est.message.startswith(EXHAUSTED), est.message
    assert np.all(np.isnan(est.screw))


@pytest.fixture(scope='module')
def spine():
    document = config.load_yaml(REPO / 'config' / 'default_spine.yaml')
    config.parameters(document)['chain']['n_joints'] = 3
    chain = JointChain.from_dict(document)
    W = np.array([0.1] * 3 + [0.003] * 3)
    res = solve_chain_equilibrium(chain, W, initial_screws=chain.unloaded_screws())
    assert res.success, res.message
    state = chain.evaluate(res.screws)
    rng = np.random.default_rng(2)
    readings = [Measurements(tensions=state.tensions[k] + rng.normal(scale=TENSION_STD, size=12),
                             tension_std=TENSION_STD) for k in range(3)]
    return chain, W, res.screws, readings


def test_spine_estimates_within_and_past_the_minimum(spine):
    chain, W, screws, readings = spine
    warm = estimate_chain_state(chain, readings, initial_screws=screws, initial_tip_wrench=W,
                                time_budget=0.0)
    assert warm.success, warm.message
    assert warm.iterations <= MIN_FIT_ITERATIONS
    cold = estimate_chain_state(chain, readings, time_budget=0.0)
    assert cold.success, cold.message
    far = chain.unloaded_screws() + np.array([0.2, -0.2, 0.2, 0.002, -0.002, 0.002])
    unbounded = estimate_chain_state(chain, readings, initial_screws=far,
                                     initial_tip_wrench=-10.0 * W)
    assert unbounded.success and unbounded.iterations > MIN_FIT_ITERATIONS
    est = estimate_chain_state(chain, readings, initial_screws=far,
                               initial_tip_wrench=-10.0 * W, time_budget=0.0)
    assert not est.success
    assert est.message.startswith(EXHAUSTED), est.message


def test_structure_estimates_within_and_past_the_minimum():
    structure, T, contacts = example('three_bar')
    m = sensor_readings(structure, T, contacts, np.random.default_rng(3))
    near = estimate_structure_poses(structure, m, start=perturbed(T, np.random.default_rng(5)),
                                    hold_rigid_motion=True, time_budget=0.0)
    assert near.success, near.message
    assert near.iterations <= structure_estimator.MIN_FIT_ITERATIONS
    far = perturbed(T, np.random.default_rng(5), 0.2)
    unbounded = estimate_structure_poses(structure, m, start=far, hold_rigid_motion=True)
    assert unbounded.success
    assert unbounded.iterations > structure_estimator.MIN_FIT_ITERATIONS
    est = estimate_structure_poses(structure, m, start=far, hold_rigid_motion=True,
                                   time_budget=0.0)
    assert not est.success
    assert est.message.startswith(
        f'time budget exhausted after {structure_estimator.MIN_FIT_ITERATIONS} iterations ('), \
        est.message
