"""The one parameter table (tensegrity_stiffness.nodes.parameters): the packaged config agrees with
it, every entry is checked by type, range and choice, and a whole set is validated at once."""

from __future__ import annotations

import math

import numpy as np
import pytest
import yaml
from support import REPO

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import parameters
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.registry import values_from_config
from tensegrity_stiffness.nodes.stiffness_node import (
    STIFFNESS_NODE_PARAMETERS,
    joint_node_settings,
)

REPO = REPO
CONFIG = REPO / 'config' / 'default_joint.yaml'
TABLE = parameters.by_name(STIFFNESS_NODE_PARAMETERS)


def test_default_joint_config_and_the_table_agree():
    """Every parameter of config/default_joint.yaml is in the table with the table's default
    (an optional array left out of the file is the table's empty default), and vice versa."""
    in_file = parameters.flatten(config.parameters(config.load_yaml(CONFIG)))
    assert set(in_file) <= set(TABLE), set(in_file) - set(TABLE)
    defaults = parameters.defaults(STIFFNESS_NODE_PARAMETERS)
    # The table leaves joint.initial_screw empty (solved by the rule of mechanics.unloaded); the
    # file writes the solution (test_the_table_builds_the_default_joint: the same screw).
    assert defaults.pop('joint.initial_screw') == []
    for name, spec in TABLE.items():
        if name == 'joint.initial_screw':
            continue
        if name not in in_file:
            assert defaults[name] == [], f'{name} is not in {CONFIG.name}'
            continue
        value = spec.check(in_file[name])
        if isinstance(value, float):
            assert value == pytest.approx(defaults[name], rel=1e-15, abs=0.0), name
        else:
            assert value == defaults[name], name


def test_the_table_builds_the_default_joint():
    settings = joint_node_settings(parameters.defaults(STIFFNESS_NODE_PARAMETERS))
    model = JointModel.from_yaml(CONFIG)
    np.testing.assert_array_equal(settings.model.link1_nodes, model.link1_nodes)
    np.testing.assert_array_equal(settings.model.rest_lengths, model.rest_lengths)
    np.testing.assert_array_equal(settings.model.max_lengths, model.max_lengths)
    np.testing.assert_allclose(settings.model.initial_screw, model.initial_screw, rtol=0,
                               atol=1e-12)
    assert settings.model.string_names == model.string_names
    assert np.abs(model.wrench(model.initial_screw)).max() < 1e-12  # its unloaded equilibrium
    assert settings.link1_frame == 'tensegrity_link1'
    assert settings.marker_period == pytest.approx(1.0 / 30.0)
    assert settings.planar.L3_max == 2.0 * settings.planar.L


def test_every_entry_is_well_formed():
    names = [spec.name for spec in STIFFNESS_NODE_PARAMETERS]
    assert len(names) == len(set(names))
    for spec in STIFFNESS_NODE_PARAMETERS:
        assert spec.description, spec.name
        spec.check(spec.default)  # the default passes its own checks
        if spec.range is not None:
            assert spec.type in ('int', 'double')
            assert spec.range[0] <= spec.range[1]
        if spec.choices:
            assert spec.type == 'string' and spec.default in spec.choices


@pytest.mark.parametrize(('spec', 'value', 'match'), [
    (ParameterSpec('a.i', 'int', 1, 'x', range=(1, 10)), 11, r'a.i = 11 is outside \[1, 10\]'),
    (ParameterSpec('a.i', 'int', 1, 'x'), 1.5, 'a.i must be an integer'),
    (ParameterSpec('a.i', 'int', 1, 'x'), True, 'a.i must be an integer'),
    (ParameterSpec('a.d', 'double', 1.0, 'x'), math.nan, 'a.d must be finite'),
    (ParameterSpec('a.d', 'double', 1.0, 'x'), 'one', 'a.d must be a number'),
    (ParameterSpec('a.s', 'string', 'p', 'x', choices=('p', 'q')), 'r', 'a.s must be one of'),
    (ParameterSpec('a.s', 'string', 'p', 'x'), 3, 'a.s must be a string'),
    (ParameterSpec('a.b', 'bool', True, 'x'), 1, 'a.b must be true or false'),
    (ParameterSpec('a.v', 'double_array', None, 'x'), ['a'], 'a.v must be a list of numbers'),
    (ParameterSpec('a.v', 'double_array', None, 'x'), 'abc', 'a.v must be a list'),
    (ParameterSpec('a.w', 'string_array', None, 'x'), [1], 'a.w must be a list of strings'),
])
def test_check_names_the_parameter_and_the_problem(spec, value, match):
    with pytest.raises(ValueError, match=match):
        spec.check(value)


def test_unknown_type_is_refused():
    with pytest.raises(ValueError, match='unknown type'):
        ParameterSpec('a', 'float', 1.0, 'x')


@pytest.mark.parametrize(('changes', 'match'), [
    ({'qos.depth': 0}, r'qos.depth = 0 is outside'),
    ({'markers.max_rate': -1.0}, r'markers.max_rate = -1 is outside'),
    ({'joint.force_law': 'linear'}, 'joint.force_law must be one of hooke | paper'),
    ({'frames.link1': '  '}, 'frames.link1 must not be empty'),
    ({'joint.rest_lengths': [0.03] * 11}, 'rest_lengths'),
    ({'planar.L3_min': 3.0}, '^planar.'),
    ({'joint.string_link1_nodes': ['A'] * 11 + ['Z']}, 'Z'),
])
def test_whole_set_validation_names_the_field(changes, match):
    values = parameters.defaults(STIFFNESS_NODE_PARAMETERS)
    values.update(changes)
    with pytest.raises(ValueError, match=match):
        joint_node_settings(values)


def test_values_from_config_overrides_defaults_and_ignores_undeclared(tmp_path):
    path = tmp_path / 'p.yaml'
    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': {
        'use_sim_time': False, 'qos': {'depth': 7}, 'planar': {'K1': 250.0}}}}))
    values = values_from_config(path, STIFFNESS_NODE_PARAMETERS)
    assert values['qos.depth'] == 7 and values['planar.K1'] == 250.0
    assert values['planar.K2'] == TABLE['planar.K2'].default
    assert 'use_sim_time' not in values
    path.write_text(yaml.safe_dump({'qos': {'depth': 'deep'}}))  # a plain config
    with pytest.raises(ValueError, match=r'qos\.depth must be an integer'):
        values_from_config(path, STIFFNESS_NODE_PARAMETERS)


def test_values_from_config_refuses_an_unknown_key_of_its_sections(tmp_path):
    """#39: ``stifness: 120`` is refused by name (not run as the default joint's 77 N/m);
    ``strict_parameters: false`` (in the file, or ``strict=False``) warns and goes on."""
    from tensegrity_stiffness.config import UnknownKeyWarning

    path = tmp_path / 'typo.yaml'
    path.write_text(yaml.safe_dump({'joint': {'stifness': 120.0}}))
    with pytest.raises(ValueError, match=r'joint\.stifness: unknown key \(did you mean '
                                         r'joint\.stiffness\?\)'):
        values_from_config(path, STIFFNESS_NODE_PARAMETERS)
    with pytest.warns(UnknownKeyWarning, match=r'joint\.stifness: unknown key'):
        values = values_from_config(path, STIFFNESS_NODE_PARAMETERS, strict=False)
    assert values['joint.stiffness'] == TABLE['joint.stiffness'].default
    path.write_text(yaml.safe_dump({'strict_parameters': False, 'joint': {'stifness': 120.0}}))
    with pytest.warns(UnknownKeyWarning):
        values_from_config(path, STIFFNESS_NODE_PARAMETERS)


def test_every_packaged_config_is_strictly_sound():
    """No packaged config or example carries an unknown key of a node's sections."""
    from pathlib import Path

    from tensegrity_stiffness import config
    from tensegrity_stiffness.nodes.registry import node_tables
    from tensegrity_stiffness.structures.schema import is_structure_document

    root = Path(__file__).resolve().parents[2] / 'config'
    files = sorted(root.rglob('*.yaml'))
    assert files
    for path in files:
        if is_structure_document(config.load_yaml(path)):
            continue  # a structure's description (docs/structures.md), not a parameter file
        for table in node_tables():
            try:
                values_from_config(path, table.parameters, strict=True)
            except ValueError as exc:
                assert 'unknown key' not in str(exc), f'{path}: {exc}'


def test_every_packaged_config_has_no_unknown_node_parameter():
    """check-config's judgement of the node sections (every node's table at once) finds
    nothing in the packaged configs and examples; the library's ``dynamics`` keys are the
    nodes' ``dynamics.*`` parameters."""
    from pathlib import Path

    from tensegrity_stiffness import config
    from tensegrity_stiffness.mechanics.dynamics import DYNAMICS_SECTION_KEYS
    from tensegrity_stiffness.nodes.registry import node_tables, unknown_config_parameters
    from tensegrity_stiffness.structures.schema import is_structure_document

    root = Path(__file__).resolve().parents[2] / 'config'
    for path in sorted(root.rglob('*.yaml')):
        document = config.load_yaml(path)
        if not is_structure_document(document):
            assert unknown_config_parameters(document)[0] == [], path
    dynamics = {spec.name.split('.', 1)[1] for table in node_tables()
                for spec in table.parameters if spec.name.startswith('dynamics.')}
    assert dynamics == set(DYNAMICS_SECTION_KEYS)


def test_unknown_config_parameters_judges_every_node_section_at_once():
    from tensegrity_stiffness.nodes.registry import unknown_config_parameters

    document = {'/**': {'ros__parameters': {
        'limits': {'tension_max': 3.0, 'max_force': 50.0, 'tension_maxx': 3.0},
        'sim': {'rate': 500.0, 'rat': 1.0}, 'use_sim_time': True}}}
    assert unknown_config_parameters(document) == ([
        'limits.tension_maxx: unknown key (did you mean limits.tension_max?)',
        'sim.rat: unknown key (did you mean sim.rate?)'], True)
    plain = {'strict_parameters': False, 'sensors': {'tension_stdd': 0.1}}
    lines, strict = unknown_config_parameters(plain)
    assert not strict and lines[0].startswith('sensors.tension_stdd: unknown key (did you mean')


def test_the_cli_planar_defaults_are_the_table():
    from tensegrity_stiffness.cli.planar_commands import PLANAR_KEYS

    assert PLANAR_KEYS == tuple(name[len('planar.'):] for name in TABLE
                                if name.startswith('planar.'))


def test_unknown_parameters_under_a_nodes_own_sections_are_named_with_the_nearest():
    """Misspelt names under the node's own sections are named with the nearest parameter (a
    spine's joint_<i> overrides for any i); another node's parameters (a shared file), names
    outside the node's sections and names without a section are no mistake."""
    from tensegrity_stiffness.nodes.registry import unknown_parameter_messages
    from tensegrity_stiffness.nodes.spine_node import spine_node_parameters
    from tensegrity_stiffness.nodes.stiffness_bridge import BRIDGE_PARAMETERS
    from tensegrity_stiffness.nodes.stiffness_node import STIFFNESS_NODE_PARAMETERS

    given = ['joint.stifness', 'joint.stiffness', 'limits.max_force', 'use_sim_time',
             'qos_overrides./x.publisher.depth', 'other_package.anything', 'planar.LL',
             'estimation.max_age']
    assert unknown_parameter_messages(given, STIFFNESS_NODE_PARAMETERS) == [
        'joint.stifness: unknown key (did you mean joint.stiffness?)',
        'planar.LL: unknown key (did you mean planar.L?)']
    assert unknown_parameter_messages(['joint_9.rest_lenghts', 'chain.n_joint'],
                                      spine_node_parameters(9)) == [
        'chain.n_joint: unknown key (did you mean chain.n_joints?)',
        'joint_9.rest_lenghts: unknown key (did you mean joint_9.rest_lengths?)']
    assert unknown_parameter_messages(['target.nod', 'target.zzzzzz'], BRIDGE_PARAMETERS) == [
        'target.nod: unknown key (did you mean target.node?)',
        'target.zzzzzz: unknown key']
