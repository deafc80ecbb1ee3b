"""sim_node's ROS-free settings: the twin's tendon damping is the config's
``dynamics.string_damping``, the one value the ``modes`` command reads (issue #39, item 7)."""

import numpy as np
import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.dynamics import ChainDynamics, JointDynamics
from tensegrity_stiffness.nodes.registry import values_from_config
from tensegrity_stiffness.nodes.sim_node import sim_node_parameters, sim_node_settings
from tensegrity_stiffness.simulation.twin import ChainSimulation, JointSimulation


def damped_config(tmp_path, name, damping):
    """The packaged config ``name`` with ``dynamics.string_damping`` set to ``damping``."""
    document = config.load_yaml(config.packaged_config_path(name))
    params = document['/**']['ros__parameters']
    params.setdefault('dynamics', {})['string_damping'] = damping
    path = tmp_path / name
    config.write_yaml(path, document)
    return path, document


def test_the_twin_of_a_joint_takes_the_config_string_damping(tmp_path):
    path, document = damped_config(tmp_path, 'default_joint.yaml', 2.0)
    settings = sim_node_settings(values_from_config(path, sim_node_parameters()))
    sim = JointSimulation(settings.model, **settings.twin_options())
    np.testing.assert_array_equal(sim.mj_model.tendon_damping, 2.0)
    assert sim.mj_model.ntendon == settings.model.n_strings
    np.testing.assert_array_equal(JointDynamics.from_config(document).string_damping, 2.0)


def test_the_twin_of_a_spine_takes_the_config_string_damping(tmp_path):
    path, document = damped_config(tmp_path, 'default_spine.yaml', 2.0)
    table = sim_node_parameters(spine=True)
    values = {**values_from_config(path, table), 'sim.spine': True}
    settings = sim_node_settings(values)
    sim = ChainSimulation(settings.chain, **settings.twin_options())
    np.testing.assert_array_equal(sim.mj_model.tendon_damping, 2.0)
    for damping in ChainDynamics.from_config(document).string_damping:
        np.testing.assert_array_equal(damping, 2.0)


def test_no_parameter_of_its_own_for_the_string_damping():
    names = {spec.name for spec in sim_node_parameters()}
    assert 'dynamics.string_damping' in names
    assert not any('tendon_damping' in name for name in names)


@pytest.mark.parametrize('damping', [-1.0, 2e9])
def test_a_string_damping_out_of_range_is_refused(damping):
    values = {spec.name: spec.default for spec in sim_node_parameters()}
    with pytest.raises(ValueError, match=r'dynamics\.string_damping'):
        sim_node_settings({**values, 'dynamics.string_damping': damping})
