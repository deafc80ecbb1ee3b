"""``check-config --sensors`` (issue #39, observability named): what each sensor set determines
at a config's unloaded equilibrium, in the estimator's own words; the failure that came from a
weakly determined direction (the ring joint's spin about its axis from its lengths, 'singular
normal matrix' before) names that direction."""

from __future__ import annotations

import json

import pytest

from tensegrity_stiffness.cli.parser import main
from tensegrity_stiffness.estimation.estimators import Measurements, estimate_joint_state
from tensegrity_stiffness.mechanics.joint import JointModel

SPIN = 'undetermined: rotation about (0.00, '


@pytest.fixture(scope='module')
def ring12(tmp_path_factory):
    path = tmp_path_factory.mktemp('ring') / 'ring12.yaml'
    assert main(['new-config', '--template', 'ring', '--strings', '12', '--pretension', '1.5',
                 '--out', str(path)]) == 0
    return path


def test_each_set_says_what_it_determines(ring12, capsys):
    capsys.readouterr()
    code = main(['check-config', str(ring12), '--json', '--sensors', 'tensions',
                 'tensions,imu', 'lengths', 'pose', 'wrench,tensions'])
    out, err = capsys.readouterr()
    assert code == 0, err
    sets = {','.join(item['sensors']): item for item in json.loads(out)['sensor_sets']}
    for name in ('tensions', 'lengths'):  # the spin about the ring's axis (+z) is open
        assert not sets[name]['determined']
        assert SPIN in sets[name]['message'] and '1.00)' in sets[name]['message']
    assert sets['tensions,imu']['determined'] and sets['tensions,imu']['redundancy'] > 0
    assert sets['pose']['determined'] and sets['pose']['redundancy'] == 0
    assert sets['wrench,tensions']['load'] == 'measured'
    assert sets['wrench,tensions']['determined']


def test_the_text_output_has_one_line_per_set(ring12, capsys):
    capsys.readouterr()
    assert main(['check-config', str(ring12), '--sensors', 'tensions', 'tensions,imu']) == 0
    lines = [line for line in capsys.readouterr()[0].splitlines()
             if line.startswith('sensors ')]
    assert lines[0].startswith('sensors tensions (load unknown): determined: no: ')
    assert lines[1].startswith('sensors tensions,imu (load unknown): determined: yes, ')


def test_an_unknown_sensor_is_refused(ring12, capsys):
    assert main(['check-config', str(ring12), '--sensors', 'tensions,sonar']) == 2
    assert 'unknown sensor sonar (known: tensions, lengths, imu, pose, wrench' in \
        capsys.readouterr()[1]


def test_a_weakly_determined_direction_is_named_not_a_singular_matrix(ring12):
    model = JointModel.from_yaml(ring12)
    state = model.evaluate(model.initial_screw)
    estimate = estimate_joint_state(model, Measurements(lengths=state.lengths, length_std=1e-4))
    assert not estimate.success and not estimate.observable
    assert 'singular normal matrix' not in estimate.message
    assert SPIN in estimate.message
