"""``tensegrity-stiffness calibrate`` on recordings written by rosbags (mcap, sqlite3) and on CSV:
the quasi-static instants are found, the fit recovers the twin's parameters, the calibrated YAML
loads as the nodes load their config, bad input exits 2 with a message naming what is missing."""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

import numpy as np
import pytest
from support.calibration_recordings import (
    HELD,
    MOVING,
    configurations,
    nominal_model,
    time_series,
    true_parameters,
    write_bag,
)

from tensegrity_stiffness import cli
from tensegrity_stiffness.estimation import calibration as cal
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.recordings import calibration_recording as rec
from tensegrity_stiffness.recordings.bag import node_settings

SEED = 23
HOLDS = 120


@pytest.fixture(scope='module')
def recording():
    model = nominal_model()
    k, d = true_parameters(model, SEED)
    states = configurations(model, k, d, HOLDS, SEED)
    series = time_series(model, states, SEED, cal.CalibrationNoise(), tensions=(1, 6))
    return model, k, d, series


def run_cli(*args: str) -> tuple[int, str, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def test_quasi_static_rule_picks_the_last_held_instant_of_every_hold(recording):
    series = recording[3]
    picked = rec.quasi_static_indices(series)
    per_hold = MOVING + HELD
    assert picked == [per_hold * (i + 1) - 1 for i in range(HOLDS)]
    moving = rec.Recording(series.times, series.rest, series.poses.copy(), series.wrench,
                           series.tensions, series.lengths)
    # A slow drift of 5 mm/s during every hold: nothing is quasi-static.
    moving.poses[:, 0, 3] += 5e-3 * series.times
    assert rec.quasi_static_indices(moving) == []


def test_one_sample_per_hold_when_a_gap_or_a_glitch_interrupts_it(recording):
    """A hold whose quasi-static run is interrupted (poses missing for 0.15 s, or one pose 5 mm
    off) still gives one sample, its last quasi-static instant; two holds at the same rest
    lengths with link 2 moved between them (a new load) give two."""
    series = recording[3]
    extra = 20  # each hold 1 s longer: room for an interruption and quiet instants after it
    per_hold = MOVING + HELD + extra
    rows = []
    for i in range(HOLDS):
        hold = np.arange(i * (MOVING + HELD), (i + 1) * (MOVING + HELD))
        rows.extend(hold.tolist() + [hold[-1]] * extra)
    rows = np.array(rows)
    times = np.arange(rows.size) / 20.0
    poses = series.poses[rows].copy()
    for i in range(0, HOLDS, 2):  # every other hold: a gap of 3 instants ...
        start = i * per_hold + MOVING + HELD + 2
        poses[start:start + 3] = np.nan
    for i in range(1, HOLDS, 4):  # ... or a motion-capture glitch
        poses[i * per_hold + MOVING + HELD + 2, :3, 3] += 5e-3
    long = rec.Recording(times, series.rest[rows], poses, series.wrench[rows],
                         series.tensions[rows], series.lengths[rows])
    picked = rec.quasi_static_indices(long)
    assert picked == [per_hold * (i + 1) - 1 for i in range(HOLDS)]
    # (The previous rule, the last instant of each run of quasi-static instants, gave two
    # samples for each of these holds.)
    # Loads only: the same rest lengths, link 2 moved 3 mm between two holds: two samples.
    twice = rec.Recording(times[:2 * per_hold], np.repeat(series.rest[:1], 2 * per_hold, 0),
                          poses[:2 * per_hold].copy(), series.wrench[rows][:2 * per_hold],
                          series.tensions[rows][:2 * per_hold],
                          series.lengths[rows][:2 * per_hold])
    twice.poses[:per_hold] = series.poses[HELD + MOVING - 1]
    twice.poses[per_hold:] = series.poses[HELD + MOVING - 1]
    twice.poses[per_hold:, 0, 3] += 3e-3
    assert rec.quasi_static_indices(twice) == [per_hold - 1, 2 * per_hold - 1]


def _check_fit(report: dict, k: np.ndarray, d: np.ndarray) -> None:
    n = len(k)
    kf = np.array([report['parameters'][f'stiffness[{j}]'] for j in range(n)])
    ks = np.array([report['std'][f'stiffness[{j}]'] for j in range(n)])
    df = np.array(report['rest_length_offsets'])
    ds = np.array([report['std'][f'rest_length_offset[{j}]'] for j in range(n)])
    assert report['samples'] == HOLDS and report['success']
    assert np.all(np.abs(kf - k) <= 3.5 * ks) and np.all(np.abs(df - d) <= 3.5 * ds)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_calibrate_a_bag(recording, tmp_path: Path, storage: str):
    model, k, d, series = recording
    bag = tmp_path / 'recording'
    write_bag(bag, series, storage,
              pose_type='PoseStamped' if storage == 'mcap' else 'PoseWithCovarianceStamped')
    out = tmp_path / 'calibrated.yaml'
    if storage == 'mcap':
        code, stdout, stderr = run_cli('calibrate', bag, '--out', out, '--json')
        assert code == 0, stderr
        report = json.loads(stdout)
        _check_fit(report, k, d)
        assert report['config'] == str(out)
        offsets = report['rest_length_offsets']
    else:  # the text output
        code, stdout, stderr = run_cli('calibrate', bag, '--out', out)
        assert code == 0, stderr
        assert f'{HOLDS} quasi-static samples' in stdout
        assert 'stiffness[0] N/m' in stdout and 'rest_length_offset[11] mm' in stdout
        for kind in ('position', 'rotation', 'force', 'moment', 'tension'):
            assert f'  {kind} ' in stdout
        assert f'wrote {out} (config)' in stdout
        offsets = JointModel.from_yaml(out).rest_lengths - model.rest_lengths
        np.testing.assert_allclose(offsets, d, atol=1e-3)
        np.testing.assert_allclose(JointModel.from_yaml(out).k, k, rtol=0.05)
    # The calibrated config loads as the node loads its parameter file, and as the library does.
    calibrated = JointModel.from_yaml(out)
    settings = node_settings(out)
    np.testing.assert_allclose(settings.model.k, calibrated.k)
    np.testing.assert_allclose(calibrated.rest_lengths, model.rest_lengths + offsets, rtol=0,
                               atol=1e-15)
    np.testing.assert_allclose(calibrated.max_lengths - calibrated.rest_lengths,
                               model.max_lengths - model.rest_lengths, atol=1e-12)
    assert calibrated.wrench(calibrated.initial_screw) == pytest.approx(np.zeros(6), abs=1e-9)
    assert out.read_text().startswith('# Calibrated by tensegrity-stiffness calibrate')


def test_calibrate_a_csv_with_table_and_plot(recording, tmp_path: Path):
    pytest.importorskip('matplotlib')
    model, k, d, series = recording
    path = tmp_path / 'recording.csv'
    rec.write_csv(path, series)
    back = rec.read_csv(path, model.n_strings)
    np.testing.assert_allclose(back.poses, series.poses, atol=1e-12)
    np.testing.assert_array_equal(np.isnan(back.tensions), np.isnan(series.tensions))
    png = tmp_path / 'residuals.png'
    code, stdout, stderr = run_cli('calibrate', path, '--plot', png, '--fit', 'stiffness',
                                   'rest_length_offsets', '--noise', 'force=0.01', '--json')
    assert code == 0, stderr
    _check_fit(json.loads(stdout), k, d)
    assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'


def test_bad_input_exits_2_and_says_what_is_missing(recording, tmp_path: Path):
    series = recording[3]
    bag = tmp_path / 'bag'
    write_bag(bag, series, 'mcap')
    code, _, err = run_cli('calibrate', bag, '--wrench-topic', '/ft_sensor/wrench')
    assert code == 2 and 'no wrench topic /ft_sensor/wrench in the bag' in err
    code, _, err = run_cli('calibrate', bag, '--rest-lengths-topic', '/motors')
    assert code == 2 and 'no rest_lengths topic /motors' in err
    # The force-torque sensor on another topic than the default, --wrench-topic not given:
    # poses alone are too few, and the message names the topic the bag lacks.
    renamed = tmp_path / 'renamed'
    write_bag(renamed, rec.Recording(series.times, series.rest, series.poses, series.wrench,
                                     np.full_like(series.tensions, np.nan), series.lengths),
              'mcap', topics={'wrench': '/ft_sensor/wrench'})
    code, _, err = run_cli('calibrate', renamed)
    assert code == 2, err
    assert 'no wrench topic /stiffness_node/measured_wrench in the bag (name yours with ' \
           '--wrench-topic)' in err, err
    code, _, err = run_cli('calibrate', tmp_path / 'missing')
    assert code == 2 and 'no such rosbag2' in err
    # No quasi-static instants: a recording that never holds still.
    csv_path = tmp_path / 'moving.csv'
    moving = rec.Recording(series.times, series.rest, series.poses.copy(), series.wrench,
                           series.tensions, series.lengths)
    moving.poses[:, 0, 3] += 5e-3 * series.times
    rec.write_csv(csv_path, moving)
    code, _, err = run_cli('calibrate', csv_path)
    assert code == 2 and 'no quasi-static instants' in err
    # Too few samples for the fit: 3 holds for 24 parameters and their screws.
    short = tmp_path / 'short.csv'
    cut = 3 * (MOVING + HELD)
    rec.write_csv(short, rec.Recording(series.times[:cut], series.rest[:cut],
                                       series.poses[:cut], np.full((cut, 6), np.nan),
                                       np.full((cut, 12), np.nan), series.lengths[:cut]))
    code, _, err = run_cli('calibrate', short)
    assert code == 2 and 'too few measurements' in err
    # A CSV without the rest-length columns of every string.
    bad = tmp_path / 'bad.csv'
    bad.write_text('time,x,y,z,qx,qy,qz,qw\n0,0,0,0,0,0,0,1\n')
    code, _, err = run_cli('calibrate', bad)
    assert code == 2 and "missing columns ['rest_length_0'" in err


def test_the_command_imports_no_rclpy_and_no_ros_message_package(recording, tmp_path: Path):
    import subprocess
    import sys

    bag = tmp_path / 'bag'
    write_bag(bag, recording[3], 'sqlite3')
    code = ('import sys\n'
            'from tensegrity_stiffness import cli\n'
            f'assert cli.main(["calibrate", r"{bag}", "--json"]) == 0\n'
            'bad = [m for m in sys.modules if m.split(".")[0] in ("rclpy", "geometry_msgs", '
            '"std_msgs", "tensegrity_stiffness.ros.conversions")]\n'
            'assert not bad, bad\n')
    done = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
