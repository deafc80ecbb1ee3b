"""Link 2's dynamics within the joint's ranges and the overdamped report (issue #42):
:func:`plausibility.check_dynamics` in :class:`JointDynamics`, :attr:`JointModes.overdamped`
and ``~/natural_frequencies``' payload and label (:func:`nodes.processing.frequency_report`)."""

from __future__ import annotations

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness.mechanics.dynamics import JointDynamics, LinkInertia
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.layouts import NATURAL_FREQUENCIES_LABEL
from tensegrity_stiffness.nodes.stiffness_node import frequency_report

CONFIG = REPO / 'config' / 'default_joint.yaml'


@pytest.mark.parametrize(('kwargs', 'match'), [
    ({'inertia': LinkInertia(mass=1e-12)}, 'link mass: 1e-12 kg is outside'),
    ({'inertia': LinkInertia(mass=1e4)}, 'link mass'),
    ({'inertia': LinkInertia(com=(1e6, 0.0, 0.0))}, 'link com'),
    ({'string_damping': 1e9}, 'string_damping: 1e\\+09 N s/m is outside'),
])
def test_dynamics_outside_the_joint_s_range_are_refused(kwargs, match) -> None:
    with pytest.raises(ValueError, match=match):
        JointDynamics(JointModel.from_yaml(CONFIG), **kwargs)


def test_overdamped_modes_are_reported_as_such() -> None:
    model = JointModel.from_yaml(CONFIG)
    light = JointDynamics(model, LinkInertia(mass=0.02), string_damping=0.3)
    modes = light.modes_at_pose(model.initial_screw)[0]
    assert not modes.overdamped.any()
    values, label = frequency_report(modes)
    assert np.array_equal(values, modes.frequencies)
    assert label == f'{NATURAL_FREQUENCIES_LABEL}; stable: yes'
    heavy = JointDynamics(model, LinkInertia(mass=0.02), string_damping=5.0)
    modes = heavy.modes_at_pose(model.initial_screw)[0]
    assert modes.overdamped.all()  # every eigenvalue real: nothing vibrates
    assert np.all(np.isreal(modes.eigenvalues))
    values, label = frequency_report(modes)
    assert np.all(values == 0.0)
    assert label.endswith('; stable: yes; overdamped (0 Hz): modes 0, 1, 2, 3, 4, 5')


def test_the_label_says_an_unstable_pose_is_unstable() -> None:
    model = JointModel.from_yaml(CONFIG)
    dynamics = JointDynamics(model, LinkInertia(mass=0.02))
    rng = np.random.default_rng(5)
    for _ in range(50):
        xi = model.initial_screw + rng.normal(scale=[0.2] * 3 + [0.005] * 3)
        modes = dynamics.modes_at_pose(xi)[0]
        if not modes.stable:
            assert '; stable: no' in frequency_report(modes)[1]
            return
    pytest.fail('no unstable pose among 50 random screws near the unloaded one')
