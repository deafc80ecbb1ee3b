"""The rule for a config's ``initial_screw`` (mechanics.unloaded) and the starter configs of
mechanics.templates: missing -> solved from the documented starts, not an equilibrium -> an
InitialScrewWarning naming the residual; the templates' equilibria are exact, stable, and the
vertebra template is the default joint and spine."""

from __future__ import annotations

import copy
import warnings

import numpy as np
import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.mechanics import templates
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.equilibrium import is_stable
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.unloaded import (
    INITIAL_SCREW_TOLERANCE,
    InitialScrewWarning,
    resolve_initial_screw,
    unloaded_equilibrium,
    unloaded_starts,
)

DEFAULT = config.packaged_config_path()
WRONG = [2.2, 0.0, -2.2, 0.016, 0.0, 0.017]


def _section(**changes):
    section = dict(config.load_section(DEFAULT, 'joint'))
    section.update(changes)
    return {k: v for k, v in section.items() if v is not None}


def test_missing_initial_screw_is_the_default_joints_written_equilibrium():
    written = JointModel.from_yaml(DEFAULT).initial_screw
    with warnings.catch_warnings():
        warnings.simplefilter('error')  # no warning on this path
        model = JointModel.from_dict(_section(initial_screw=None))
    np.testing.assert_allclose(model.initial_screw, written, rtol=0, atol=1e-12)
    assert np.abs(model.evaluate(model.initial_screw).wrench).max() < 1e-12
    assert len(unloaded_starts(model)) == 10


def test_wrong_initial_screw_warns_with_its_residual_and_is_kept():
    section = _section(initial_screw=WRONG)
    with pytest.warns(InitialScrewWarning, match=r'residual \|F\| = [0-9.e+-]+ .*reaches') as rec:
        model = JointModel.from_dict(section)
    np.testing.assert_array_equal(model.initial_screw, WRONG)
    residual = np.linalg.norm(model.evaluate(WRONG).wrench)
    assert f'{residual:.3e}' in str(rec[0].message)
    assert 'joint.initial_screw' in str(rec[0].message)


def test_an_equilibrium_within_the_tolerance_is_silent():
    written = JointModel.from_yaml(DEFAULT)
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert resolve_initial_screw(written, written.initial_screw) is not None
    assert INITIAL_SCREW_TOLERANCE == 1e-9


def test_no_stable_equilibrium_asks_for_the_screw():
    # Two strings between coincident nodes: no stable unloaded equilibrium.
    section = {'link1_nodes': [0.0, 0.0, 0.0, 0.01, 0.0, 0.0], 'string_link1_nodes': ['0', '1'],
               'string_link2_nodes': ['0', '1'], 'stiffness': [10.0], 'rest_lengths': [0.01],
               'max_lengths': [0.03]}
    with pytest.raises(ValueError, match='initial_screw is missing and no stable unloaded'):
        JointModel.from_dict(section)


def test_chains_apply_the_rule_to_every_joint():
    document = copy.deepcopy(config.load_yaml(config.packaged_config_path('default_spine.yaml')))
    written = JointChain.from_dict(document).joints[0].initial_screw
    del config.parameters(document)['joint']['initial_screw']
    chain = JointChain.from_dict(document)
    for model in chain.joints:
        np.testing.assert_allclose(model.initial_screw, written, rtol=0, atol=1e-12)
    config.parameters(document)['joint']['initial_screw'] = WRONG
    with pytest.warns(InitialScrewWarning):
        JointChain.from_dict(document)


@pytest.mark.parametrize('n', [6, 8, 16])
def test_ring_template_equilibrium_is_exact_and_stable(n):
    section, model, _, _ = templates.starter_joint(
        templates.JointChoices('ring', n_strings=n, pretension=0.8))
    xi = np.asarray(section['initial_screw'])
    np.testing.assert_allclose(xi, [0, 0, 0, 0, 0, 0.015], atol=1e-12)
    state = model.evaluate(xi)
    assert np.linalg.norm(state.wrench) < 1e-12
    assert is_stable(state.cartesian_stiffness) and not state.slack.any()
    np.testing.assert_allclose(state.tensions[n // 2:], 0.8, rtol=1e-9)
    # The written file reads back to the same model with no warning.
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        again = JointModel.from_dict(section)
    np.testing.assert_array_equal(again.initial_screw, xi)


def test_vertebra_template_is_the_default_joint_and_spine():
    default = JointModel.from_yaml(DEFAULT)
    document = templates.starter_config(templates.JointChoices(), spine_joints=5)
    joint = JointModel.from_dict(config.section(document, 'joint'))
    np.testing.assert_array_equal(joint.link1_nodes, default.link1_nodes)
    np.testing.assert_array_equal(joint.rest_lengths, default.rest_lengths)
    np.testing.assert_allclose(joint.max_lengths, default.max_lengths, rtol=1e-12)
    np.testing.assert_allclose(joint.initial_screw, default.initial_screw, atol=1e-12)
    spine = config.load_section(config.packaged_config_path('default_spine.yaml'), 'chain')
    chain = config.section(document, 'chain')
    for key in ('link_offsets', 'tool'):
        np.testing.assert_allclose(rigid_transform(chain[key]), rigid_transform(spine[key]),
                                   atol=1e-6)  # the default spine's 55 mm is rounded


def test_stacking_offset_stacks_upright():
    xi = JointModel.from_yaml(DEFAULT).initial_screw
    offset = templates.stacking_offset(xi, [0.0, 0.04, 0.0])
    step = exp_se3(xi) @ offset
    np.testing.assert_allclose(step[:3, :3], np.eye(3), atol=1e-12)
    np.testing.assert_allclose(step[:3, 3], [0.0, 0.04, 0.0], atol=1e-12)


@pytest.mark.parametrize(('choices', 'match'), [
    (templates.JointChoices('ring', n_strings=7), 'n_strings must be even'),
    (templates.JointChoices('ring', gap=0.05), 'gap must be below'),
    (templates.JointChoices('ring', pretension=1.0, rest_lengths=[0.01]), 'not both'),
    (templates.JointChoices('vertebra', radius=-1.0), 'radius must be'),
    (templates.JointChoices('ring', radius=0.0), 'radius must be'),
    (templates.JointChoices('vertebra', stiffness=[1.0, 2.0]), 'stiffness must have 12 values'),
    (templates.JointChoices('cube'), 'template must be one of'),
])
def test_bad_choices_name_the_problem(choices, match):
    with pytest.raises(ValueError, match=match):
        templates.starter_joint(choices)


def test_check_config_reports_and_flags():
    good = templates.check_config(templates.starter_config(templates.JointChoices('ring')))
    assert good['sound'] and good['residual'] < 1e-9 and good['stable']
    assert good['slack'] == [] and good['saturated'] == []
    assert len(good['modes']['frequencies_hz']) == 6 and good['modes']['stable']
    document = {'joint': _section(initial_screw=WRONG)}
    bad = templates.check_config(document)
    assert not bad['sound'] and 'residual |F|' in bad['problems'][0]
    assert bad['initial_screw']['given'] and not bad['initial_screw']['equilibrium']
    missing = templates.check_config({'joint': _section(initial_screw=None)})
    assert missing['sound'] and not missing['initial_screw']['given']
    assert any('missing' in note for note in missing['notes'])
    result = unloaded_equilibrium(JointModel.from_yaml(DEFAULT))
    np.testing.assert_allclose(missing['screw'], result.screw, atol=1e-12)
