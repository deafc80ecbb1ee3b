"""``tensegrity-stiffness modes``: the table, ``--json``, ``--spine``, ``--string-damping``, the
``--plot`` figure and bad input, against :func:`tensegrity_stiffness.mechanics.dynamics.
modes_from_config`."""

from __future__ import annotations

import dataclasses
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest
import yaml
from support.cli_runs import run

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.common import EXIT_BAD_INPUT, EXIT_OK
from tensegrity_stiffness.cli.dynamics_plots import DEFAULT_SIZE
from tensegrity_stiffness.mechanics import dynamics

#: Relative agreement of the table's 4-decimal frequencies with the library.
TABLE_RTOL = 1e-4


def png_header_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b'\x89PNG\r\n\x1a\n' and head[12:16] == b'IHDR', f'{path} is not a PNG'
    return struct.unpack('>II', head[16:24])


def test_modes_table_is_the_library_s(capsys):
    code, out, err = run(capsys, 'modes')
    assert code == EXIT_OK, err
    _, modes, _ = dynamics.modes_from_config()
    assert out == dynamics.format_modes(modes) + '\n'
    lines = out.splitlines()
    assert lines[0].startswith('mode  frequency (Hz)  damping ratio')
    rows = [line.split() for line in lines[1:-1]]
    assert len(rows) == 6 and lines[-1] == 'stable: yes'
    np.testing.assert_allclose([float(r[1]) for r in rows], modes.frequencies, rtol=TABLE_RTOL)
    assert all(float(r[1]) > 0.0 for r in rows)


def test_modes_json_is_the_report(capsys):
    code, out, err = run(capsys, 'modes', '--json')
    assert code == EXIT_OK, err
    report = json.loads(out)
    _, modes, expected = dynamics.modes_from_config()
    assert report['stable'] is True and len(report['modes']) == 6
    np.testing.assert_allclose([m['frequency_hz'] for m in report['modes']],
                               modes.frequencies, rtol=1e-12)
    assert report.keys() == expected.keys()
    assert report['string_damping'] == expected['string_damping']


def test_modes_of_the_spine_with_string_damping(capsys):
    code, out, err = run(capsys, 'modes', '--spine', '--string-damping', '0.5', '--json')
    assert code == EXIT_OK, err
    report = json.loads(out)
    _, modes, _ = dynamics.modes_from_config(None, True, 0.5)
    assert len(report['modes']) == modes.frequencies.size == 30
    np.testing.assert_allclose([m['damping_ratio'] for m in report['modes']],
                               modes.damping_ratios, rtol=1e-12)
    assert any(m['damping_ratio'] > 0.0 for m in report['modes'])
    code, out, _ = run(capsys, 'modes', '--spine')
    assert code == EXIT_OK and 'joint 1' in out


@pytest.mark.parametrize('spine', [False, True])
def test_undamped_modes_print_a_damping_ratio_of_zero(capsys, spine):
    """``--string-damping 0``: every ratio is 0.0000 in the table and 0 (not -0) in the JSON
    (docs/dynamics.md shows the command)."""
    flag = ('--spine',) if spine else ()
    code, out, err = run(capsys, 'modes', *flag, '--string-damping', '0')
    assert code == EXIT_OK, err
    rows = [line.split() for line in out.splitlines()[1:-1]]
    assert rows and all(row[2] == '0.0000' for row in rows), out
    assert '-0.0' not in out
    code, out, err = run(capsys, 'modes', *flag, '--string-damping', '0', '--json')
    assert code == EXIT_OK, err
    ratios = [m['damping_ratio'] for m in json.loads(out)['modes']]
    assert all(r == 0.0 and math.copysign(1.0, r) == 1.0 for r in ratios), ratios


def test_a_ratio_of_rounding_noise_prints_zero():
    _, modes, _ = dynamics.modes_from_config(None, False, 0.0)
    noisy = dataclasses.replace(modes, damping_ratios=np.full(6, -1e-17))
    assert '-0.0000' not in dynamics.format_modes(noisy)
    assert dynamics.format_modes(noisy) == dynamics.format_modes(modes)


def test_modes_plot_writes_the_figure(capsys, tmp_path):
    pytest.importorskip('matplotlib')
    import matplotlib.image

    path = tmp_path / 'modes.png'
    code, out, err = run(capsys, 'modes', '--plot', str(path))
    assert code == EXIT_OK, err
    assert out.splitlines()[-1] == 'stable: yes'  # stdout: the table only
    assert f'wrote {path} ({DEFAULT_SIZE[0]}x{DEFAULT_SIZE[1]} px)' in err
    assert png_header_size(path) == DEFAULT_SIZE
    assert float(matplotlib.image.imread(path)[..., :3].var()) > 0.0
    spine = tmp_path / 'spine_modes.png'
    code, out, err = run(capsys, 'modes', '--spine', '--json', '--plot', str(spine))
    assert code == EXIT_OK, err
    json.loads(out)  # the figure's line is not in the JSON
    assert png_header_size(spine) == DEFAULT_SIZE


@pytest.mark.parametrize(('example', 'up'), [('ring8_joint.yaml', 'z'), (None, 'y')])
def test_the_mode_figure_stands_the_joint_on_its_own_axis(capsys, tmp_path, monkeypatch,
                                                          example, up):
    """#39: a +z ring joint's figure is drawn with z up (it lay on its side), the +y vertebra
    with y up: every panel's view takes the joint's axis as vertical."""
    pytest.importorskip('matplotlib')
    from mpl_toolkits.mplot3d import Axes3D

    seen = []
    view_init = Axes3D.view_init

    def recorded(self, *args, **kwargs):
        if 'vertical_axis' in kwargs:  # the figure's own views (matplotlib's default: z)
            seen.append(kwargs['vertical_axis'])
        return view_init(self, *args, **kwargs)

    monkeypatch.setattr(Axes3D, 'view_init', recorded)
    path = config.example_config_path(example) if example else config.packaged_config_path()
    code, _, err = run(capsys, 'modes', '--config', path, '--plot', tmp_path / 'modes.png')
    assert code == EXIT_OK, err
    assert seen == [up] * 6


def test_modes_bad_input_is_exit_2(capsys, tmp_path):
    joint = dict(config.load_section(config.packaged_config_path(), 'joint'), link2_mass=-1.0)
    bad = tmp_path / 'bad.yaml'
    bad.write_text(yaml.safe_dump({'joint': joint}))
    code, out, err = run(capsys, 'modes', '--config', str(bad))
    assert code == EXIT_BAD_INPUT and out == ''
    assert err.startswith('tensegrity-stiffness: error:') and 'link2_mass' in err
    assert 'Traceback' not in err
    code, _, err = run(capsys, 'modes', '--config', str(tmp_path / 'missing.yaml'))
    assert code == EXIT_BAD_INPUT and 'missing.yaml' in err
    code, _, err = run(capsys, 'modes', '--string-damping', '-1')
    assert code == EXIT_BAD_INPUT and 'string_damping' in err
    code, _, err = run(capsys, 'modes', '--string-damping', 'lots')
    assert code == EXIT_BAD_INPUT and 'not a number' in err
