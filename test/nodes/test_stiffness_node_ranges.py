"""``stiffness_node``'s doors without ROS (issue #42): the ``~/rest_lengths`` topic and the
dynamics parameters judged by the joint's ranges, the one home of each
(:mod:`tensegrity_stiffness.mechanics.plausibility`), as the equilibrium service and the
library's dynamics judge them; also with the dynamics off."""

from __future__ import annotations

import numpy as np
import pytest

from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.nodes.stiffness_node import (
    STIFFNESS_NODE_PARAMETERS,
    joint_node_settings,
    with_rest_lengths,
)


def defaults() -> dict:
    return {spec.name: spec.default for spec in STIFFNESS_NODE_PARAMETERS}


def test_rest_lengths_below_the_range_are_refused_naming_it() -> None:
    model = joint_node_settings(defaults()).model
    with pytest.raises(BadRestLengthsError,
                       match=r'rest_lengths: cross_AA = 1e-06 m is below the range of this '
                             r'joint \(at least 0\.0003\d* m'):
        with_rest_lengths(model, np.full(model.n_strings, 1e-6))
    np.testing.assert_array_equal(with_rest_lengths(model, model.rest_lengths).rest_lengths,
                                  model.rest_lengths)


@pytest.mark.parametrize('enabled', [False, True])
@pytest.mark.parametrize('name, value, reason', [
    ('joint.link2_mass', 1e-12, r'joint\.link2_mass = 1e-12 is outside \[1e-06, inf\]'),
    ('joint.link2_mass', 1e6, r'joint\.link2_mass: 1e\+06 kg is outside the range of this '
                              r'joint \(1e-06 to'),
    ('joint.link2_com', [1e6, 0.0, 0.0], r'joint\.link2_com: 1e\+06 m'),
    ('dynamics.string_damping', 1e9, r'dynamics\.string_damping: 1e\+09 N s/m is outside '
                                     r'the range of this joint'),
])
def test_dynamics_outside_the_joints_range_are_refused_as_parameters(
        enabled: bool, name: str, value: object, reason: str) -> None:
    values = defaults()
    values['dynamics.enabled'] = enabled
    assert (joint_node_settings(values).dynamics is not None) == enabled
    values[name] = value
    with pytest.raises(ValueError, match=reason):
        joint_node_settings(values)
