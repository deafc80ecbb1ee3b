"""docs/your_joint.md on the command line: every ``tensegrity-stiffness`` command of the page runs
(in a scratch folder, in process) and the worked examples it makes are the files shipped in
config/examples/; ``new-config`` / ``check-config`` and the rule for ``initial_screw`` at the
command line (a missing one solved, a wrong one a line on stderr; ``check-config`` exit 2)."""

from __future__ import annotations

import json
import re
import shlex

import numpy as np
import pytest
import yaml
from support import REPO

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.parser import main

PAGE = REPO / 'docs' / 'your_joint.md'
EXAMPLES = REPO / 'config' / 'examples'


def _page_commands() -> list[list[str]]:
    blocks = re.findall(r'```bash\n(.*?)```', PAGE.read_text(encoding='utf-8'), re.S)
    return [shlex.split(line)[1:] for block in blocks for line in block.splitlines()
            if line.startswith('tensegrity-stiffness ')]


def test_every_command_of_the_page_runs(tmp_path, monkeypatch, capsys):
    commands = _page_commands()
    assert len(commands) >= 12
    monkeypatch.chdir(tmp_path)
    for argv in commands:
        code = main(argv)
        out, err = capsys.readouterr()
        assert code == 0, (argv, err)
        assert 'warning' not in err, (argv, err)
        if argv[0] == 'check-config':
            assert 'sound: yes' in out
    made = sorted(p.name for p in tmp_path.glob('ring*.yaml'))
    assert made == sorted(p.name for p in EXAMPLES.glob('ring*.yaml'))
    for name in made:  # the shipped examples are what the page's commands write
        assert (tmp_path / name).read_text() == (EXAMPLES / name).read_text(), name


def _section(number: int) -> str:
    """The text of the page's section ``number`` (``## <number>.`` to the next ``## ``)."""
    text = PAGE.read_text(encoding='utf-8')
    start = text.index(f'\n## {number}. ')
    end = text.find('\n## ', start + 1)
    return text[start:] if end < 0 else text[start:end]


def test_section_6_states_what_check_config_sensors_prints(tmp_path, monkeypatch, capsys):
    """The results section 6 states for its ``check-config --sensors`` commands (the quoted
    ``undetermined: ...`` and ``determined: ...`` in the page's order, the pose std to the
    digits shown) are what the commands print: read from the page, so the two cannot drift."""
    section = _section(6)
    commands = [shlex.split(line)[1:] for block in re.findall(r'```bash\n(.*?)```', section,
                                                               re.S)
                for line in block.splitlines() if line.startswith('tensegrity-stiffness ')]
    sensor_runs = [argv for argv in commands if argv[0] == 'check-config' and '--sensors' in argv]
    stated = re.findall(r'`((?:un)?determined: [^`]*)`', section)
    assert len(sensor_runs) >= 2 and len(stated) == len(sensor_runs), (sensor_runs, stated)
    monkeypatch.chdir(tmp_path)
    lines = []
    for argv in commands:
        assert main(argv) == 0, argv
        out = capsys.readouterr().out
        if argv in sensor_runs:
            found = [line for line in out.splitlines() if line.startswith('sensors ')]
            assert len(found) == 1, out
            lines.append(found[0])
    for expected, line in zip(stated, lines, strict=True):
        assert expected in line, (expected, line)
    std = re.search(r'pose std ([0-9.]+) mm / ([0-9.]+) deg', section)
    printed = re.search(r'pose std ([0-9.]+) mm / ([0-9.]+) deg', ' '.join(lines))
    assert std and printed, (section, lines)
    for shown, value in zip(std.groups(), printed.groups(), strict=True):
        digits = len(shown.partition('.')[2])
        assert float(shown) == pytest.approx(float(value), abs=0.5 * 10.0 ** -digits), \
            (shown, value)


def test_example_paths_and_check_config_example(capsys):
    path = config.example_config_path('ring8_joint.yaml')
    assert path.is_file() and path.parent.name == 'examples'
    assert main(['check-config', '--example', 'ring8_joint.yaml', '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    assert report['config'] == str(path) and report['sound']
    with pytest.raises(ValueError, match='no packaged example'):
        config.example_config_path('nope.yaml')
    assert main(['check-config', '--example', 'nope.yaml']) == 2
    assert 'ring16_joint.yaml' in capsys.readouterr().err


def _write(path, joint):
    path.write_text(yaml.safe_dump({'joint': joint}))
    return path


def test_check_config_json_and_exit_codes(tmp_path, capsys):
    good = tmp_path / 'good.yaml'
    assert main(['new-config', '--template', 'ring', '--strings', '10', '--out', str(good)]) == 0
    capsys.readouterr()
    assert main(['check-config', str(good), '--json']) == 0
    report = json.loads(capsys.readouterr().out)
    joint = config.load_section(good, 'joint')
    assert report['screw'] == pytest.approx(joint['initial_screw'], abs=1e-12)
    assert report['residual'] < 1e-9 and report['stable'] and report['sound']
    assert report['initial_screw'] == {'given': True, 'value': joint['initial_screw'],
                                       'residual': pytest.approx(report['residual']),
                                       'equilibrium': True}
    wrong = dict(joint, initial_screw=[0.0, 0.0, 0.0, 0.0, 0.0, 0.02])
    assert main(['check-config', str(_write(tmp_path / 'wrong.yaml', wrong))]) == 2
    out, err = capsys.readouterr()
    assert 'NOT an unloaded equilibrium' in out
    assert re.search(r'error: joint\.initial_screw is not an unloaded equilibrium: residual '
                     r'\|F\| = [0-9.]+e[-+]\d+', err)
    assert main(['check-config', str(_write(tmp_path / 'bad.yaml', dict(joint, stiffness=[-1])))
                 ]) == 2
    assert 'joint.stiffness must be > 0' in capsys.readouterr().err


def test_joint_and_equilibrium_follow_the_rule(tmp_path, capsys):
    """Missing: solved, no warning; wrong: one stderr line naming the residual, and the command
    still reports at it (as the node would)."""
    joint = dict(config.load_section(EXAMPLES / 'ring8_joint.yaml', 'joint'))
    written = np.asarray(joint.pop('initial_screw'))
    missing = _write(tmp_path / 'missing.yaml', joint)
    assert main(['joint', '--config', str(missing), '--json']) == 0
    out, err = capsys.readouterr()
    assert err == ''
    np.testing.assert_allclose(json.loads(out)['screw'], written, atol=1e-12)
    wrong = _write(tmp_path / 'wrong.yaml', dict(joint, initial_screw=[0, 0, 0, 0, 0, 0.02]))
    assert main(['equilibrium', '--config', str(wrong), '--wrench', '0', '0', '0', '0', '0', '0',
                 '--json']) == 0
    out, err = capsys.readouterr()
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith('tensegrity-stiffness: warning: joint.'
                                                   'initial_screw is not an unloaded equilibrium')
    np.testing.assert_allclose(json.loads(out)['screw'], written, atol=1e-12)


def test_new_config_to_stdout_and_bad_choices(capsys):
    assert main(['new-config', '--template', 'vertebra', '--radius', '0.04']) == 0
    out = capsys.readouterr().out
    assert out.startswith('# Starter config written by tensegrity-stiffness new-config')
    assert config.section(yaml.safe_load(out), 'joint')['link1_nodes'][0] == pytest.approx(-0.04)
    assert main(['new-config', '--template', 'ring', '--strings', '7']) == 2
    assert 'n_strings must be even' in capsys.readouterr().err
    assert main(['new-config', '--pretension', '1', '--rest-lengths', '0.03']) == 2


def _page_shell_commands() -> list[list[str]]:
    """The page's ``bash scripts/...`` lines (the demos), as argument lists."""
    blocks = re.findall(r'```bash\n(.*?)```', PAGE.read_text(encoding='utf-8'), re.S)
    return [shlex.split(line) for block in blocks for line in block.splitlines()
            if line.startswith('bash scripts/')]


@pytest.mark.ros
@pytest.mark.slow
def test_the_pages_demos_run_from_outside_the_repository(tmp_path, monkeypatch, capsys):
    """Section 6 from a scratch folder: the page's config commands, then each demo of the page
    (its --duration bounded to 15 s, the loop's to 30 s), with the repository's script by its
    path: each runs the joint the page made, shows its live lines and stops cleanly (exit 0)."""
    import os
    import subprocess

    pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
    monkeypatch.chdir(tmp_path)
    for argv in _page_commands():
        if 'lab_joint.yaml' in argv:
            assert main(argv) == 0, argv
            capsys.readouterr()
    demos = _page_shell_commands()
    assert len(demos) >= 2 and all('lab_joint.yaml' in argv for argv in demos)
    for argv in demos:
        argv = [str(REPO / a) if a.startswith('scripts/') else a for a in argv]
        # bounded: the demo's clock starts with its nodes, whose start alone took 9 s beside
        # the suite's colcon build; long enough for the controller's first state then
        argv[argv.index('--duration') + 1] = '30' if '--control' in argv else '15'
        done = subprocess.run(argv, cwd=tmp_path, capture_output=True, text=True, timeout=300,
                              env=os.environ.copy(), check=False)
        lines = [line for line in done.stdout.splitlines() if line.startswith('t ')]
        assert done.returncode == 0, done.stdout + done.stderr
        assert len(lines) >= 5 and 'stopped (' in done.stdout, done.stdout
        if '--control' in argv:
            assert any('(true ' in line for line in lines), done.stdout
        else:
            assert any('answered' in line and 'slack 0/8' in line for line in lines), done.stdout
