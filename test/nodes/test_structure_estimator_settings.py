"""The ROS-free part of structure_estimator_node: its settings and their refusals (naming the
parameter), the readings' checks, the rest lengths and contacts an estimate takes, and one
estimate of the MuJoCo twin's readings (static and filter) against the twin's truth."""

import time

import numpy as np
import pytest

from tensegrity_stiffness.nodes.estimator_node import EstimatorInput, Reading
from tensegrity_stiffness.nodes.parameters import defaults
from tensegrity_stiffness.nodes.structure_estimator_node import (
    STRUCTURE_ESTIMATOR_PARAMETERS,
    FilterTrack,
    array_reading,
    covariance_labels,
    estimate,
    estimate_contacts,
    estimate_rest_lengths,
    imu_sample,
    pose_errors,
    structure_estimator_settings,
)
from tensegrity_stiffness.structures.equilibrium import resting_poses


def values(**changes):
    v = defaults(STRUCTURE_ESTIMATOR_PARAMETERS)
    v['structure.config'] = 'three_bar.yaml'
    v.update({k.replace('__', '.'): x for k, x in changes.items()})
    return v


def test_the_defaults():
    settings = structure_estimator_settings(values())
    assert settings.method == 'filter' and settings.trigger_reading == 'measured_lengths'
    assert settings.imu_bodies == ('bar0', 'bar1', 'bar2')  # every free bar, as the twin's
    assert structure_estimator_settings(values(estimation__trigger='imu')).trigger_reading \
        == 'imu/bar2'
    rows, cols = covariance_labels(['bar0'])
    assert rows.endswith('[bar0.x bar0.y bar0.z bar0.rx bar0.ry bar0.rz]') and cols[:5] == 'cols:'


@pytest.mark.parametrize('changes, match', [
    ({'estimation__contacts': ['bar0.q']}, 'estimation.contacts: no node'),
    ({'estimation__imu_bodies': ['bar7']}, 'estimation.imu_bodies'),
    ({'estimation__method': 'guess'}, 'estimation.method'),
    ({'structure__config': 'nine_bar.yaml'}, 'structure.config'),
    ({'sensors__length_std': 0.0}, 'sensors.length_std'),
])
def test_bad_settings_name_the_parameter(changes, match):
    with pytest.raises(ValueError, match=match):
        structure_estimator_settings(values(**changes))


def test_bad_readings_name_the_topic():
    settings = structure_estimator_settings(values(estimation__method='static'))
    with pytest.raises(ValueError, match='~/measured_lengths: expected 9 values'):
        array_reading(settings, 'measured_lengths', np.ones(5))
    with pytest.raises(ValueError, match='~/measured_lengths: lengths must be > 0'):
        array_reading(settings, 'measured_lengths', -np.ones(9))
    with pytest.raises(ValueError, match='~/measured_markers: expected 18 values'):
        array_reading(settings, 'measured_markers', np.ones(9))
    with pytest.raises(ValueError, match='~/measured_contacts: values must be 1'):
        array_reading(settings, 'measured_contacts', np.full(6, 0.5))
    with pytest.raises(ValueError, match=r'~/imu/bar0: .*not at rest'):
        imu_sample(settings, 'bar0', np.array([0.0, 0.0, 5.0]), None)
    nan_ok = array_reading(settings, 'measured_lengths', np.r_[np.nan, np.ones(8)])
    assert np.isnan(nan_ok[0])


def test_rest_lengths_and_contacts_of_an_estimate():
    settings = structure_estimator_settings(values(joint__rest_length_offsets=[0.001]))
    s = settings.structure
    encoders = s.rest_lengths - 0.001
    encoders[0] = np.nan  # not measured: the node's own
    rest = estimate_rest_lengths(settings, {'measured_rest_lengths': Reading(encoders, 0.0)})
    np.testing.assert_allclose(rest, s.rest_lengths, rtol=0, atol=1e-15)
    T = resting_poses(s)
    assert estimate_contacts(settings, T, {}) == ('bar0.a', 'bar1.a', 'bar2.a')
    touching = np.array([0.0, 1.0, 0.0, 0.0, np.nan, 0.0])  # bar0.b only
    assert estimate_contacts(settings, T, {'measured_contacts': Reading(touching, 0.0)}) == (
        'bar0.b',)
    listed = structure_estimator_settings(values(estimation__contacts=['bar1.a']))
    assert estimate_contacts(listed, T, {}) == ('bar1.a',)


@pytest.mark.parametrize('method', ['static', 'filter'])
def test_an_estimate_of_the_twin_s_readings(method):
    """The 3-bar twin settled, its lengths (1 mm noise), encoders, IMUs and markers: every bar
    within 3 mm / 1 deg and inside its covariance's 3-sigma bound; the structure node's
    tensions at the estimate."""
    from scipy.spatial.transform import Rotation
    from scipy.stats import chi2

    from tensegrity_stiffness.simulation.structure_twin import StructureSimulation

    settings = structure_estimator_settings(values(estimation__method=method,
                                                   sensors__imu_std=0.005))
    s = settings.structure
    sim = StructureSimulation(s, poses=resting_poses(s))
    sim.settle(max_time=3.0)
    truth = sim.poses()
    rng = np.random.default_rng(5)
    now = time.monotonic()
    readings = {
        'measured_lengths': Reading(sim.string_lengths() + rng.normal(0, 1e-3, s.n_strings),
                                    now),
        'measured_rest_lengths': Reading(sim.rest_lengths.copy(), now),
        'measured_markers': Reading((sim.markers() + rng.normal(0, 1e-3, (6, 3))).ravel(), now),
    }
    for name, r in zip(sim.imu_bodies, sim.imus(), strict=True):
        readings[f'imu/{name}'] = Reading(imu_sample(
            settings, name, r.specific_force + rng.normal(0, 0.02, 3), r.angular_velocity), now)
    track = FilterTrack()
    out = estimate(settings, EstimatorInput(readings, now, None), track)
    out = estimate(settings, EstimatorInput(readings, now + 0.01, out.anchor), track)
    assert out.method == method and out.contacts == ('bar0.a', 'bar1.a', 'bar2.a')
    assert out.gauge == () and out.consistent is not False
    dp, angle = pose_errors(out.poses, truth)
    assert dp.max() < 3e-3 and np.degrees(angle).max() < 1.0, (dp, np.degrees(angle))
    for i in range(s.n_bodies):
        dw = Rotation.from_matrix(out.poses[i, :3, :3] @ truth[i, :3, :3].T).as_rotvec()
        e = np.concatenate([out.poses[i, :3, 3] - truth[i, :3, 3], dw])
        assert e @ np.linalg.solve(out.body_covariance(i), e) <= chi2.ppf(0.9973, 6)
    np.testing.assert_allclose(out.structure.state.tensions,
                               s.evaluate(out.poses, sim.rest_lengths).tensions, atol=1e-12)


def test_no_fresh_reading_is_refused():
    settings = structure_estimator_settings(values())
    old = {'measured_lengths': Reading(np.ones(9), 0.0)}
    with pytest.raises(ValueError, match=r'no input within estimation\.max_age'):
        estimate(settings, EstimatorInput(old, 10.0, None), FilterTrack())
