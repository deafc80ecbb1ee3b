"""The command line under hostile files and options (issue #42, the command line; issue #39,
strict configs): every case exits 2 with one error line naming the problem, no traceback and no
numpy warning before it, in bounded time; what ``new-config`` writes the other tools accept;
``modes --spine`` works with link masses; a damaged recording says how much was read and fails
unless asked to go on."""

from __future__ import annotations

import json
import re
import shutil
import warnings
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.cli_runs import run

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.parser import main
from tensegrity_stiffness.mechanics.chain import MAX_JOINTS, JointChain
from tensegrity_stiffness.mechanics.joint import MAX_STRINGS, JointModel


def refused(capsys, *argv: object) -> str:
    """The one error line of a refused command (exit 2, no traceback, no numpy warning)."""
    code, _, err = run(capsys, *argv)
    assert code == 2, err
    assert 'Traceback' not in err and 'RuntimeWarning' not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and lines[0].startswith('tensegrity-stiffness: error: '), err
    return lines[0]


@pytest.fixture(scope='module')
def ring_document(tmp_path_factory) -> dict:
    path = tmp_path_factory.mktemp('ring') / 'ring.yaml'
    assert main(['new-config', '--template', 'ring', '--out', str(path)]) == 0
    return config.load_yaml(path)


def joint_of(document: dict) -> dict:
    return config.parameters(document)['joint']


def write(tmp_path: Path, document: object, name: str = 'joint.yaml') -> Path:
    path = tmp_path / name
    path.write_text(yaml.safe_dump(document), encoding='utf-8')
    return path


# ------------------------------------------------------------------------------ files
def test_a_yaml_nested_20000_deep_is_refused_without_a_traceback(tmp_path, capsys):
    path = tmp_path / 'deep.yaml'
    path.write_text('joint: ' + '[' * 20000 + ']' * 20000, encoding='utf-8')
    assert 'nested too deeply' in refused(capsys, 'check-config', path)


def test_a_file_over_the_size_limit_is_refused_before_it_is_read(tmp_path, capsys):
    path = tmp_path / 'huge.yaml'
    with path.open('w', encoding='utf-8') as handle:  # one 2 MB line
        handle.write('joint: {string_names: [' + 'a, ' * (config.MAX_CONFIG_BYTES // 3 + 1)
                     + 'a]}\n')
    line = refused(capsys, 'check-config', path)
    assert f'more than the {config.MAX_CONFIG_BYTES}' in line


def test_a_file_that_is_not_text_is_refused(tmp_path, capsys):
    path = tmp_path / 'binary.yaml'
    path.write_bytes(b'joint: \xff\xfe\x00\x81')
    assert 'not UTF-8 text' in refused(capsys, 'check-config', path)


def test_more_strings_than_a_joint_may_have_are_refused(ring_document, tmp_path):
    joint = dict(joint_of(ring_document))
    n = MAX_STRINGS + 1
    joint.update(string_names=[f's{i}' for i in range(n)],
                 string_link1_nodes=['P'] * n, string_link2_nodes=['R0'] * n,
                 stiffness=[77.0], rest_lengths=[0.02], max_lengths=[], initial_screw=[])
    with pytest.raises(ValueError, match=f'more than the {MAX_STRINGS}'):
        JointModel.from_dict(joint)


# ------------------------------------------------------------------------------ names and keys
def test_a_config_of_20000_strings_of_unknown_nodes_is_refused_in_a_short_line(
        ring_document, tmp_path, capsys):
    """A file near the size limit with 20,000 strings between nodes that do not exist: the
    count is judged before any name is looked up, and the line stays short (it listed every
    unknown name: 660 KB for 1e5 strings)."""
    document = yaml.safe_load(yaml.safe_dump(ring_document))
    joint = joint_of(document)
    n = 20_000
    joint.update(string_link1_nodes=[f'no_node_{i:05d}' for i in range(n)],
                 string_link2_nodes=[f'nor_this_{i:05d}' for i in range(n)])
    path = write(tmp_path, document)
    assert 0.5 * config.MAX_CONFIG_BYTES < path.stat().st_size <= config.MAX_CONFIG_BYTES
    line = refused(capsys, 'check-config', path)
    assert f'{n} strings, more than the {MAX_STRINGS}' in line
    assert len(line) < 300, len(line)


def test_many_unknown_or_repeated_names_are_named_first_few_and_counted(ring_document,
                                                                        tmp_path, capsys):
    document = yaml.safe_load(yaml.safe_dump(ring_document))
    joint = joint_of(document)
    n = MAX_STRINGS
    joint.update(string_link1_nodes=[f'no_such_node_{i:06d}' for i in range(n)],
                 string_link2_nodes=[joint['string_link2_nodes'][0]] * n,
                 string_names=[], stiffness=[77.0], rest_lengths=[0.02], max_lengths=[],
                 initial_screw=[])
    line = refused(capsys, 'check-config', write(tmp_path, document))
    assert "unknown nodes ['no_such_node_000000', " in line
    assert f'and {n - 5} more ({n} in all)' in line and len(line) < 400, line
    path = tmp_path / 'ring40.yaml'
    assert main(['new-config', '--template', 'ring', '--strings', '40', '--out', str(path)]) == 0
    capsys.readouterr()
    document = config.load_yaml(path)
    joint_of(document)['string_names'] = [f'pair_{i // 2}' for i in range(40)]
    line = refused(capsys, 'check-config', write(tmp_path, document))
    assert "got ['pair_0', 'pair_1', 'pair_10', " in line and '(20 in all)' in line, line
    assert len(line) < 400, line


def test_duplicate_string_names_are_named(ring_document, tmp_path, capsys):
    document = yaml.safe_load(yaml.safe_dump(ring_document))
    names = joint_of(document)['string_names']
    names[1] = names[0]
    line = refused(capsys, 'check-config', write(tmp_path, document))
    assert f"joint.string_names must be unique, got ['{names[0]}'] more than once" in line


def test_duplicate_node_names_are_named_not_reported_as_unknown(ring_document, tmp_path,
                                                               capsys):
    document = yaml.safe_load(yaml.safe_dump(ring_document))
    nodes = joint_of(document)['node_names']
    nodes[1] = nodes[0]
    line = refused(capsys, 'check-config', write(tmp_path, document))
    assert f"joint.node_names must be unique, got ['{nodes[0]}']" in line
    assert 'unknown' not in line


@pytest.mark.parametrize(('typo', 'key'), [('stifness', 'stiffness'),
                                           ('link2_mas', 'link2_mass')])
def test_a_misspelt_key_is_refused_with_the_nearest_name_and_one_prefix(
        ring_document, tmp_path, capsys, typo, key):
    document = yaml.safe_load(yaml.safe_dump(ring_document))
    joint = joint_of(document)
    joint[typo] = joint.pop(key)
    line = refused(capsys, 'check-config', write(tmp_path, document))
    assert line.endswith(f'joint.{typo}: unknown key (did you mean joint.{key}?)')
    assert 'joint.joint' not in line


def test_a_missing_key_is_named_once(ring_document):
    joint = dict(joint_of(ring_document))
    del joint['stiffness']
    with pytest.raises(ValueError) as caught:
        JointModel.from_dict(joint)
    assert str(caught.value) == 'joint.stiffness is missing'


def test_strict_false_warns_about_an_unknown_key_and_reads_the_rest(ring_document):
    joint = {**joint_of(ring_document), 'colour': 'red'}
    with pytest.warns(config.UnknownKeyWarning, match='joint.colour: unknown key'):
        model = JointModel.from_dict(joint, strict=False)
    assert model.n_strings == len(joint['string_names'])


def test_a_chain_section_key_and_a_joint_override_key_are_checked(tmp_path, capsys):
    path = tmp_path / 'spine.yaml'
    assert main(['new-config', '--spine', '2', '--out', str(path)]) == 0
    document = config.load_yaml(path)
    params = config.parameters(document)
    params['chain']['link_mases'] = [0.02]
    with pytest.raises(ValueError, match=r'chain.link_mases: unknown key \(did you mean '
                                         r'chain.link_masses\?\)'):
        JointChain.from_dict(document)
    del params['chain']['link_mases']
    params['joint_2'] = {'rest_length': [0.03]}
    with pytest.raises(ValueError, match=r'joint_2.rest_length: unknown key \(did you mean '
                                         r'joint_2.rest_lengths\?\)'):
        JointChain.from_dict(document)
    del params['joint_2']
    params['chain']['n_joints'] = MAX_JOINTS + 1
    with pytest.raises(ValueError, match=f'in \\[1, {MAX_JOINTS}\\]'):
        JointChain.from_dict(document)


# ------------------------------------------------------------------------------ new-config
@pytest.mark.parametrize(('options', 'words'), [
    (['--template', 'vertebra', '--strings', '8'], 'n_strings: only the ring template'),
    (['--template', 'vertebra', '--height', '0.05', '--gap', '0.02'],
     'height, gap: only the ring template'),
    (['--template', 'ring', '--pretension', '2'], 'it can carry at most 1.54 N'),
    (['--link2-inertia', '0', '0', '0'], 'link2_inertia must be positive definite'),
    (['--link2-inertia', '-1', '1', '1'], 'link2_inertia must be positive definite'),
    (['--link2-inertia', '1', '1'], 'link2_inertia must be 3 principal moments'),
    (['--spine', '100000'], f'n_joints must be in [1, {MAX_JOINTS}]'),
    (['--template', 'ring', '--strings', '1000000'], f'<= {MAX_STRINGS} (MAX_STRINGS)'),
])
def test_new_config_refuses_what_the_other_tools_would_refuse(tmp_path, capsys, options,
                                                              words):
    out = tmp_path / 'new.yaml'
    assert words in refused(capsys, 'new-config', *options, '--out', out)
    assert not out.exists()


@pytest.mark.parametrize('options', [[], ['--template', 'ring'],
                                     ['--template', 'ring', '--strings', '12',
                                      '--pretension', '1.5'],
                                     ['--spine', '3', '--link2-inertia', '1e-6', '1e-6',
                                      '2e-6']])
def test_what_new_config_writes_every_tool_accepts(tmp_path, capsys, options):
    out = tmp_path / 'new.yaml'
    assert run(capsys, 'new-config', *options, '--out', out)[0] == 0
    code, stdout, err = run(capsys, 'check-config', out)
    assert code == 0 and 'sound: yes' in stdout, err
    assert run(capsys, 'modes', '--config', out, *(['--spine'] if '--spine' in options
                                                    else []))[0] == 0


def test_check_config_fails_on_strings_saturated_at_the_design_pose(ring_document, tmp_path,
                                                                    capsys):
    document = yaml.safe_load(yaml.safe_dump(ring_document))
    joint = joint_of(document)
    # The apex strings' maximum length just above their rest length: saturated when unloaded.
    joint['max_lengths'] = [r + (1e-4 if name.startswith('apex') else 0.02)
                            for r, name in zip(joint['rest_lengths'], joint['string_names'],
                                               strict=True)]
    code, out, err = run(capsys, 'check-config', write(tmp_path, document))
    assert code == 2 and 'sound: no' in out
    assert 'strings at their maximum length at the unloaded equilibrium' in err


def packaged_with(tmp_path: Path, section: str, key: str, value: object,
                  strict: bool | None = None) -> Path:
    """The packaged default_joint.yaml (node sections and all) with ``section.key`` set."""
    document = config.load_yaml(config.packaged_config_path())
    params = config.parameters(document)
    params.setdefault(section, {})[key] = value
    if strict is not None:
        params['strict_parameters'] = strict
    return write(tmp_path, document)


def test_check_config_names_a_misspelt_node_key_with_the_nearest(tmp_path, capsys):
    """A key of a node's section no node has: the node would refuse to start, so the file is
    not sound (issue #39: it said ``sound: yes``)."""
    path = packaged_with(tmp_path, 'limits', 'tension_maxx', 3.0)
    code, out, err = run(capsys, 'check-config', path)
    assert code == 2 and 'sound: no' in out, err
    assert err.strip() == ('tensegrity-stiffness: error: limits.tension_maxx: unknown key '
                           '(did you mean limits.tension_max?)')
    code, out, err = run(capsys, 'check-config', path, '--sensors', 'tensions,imu', '--json')
    assert code == 2 and json.loads(out)['sound'] is False
    assert 'limits.tension_maxx: unknown key (did you mean limits.tension_max?)' in err


def test_check_config_with_strict_parameters_false_notes_a_node_key(tmp_path, capsys):
    path = packaged_with(tmp_path, 'limits', 'tension_maxx', 3.0, strict=False)
    code, out, err = run(capsys, 'check-config', path)
    assert code == 0 and 'sound: yes' in out, err
    assert ('note: limits.tension_maxx: unknown key (did you mean limits.tension_max?): '
            'ignored (strict_parameters: false)') in out


def test_check_config_accepts_every_node_s_parameters_in_one_file(tmp_path, capsys):
    """A file shared by several nodes: each one's parameters are no mistake."""
    document = config.load_yaml(config.packaged_config_path())
    params = config.parameters(document)
    params.setdefault('limits', {}).update(tension_max=3.0, max_force=50.0)
    params.setdefault('sim', {})['rate'] = 500.0
    code, out, err = run(capsys, 'check-config', write(tmp_path, document))
    assert code == 0 and 'sound: yes' in out, err


def test_a_misspelt_dynamics_key_is_refused_with_the_nearest(tmp_path, capsys):
    path = packaged_with(tmp_path, 'dynamics', 'string_dampin', 0.0)
    expected = 'dynamics.string_dampin: unknown key (did you mean dynamics.string_damping?)'
    for argv in (('check-config', path), ('modes', '--config', path),
                 ('modes', '--config', path, '--string-damping', '0')):
        assert refused(capsys, *argv).endswith(expected)


# ------------------------------------------------------------------------------ modes
def test_modes_of_a_spine_with_link_masses(tmp_path, capsys):
    path = tmp_path / 'spine.yaml'
    assert main(['new-config', '--spine', '3', '--out', str(path)]) == 0
    capsys.readouterr()
    frequencies = {}
    for mass in (0.0, 0.02):  # 0: the twin's default mass without weight (documented)
        document = config.load_yaml(path)
        config.parameters(document)['chain']['link_masses'] = [mass]
        code, out, err = run(capsys, 'modes', '--spine', '--config',
                             write(tmp_path, document, f'spine_{mass}.yaml'), '--json')
        assert code == 0, err
        frequencies[mass] = np.array([m['frequency_hz'] for m in json.loads(out)['modes']])
        assert np.all(np.isfinite(frequencies[mass])) and np.all(frequencies[mass] > 0)
    # The weights bend the spine: another equilibrium, other frequencies.
    assert not np.allclose(frequencies[0.0], frequencies[0.02], rtol=1e-3)


# ------------------------------------------------------------------------------ numbers
@pytest.mark.parametrize('argv', [['joint', '--screw', '1e308', '0', '0', '0', '0', '0']])
def test_an_absurd_number_gives_the_error_line_alone(capsys, argv):
    with warnings.catch_warnings():
        warnings.simplefilter('error', RuntimeWarning)
        assert '|omega|' in refused(capsys, *argv)


# ------------------------------------------------------------------------------ damaged bags
@pytest.fixture(scope='module')
def bags(tmp_path_factory):
    pytest.importorskip('rosbags')
    from support.calibration_recordings import (
        configurations,
        nominal_model,
        time_series,
        true_parameters,
        write_bag,
    )

    from tensegrity_stiffness.estimation import calibration as cal

    folder = tmp_path_factory.mktemp('bags')
    model = nominal_model()
    k, d = true_parameters(model, 23)
    states = configurations(model, k, d, 40, 23)
    series = time_series(model, states, 23, cal.CalibrationNoise(), tensions=(1, 6))
    whole = folder / 'whole'
    write_bag(whole, series, 'mcap', pose_type='PoseStamped')
    damaged = folder / 'damaged'
    shutil.copytree(whole, damaged)
    mcap = next(damaged.glob('*.mcap'))
    data = bytearray(mcap.read_bytes())
    start = len(data) // 2
    data[start:start + 200] = bytes(b ^ 0xFF for b in data[start:start + 200])
    mcap.write_bytes(bytes(data))
    return whole, damaged


@pytest.mark.parametrize('command', ['calibrate', 'bag'])
def test_a_damaged_bag_says_how_much_was_read_and_fails(bags, tmp_path, capsys, command):
    whole, damaged = bags
    out = tmp_path / ('out.yaml' if command == 'calibrate' else 'out')
    line = refused(capsys, command, damaged, '--out', out)
    assert f'{damaged}: damaged: ' in line and ' messages read (' in line
    assert '--allow-damaged' in line
    assert not out.exists()
    assert run(capsys, command, whole, '--out', tmp_path / 'whole_out')[0] == 0


def test_allow_damaged_goes_on_with_what_was_read(bags, tmp_path, capsys):
    from tensegrity_stiffness.recordings.bag import MessageReading

    _, damaged = bags
    # The flipped bytes are in the bag's only chunk: nothing of it is readable, so going on
    # with what was read ends in the refusal of a recording without rest lengths, which says
    # how much of the storage was read (docs/command_line.md's limits table), not a fit.
    line = refused(capsys, 'calibrate', damaged, '--out', tmp_path / 'c.yaml',
                   '--allow-damaged')
    assert 'no valid message on the rest_lengths topic' in line and '--allow-damaged' not in line
    match = re.search(r'\(damaged: (\d+) of (\d+) messages read \(\w+', line)
    assert match, line
    read, total = int(match[1]), int(match[2])
    assert read < total and total == 1840, line  # 40 rest lengths, 600 each of 3 signals
    assert not (tmp_path / 'c.yaml').exists()
    reading = MessageReading(10, 4, 'OverflowError: x')
    assert reading.summary() == 'damaged: 4 of 10 messages read (OverflowError: x)'
