"""The joint's physical ranges (issue #42, ``mechanics.plausibility``): finite but absurd
inputs are refused by name before any work (a pose 1 m away, a screw with v = 1e300, rest
lengths of 5e-324 and 1e-6 m, a 1e308 N load, targets of 1e12 I, -100 I or zero), while
everything a joint can do passes (its equilibria under loads, their K_c as targets)."""

from __future__ import annotations

import re

import numpy as np
import pytest

from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics import plausibility as pl
from tensegrity_stiffness.mechanics.design import design_rest_lengths
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel

MODEL = JointModel.from_yaml(packaged_config_path())


def test_the_default_joints_ranges_come_from_its_geometry_and_strings():
    ranges = pl.joint_ranges(MODEL)
    radii = np.linalg.norm(MODEL.link1_nodes, axis=1)
    assert ranges.size == pytest.approx(radii.max())
    # Every string at its maximum length, its ends as far from the origins as they are.
    assert ranges.reach == pytest.approx(float(np.max(
        radii[MODEL.connections[:, 0]] + MODEL.max_lengths
        + np.linalg.norm(MODEL.link2_nodes, axis=1)[MODEL.connections[:, 1]])))
    assert ranges.capacity == pytest.approx(float(np.sum(MODEL.k * MODEL.max_stretch)))
    # Without a maximum length a string is taken to UNBOUNDED_STRETCH rest lengths.
    free = JointModel(MODEL.link1_nodes, MODEL.connections, MODEL.k, MODEL.rest_lengths)
    np.testing.assert_allclose(pl.string_length_limits(free),
                               pl.UNBOUNDED_STRETCH * MODEL.rest_lengths)


def test_what_the_joint_does_passes():
    rng = np.random.default_rng(3)
    passed = 0
    for _ in range(40):
        W = np.r_[rng.normal(0.0, 0.3, 3), rng.normal(0.0, 0.005, 3)]
        result = solve_equilibrium(MODEL, W)
        if not result.success:
            continue
        pl.check_screw(MODEL, result.screw)
        pl.check_wrench(MODEL, W)
        # Its K_c is a target: asymmetric by the load's part only.
        pl.check_target_stiffness(MODEL, result.state.cartesian_stiffness, wrench=W)
        passed += 1
    assert passed >= 30


def test_the_screw_check_equals_the_pose_it_puts_link_2_at():
    """The fast path (|v| within reach) never accepts a screw whose pose is out of reach:
    every singular value of the left Jacobian is at most 1."""
    rng = np.random.default_rng(4)
    limit = pl.REACH_MARGIN * pl.reach(MODEL)
    for _ in range(2000):
        omega = rng.normal(size=3)
        omega *= rng.uniform(0.0, 6.0) / np.linalg.norm(omega)
        xi = np.r_[omega, rng.normal(size=3) * rng.choice([0.01, 0.1, 0.3, 1.0])]
        inside = np.linalg.norm(exp_se3(xi)[:3, 3]) <= limit
        try:
            pl.check_screw(MODEL, xi)
            accepted = True
        except ValueError:
            accepted = False
        assert accepted == inside, xi


@pytest.mark.parametrize('screw', [[0, 0, 0, 1.0, 0, 0], [0, 0, 0, 1e300, 0, 0],
                                   [0.1, 0.2, 0.3, 0.0, -1e308, 1e308]])
def test_a_screw_out_of_reach_is_refused(screw):
    with pytest.raises(ValueError, match=r'screw: .* m from link 1 is outside the range of '
                                         r'this joint \(at most 0.2368 m'):
        pl.check_screw(MODEL, screw)


@pytest.mark.parametrize('rest', [5e-324, 1e-6])
def test_equilibrium_refuses_rest_lengths_below_the_range(rest):
    with pytest.raises(ValueError, match=r'rest_lengths: cross_AA = .* m is below the range'):
        solve_equilibrium(MODEL, np.zeros(6), rest_lengths=np.full(12, rest))


def test_equilibrium_refuses_a_load_no_string_set_can_hold():
    for W, words in (([1e308, 0, 0, 0, 0, 0], 'external_wrench force: 1e+308 N'),
                     ([0, 0, 0, 0, 0, 1e6], 'external_wrench moment: 1e+06 N m')):
        with pytest.raises(ValueError, match=re.escape(words)):
            solve_equilibrium(MODEL, W)
    # Large but possible: solved or refused by the solver with a reason, never a ValueError.
    result = solve_equilibrium(MODEL, [100.0, 50.0, 0, 0, 0, 0])
    assert not result.success and result.message


@pytest.mark.parametrize(('target', 'words'), [
    (1e12 * np.eye(6), 'is outside the range of this joint'),
    (-100.0 * np.eye(6), 'not positive semidefinite'),
    (np.zeros((6, 6)), 'zero'),
    (np.full((6, 6), 1e308), 'entries too large'),
    (np.triu(np.ones((6, 6)), 1) - np.tril(np.ones((6, 6)), -1), 'mostly antisymmetric'),
])
def test_design_refuses_a_target_that_is_no_stiffness_with_the_reason(target, words):
    with pytest.raises(ValueError, match=f'target_stiffness: .*{words}'):
        design_rest_lengths(MODEL, MODEL.initial_screw, target_stiffness=target)


def test_design_refuses_an_absurd_load_and_screw():
    with pytest.raises(ValueError, match='external_wrench force'):
        design_rest_lengths(MODEL, MODEL.initial_screw, [1e308, 0, 0, 0, 0, 0])
    with pytest.raises(ValueError, match='screw: '):
        design_rest_lengths(MODEL, [0, 0, 0, 1e300, 0, 0])
