"""The ``tensegrity-stiffness`` command: every subcommand and every plot, on small sizes.

Tables and JSON are checked against the library; each PNG for existence, exact pixel size (read
from the IHDR header with ``struct``) and non-blank pixels (variance > 0). Runs in-process through
``main([...])`` except for the ``python -m`` and no-rclpy checks.
"""

from __future__ import annotations

import argparse
import io
import json
import math
import re
import struct
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from support import REPO
from support.cli_runs import run, run_json

from tensegrity_stiffness import config
from tensegrity_stiffness.cli import plots
from tensegrity_stiffness.cli.common import (
    EXIT_BAD_INPUT,
    EXIT_NO_MATPLOTLIB,
    EXIT_NO_SOLUTION,
    parse_number,
)
from tensegrity_stiffness.cli.figure_commands import FIGURE_FILES, README_JOINT_SCREW, png_size
from tensegrity_stiffness.cli.progress import ProgressBar
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics import sweeps
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.interpretation import (
    BLOCK_NAMES,
    COLUMN_NAMES,
    ROW_NAMES,
    interpret_stiffness,
)
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.planar import PlanarMechanism

REPO = REPO
CONFIG = REPO / 'config' / 'default_joint.yaml'
#: A screw near the unloaded equilibrium with two slack strings (docs/figures.md, the joint).
SCREW = np.array(README_JOINT_SCREW)
#: Small PNG size used by the plot tests (pixels).
SMALL = (240, 180)
#: Relative agreement of 6-significant-digit table entries with the library.
TABLE_RTOL = 1e-5
#: Tolerance of JSON numbers (exact float round trip, same computation).
JSON_RTOL = 1e-12
#: Largest committed figure (bytes).
MAX_FIGURE_BYTES = 300_000


@pytest.fixture(scope='module')
def model() -> JointModel:
    return JointModel.from_yaml(CONFIG)


def screw_args(xi: np.ndarray) -> list[str]:
    return ['--screw', *(repr(float(v)) for v in xi)]


def png_header_size(path: Path) -> tuple[int, int]:
    head = path.read_bytes()[:24]
    assert head[:8] == b'\x89PNG\r\n\x1a\n' and head[12:16] == b'IHDR', f'{path} is not a PNG'
    return struct.unpack('>II', head[16:24])


def check_png(path: Path, size: tuple[int, int]) -> None:
    """Exists, exact pixel size, not blank."""
    import matplotlib.image

    assert path.is_file(), path
    assert png_header_size(path) == size
    pixels = matplotlib.image.imread(path)
    assert pixels.shape[:2] == (size[1], size[0])
    assert float(pixels[..., :3].var()) > 0.0, f'{path} is blank'


def table_rows(text: str, title: str, n_rows: int) -> np.ndarray:
    """The numbers of the ``n_rows`` rows under the header line following ``title``."""
    lines = text.splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith(title))
    rows = lines[start + 2:start + 2 + n_rows]
    return np.array([[float(v) for v in row.split()[1:]] for row in rows])


# ------------------------------------------------------------------------------ entry points
def test_python_m_help_runs_in_a_subprocess():
    proc = subprocess.run([sys.executable, '-m', 'tensegrity_stiffness.cli', '--help'],
                          capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stderr
    for command in ('joint', 'equilibrium', 'planar-fk', 'planar-ik', 'plot', 'figures'):
        assert command in proc.stdout


def test_cli_does_not_import_rclpy():
    code = ('import sys; from tensegrity_stiffness.cli import main; '
            "rc = main(['joint', '--json']); print('RCLPY' if 'rclpy' in sys.modules else 'OK', "
            'rc)')
    proc = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=60, check=False)
    assert proc.stdout.strip().splitlines()[-1] == 'OK 0', proc.stderr


@pytest.mark.parametrize('argv', [['--help'], ['plot', '--help'], ['plot', 'joint', '--help']])
def test_help_exits_zero(capsys, argv):
    code, out, _ = run(capsys, *argv)
    assert code == 0
    assert 'usage' in out


# ------------------------------------------------------------------------------ joint
def test_joint_json_matches_library(capsys, model):
    data = run_json(capsys, 'joint', '--config', str(CONFIG), *screw_args(SCREW))
    state = model.evaluate(SCREW)
    for key, expected in (('screw', SCREW), ('wrench', state.wrench),
                          ('stiffness', state.stiffness),
                          ('cartesian_stiffness', state.cartesian_stiffness),
                          ('tensions', state.tensions), ('transform', state.transform)):
        np.testing.assert_allclose(np.array(data[key]), expected, rtol=JSON_RTOL, atol=0.0,
                                   err_msg=key)
    interp = interpret_stiffness(state.stiffness)
    for key, names, values in (('block_norms', BLOCK_NAMES, interp.block_norms),
                               ('column_norms', COLUMN_NAMES, interp.column_norms),
                               ('row_norms', ROW_NAMES, interp.row_norms)):
        got = [data['interpretation'][key][n] for n in names]
        np.testing.assert_allclose(got, values, rtol=JSON_RTOL)
    assert [s['name'] for s in data['strings']] == model.string_names
    assert [s['state'] == 'slack' for s in data['strings']] == state.slack.tolist()
    assert sum(s['state'] == 'slack' for s in data['strings']) == 2
    assert data['energy'] == pytest.approx(model.energy(SCREW), rel=JSON_RTOL)
    R = np.array(data['transform'])[:3, :3]
    np.testing.assert_allclose(Rotation.from_quat(data['quaternion']).as_matrix(), R,
                               atol=1e-12)


def test_joint_table_matches_library(capsys, model):
    code, out, err = run(capsys, 'joint', *screw_args(SCREW))
    assert code == 0, err
    state = model.evaluate(SCREW)
    for title, expected in (('stiffness K', state.stiffness),
                            ('Cartesian stiffness K_c', state.cartesian_stiffness)):
        got = table_rows(out, title, 6)
        scale = np.abs(expected).max()
        np.testing.assert_allclose(got, expected, rtol=TABLE_RTOL, atol=1e-11 * scale,
                                   err_msg=title)
    lines = out.splitlines()
    w_line = lines[next(i for i, s in enumerate(lines) if s.startswith('string wrench')) + 2]
    np.testing.assert_allclose([float(v) for v in w_line.split()], state.wrench,
                               rtol=TABLE_RTOL, atol=1e-11)
    tensions = [float(line.split()[4]) for line in lines if line.strip().startswith(
        ('cross_', 'straight_'))]
    np.testing.assert_allclose(tensions, state.tensions, rtol=TABLE_RTOL, atol=1e-12)
    assert out.count(' slack') == 2
    block = re.search(r'block Frobenius norms\s+(.*)', out).group(1).split()
    np.testing.assert_allclose([float(v) for v in block[1::2]],
                               interpret_stiffness(state.stiffness).block_norms, rtol=TABLE_RTOL)


def test_joint_default_is_the_unloaded_equilibrium(capsys, model):
    data = run_json(capsys, 'joint')
    np.testing.assert_allclose(data['screw'], model.initial_screw, rtol=0, atol=0)
    assert np.linalg.norm(data['wrench']) < 1e-12
    assert data['cartesian_stiffness_positive_definite'] is True


def test_pose_gives_the_screw_on_the_initial_branch(capsys, model):
    """The default joint rests at |omega| = pi: a pose maps back to the config's branch, as
    in the node."""
    for xi in (model.initial_screw, SCREW):
        T = exp_se3(xi)
        q = Rotation.from_matrix(T[:3, :3]).as_quat()
        data = run_json(capsys, 'joint', '--pose', *(repr(float(v)) for v in T[:3, 3]),
                        *(repr(float(v)) for v in q))
        np.testing.assert_allclose(data['screw'], xi, atol=1e-9)


def test_rest_lengths_and_force_law(capsys):
    section = dict(config.load_section(CONFIG, 'joint'))
    section['force_law'] = 'paper'
    paper = JointModel.from_dict(section)
    rest = np.full(paper.n_strings, 0.034)
    data = run_json(capsys, 'joint', '--force-law', 'paper', '--rest-lengths', '0.034',
                    *screw_args(SCREW))
    state = paper.evaluate(SCREW, rest)
    assert data['force_law'] == 'paper'
    np.testing.assert_allclose(data['stiffness'], state.stiffness, rtol=JSON_RTOL)
    np.testing.assert_allclose([s['rest_length'] for s in data['strings']], rest)


def test_negative_numbers_and_pi_expressions(capsys, model):
    xi = np.array([2.2, 0.0, -2.2, -1e-3, 0.0, math.pi / 100])
    data = run_json(capsys, 'joint', '--screw', '2.2', '0', '-2.2', '-1e-3', '0', 'pi/100')
    np.testing.assert_allclose(data['screw'], xi, rtol=0, atol=1e-15)
    np.testing.assert_allclose(data['wrench'], model.wrench(xi), rtol=JSON_RTOL)


@pytest.mark.parametrize(('text', 'value'), [('pi/10', math.pi / 10), ('-3*pi/4', -2.35619449),
                                             ('1e-3', 1e-3), (' -2 ', -2.0), ('2**3', 8.0)])
def test_parse_number_accepts(text, value):
    assert parse_number(text) == pytest.approx(value)


@pytest.mark.parametrize('text', ['nan', 'inf', '1/0', 'x', '__import__("os")', '', '1e999',
                                  'pi' * 60])
def test_parse_number_rejects(text):
    with pytest.raises(argparse.ArgumentTypeError, match='not a'):
        parse_number(text)


# ------------------------------------------------------------------------------ equilibrium
def test_equilibrium_json_matches_solver(capsys, model):
    W = np.array([0.0, 2.0, 0.0, 0.0, 0.0, 0.0])
    data = run_json(capsys, 'equilibrium', '--wrench', *(str(v) for v in W))
    result = solve_equilibrium(model, W)
    assert data['success'] is True and data['stable'] is True
    np.testing.assert_allclose(data['screw'], result.screw, atol=1e-12)
    np.testing.assert_allclose(data['joint']['wrench'], -W, atol=1e-9)
    np.testing.assert_allclose(data['joint']['stiffness'], result.stiffness, rtol=1e-9,
                               atol=1e-9)


def test_equilibrium_table_and_failure(capsys):
    code, out, _ = run(capsys, 'equilibrium', '--wrench', '0', '2', '0', '0', '0', '0')
    assert code == 0
    assert 'converged' in out and 'stiffness K = dF/dxi' in out
    code, out, err = run(capsys, 'equilibrium', '--wrench', '0', '100', '0', '0', '0', '0')
    assert code == EXIT_NO_SOLUTION
    assert 'no equilibrium found' in err
    assert 'Traceback' not in err


# ------------------------------------------------------------------------------ planar
def test_planar_fk_matches_library(capsys):
    mech = PlanarMechanism(L=1.0, K1=100.0, K2=10.0)  # the config's planar section
    data = run_json(capsys, 'planar-fk', '1.5', 'pi/10')
    r = mech.forward(1.5, math.pi / 10)
    for key in ('x', 'y', 'theta2', 'stiffness', 'energy', 'jacobian_determinant'):
        assert data[key] == pytest.approx(getattr(r, key), rel=JSON_RTOL), key
    np.testing.assert_allclose(data['jacobian'], r.jacobian, rtol=JSON_RTOL)
    assert data['singularities'] == list(r.singularities)
    code, out, _ = run(capsys, 'planar-fk', '1.5', 'pi/10')
    assert code == 0
    x, y = re.search(r'x = (\S+) m, y = (\S+) m', out).groups()
    assert (float(x), float(y)) == (pytest.approx(r.x, rel=TABLE_RTOL),
                                    pytest.approx(r.y, rel=TABLE_RTOL))
    assert f'{r.stiffness:.6g} N m/rad' in out


def test_planar_fk_options_and_singularity(capsys):
    mech = PlanarMechanism(L=1.0, K1=200.0, K2=100.0)
    data = run_json(capsys, 'planar-fk', '0', '1', '--K1', '200', '--K2', '100')
    assert 'i' in data['singularities']
    assert data['stiffness'] == pytest.approx(mech.forward(0.0, 1.0).stiffness)
    code, out, _ = run(capsys, 'planar-fk', '0', '1', '--K1', '200', '--K2', '100')
    assert code == 0 and 'i: eq. 26' in out


def test_planar_ik_matches_library(capsys):
    mech = PlanarMechanism(L=1.0, K1=100.0, K2=10.0)
    data = run_json(capsys, 'planar-ik', '0.5', '1.0', '--include-unstable')
    expected = mech.inverse(0.5, 1.0, include_unstable=True)
    assert len(data['solutions']) == len(expected) >= 1
    for got, want in zip(data['solutions'], expected, strict=True):
        for key in ('L3', 'theta1', 'theta2', 'stiffness', 'energy'):
            assert got[key] == pytest.approx(getattr(want, key), rel=JSON_RTOL), key
    code, out, _ = run(capsys, 'planar-ik', '0.5', '1.0')
    assert code == 0
    row = next(line for line in out.splitlines() if line.strip().startswith('0 '))
    assert float(row.split()[1]) == pytest.approx(expected[0].L3, rel=TABLE_RTOL)


def test_planar_ik_unreachable_is_exit_1_with_reason(capsys):
    code, out, err = run(capsys, 'planar-ik', '-0.43', '-1.5', '--K1', '200', '--K2', '100',
                         '--json')
    assert code == EXIT_NO_SOLUTION
    data = json.loads(out)
    assert data['solutions'] == [] and 'fold circle' in data['reason']
    assert 'fold circle' in err


# ------------------------------------------------------------------------------ bad input
@pytest.mark.parametrize(('argv', 'needle'), [
    (['joint', '--screw', '1', '2', '3'], 'expected 6 arguments'),
    (['joint', '--screw', '1', '2', '3', '4', '5', 'abc'], "not a number: 'abc'"),
    (['joint', '--rest-lengths', '0.03', '0.03'], '--rest-lengths needs 1 or 12 values'),
    (['joint', '--rest-lengths', '-1'], 'rest_lengths must be > 0'),
    (['joint', '--config', '/nonexistent/joint.yaml'], 'cannot read config'),
    (['joint', '--pose', '0', '0', '0', '1', '1', '0', '0'], 'not a unit quaternion'),
    (['joint', '--screw', '7', '0', '0', '0', '0', '0'], '|omega|'),
    (['joint', '--screw', '1', '0', '0', '0', '0', '0', '--pose', '0', '0', '0', '0', '0', '0',
      '1'], 'not allowed with argument'),
    (['equilibrium'], '--wrench'),
    (['planar-fk', '-1', '0'], 'L3 must be >= 0'),
    (['planar-fk', '1', '0', '--K1', '-5'], 'K1 must be > 0'),
    (['planar-ik', '0', 'y'], "not a number: 'y'"),
    (['plot', 'joint', '--size', '10', '10'], 'width must be in'),
    (['plot', 'theta2', '--out', '/nonexistent/dir/x.png'], 'output folder'),
    (['plot', 'extension', '--extent', '-0.01'], 'extent must be finite and > 0'),
    (['plot', 'nope'], 'invalid choice'),
    (['figures', '--scale', '9'], '--scale must be in'),
    (['bogus'], 'invalid choice'),
])
def test_bad_input_exit_2_with_message(capsys, argv, needle):
    code, out, err = run(capsys, *argv)
    assert code == EXIT_BAD_INPUT
    assert needle in err
    assert 'Traceback' not in err
    assert out == ''


# ------------------------------------------------------------------------------ plots
PLOT_CASES = {
    'joint': [*screw_args(SCREW), '--elevation', '30'],
    'extension': ['--samples', '15', '--extent', '0.01'],
    'actuator-workspace': ['--samples', '40'],
    'cartesian-workspace': ['--samples', '40', '--resolution', '30'],
    'theta2': ['--samples', '60', '--L3', '6', '--theta1', 'pi/10'],
    'actuator-stiffness': ['--resolution', '25'],
    'cartesian-stiffness': ['--resolution', '25', '--samples', '40'],
    'stiffness-range': ['--samples', '4', '--extent', '0.1', '--coordinate', 'vy'],
    'spine': ['--tip-wrench', '0.05', '0', '0', '0', '0', '0', '--elevation', '20'],
}


def test_every_figure_has_a_case():
    assert set(PLOT_CASES) == set(FIGURE_FILES) == set(plots.DEFAULT_SIZES)


@pytest.mark.parametrize('figure', list(PLOT_CASES))
def test_plot_writes_png_of_exact_size(capsys, tmp_path, figure):
    path = tmp_path / f'{figure}.png'
    code, out, err = run(capsys, 'plot', figure, '--out', str(path), '--size',
                         *(str(v) for v in SMALL), *PLOT_CASES[figure])
    assert code == 0, err
    assert err == ''  # no progress line when stderr is not a terminal
    assert f'wrote {path} ({SMALL[0]}x{SMALL[1]} px' in out
    check_png(path, SMALL)


def test_plot_default_output_name(capsys, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, err = run(capsys, 'plot', 'actuator-workspace', '--samples', '20')
    assert code == 0, err
    check_png(tmp_path / FIGURE_FILES['actuator-workspace'],
              plots.DEFAULT_SIZES['actuator-workspace'])


def test_figures_writes_every_figure(capsys, tmp_path):
    out_dir = tmp_path / 'figs'
    scale = 0.3
    code, out, err = run(capsys, 'figures', '--out', str(out_dir), '--scale', str(scale),
                         '--resolution', '12')
    assert code == 0, err
    for figure, name in FIGURE_FILES.items():
        w, h = plots.DEFAULT_SIZES[figure]
        check_png(out_dir / name, (round(w * scale), round(h * scale)))
        assert str(out_dir / name) in out


def test_missing_matplotlib_is_exit_3_with_clear_message(capsys, tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, 'matplotlib', None)  # `import matplotlib` -> ImportError
    path = tmp_path / 'theta2.png'
    code, out, err = run(capsys, 'plot', 'theta2', '--out', str(path))
    assert code == EXIT_NO_MATPLOTLIB
    assert out == ''
    assert err.strip() == 'tensegrity-stiffness: matplotlib is required for plots: pip install ' \
                          'matplotlib'
    assert not path.exists()
    code, _, err = run(capsys, 'figures', '--out', str(tmp_path / 'figs'))
    assert code == EXIT_NO_MATPLOTLIB and 'pip install matplotlib' in err
    with pytest.raises(plots.MatplotlibMissingError, match='pip install matplotlib'):
        plots.plot_theta2_curves(PlanarMechanism(1.0, 100.0, 10.0), path)
    code, _, _ = run(capsys, 'joint')  # the tables need no matplotlib
    assert code == 0


def test_committed_figures_and_docs():
    """docs/figures.md shows every committed figure (made by `bash scripts/make_figures.sh`)."""
    doc = (REPO / 'docs' / 'figures.md').read_text(encoding='utf-8')
    for figure, name in FIGURE_FILES.items():
        path = REPO / 'docs' / 'figures' / name
        assert f'](figures/{name})' in doc, name
        assert png_header_size(path) == plots.DEFAULT_SIZES[figure], name
        assert path.stat().st_size < MAX_FIGURE_BYTES, name
    assert 'bash scripts/make_figures.sh' in doc


# ------------------------------------------------------------------------------ progress
class FakeTerminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_progress_only_on_a_terminal():
    tty = FakeTerminal()
    progress = ProgressBar('map', stream=tty)
    for done in (0, 5, 5, 10):
        progress(done, 10)
    progress(10, 10)  # after the end nothing more is drawn
    progress.finish()
    text = tty.getvalue()
    last = text.split('\r')[-1]
    assert last.startswith('map: 100%') and '10/10' in last
    assert text.endswith('\n') and text.count('\n') == 1
    pipe = io.StringIO()
    quiet = ProgressBar('map', stream=pipe)
    quiet(5, 10)
    quiet.finish()
    assert pipe.getvalue() == ''
    started = FakeTerminal()
    half = ProgressBar('x', stream=started)
    half(1, 2)
    half.finish()
    assert started.getvalue().split('\r')[-1].startswith('x:  50%')
    assert started.getvalue().endswith('\n')
    never = FakeTerminal()
    ProgressBar('y', stream=never).finish()  # nothing drawn: no line to end
    assert never.getvalue() == ''


def test_long_computations_report_progress(tmp_path):
    calls: list[tuple[int, int]] = []
    mech = PlanarMechanism(L=1.0, K1=200.0, K2=100.0)
    plots.plot_cartesian_stiffness(mech, tmp_path / 'c.png', resolution=40, samples=30,
                                   width=SMALL[0], height=SMALL[1],
                                   progress=lambda d, t: calls.append((d, t)))
    assert len(calls) > 1 and calls[-1] == (40, 40)
    calls.clear()
    model = JointModel.from_yaml(CONFIG)
    sweeps.extension_sweep(model, 0.01, 600, progress=lambda d, t: calls.append((d, t)))
    assert len(calls) > 1 and calls[-1] == (600, 600)


# ------------------------------------------------------------------------------ sweep
def test_extension_sweep_is_a_pure_translation_from_the_unloaded_equilibrium(model):
    extent, n = 0.012, 13
    sweep = sweeps.extension_sweep(model, extent, n)
    T = exp_se3(sweep.screws)
    T0 = T[0]
    assert np.linalg.norm(sweep.state.wrench[0]) < 1e-10  # unloaded equilibrium
    np.testing.assert_allclose(np.linalg.norm(sweep.direction), 1.0, rtol=1e-15)
    np.testing.assert_allclose(sweep.direction, T0[:3, 3] / np.linalg.norm(T0[:3, 3]),
                               atol=1e-12)
    np.testing.assert_allclose(T[:, :3, :3], np.broadcast_to(T0[:3, :3], (n, 3, 3)),
                               atol=1e-12)
    np.testing.assert_allclose(T[:, :3, 3], T0[:3, 3] + sweep.displacement[:, None]
                               * sweep.direction, atol=1e-12)
    np.testing.assert_allclose(sweep.displacement[[0, -1]], [0.0, extent])
    # Moving along d pulls the links apart: the restoring force points back (F . d < 0).
    assert np.all(sweep.state.wrench[1:, :3] @ sweep.direction < 0.0)
    for k in (0, n // 2, n - 1):
        interp = interpret_stiffness(model.stiffness(sweep.screws[k]))
        np.testing.assert_allclose(sweep.block_norms[k], interp.block_norms, rtol=1e-12)
        np.testing.assert_allclose(sweep.column_norms[k], interp.column_norms, rtol=1e-12)
        np.testing.assert_allclose(sweep.row_norms[k], interp.row_norms, rtol=1e-12)


def test_batched_interpretation_matches_single():
    rng = np.random.default_rng(0)
    K = rng.normal(size=(5, 6, 6))
    blocks, cols, rows = sweeps.batched_interpretation(K)
    for k in range(5):
        interp = interpret_stiffness(K[k])
        np.testing.assert_allclose(blocks[k], interp.block_norms, rtol=1e-13)
        np.testing.assert_allclose(cols[k], interp.column_norms, rtol=1e-13)
        np.testing.assert_allclose(rows[k], interp.row_norms, rtol=1e-13)
    with pytest.raises(ValueError, match=r'shape \(N, 6, 6\)'):
        sweeps.batched_interpretation(np.zeros((6, 6)))


def test_sweep_default_extent_and_bad_input(model):
    assert sweeps.default_extent(model) == pytest.approx(0.02)  # lmax - l0 of every string
    with pytest.raises(ValueError, match='samples must be an integer >= 2'):
        sweeps.extension_sweep(model, 0.01, 1)
    with pytest.raises(ValueError, match='extent must be finite'):
        sweeps.extension_sweep(model, math.inf)


def test_png_size_validation():
    with pytest.raises(ValueError, match='height must be in'):
        plots.check_size(300, 50)
    with pytest.raises(ValueError, match='integer number of pixels'):
        plots.check_size(300.5, 200)
    assert plots.check_size(300, 200) == (300, 200)


def test_png_size_reads_pngs_only(tmp_path):
    from PIL import Image

    png, jpeg, text = tmp_path / 'a.png', tmp_path / 'a.jpg', tmp_path / 'a.txt'
    Image.new('RGB', (31, 17)).save(png)
    Image.new('RGB', (31, 17)).save(jpeg)
    text.write_text('not an image')
    assert png_size(png) == png_header_size(png) == (31, 17)
    for path in (jpeg, text):
        with pytest.raises(ValueError, match='is not a PNG file'):
            png_size(path)
