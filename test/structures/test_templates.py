"""The structure templates write only what the tools accept: documents that Structure.from_dict
loads back (to_dict round trip), in exact equilibrium at the pretension with every string taut
and positive rest lengths; a pretension the strings cannot carry refused by name; the six-bar on
the ground resting on a triangle of strings; a joint and a spine config as structures; the
shipped worked examples are what new-config writes."""

import math

import numpy as np
import pytest
import yaml
from support import REPO

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.parser import main
from tensegrity_stiffness.structures import templates
from tensegrity_stiffness.structures.analysis import analyse
from tensegrity_stiffness.structures.structure import Structure

EXAMPLES = REPO / 'config' / 'examples'
#: The worked examples and the new-config arguments that write them (docs/structures.md).
WORKED_EXAMPLES = {
    'three_bar.yaml': ['--template', 'prism', '--bars', '3', '--ground'],
    'six_bar.yaml': ['--template', 'six-bar', '--ground'],
}


@pytest.mark.parametrize('p', (3, 4, 5, 6))
@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_prism_documents_are_taut_equilibria_at_the_pretension(p, force_law):
    document = templates.prism_document(p, radius=0.12, height=0.3, stiffness=300.0,
                                        pretension=7.0, force_law=force_law)
    structure = Structure.from_dict(document)
    assert structure.n_bodies == p and structure.n_strings == 3 * p
    state = structure.evaluate()
    assert np.abs(state.wrenches).max() < 1e-12
    assert not state.slack.any() and np.all(structure.rest_lengths > 0.0)
    assert state.tensions.max() == pytest.approx(7.0, rel=1e-12)
    assert np.all(state.bar_forces > 0.0)
    back = Structure.from_dict(structure.to_dict())
    np.testing.assert_allclose(back.evaluate().tensions, state.tensions, rtol=1e-12)
    assert analyse(structure).super_stable


def test_a_prism_started_off_its_twist_keeps_the_equilibrium_rest_lengths():
    twisted = Structure.from_dict(templates.prism_document(3, twist=0.7))
    straight = Structure.from_dict(templates.prism_document(3))
    np.testing.assert_allclose(twisted.rest_lengths, straight.rest_lengths, rtol=1e-14)
    assert np.abs(twisted.evaluate().wrenches).max() > 1e-3  # not at its equilibrium


def test_the_six_bar_document_and_its_ground():
    L = 0.4
    document = templates.six_bar_document(bar_length=L, ground=True, pretension=3.0)
    section = document['structure']
    assert section['gravity'] == [0.0, 0.0, -templates.STANDARD_GRAVITY]
    structure = Structure.from_dict(document)
    state = structure.evaluate()
    assert np.abs(state.wrenches).max() < 1e-12 and not state.slack.any()
    np.testing.assert_allclose([b.length for b in structure.bodies], L, rtol=1e-14)
    np.testing.assert_allclose(state.lengths, L * math.sqrt(6.0) / 4.0, rtol=1e-13)
    z = np.sort(structure.node_positions(structure.transforms())[:, 2])
    np.testing.assert_allclose(z[:3], 0.0, atol=1e-15)  # a triangle on the ground
    assert z[3] > 0.05 * L and abs(structure.ground.height) < 1e-15


def test_pretensions_the_strings_cannot_carry_are_refused():
    with pytest.raises(ValueError, match=r'pretension 1000 N: string vertical_\d .*rest length'):
        templates.prism_document(3, stiffness=10.0, pretension=1000.0)
    with pytest.raises(ValueError, match='pretension must be finite and > 0'):
        templates.prism_document(3, pretension=-1.0)
    with pytest.raises(ValueError, match=r'stiffness must have 9 values \(one per string\)'):
        templates.prism_document(3, stiffness=[1.0, 2.0])
    with pytest.raises(ValueError, match='stiffness must be one positive value or 9'):
        templates.prism_document(3, stiffness=[1.0] * 8 + [0.0])
    with pytest.raises(ValueError, match='bars must be an integer >= 3'):
        templates.prism_document(2)


def test_max_stretch_writes_maximum_lengths_above_the_lengths():
    structure = Structure.from_dict(templates.prism_document(4, max_stretch=0.01))
    state = structure.evaluate()
    np.testing.assert_allclose(structure.max_lengths - state.lengths, 0.01, rtol=1e-12)
    assert not state.saturated.any()


@pytest.mark.parametrize('name', ['default_joint.yaml', 'default_spine.yaml'])
def test_a_joint_or_spine_config_as_a_structure(name):
    document = config.load_yaml(REPO / 'config' / name)
    structure = Structure.from_dict(templates.config_structure_document(document))
    assert structure.fixed[0] and not structure.fixed[1:].any()
    state = structure.evaluate()
    # Written at the config's unloaded screws: the free links are in equilibrium.
    assert np.abs(state.wrenches[1:]).max() < 1e-9


@pytest.mark.parametrize('name', sorted(WORKED_EXAMPLES))
def test_the_worked_examples_are_what_new_config_writes(name, tmp_path, capsys):
    out = tmp_path / name
    assert main(['new-config', *WORKED_EXAMPLES[name], '--out', str(out)]) == 0
    capsys.readouterr()
    assert out.read_text() == (EXAMPLES / name).read_text()
    structure = Structure.from_yaml(EXAMPLES / name)
    assert structure.ground is not None and structure.gravity is not None
    assert yaml.safe_load(out.read_text())['structure']['force_law'] == 'hooke'


def test_the_joint_structure_template_has_the_joint_s_modes():
    """from-config writes the config's link inertia: the structure's modes at its equilibrium
    are the joint dynamics' at the unloaded screw."""
    from tensegrity_stiffness.mechanics.dynamics import JointDynamics
    from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
    from tensegrity_stiffness.structures.modes import structure_modes

    document = config.load_yaml(REPO / 'config' / 'default_joint.yaml')
    structure = Structure.from_dict(templates.config_structure_document(document))
    ours = structure_modes(structure, solve_structure_equilibrium(structure))
    dynamics = JointDynamics.from_config(document)
    theirs = dynamics.modes(dynamics.model.initial_screw)
    np.testing.assert_allclose(ours.frequencies, theirs.frequencies, rtol=1e-9)
