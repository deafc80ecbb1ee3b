"""stiffness_controller's behaviour without ROS
(:mod:`tensegrity_stiffness.nodes.control_processing`): its parameter table, the settings of a
parameter set (defaults, per-string limits, offsets, every bad field named) and the reading of a
``~/target_stiffness`` payload. No rclpy, no node."""

from __future__ import annotations

import numpy as np
import pytest
from support import JOINT_CONFIG

from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import parameters
from tensegrity_stiffness.nodes.stiffness_controller import (
    CONTROLLER_PARAMETERS,
    DEFAULT_RANGE,
    controller_settings,
    default_tension_limits,
    stiffness_target,
)


@pytest.fixture(scope='module')
def defaults() -> dict:
    return parameters.defaults(CONTROLLER_PARAMETERS)


@pytest.fixture(scope='module')
def model() -> JointModel:
    return JointModel.from_yaml(JOINT_CONFIG)


def test_table_has_one_row_per_name_and_the_controller_sections(defaults):
    names = [spec.name for spec in CONTROLLER_PARAMETERS]
    assert len(names) == len(set(names))
    for name in ('limits.rest_length_min', 'limits.rest_length_max', 'limits.max_rate',
                 'limits.tension_min', 'limits.tension_max', 'control.rate',
                 'control.max_state_age', 'control.integral_gain', 'control.proportional_gain',
                 'control.use_wrench_estimate', 'joint.rest_lengths',
                 'joint.rest_length_offsets', 'frames.link1', 'qos.depth',
                 'diagnostics.period'):
        assert name in names, name
    assert set(defaults) == set(names)


def test_default_settings_are_the_default_joint_and_the_default_range(defaults, model):
    settings = controller_settings(defaults)
    assert settings.model.n_strings == model.n_strings
    np.testing.assert_array_equal(settings.model.rest_lengths, model.rest_lengths)
    np.testing.assert_array_equal(settings.limits.rest_length_min,
                                  DEFAULT_RANGE[0] * model.rest_lengths)
    np.testing.assert_array_equal(settings.limits.rest_length_max,
                                  DEFAULT_RANGE[1] * model.rest_lengths)
    assert float(settings.limits.max_rate) == defaults['limits.max_rate']
    # 0 (the default) takes the tension range from the joint (issue #39):
    # the default joint's 0.1 / 1.5 N.
    assert defaults['limits.tension_min'] == defaults['limits.tension_max'] == 0.0
    assert (float(settings.limits.tension_min), float(settings.limits.tension_max)) == \
        default_tension_limits(model) == (0.1, 1.5)
    np.testing.assert_array_equal(settings.offsets, np.zeros(model.n_strings))
    assert settings.link1_frame == defaults['frames.link1']
    assert settings.values['control.rate'] == defaults['control.rate']


def test_per_string_limits_one_value_or_one_per_string(defaults, model):
    n = model.n_strings
    one = controller_settings({**defaults, 'limits.rest_length_min': [0.012],
                               'limits.rest_length_max': [0.05]})
    np.testing.assert_array_equal(one.limits.rest_length_min, np.full(n, 0.012))
    np.testing.assert_array_equal(one.limits.rest_length_max, np.full(n, 0.05))
    each = np.linspace(0.010, 0.012, n)
    per = controller_settings({**defaults, 'limits.rest_length_min': each.tolist()})
    np.testing.assert_array_equal(per.limits.rest_length_min, each)
    for bad in ([0.01, 0.02], [0.01] * (n + 1)):
        # the shared per-string rule's text (geometry/validation.per_string)
        with pytest.raises(ValueError, match=rf'limits\.rest_length_min must have {n} values '
                           r'\(one per string\), got \d+ \(or one value for all\)'):
            controller_settings({**defaults, 'limits.rest_length_min': bad})


def test_rest_length_offsets_are_read(defaults, model):
    offsets = np.linspace(-1e-3, 1e-3, model.n_strings)
    settings = controller_settings({**defaults, 'joint.rest_length_offsets': offsets.tolist()})
    np.testing.assert_allclose(settings.offsets, offsets, rtol=0, atol=0)
    with pytest.raises(ValueError, match='rest_length_offsets'):
        controller_settings({**defaults, 'joint.rest_length_offsets': [1e-3, 2e-3]})


@pytest.mark.parametrize('name, value, match', [
    ('limits.max_rate', 0.0, 'max_rate'),
    ('limits.max_rate', -1.0, 'max_rate'),
    ('limits.tension_min', 2.0, 'tension'),            # above tension_max 1.5
    ('limits.tension_max', -1.0, 'tension_max'),
    ('limits.rest_length_min', [0.05], 'rest_length'),  # above the default maximum
    ('limits.rest_length_max', [-0.01], 'rest_length'),
    ('control.integral_gain', -1.0, 'integral_gain'),
    ('control.proportional_gain', 1.0, 'proportional_gain'),
    ('control.max_state_age', -0.1, 'max_state_age'),
    ('control.rate', 0.0, 'control.rate'),
    ('joint.rest_lengths', [0.03, 0.03], 'rest_lengths'),
])
def test_a_bad_field_is_named(defaults, name, value, match):
    with pytest.raises(ValueError, match=match):
        controller_settings({**defaults, name: value})


def test_unknown_names_are_not_settings(defaults):
    settings = controller_settings({**defaults, 'not.a.parameter': 3})
    assert 'not.a.parameter' not in settings.values


def test_stiffness_target_layouts():
    rng = np.random.default_rng(40)
    full = rng.normal(size=36)
    np.testing.assert_array_equal(stiffness_target(full), full.reshape(6, 6))
    diag = rng.uniform(1.0, 2.0, size=6)
    np.testing.assert_array_equal(stiffness_target(diag), np.diag(diag))
    assert stiffness_target(np.zeros(0)) is None
    for size in (1, 5, 7, 35, 37):
        with pytest.raises(ValueError, match=f'36, 6 or 0 values, got {size}'):
            stiffness_target(np.ones(size))
