"""The controller's library side under hostile input (issue #42; #39 item 1): the settings'
start, default limits and refusals, the stiffness target's layout, the integral's restart."""

from __future__ import annotations

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness.control.controller import ControlTarget, StiffnessController
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.design import DEFAULT_TENSION_MAX, DEFAULT_TENSION_MIN
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.plausibility import check_target_stiffness
from tensegrity_stiffness.nodes.stiffness_controller import (
    CONTROLLER_PARAMETERS,
    PRETENSION_RANGE,
    controller_settings,
    default_tension_limits,
    stiffness_target,
)

CONFIG = REPO / 'config' / 'default_joint.yaml'


def defaults() -> dict:
    return {spec.name: spec.default for spec in CONTROLLER_PARAMETERS}


def test_a_start_outside_the_range_is_moved_in_with_a_warning() -> None:
    values = defaults()
    values['joint.rest_length_offsets'] = [0.05]  # the config's rest lengths less it: < 0
    settings = controller_settings(values)
    low, high, *_ = settings.limits.for_strings(settings.model.n_strings)
    assert np.all(settings.start >= low) and np.all(settings.start <= high)
    assert 'moved into the range' in settings.start_warning
    values = defaults()
    values['limits.rest_length_min'], values['limits.rest_length_max'] = [0.04], [0.05]
    settings = controller_settings(values)
    assert np.all(settings.start >= 0.04) and 'cross_AA' in settings.start_warning
    assert controller_settings(defaults()).start_warning == ''


def test_refused_settings_name_the_field() -> None:
    values = defaults()
    values['frames.link1'] = ''
    with pytest.raises(ValueError, match=r'frames\.link1 must not be empty'):
        controller_settings(values)
    values = defaults()
    values['joint.rest_length_offsets'] = [-1.0]
    with pytest.raises(ValueError, match=r'true rest length .* must be > 0'):
        controller_settings(values)


def test_default_tension_limits_come_from_the_joint() -> None:
    model = JointModel.from_yaml(CONFIG)
    tensions = model.evaluate(model.initial_screw).tensions
    low, high = default_tension_limits(model)
    assert low == min(DEFAULT_TENSION_MIN, PRETENSION_RANGE[0] * tensions.min())
    assert high == max(DEFAULT_TENSION_MAX, PRETENSION_RANGE[1] * tensions.max())
    # a joint pretensioned at 4x: the range follows its design tensions
    strong = model.with_rest_lengths(model.rest_lengths * 0.9)
    t = strong.evaluate(strong.initial_screw).tensions
    assert default_tension_limits(strong)[1] >= PRETENSION_RANGE[1] * t.max()
    settings = controller_settings(defaults())
    assert settings.limits.tension_max == high
    values = defaults()
    values['limits.tension_max'] = 3.0
    assert controller_settings(values).limits.tension_max == 3.0


def test_stiffness_targets_refused_with_the_reason() -> None:
    with pytest.raises(ValueError, match='layout 3 x 12'):
        stiffness_target(np.ones(36), (3, 12))
    assert stiffness_target(np.ones(36), (6, 6)).shape == (6, 6)
    model = JointModel.from_yaml(CONFIG)
    rng = np.random.default_rng(3)
    A = rng.standard_normal((6, 6))
    for K, reason in ((np.diag([1e12] * 6), 'outside the range'),
                      (np.full((6, 6), 1e308), 'too large'),
                      (-100.0 * np.eye(6), 'not positive semidefinite'),
                      (np.zeros((6, 6)), 'zero'), (A - A.T, 'antisymmetric')):
        with pytest.raises(ValueError, match=reason):
            check_target_stiffness(model, K)


def test_the_integral_restarts_when_the_target_moves_far() -> None:
    """The issue's: a target turned by 180 deg about the joint's axis needs the same rest
    lengths, no limit binds and the integral sat at its clamp; back at the first target the
    commands stayed off. Now: the integral restarts there, and the clamp is reported."""
    settings = controller_settings(defaults())
    model = settings.model
    ctl = StiffnessController(model, settings.limits, settings.start)
    T0 = exp_se3(model.initial_screw)
    turn = np.diag([-1.0, 1.0, -1.0, 1.0])  # 180 deg about link 2's y axis (the joint's)
    for _ in range(200):
        cmd = ctl.update(0.002, ControlTarget(pose=T0 @ turn), pose=T0)
    assert np.isclose(np.linalg.norm(ctl.integral[:3]), ctl.integral_limit[0])
    assert 'integral correction at its clamp' in cmd.message
    cmd = ctl.update(0.002, ControlTarget(pose=T0), pose=T0)
    assert np.all(ctl.integral == 0.0)
    assert np.all(np.isfinite(cmd.rest_lengths))
