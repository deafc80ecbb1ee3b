"""The ROS-free settings of structure_sim_node: the structure from structure.config (a file or a
packaged example, as every structure node; structure.file and structure.example deprecated
aliases that warn), the twin's options and noise from the table, refusals naming the
parameter."""

import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.nodes.parameter_docs import node_usage
from tensegrity_stiffness.nodes.parameter_specs import defaults
from tensegrity_stiffness.nodes.structure_sim_node import (
    STRUCTURE_SIM_PARAMETERS,
    live_line,
    structure_sim_settings,
)


def values(**changes):
    v = defaults(STRUCTURE_SIM_PARAMETERS)
    v.update({k.replace('__', '.'): x for k, x in changes.items()})
    return v


def test_the_default_is_the_packaged_six_bar():
    settings = structure_sim_settings(values())
    assert settings.structure.n_bodies == 6 and settings.structure.n_strings == 24
    assert settings.source.endswith('six_bar.yaml')
    assert settings.options.timestep == 1e-3
    assert settings.options.rest_length_rate == 0.02
    assert settings.world_frame == 'world'


def test_a_file_the_rates_the_noise_and_the_range():
    path = str(config.example_config_path('three_bar.yaml'))
    settings = structure_sim_settings(values(**{
        'structure__config': path, 'sim__rate': 500.0, 'sim__rest_length_rate': 0.0,
        'noise__encoders': 1e-4, 'noise__markers': 2e-3,
        'limits__rest_length_range': [0.01, 1.0]}))
    assert settings.structure.n_bodies == 3
    assert settings.options.timestep == 2e-3
    assert settings.options.rest_length_rate is None  # 0: at once
    assert settings.noise.encoders == 1e-4 and settings.noise.markers == 2e-3
    assert settings.options.rest_length_range == (0.01, 1.0)


@pytest.mark.parametrize('changes, match', [
    ({'structure__config': '/no/such.yaml'}, "structure.config: no file '/no/such.yaml'"),
    ({'structure__file': '/no/such.yaml'}, "structure.file: no file '/no/such.yaml'"),
    ({'structure__example': 'nine_bar.yaml'}, "structure.example: no packaged example"),
    ({'structure__example': 'three_bar.yaml', 'structure__config': 'three_bar.yaml'},
     'structure.example .deprecated. and structure.config name the structure'),
    ({'gait__direction': [0.0, 0.0, 0.0]}, 'gait.direction'),
    ({'gait__direction': [1.0, 0.0]}, 'gait.direction'),
    ({'limits__rest_length_range': [0.5, 0.1]}, 'limits.rest_length_range'),
    ({'frames__world': ' '}, 'frames.world'),
    ({'sim__rate': 10.0}, r'sim.rate = 10 is outside'),
    ({'noise__gyro': -1.0}, 'noise.gyro'),
])
def test_bad_settings_name_the_parameter(changes, match):
    with pytest.raises(ValueError, match=match):
        structure_sim_settings(values(**changes))


def test_a_structure_file_with_an_error_names_the_file(tmp_path):
    bad = tmp_path / 'bad.yaml'
    bad.write_text('structure:\n  bodies: []\n  strings: []\n')
    with pytest.raises(ValueError, match=f'structure {bad}'):
        structure_sim_settings(values(structure__config=str(bad)))


@pytest.mark.parametrize('alias, name', [('structure.file', 'path'),
                                         ('structure.example', 'three_bar.yaml')])
def test_the_old_names_are_deprecated_aliases_that_warn(alias, name):
    if name == 'path':
        name = str(config.example_config_path('three_bar.yaml'))
    settings = structure_sim_settings(values(**{alias.replace('.', '__'): name}))
    assert settings.structure.n_bodies == 3
    assert settings.deprecations == (f'{alias} is deprecated: use structure.config:={name} (a '
                                     'path or a packaged example)',)
    assert structure_sim_settings(values(structure__config=name)).deprecations == ()


def test_usage_and_live_line():
    usage = node_usage('structure_sim_node')  # the registry's, as every node's --help
    assert usage.startswith('usage: structure_sim_node')
    line = live_line(1.5, [0.01, -0.02, 0.125], ['x1.a', 'y2.a'], [], 'tip', 1.0, 3)
    assert 'com [+0.010 -0.020 +0.125] m' in line and 'contacts x1.a,y2.a' in line
    assert 'slack -' in line and 'gait tip' in line and line.endswith('missed 3')


def test_sensor_faults_are_named_and_put_into_the_readings():
    import numpy as np

    settings = structure_sim_settings(values())
    assert settings.faults.names == ()
    s = settings.structure
    string, bar = s.string_names[3], s.bar_names[2]
    faults = structure_sim_settings(values(faults__broken_length=string,
                                           faults__flipped_imu=bar)).faults
    assert faults.names == (f'length[{string}]', f'imu[{bar}]')
    lengths = np.linspace(0.1, 0.2, s.n_strings)
    read = faults.lengths(s, lengths)
    np.testing.assert_allclose(read - lengths, np.eye(s.n_strings)[3] * 0.02, rtol=0, atol=1e-15)
    assert faults.imu_sign(bar) == -1.0 and faults.imu_sign(s.bar_names[0]) == 1.0


@pytest.mark.parametrize('changes, match', [
    ({'faults__broken_length': 'nope'}, "faults.broken_length: no string 'nope' .the strings: "),
    ({'faults__flipped_imu': 'x1.a'}, r"faults.flipped_imu: no IMU on 'x1.a' \(the IMUs: x1, "),
    ({'faults__broken_length': 'x1b-y1a', 'faults__length_offset': 0.0},
     'faults.length_offset must not be 0'),
    ({'faults__length_offset': 2.0}, r'faults.length_offset = 2 is outside \[-1, 1\]'),
])
def test_unknown_faulty_sensors_are_refused_by_name(changes, match):
    with pytest.raises(ValueError, match=match):
        structure_sim_settings(values(**changes))
