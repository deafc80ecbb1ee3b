"""``tensegrity-stiffness calibrate RECORDING --structure FILE``: a recording of the 3-bar's twin
(stiffnesses 10 % off nominal, encoder offsets up to 3 mm) as a rosbag2 of structure_sim_node's
topics or a CSV; the still instants are found (one per hold), every string's stiffness and
offset recovered within its reported std, the calibrated structure file loads; bad input exits
2 naming what is missing."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from support.cli_runs import run
from support.structure_recordings import perturbed_strings, twin_series, write_bag

from tensegrity_stiffness import config
from tensegrity_stiffness.recordings import calibration_recording as rec
from tensegrity_stiffness.recordings.structure_recording import still_indices
from tensegrity_stiffness.structures.structure import Structure

SEED = 41
HOLDS = 40
LENGTH_NOISE = 1e-4
TENSION_NOISE = 5e-3
NOISE = ('--noise', f'length={LENGTH_NOISE}', f'tension={TENSION_NOISE}')
#: 18 correlated parameters: |z| < 5 for all fails by chance in fewer than 1e-5 of the draws.
Z_BOUND = 5.0

pytest.importorskip('mujoco')


@pytest.fixture(scope='module')
def recording():
    nominal = Structure.from_yaml(config.example_config_path('three_bar.yaml'))
    truth, k, d = perturbed_strings(nominal, np.random.default_rng(SEED))
    return nominal, k, d, twin_series(truth, d, HOLDS, SEED, LENGTH_NOISE, TENSION_NOISE)


def _check_fit(report: dict, nominal: Structure, k: np.ndarray, d: np.ndarray) -> None:
    names = nominal.string_names
    kf = np.array([report['parameters'][f'stiffness[{s}]'] for s in names])
    ks = np.array([report['std'][f'stiffness[{s}]'] for s in names])
    df = np.array(report['rest_length_offsets'])
    ds = np.array([report['std'][f'rest_length_offset[{s}]'] for s in names])
    assert report['samples'] == HOLDS and report['unidentifiable'] == []
    assert np.all(np.abs(kf - k) < Z_BOUND * ks), (kf - k) / ks
    assert np.all(np.abs(df - d) < Z_BOUND * ds), (df - d) / ds
    # measured (seed 41, the bag): stiffness std 0.7-1.8 % (errors up to 3.9 %), offsets' std
    # 0.076-0.086 mm (errors up to 0.23 mm), largest |z| 2.8, chi2/dof 0.96
    assert np.max(ks / k) < 0.04 and np.max(ds) < 2e-4
    assert 0.6 < report['chi2'] / report['dof'] < 1.4


def test_one_still_sample_per_hold(recording):
    series = recording[3]
    per_hold = len(series) // HOLDS
    picked = still_indices(series)
    assert len(picked) == HOLDS
    for i, index in enumerate(picked):
        # in hold i, the motors arrived, before the next command (which the window sees)
        end = per_hold * (i + 1) - 1
        assert per_hold * i <= index < end
        np.testing.assert_array_equal(series.rest[index], series.rest[end])
    assert picked[-1] >= len(series) - 3  # the last hold: near the recording's end
    moving = rec.Recording(series.times, series.rest, series.poses, series.wrench,
                           series.tensions, series.lengths + 5e-3 * series.times[:, None])
    assert still_indices(moving) == []  # 5 mm/s on every string: nothing is still


def test_calibrate_a_structure_bag(recording, tmp_path: Path, capsys):
    nominal, k, d, series = recording
    bag = tmp_path / 'recording'
    write_bag(bag, series)
    out = tmp_path / 'calibrated.yaml'
    code, stdout, stderr = run(capsys, 'calibrate', bag, '--structure', 'three_bar.yaml',
                               '--out', out, *NOISE, '--json')
    assert code == 0, stderr
    report = json.loads(stdout)
    _check_fit(report, nominal, k, d)
    assert report['config'] == str(out)
    calibrated = Structure.from_yaml(out)
    np.testing.assert_allclose(calibrated.k, [report['parameters'][f'stiffness[{s}]']
                                              for s in nominal.string_names], rtol=1e-12)
    np.testing.assert_allclose(calibrated.rest_lengths,
                               nominal.rest_lengths + report['rest_length_offsets'], atol=1e-12)
    text = out.read_text()
    assert text.startswith('# Calibrated by tensegrity-stiffness calibrate --structure')
    assert '# joint.rest_length_offsets' in text


def test_calibrate_a_structure_csv_with_the_table(recording, tmp_path: Path, capsys):
    nominal, k, d, series = recording
    path = tmp_path / 'recording.csv'
    rec.write_csv(path, series)
    out = tmp_path / 'calibrated.yaml'
    code, stdout, stderr = run(capsys, 'calibrate', path, '--structure',
                               config.example_config_path('three_bar.yaml'), *NOISE,
                               '--out', out)
    assert code == 0, stderr
    assert f'{HOLDS} still samples' in stdout
    for s in nominal.string_names:
        assert f'stiffness[{s}] N/m' in stdout and f'rest_length_offset[{s}] mm' in stdout
    assert f'wrote {out} (structure)' in stdout
    np.testing.assert_allclose(Structure.from_yaml(out).rest_lengths - nominal.rest_lengths, d,
                               atol=5e-4)
    code, stdout, _ = run(capsys, 'calibrate', path, '--structure', 'three_bar.yaml', *NOISE,
                          '--json')
    _check_fit(json.loads(stdout), nominal, k, d)


def test_bad_structure_input_exits_2_and_says_what(recording, tmp_path: Path, capsys):
    series = recording[3]
    bag = tmp_path / 'no_tensions'
    write_bag(bag, series, skip=('tensions',))
    code, _, err = run(capsys, 'calibrate', bag, '--structure', 'three_bar.yaml')
    assert code == 2 and 'no tensions topic /structure_sim_node/measured_tensions' in err, err
    code, _, err = run(capsys, 'calibrate', bag, '--structure', 'three_bar.yaml',
                       '--pose-topic', '/mocap')
    assert code == 2 and '--pose-topic: not for a structure' in err, err
    code, _, err = run(capsys, 'calibrate', bag, '--structure', 'no_such_structure.yaml')
    assert code == 2 and "--structure: no file 'no_such_structure.yaml'" in err, err
    # A CSV without a load cell on string 4.
    path = tmp_path / 'recording.csv'
    tensions = series.tensions.copy()
    tensions[:, 4] = np.nan
    rec.write_csv(path, rec.Recording(series.times, series.rest, series.poses, series.wrench,
                                      tensions, series.lengths))
    code, _, err = run(capsys, 'calibrate', path, '--structure', 'three_bar.yaml')
    assert code == 2 and 'no tensions reading of string 4' in err, err
