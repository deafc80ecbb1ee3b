"""estimator_node's parts without a node: its parameter section, the choice of fresh readings,
the measurements they make, the outputs of one estimate, and the message conversions (messages
built directly, no rclpy.init)."""

import time

import numpy as np
import pytest
from geometry_msgs.msg import PoseWithCovariance, PoseWithCovarianceStamped
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray
from support.estimation_trials import GRAVITY_BASE, TENSION_STD, truth_from_model

from tensegrity_stiffness.estimation.estimators import CONSISTENCY_PROBABILITY
from tensegrity_stiffness.nodes import parameters
from tensegrity_stiffness.nodes.estimator_node import (
    ESTIMATOR_NODE_PARAMETERS,
    EstimatorInput,
    Reading,
    diagnostic_summary,
    diagnostic_values,
    estimator_node_settings,
    estimator_outputs,
    gravity_reading,
    measured_array,
    measurements,
)
from tensegrity_stiffness.nodes.layouts import ESTIMATOR_OUTPUTS
from tensegrity_stiffness.ros.conversions import estimation as estimation_msgs
from tensegrity_stiffness.ros.conversions.geometry import transform_to_pose
from tensegrity_stiffness.ros.conversions.outputs import output_topics


@pytest.fixture(scope='module')
def settings():
    return estimator_node_settings(parameters.defaults(ESTIMATOR_NODE_PARAMETERS))


def readings_at(model, rng, now, imu_age=0.01):
    truth = truth_from_model(model, model.initial_screw)
    tensions = truth.tensions + rng.normal(scale=TENSION_STD, size=model.n_strings)
    return truth, {'measured_tensions': Reading(tensions, now),
                   'imu': Reading(truth.gravity, now - imu_age)}


def test_settings_defaults_and_bad_fields(settings):
    assert settings.load_mode == 'unknown' and settings.trigger == 'measured_tensions'
    np.testing.assert_allclose(settings.gravity_base, GRAVITY_BASE)
    values = parameters.defaults(ESTIMATOR_NODE_PARAMETERS)
    for name, value, match in (('estimation.external_wrench', 'maybe', 'external_wrench'),
                               ('estimation.trigger', 'screw', 'estimation.trigger'),
                               ('estimation.max_age', -1.0, 'max_age'),
                               ('sensors.tension_std', 0.0, 'tension_std'),
                               ('sensors.gravity_base', [0.0, 0.0], 'gravity_base'),
                               ('sensors.gravity_base', [0.0, 0.0, 0.0], 'gravity_base'),
                               ('frames.link1', '', 'frames.link1')):
        with pytest.raises(ValueError, match=match):
            estimator_node_settings({**values, name: value})


def test_estimate_of_fresh_readings(settings):
    rng = np.random.default_rng(0)
    now = time.monotonic()
    truth, readings = readings_at(settings.model, rng, now)
    out = estimator_outputs(settings, EstimatorInput(readings, now, truth.screw))
    assert out.used == ('measured_tensions', 'imu')
    assert out.estimate.success and out.estimate.dof == 8
    np.testing.assert_allclose(out.screw, truth.screw, atol=0.05)
    keys = dict(diagnostic_values(out))
    assert keys['inputs used'] == 'measured_tensions, imu' and keys['rank'] == 6
    assert keys['age of imu [ms]'] == pytest.approx(10.0)


def test_stale_readings_are_left_out_and_named(settings):
    rng = np.random.default_rng(1)
    now = time.monotonic()
    truth, readings = readings_at(settings.model, rng, now, imu_age=1.0)
    out = estimator_outputs(settings, EstimatorInput(readings, now, truth.screw))
    assert out.used == ('measured_tensions',)  # 12 tensions alone still determine the pose
    few = readings['measured_tensions'].value.copy()
    few[4:] = np.nan
    readings['measured_tensions'] = Reading(few, now)
    with pytest.raises(ValueError, match=r'no estimate: 4 tensions.*older than 0.05 s: imu'):
        estimator_outputs(settings, EstimatorInput(readings, now, truth.screw))


def test_load_modes(settings):
    now = time.monotonic()
    _, readings = readings_at(settings.model, np.random.default_rng(2), now)
    zero = estimator_node_settings({**settings.values, 'estimation.external_wrench': 'zero'})
    m = measurements(zero, readings)
    np.testing.assert_array_equal(m.external_wrench, np.zeros(6))
    measured = estimator_node_settings({**settings.values,
                                        'estimation.external_wrench': 'measured'})
    with pytest.raises(ValueError, match="'measured' but no ~/measured_wrench"):
        measurements(measured, readings)
    readings['measured_wrench'] = Reading(np.ones(6), now)
    np.testing.assert_array_equal(measurements(measured, readings).external_wrench, np.ones(6))


def test_readings_are_checked():
    with pytest.raises(ValueError, match='expected 12'):
        measured_array(np.ones(5), 12, '~/measured_tensions')
    with pytest.raises(ValueError, match='NaN'):
        measured_array(np.full(12, np.nan), 12, '~/measured_tensions')
    with pytest.raises(ValueError, match='inf'):
        measured_array(np.array([np.inf] + [1.0] * 11), 12, '~/measured_tensions')
    np.testing.assert_allclose(gravity_reading([0.0, 9.8, 0.0], 0.5), [0.0, -1.0, 0.0])
    with pytest.raises(ValueError, match='not at rest'):
        gravity_reading([0.0, 12.0, 0.0], 0.5)


def test_message_conversions():
    T = np.eye(4)
    T[:3, 3] = [0.01, 0.02, 0.03]
    cov = np.diag(np.arange(1.0, 7.0))
    msg = PoseWithCovarianceStamped()
    estimation_msgs.write_pose_with_covariance(msg, T, cov, msg.header.stamp, 'f')
    T2, cov2 = estimation_msgs.pose_with_covariance_to_arrays(msg.pose)
    np.testing.assert_allclose(T2, T)
    np.testing.assert_array_equal(cov2, cov)
    assert msg.header.frame_id == 'f'
    empty = PoseWithCovariance(pose=transform_to_pose(T))
    assert estimation_msgs.pose_with_covariance_to_arrays(empty)[1] is None
    bad = PoseWithCovariance(pose=transform_to_pose(T))
    bad.covariance[0] = float('nan')
    with pytest.raises(ValueError, match='covariance'):
        estimation_msgs.pose_with_covariance_to_arrays(bad)
    values = estimation_msgs.measured_values(Float64MultiArray(data=[1.0, float('nan')]), 10)
    assert values[0] == 1.0 and np.isnan(values[1])
    with pytest.raises(ValueError, match='too many'):
        estimation_msgs.measured_values(Float64MultiArray(data=[1.0] * 11), 10)
    imu = Imu()
    imu.linear_acceleration.y = 9.81
    np.testing.assert_array_equal(estimation_msgs.imu_specific_force(imu), [0.0, 9.81, 0.0])


def test_output_messages(settings):
    now = time.monotonic()
    truth, readings = readings_at(settings.model, np.random.default_rng(3), now)
    out = estimator_outputs(settings, EstimatorInput(readings, now, truth.screw))
    messages = estimation_msgs.EstimatorOutputMessages(tuple(settings.model.string_names))
    stamp = PoseWithCovarianceStamped().header.stamp
    messages.fill(out, stamp, 'link1')
    pose, wrench, screw, K, Kc, tensions, Kc_std, K_stamped, Kc_stamped = messages.messages()
    # the stamped K and K_c: the estimate's stamp and frame, the arrays' labels and data
    for stamped, plain in ((K_stamped, K), (Kc_stamped, Kc)):
        assert stamped.header.frame_id == 'link1' and stamped.header.stamp == stamp
        assert (stamped.row_label, stamped.column_label, stamped.rows, stamped.cols) == (
            plain.layout.dim[0].label, plain.layout.dim[1].label, 6, 6)
        np.testing.assert_array_equal(stamped.data, plain.data)
    topics = output_topics(messages.layouts)
    assert [topic for _, topic in topics] == [
        *(f'~/{name}' for name in ESTIMATOR_OUTPUTS), '~/stiffness_stamped',
        '~/cartesian_stiffness_stamped']
    T, cov = estimation_msgs.pose_with_covariance_to_arrays(pose.pose)
    np.testing.assert_allclose(T, out.estimate.transform, atol=1e-12)
    np.testing.assert_allclose(cov, out.estimate.covariance)
    np.testing.assert_allclose(screw.data, out.screw)
    np.testing.assert_allclose(np.reshape(Kc_std.data, (6, 6)),
                               out.estimate.cartesian_stiffness_std)
    assert Kc_std.layout.dim[1].label == Kc.layout.dim[1].label
    assert wrench.header.frame_id == 'link1' and len(tensions.data) == 12
    np.testing.assert_allclose(np.reshape(K.data, (6, 6)), out.state.stiffness)


def test_the_controller_subscribes_to_the_estimators_pose_and_load_by_name():
    """stiffness_controller's state inputs are estimator_node's pose and load outputs, named in
    the output table (not taken by position): the same topics, with the message types the
    controller subscribes with."""
    from geometry_msgs.msg import WrenchStamped

    from tensegrity_stiffness.ros import estimator_node, stiffness_controller

    topics = {topic: msgtype for msgtype, topic in estimator_node.EstimatorNode.OUTPUT_TOPICS}
    assert topics[stiffness_controller.POSE_ESTIMATE] is PoseWithCovarianceStamped
    assert topics[stiffness_controller.WRENCH_ESTIMATE] is WrenchStamped


def test_the_std_of_the_cartesian_stiffness_only_when_asked(settings):
    """The node asks for the std of K_c only while ~/cartesian_stiffness_std has a subscriber:
    without it the outputs say so, the std is NaN (never published) and the rest is the same
    estimate; None takes the settings'."""
    now = time.monotonic()
    truth, readings = readings_at(settings.model, np.random.default_rng(4), now)
    snapshot = EstimatorInput(readings, now, truth.screw)
    with_std = estimator_outputs(settings, snapshot)
    assert settings.stiffness_std and with_std.stiffness_std
    assert np.all(np.isfinite(with_std.estimate.cartesian_stiffness_std))
    without = estimator_outputs(settings, snapshot, stiffness_std=False)
    assert not without.stiffness_std
    assert np.all(np.isnan(without.estimate.cartesian_stiffness_std))
    np.testing.assert_array_equal(without.screw, with_std.screw)
    np.testing.assert_array_equal(without.estimate.covariance, with_std.estimate.covariance)


def test_spine_settings_and_outputs():
    """spine_estimator_node's settings (no IMU trigger) and one estimate of a 3-joint spine's
    tensions, split per joint from the joint-major array."""
    from tensegrity_stiffness.nodes.spine_estimator_node import (
        spine_estimator_node_parameters,
        spine_estimator_node_settings,
        spine_estimator_outputs,
    )

    values = parameters.defaults(spine_estimator_node_parameters(3))
    values['chain.n_joints'] = 3
    settings = spine_estimator_node_settings(values)
    assert settings.n_joints == 3 and settings.estimator.load_mode == 'unknown'
    with pytest.raises(ValueError, match=r'estimation\.trigger'):
        spine_estimator_node_settings({**values, 'estimation.trigger': 'imu'})
    screws = settings.chain.unloaded_screws()
    state = settings.chain.evaluate(screws)
    now = time.monotonic()
    tensions = np.concatenate(list(state.tensions))
    tensions[12:24] = np.nan  # joint 2 without load cells
    out = spine_estimator_outputs(settings, EstimatorInput(
        {'measured_tensions': Reading(tensions, now)}, now, (screws, np.zeros(6))))
    assert out.estimate.success and out.used == ('measured_tensions',)
    np.testing.assert_allclose(out.estimate.tip_wrench, 0.0, atol=1e-7)
    messages = estimation_msgs.SpineEstimatorOutputMessages(3)
    messages.fill(out, PoseWithCovarianceStamped().header.stamp, 'spine_base')
    screws_msg, pose, wrench, K, K_std, K_stamped = messages.messages()
    assert K_stamped.header.frame_id == 'spine_base'
    np.testing.assert_array_equal(K_stamped.data, K.data)
    np.testing.assert_allclose(np.reshape(screws_msg.data, (3, 6)), out.estimate.screws)
    np.testing.assert_allclose(np.reshape(K.data, (6, 6)), out.estimate.tip_stiffness)
    assert pose.header.frame_id == wrench.header.frame_id == 'spine_base'
    assert len(K_std.data) == 36


def test_diagnostics_warn_on_a_reading_left_out_and_say_when_nothing_checks(settings):
    rng = np.random.default_rng(2)
    now = time.monotonic()
    truth, readings = readings_at(settings.model, rng, now)
    out = estimator_outputs(settings, EstimatorInput(readings, now, truth.screw))
    assert diagnostic_summary(out)[0] == 'OK'
    keys = dict(diagnostic_values(out))
    assert keys['consistent'] is True and keys['redundancy'] == 8 and keys['outliers'] == 'none'
    broken = readings['measured_tensions'].value.copy()
    broken[3] += 0.8
    readings['measured_tensions'] = Reading(broken, now)
    out = estimator_outputs(settings, EstimatorInput(readings, now, truth.screw))
    level, message = diagnostic_summary(out)
    assert level == 'WARN' and 'left out tension[cross_DD]' in message
    keys = dict(diagnostic_values(out))
    assert keys['outliers'] == 'tension[cross_DD]' and keys['redundancy'] == 7
    assert 'contradicted by the others' in keys['left out: tension[cross_DD]']
    four = np.full(12, np.nan)
    four[[0, 2, 6, 11]] = truth.tensions[[0, 2, 6, 11]]
    readings['measured_tensions'] = Reading(four, now)
    out = estimator_outputs(settings, EstimatorInput(readings, now, truth.screw))
    level, message = diagnostic_summary(out)
    assert level == 'OK' and 'cannot check themselves' in message
    assert dict(diagnostic_values(out))['consistent'] == 'none (no redundancy)'


def test_the_consistency_probability_is_a_parameter(settings):
    assert settings.consistency_probability == CONSISTENCY_PROBABILITY
    values = parameters.defaults(ESTIMATOR_NODE_PARAMETERS)
    with pytest.raises(ValueError, match='consistency_probability'):
        estimator_node_settings({**values, 'estimation.consistency_probability': 0.9})


def test_the_filter_at_rest_agrees_with_the_static_estimate(settings):
    """``estimation.method: filter`` (the default): the node's filter stepped on noisy readings
    of a resting joint (12 tensions, the IMU's raw specific force and gyro, 1 ms apart) agrees
    with the static estimate of the same readings within its std; the IMU reading is raw for the
    filter and the direction of gravity for the static estimator, which refuses an accelerating
    one."""
    from tensegrity_stiffness.estimation import sensor_models as sm
    from tensegrity_stiffness.nodes.estimator_node import (
        ImuReading,
        filter_outputs,
        imu_reading,
        new_joint_filter,
    )

    assert settings.method == 'filter'
    static = estimator_node_settings({**parameters.defaults(ESTIMATOR_NODE_PARAMETERS),
                                      'estimation.method': 'static'})
    model = settings.model
    truth = truth_from_model(model, model.initial_screw)
    g = 9.81
    specific_force = -g * truth.gravity  # at rest: -g in {2}
    raw = imu_reading(settings, specific_force, np.zeros(3))
    assert isinstance(raw, ImuReading)
    np.testing.assert_allclose(imu_reading(static, specific_force, None),
                               sm.gravity_from_specific_force(specific_force))
    with pytest.raises(ValueError, match='not at rest'):
        imu_reading(static, 2.0 * specific_force, None)
    assert isinstance(imu_reading(settings, 2.0 * specific_force, None), ImuReading)
    joint_filter = new_joint_filter(settings)
    rng = np.random.default_rng(37)
    for k in range(200):
        now = 1e-3 * k
        tensions = truth.tensions + rng.normal(scale=TENSION_STD, size=model.n_strings)
        imu = ImuReading(specific_force + rng.normal(scale=settings.accelerometer_std, size=3),
                         rng.normal(scale=settings.gyro_std, size=3))
        snapshot = EstimatorInput({'measured_tensions': Reading(tensions, now),
                                   'imu': Reading(imu, now)}, now)
        outputs = filter_outputs(settings, snapshot, joint_filter, False)
    est = outputs.estimate
    assert est.success and outputs.used == ('measured_tensions', 'imu')
    assert np.all(np.isnan(est.cartesian_stiffness_std))  # not asked
    reference = estimator_outputs(static, EstimatorInput(
        {'measured_tensions': Reading(truth.tensions, 0.0),
         'imu': Reading(truth.gravity, 0.0)}, 0.0), False).estimate
    std = np.sqrt(np.diag(est.screw_covariance))
    assert np.all(np.abs(est.screw - reference.screw) <= 3.0 * std), (
        (est.screw - reference.screw) / std)
    assert est.twist.shape == (6,) and est.twist_covariance.shape == (6, 6)


def test_a_spine_filter_at_rest():
    """A spine's default is the filter too (its process noise ChainFilter's defaults): stepped
    on noiseless tensions of every joint at the unloaded configuration it converges there, with
    a finite covariance; the static method is there too."""
    from tensegrity_stiffness.estimation.joint_filter import DEFAULT_CHAIN_PROCESS_NOISE
    from tensegrity_stiffness.nodes.spine_estimator_node import (
        new_chain_filter,
        spine_filter_outputs,
    )

    values = parameters.defaults(parameters.spine_estimator_node_parameters())
    assert values['estimation.method'] == 'filter'
    noise = DEFAULT_CHAIN_PROCESS_NOISE
    assert values['filter.angular_acceleration'] == noise.angular_acceleration
    settings = parameters.spine_estimator_node_settings(values)
    chain = settings.chain
    screws = np.array([joint.initial_screw for joint in chain.joints])
    state = chain.evaluate(screws)
    tensions = np.concatenate([np.ravel(t) for t in state.tensions])
    chain_filter = new_chain_filter(settings)
    for k in range(50):
        snapshot = EstimatorInput({'measured_tensions': Reading(tensions, 1e-3 * k)}, 1e-3 * k)
        outputs = spine_filter_outputs(settings, snapshot, chain_filter, False)
    assert outputs.estimate.success
    assert np.all(np.isfinite(outputs.estimate.screws))
    static = parameters.spine_estimator_node_settings({**values, 'estimation.method': 'static'})
    assert static.estimator.method == 'static'


def test_a_spine_reading_is_judged_on_arrival():
    """issue #42 on a spine: each reading is judged when it arrives (check_spine_reading), the
    error naming the input and the joint, so a bad one is dropped alone; the readings kept
    still estimate, where the bad one in the set fails the estimate."""
    from tensegrity_stiffness.nodes.spine_estimator_node import (
        check_spine_reading,
        spine_estimator_node_parameters,
        spine_estimator_node_settings,
        spine_estimator_outputs,
    )

    values = parameters.defaults(spine_estimator_node_parameters(3))
    values['chain.n_joints'] = 3
    settings = spine_estimator_node_settings({**values, 'estimation.method': 'static'})
    chain = settings.chain
    screws = chain.unloaded_screws()
    state = chain.evaluate(screws)
    tensions = np.concatenate(list(state.tensions))
    T = chain.tip_transform(screws)
    good = {'measured_tensions': tensions}
    check_spine_reading(settings, 'measured_tensions', tensions)
    lengths = np.full(tensions.size, np.nan)
    lengths[14] = -0.01  # joint 2's third string
    with pytest.raises(ValueError, match=r'~/measured_lengths: joint 2: .*dropped'):
        check_spine_reading(settings, 'measured_lengths', lengths)
    asymmetric = np.diag([1e-6] * 6)
    asymmetric[0, 1] = 5e-7
    with pytest.raises(ValueError, match=r'~/measured_pose: .*covariance'):
        check_spine_reading(settings, 'measured_pose', (T, asymmetric))
    for distance in (10.0, 1e308):
        far = T.copy()
        far[0, 3] += distance
        with pytest.raises(ValueError, match=r'~/measured_pose: measured_pose: .* this spine'):
            check_spine_reading(settings, 'measured_pose', (far, None))
    with pytest.raises(ValueError, match=r'~/measured_wrench: measured_wrench force: .* spine'):
        check_spine_reading(settings, 'measured_wrench', np.array([1e9, 0, 0, 0, 0, 0]))
    check_spine_reading(settings, 'measured_wrench', np.array([0.05, 0, 0, 0, 0, 0.001]))
    check_spine_reading(settings, 'measured_pose', (T, None))
    now = time.monotonic()
    kept = spine_estimator_outputs(settings, EstimatorInput(
        {name: Reading(value, now) for name, value in good.items()}, now))
    assert kept.estimate.success
    with pytest.raises(ValueError):  # the bad reading in the set: no estimate (before #42)
        spine_estimator_outputs(settings, EstimatorInput(
            {'measured_tensions': Reading(tensions, now),
             'measured_lengths': Reading(lengths, now)}, now))
