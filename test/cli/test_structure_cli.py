"""``tensegrity-stiffness structure``: check (sound exit 0, the reason and exit 2 otherwise),
equilibrium, form-find (force density, kinematic, design) and the 3D figure, on the worked
examples and templates; the installed command run as a subprocess from a scratch folder outside
the repository, the rest in process through ``main``."""

from __future__ import annotations

import json
import math
import struct
import subprocess
import sys

import numpy as np
import pytest
import yaml
from support.cli_runs import run, run_json

from tensegrity_stiffness.cli.common import EXIT_BAD_INPUT, EXIT_NO_SOLUTION
from tensegrity_stiffness.cli.parser import main
from tensegrity_stiffness.structures import templates
from tensegrity_stiffness.structures.structure import Structure


def write_prism(tmp_path, name='prism.yaml', **kwargs):
    path = tmp_path / name
    assert main(['new-config', '--template', 'prism', '--out', str(path),
                 *[str(a) for pair in kwargs.items() for a in pair]]) == 0
    return path


def test_check_the_worked_examples_in_a_subprocess_outside_the_repository(tmp_path):
    for name in ('three_bar.yaml', 'six_bar.yaml'):
        proc = subprocess.run([sys.executable, '-m', 'tensegrity_stiffness.cli', 'structure',
                               'check', '--example', name, '--json'], cwd=tmp_path,
                              capture_output=True, text=True, timeout=120, check=False)
        assert proc.returncode == 0, proc.stderr
        report = json.loads(proc.stdout)
        assert report['sound'] and report['equilibrium']['stable']
        assert report['ground'] and len(report['contacts']) == 3
        weight = sum(0.1 * 9.80665 for _ in range(report['n_bars']))
        normal = sum(f[2] for f in report['contacts'].values())
        assert normal == pytest.approx(weight, rel=1e-9)
        a = report['analysis']
        assert (a['self_stresses'], a['mechanisms']) == (1, 1)
        assert a['super_stable'] and a['prestress_stable']
        # Three sticking contacts (9 constraints) and a spin per bar leave 6N - 9 - N modes.
        n = report['n_bars']
        assert report['modes']['counts']['spins'] == n
        assert len(report['modes']['frequencies_hz']) == 6 * n - 9 - n


def test_check_table_and_json_agree(capsys, tmp_path):
    path = write_prism(tmp_path, **{'--bars': 5})
    code, out, _ = run(capsys, 'structure', 'check', str(path))
    assert code == 0 and 'sound: yes' in out
    assert 'analysis: 1 self-stress(es), 5 mechanism(s)' in out
    report = run_json(capsys, 'structure', 'check', str(path))
    assert report['analysis']['mechanisms'] == 2 * 5 - 5
    assert report['contacts'] == {} and report['slack'] == []
    q = report['analysis']['force_densities']
    ring, vertical, _ = templates.prism_force_densities(5)
    assert q['vertical_0'] / q['bottom_0'] == pytest.approx(vertical / ring, rel=1e-8)


def test_check_an_unsound_structure_exits_2_with_the_reason(capsys, tmp_path):
    """Strings too long to hold anything: the start is no equilibrium and none is stable."""
    path = tmp_path / 'loose.yaml'
    document = templates.prism_document(3)
    for entry in document['structure']['strings']:
        entry['rest_length'] *= 3.0
    path.write_text(yaml.safe_dump(document))
    code, out, err = run(capsys, 'structure', 'check', str(path))
    assert code == EXIT_BAD_INPUT
    assert 'sound: no' in out and 'error:' in err
    code, _, err = run(capsys, 'structure', 'check', str(tmp_path / 'missing.yaml'))
    assert code == EXIT_BAD_INPUT and 'missing.yaml' in err
    code, _, err = run(capsys, 'structure', 'check')
    assert code == EXIT_BAD_INPUT and 'FILE or --example' in err


@pytest.mark.parametrize('p', (3, 4, 5, 6))
def test_equilibrium_from_a_wrong_twist_returns_to_90_minus_180_over_p(capsys, tmp_path, p):
    path = write_prism(tmp_path, **{'--bars': p, '--twist': templates.prism_twist(p) + 0.15})
    out_file = tmp_path / 'at_equilibrium.yaml'
    result = run_json(capsys, 'structure', 'equilibrium', str(path), '--out', str(out_file))
    assert result['success'] and result['stable']
    s = Structure.from_yaml(out_file)
    X = s.node_positions(s.transforms())
    bottom = [s.node_index(f'bar{i}.a') for i in range(p)]
    top = [s.node_index(f'bar{(i - 1) % p}.b') for i in range(p)]  # t_i ends bar i-1
    b, t = X[bottom] - X[bottom].mean(axis=0), X[top] - X[top].mean(axis=0)
    axis = np.cross(b[1] - b[0], b[2] - b[0])
    axis /= np.linalg.norm(axis)
    u = b[0] / np.linalg.norm(b[0])
    v = np.cross(axis, u)
    turn = math.atan2(t[0] @ v, t[0] @ u)  # vertical_0 joins b0 to t0: the twist itself
    assert turn == pytest.approx(templates.prism_twist(p), abs=1e-7)


def test_form_find_force_density_kinematic_and_design(capsys, tmp_path):
    path = write_prism(tmp_path, **{'--bars': 3, '--twist': 0.9})
    out = tmp_path / 'fd.yaml'
    s3 = '3**0.5'
    report = run_json(capsys, 'structure', 'form-find', str(path), '--method',
                      'force-density', '--density', 'bottom=1', '--density', 'top=1',
                      '--density', f'vertical={s3}', '--density', f'bar=-{s3}',
                      '--pretension', '4', '--out', str(out))
    assert report['success'] and report['nullity'] == 4
    found = Structure.from_yaml(out)
    state = found.evaluate()
    assert np.abs(state.wrenches).max() < 1e-10 and state.tensions.max() == pytest.approx(4.0)
    kin = tmp_path / 'kin.yaml'
    report = run_json(capsys, 'structure', 'form-find', str(path), '--method', 'kinematic',
                      '--out', str(kin))
    assert report['success'] and report['self_stresses'] == 1
    assert np.abs(Structure.from_yaml(kin).evaluate().wrenches).max() < 1e-9
    report = run_json(capsys, 'structure', 'form-find', str(out), '--method', 'design',
                      '--t-min', '2', '--t-max', '6')
    assert report['success']
    assert all(2.0 - 1e-9 <= t <= 6.0 + 1e-9 for t in report['tensions'].values())
    code, _, err = run(capsys, 'structure', 'form-find', str(path), '--method', 'force-density',
                       '--density', 'bottom=1')
    assert code == EXIT_BAD_INPUT and "no prefix matches member 'top_0'" in err
    code, _, _ = run(capsys, 'structure', 'form-find', str(out), '--method', 'design',
                     '--t-min', '2', '--t-max', '2.5')
    assert code == EXIT_NO_SOLUTION


def _png_size(path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == b'\x89PNG\r\n\x1a\n'
    return struct.unpack('>II', data[16:24])


def test_the_3d_figure(capsys, tmp_path):
    pytest.importorskip('matplotlib')
    png = tmp_path / 'six_bar.png'
    code, _, err = run(capsys, 'structure', 'plot', '--example', 'six_bar.yaml', '--out',
                       str(png), '--width', '400', '--height', '300')
    assert code == 0, err
    assert _png_size(png) == (400, 300)
    start = tmp_path / 'start.png'
    assert main(['structure', 'plot', '--example', 'three_bar.yaml', '--start', '--out',
                 str(start)]) == 0
    assert _png_size(start) == (900, 700)
    check_png = tmp_path / 'check.png'
    assert main(['structure', 'check', '--example', 'three_bar.yaml', '--plot',
                 str(check_png)]) == 0
    assert check_png.stat().st_size > 10_000


@pytest.mark.parametrize('p', (3, 4))
def test_modes_of_a_free_prism_name_its_zero_modes(capsys, tmp_path, p):
    """Free-floating: 6 rigid motions and a spin per bar; the pin-jointed framework's 2p - 5
    mechanisms are stiffened by the prestress, so they are modes with a frequency."""
    path = write_prism(tmp_path, **{'--bars': p})
    report = run_json(capsys, 'structure', 'modes', str(path))
    assert report['counts'] == {'rigid': 6, 'spins': p, 'mechanisms': 0}
    assert len(report['frequencies_hz']) == 6 * p - 6 - p
    assert report['stable'] and min(report['frequencies_hz']) > 0.0
    code, out, _ = run(capsys, 'structure', 'modes', str(path))
    assert code == 0 and f'(6 rigid, {p} spins, 0 mechanisms)' in out


def test_a_joint_config_as_a_structure_checks_sound(capsys, tmp_path):
    from support import REPO

    path = tmp_path / 'joint_structure.yaml'
    assert main(['new-config', '--template', 'from-config', '--config',
                 str(REPO / 'config' / 'default_joint.yaml'), '--out', str(path)]) == 0
    capsys.readouterr()
    report = run_json(capsys, 'structure', 'check', str(path))
    assert report['sound'] and report['equilibrium']['iterations'] == 0  # written at it
    assert report['body_counts'] == {'rank': 6, 'self_stresses': 6, 'mechanisms': 0,
                                     'rigid_motions': 0, 'spins': 0}
    assert report['analysis'] is None
    assert any("'link2' is a free body of 4 nodes" in note for note in report['notes'])
    code, _, err = run(capsys, 'new-config', '--template', 'from-config')
    assert code == EXIT_BAD_INPUT and 'needs --config FILE' in err


def test_the_command_line_page_s_structure_commands_run(capsys, tmp_path, monkeypatch):
    """docs/command_line.md's structure block, as printed, from a scratch folder."""
    import re
    import shlex

    from support import REPO

    text = (REPO / 'docs' / 'command_line.md').read_text(encoding='utf-8')
    block = next(b for b in re.findall(r'```bash\n(.*?)```', text, re.S)
                 if 'structure check' in b)
    monkeypatch.chdir(tmp_path)
    for line in block.splitlines():
        argv = shlex.split(line)[1:]
        code = main(argv)
        _, err = capsys.readouterr()
        assert code == 0, (argv, err)
    assert (tmp_path / 'designed.yaml').is_file()


@pytest.mark.parametrize('argv, message', [
    (['--template', 'prism', '--rest-lengths', '0.1'], '--rest-lengths does not apply'),
    (['--template', 'six-bar', '--radius', '0.1'], '--radius does not apply'),
    (['--template', 'ring', '--bars', '4'], '--bars does not apply'),
    (['--template', 'vertebra', '--ground'], '--ground does not apply'),
    (['--template', 'prism', '--bars', '2'], 'bars must be an integer >= 3'),
])
def test_new_config_refuses_options_its_template_does_not_take(capsys, argv, message):
    code, _, err = run(capsys, 'new-config', *argv)
    assert code == EXIT_BAD_INPUT and message in err
