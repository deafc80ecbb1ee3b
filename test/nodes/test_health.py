"""The health a node reports in ``/diagnostics`` (:mod:`tensegrity_stiffness.nodes.health`),
without ROS: slack and saturated strings by name, the chart margin, the stability margin and the
conditioning of K of evaluated configurations of the default joint, and what a WARN names."""

from __future__ import annotations

import math

import numpy as np
import pytest
from support import JOINT_CONFIG

from tensegrity_stiffness.geometry.screw import CHART_LIMIT
from tensegrity_stiffness.mechanics.equilibrium import STABILITY_TOLERANCE, stability_margin
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.health import CHART_WARNING_MARGIN, JointHealth, joint_health


@pytest.fixture(scope='module')
def model() -> JointModel:
    return JointModel.from_yaml(JOINT_CONFIG)


def test_the_default_joint_at_its_initial_screw_is_healthy(model):
    state = model.evaluate(model.initial_screw)
    health = joint_health(state, model.string_names)
    assert health.slack == [] and health.saturated == []
    assert health.stable and health.problems == []
    assert health.stability_margin == stability_margin(state.cartesian_stiffness)
    assert health.stability_margin > STABILITY_TOLERANCE
    assert health.condition_number == pytest.approx(np.linalg.cond(state.stiffness), rel=1e-12)
    assert health.chart_margin == pytest.approx(
        CHART_LIMIT - np.linalg.norm(model.initial_screw[:3]), rel=0, abs=1e-15)
    values = dict(health.values())
    assert values['slack strings'] == 'none' and values['saturated strings'] == 'none'
    assert values['chart margin 2pi - |omega| [rad]'] == health.chart_margin
    assert values['condition number of K'] == health.condition_number
    assert len(health.values()) == 5


def test_slack_strings_are_named_and_warned(model):
    rest = model.rest_lengths.copy()
    state0 = model.evaluate(model.initial_screw)
    rest[[1, 4]] = state0.lengths[[1, 4]] * 1.5  # longer than the string: slack
    state = model.evaluate(model.initial_screw, rest)
    health = joint_health(state, model.string_names)
    assert health.slack == [model.string_names[1], model.string_names[4]]
    assert '2 slack' in health.problems
    assert dict(health.values())['slack strings'] == health.slack


def test_saturated_strings_are_named_and_warned(model):
    state0 = model.evaluate(model.initial_screw)
    max_lengths = np.array(model.max_lengths, dtype=float)
    max_lengths[[0, 7]] = 0.5 * (model.rest_lengths[[0, 7]] + state0.lengths[[0, 7]])
    capped = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                        link2_nodes=model.link2_nodes, max_lengths=max_lengths,
                        force_law=model.force_law, initial_screw=model.initial_screw,
                        string_names=model.string_names)
    health = joint_health(capped.evaluate(model.initial_screw), model.string_names)
    assert health.saturated == [model.string_names[0], model.string_names[7]]
    assert '2 saturated' in health.problems


def test_names_fall_back_to_indices_when_the_list_does_not_fit(model):
    rest = model.rest_lengths.copy()
    rest[2] = 10.0
    state = model.evaluate(model.initial_screw, rest)
    assert joint_health(state, ['only', 'two']).slack == ['2']


def test_near_the_chart_limit_is_warned(model):
    axis = np.array([0.0, 0.0, 1.0])
    for theta, warned in ((CHART_LIMIT - 0.5 * CHART_WARNING_MARGIN, True),
                          (CHART_LIMIT - 2.0 * CHART_WARNING_MARGIN, False)):
        xi = np.r_[theta * axis, model.initial_screw[3:]]
        health = joint_health(model.evaluate(xi), model.string_names)
        assert health.chart_margin == pytest.approx(CHART_LIMIT - theta, abs=1e-12)
        assert ('near the chart limit |omega| = 2 pi' in health.problems) is warned


def test_stability_and_problems_of_a_health_record():
    base = dict(slack=[], saturated=[], chart_margin=1.0, condition_number=10.0)
    assert JointHealth(stability_margin=2 * STABILITY_TOLERANCE, **base).stable
    for margin in (STABILITY_TOLERANCE, 0.0, -1.0, -math.inf):
        health = JointHealth(stability_margin=margin, **base)
        assert not health.stable and health.problems == ['not stable']
    everything = JointHealth(slack=['a'], saturated=['b', 'c'], chart_margin=0.0,
                             stability_margin=-1.0, condition_number=math.inf)
    assert everything.problems == ['1 slack', '2 saturated', 'not stable',
                                   'near the chart limit |omega| = 2 pi']
