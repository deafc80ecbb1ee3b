"""Equilibrium solver: convergence rate, residuals, stability, and clear failures."""

import math

import numpy as np
import pytest
from support import REPO
from support.screw_samples import moderate_wrench

from tensegrity_stiffness.mechanics.equilibrium import (
    MIN_NEWTON_ITERATIONS,
    is_stable,
    solve_equilibrium,
)
from tensegrity_stiffness.mechanics.joint import JointModel

CONFIG = REPO / 'config' / 'default_joint.yaml'
RESIDUAL_GOAL = 1e-9


@pytest.fixture(scope='module')
def model():
    return JointModel.from_yaml(CONFIG)


@pytest.mark.slow
def test_10000_moderate_wrenches_converge(model):
    rng = np.random.default_rng(0)
    n = 10_000
    converged = 0
    for _ in range(n):
        W = moderate_wrench(rng)
        res = solve_equilibrium(model, W)
        if res.success:
            converged += 1
            assert res.residual <= RESIDUAL_GOAL
            np.testing.assert_allclose(res.wrench + W, 0.0, atol=RESIDUAL_GOAL)
            assert np.linalg.norm(res.screw[:3]) < 2 * math.pi
    assert converged >= 0.999 * n, converged


def test_unloaded_solution_is_the_configured_equilibrium(model):
    res = solve_equilibrium(model, np.zeros(6))
    assert res.success and res.stable and res.iterations <= 1
    np.testing.assert_allclose(res.screw, model.initial_screw, atol=1e-12)
    assert res.energy == pytest.approx(model.energy(res.screw))
    assert res.tensions.shape == (12,) and np.all(res.tensions > 0)


def test_start_from_a_perturbed_screw_and_from_rest_length_changes(model):
    x0 = model.initial_screw + np.r_[0.3, -0.2, 0.25, 0.004, -0.003, 0.002]
    res = solve_equilibrium(model, np.zeros(6), initial_screw=x0)
    assert res.success and res.stable
    np.testing.assert_allclose(res.screw, model.initial_screw, atol=1e-9)
    rest = model.rest_lengths * 0.95
    res = solve_equilibrium(model, np.zeros(6), rest_lengths=rest)
    assert res.success and res.stable
    np.testing.assert_allclose(model.wrench(res.screw, rest), 0.0, atol=RESIDUAL_GOAL)


def test_unstable_equilibrium_is_reported(model):
    # Stretch the joint along its symmetry axis: an equilibrium that buckles sideways.
    rng = np.random.default_rng(1)
    found_unstable = False
    for _ in range(200):
        axis = rng.normal(size=3)
        x0 = np.r_[axis / np.linalg.norm(axis) * rng.uniform(0, math.pi),
                   rng.normal(scale=0.02, size=3)]
        res = solve_equilibrium(model, np.zeros(6), initial_screw=x0)
        if res.success and not res.stable:
            found_unstable = True
            assert 'not stable' in res.message
            assert not is_stable(res.cartesian_stiffness)
            assert np.linalg.eigvalsh(0.5 * (res.cartesian_stiffness
                                             + res.cartesian_stiffness.T)).min() < 0
            break
    assert found_unstable


def test_wrench_beyond_capacity_fails_with_a_reason(model):
    # Saturated strings carry at most k * 0.02 m = 1.54 N each: 100 N cannot be balanced.
    res = solve_equilibrium(model, np.r_[100.0, 0, 0, 0, 0, 0], time_budget=0.5)
    assert not res.success
    assert 'residual' in res.message
    assert res.residual > 1.0 and res.screw.shape == (6,)


def test_all_strings_slack_fails_with_a_reason(model):
    res = solve_equilibrium(model, np.zeros(6), rest_lengths=model.rest_lengths * 10)
    assert not res.success
    assert 'slack' in res.message


def test_time_and_iteration_budgets(model):
    unreachable = np.r_[100.0, 50, 0, 0, 0, 0]
    full = solve_equilibrium(model, unreachable, time_budget=1e9)
    res = solve_equilibrium(model, unreachable, time_budget=0.02)
    assert not full.success and 'time budget' not in full.message
    # Stops at its budget, not after all fallbacks (counted in iterations, not timed).
    assert not res.success and 'time budget' in res.message
    assert res.iterations < full.iterations / 2
    res = solve_equilibrium(model, np.r_[0.05, 0, 0, 0, 0, 0], max_iterations=1)
    assert res.iterations >= 1


def test_bad_input_raises(model):
    with pytest.raises(ValueError, match=r'external_wrench must have shape \(6,\)'):
        solve_equilibrium(model, np.zeros(5))
    with pytest.raises(ValueError, match='external_wrench must be finite'):
        solve_equilibrium(model, np.r_[np.nan, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match='rest_lengths must be > 0'):
        solve_equilibrium(model, np.zeros(6), rest_lengths=-model.rest_lengths)
    with pytest.raises(ValueError, match='initial_screw must have'):
        solve_equilibrium(model, np.zeros(6), initial_screw=np.r_[7.0, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match='initial_screw must be finite'):
        solve_equilibrium(model, np.zeros(6), initial_screw=np.full(6, np.inf))
    with pytest.raises(ValueError, match='tolerance'):
        solve_equilibrium(model, np.zeros(6), tolerance=-1.0)


def test_initial_screw_with_a_collapsed_string_fails_cleanly(model):
    res = solve_equilibrium(model, np.zeros(6), initial_screw=np.zeros(6))
    assert not res.success
    assert 'not admissible' in res.message


def test_far_out_start_is_not_reported_as_converged(model):
    # String vectors beyond ~1e154 overflow |s|^2: the wrench evaluates to 0 there, which must
    # not pass for an equilibrium.
    with np.errstate(over='ignore', invalid='ignore'):
        res = solve_equilibrium(model, np.zeros(6), initial_screw=np.r_[0.1, 0, 0, 1e200, 0, 0],
                                time_budget=0.5)
    assert not res.success


def test_an_easy_solve_is_not_cut_short_by_a_spent_budget(model):
    """A worker starved of CPU may reach its deadline before Newton's first steps: the first
    MIN_NEWTON_ITERATIONS steps are taken anyway, so an easy request still converges."""
    W = np.array([0.05, 0.0, 0.0, 0.0, 0.0, 0.001])
    res = solve_equilibrium(model, W, time_budget=1e-9)
    assert res.success, res.message
    assert 1 <= res.iterations <= MIN_NEWTON_ITERATIONS
    hard = solve_equilibrium(model, np.r_[100.0, 0, 0, 0, 0, 0], time_budget=1e-9)
    assert not hard.success and 'time budget' in hard.message


def test_newton_only_stops_at_its_iterations_without_the_fallback(model):
    """The nodes' first try (ros/services/joint_services.QUICK_SOLVE_ITERATIONS): from this start
    Newton needs 9 steps; with 8 and ``newton_only`` it fails after exactly 8, where the full
    solve's trust-region fallback finishes the job."""
    start = [2.4408, -0.426, -1.4901, 0.0369, -0.0106, 0.0204]
    full = solve_equilibrium(model, np.zeros(6), initial_screw=start)
    assert full.success and full.iterations == 9
    assert np.allclose(full.screw, model.initial_screw, atol=1e-9)
    quick = solve_equilibrium(model, np.zeros(6), initial_screw=start, max_iterations=8,
                              newton_only=True)
    assert not quick.success and quick.iterations == 8
    assert 'no convergence' in quick.message
    assert solve_equilibrium(model, np.zeros(6), initial_screw=start, max_iterations=8).success
    nine = solve_equilibrium(model, np.zeros(6), initial_screw=start, max_iterations=9,
                             newton_only=True)
    assert nine.success and np.allclose(nine.screw, full.screw, atol=1e-12)
