"""structure_estimator_node over the real middleware, across processes: the MuJoCo twin of the
3-bar (structure_sim_node, with sensor noise) feeds the installed estimator node its string
lengths, encoders, per-bar IMUs and markers. At rest every bar's estimated pose is within a few
mm of the twin's truth and the truth inside the 5-sigma bound of each body's covariance: with
markers (everything determined), then without them (the Rutgers/Yale set: the motion along the
ground held, named), then by the filter; bad input is refused with a log line and the node keeps
estimating."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseArray  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from scipy.spatial.transform import Rotation  # noqa: E402
from scipy.stats import chi2  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    RosClient,
    log_has,
    start_structure_twin_and_estimator,
    unique_namespace,
)

from tensegrity_stiffness import config  # noqa: E402
from tensegrity_stiffness.ros.runtime.reporting import WARN_THROTTLE_S  # noqa: E402
from tensegrity_stiffness.structures.structure import Structure  # noqa: E402

EXAMPLE = 'three_bar.yaml'
#: The twin's sensor noise and the estimator's stds (the IMU: 0.02 m/s^2 per axis of 9.81 is
#: 2 mrad of the gravity direction).
LENGTH_NOISE, ACCELEROMETER_NOISE, MARKER_NOISE = 1e-3, 0.02, 1e-3
IMU_STD = 0.003
#: The issue's bounds, 5 mm and 2 degrees, with markers and while the turn about the vertical
#: is held where the last estimate with markers had it. A degree was tried: 1 mm marker noise on
#: bars this long gives a turn's std of a few mrad, and a run saw 0.94 deg (16 mrad) on a bar,
#: inside its 5-sigma covariance bound, which is the statistical check.
POSITION_BOUND, ANGLE_BOUND, HELD_ANGLE_BOUND = 5e-3, np.radians(2.0), np.radians(2.0)
#: The 5-sigma bound of a body's pose as a chi-square bound of its Mahalanobis distance (the
#: probability of |z| <= 5, over the body's determined degrees of freedom). One estimate checked
#: body by body catches a covariance grossly too small; its calibration is proven statistically
#: in test/estimation/test_structure_estimator.py (NEES over seeded trials). At 3 sigma these
#: twelve single draws (four estimates, three bodies), whose readings depend on the machine's
#: timing, would fail about one run in thirty with a calibrated covariance.
FIVE_SIGMA = 1.0 - 5.733e-7


def poses_of(msg: PoseArray) -> np.ndarray:
    """(N, 7) [x y z qx qy qz qw] of a PoseArray."""
    return np.array([[p.position.x, p.position.y, p.position.z, p.orientation.x,
                      p.orientation.y, p.orientation.z, p.orientation.w] for p in msg.poses])


def trust_of(msg: DiagnosticArray) -> dict[str, str]:
    return {kv.key: kv.value for kv in msg.status[0].values}


@pytest.fixture(scope='module')
def loop(tmp_path_factory):
    structure = Structure.from_yaml(config.example_config_path(EXAMPLE))
    folder = tmp_path_factory.mktemp('structure_estimator')
    twin_params, est_params = folder / 'twin.yaml', folder / 'estimator.yaml'
    twin_params.write_text(
        '/**:\n  ros__parameters:\n    structure:\n'
        f'      config: {EXAMPLE}\n    sim:\n      publish_every: 10\n'
        f'    noise:\n      lengths: {LENGTH_NOISE}\n      accelerometer: {ACCELEROMETER_NOISE}\n'
        f'      gyro: 0.005\n      markers: {MARKER_NOISE}\n      seed: 3\n'
        '    markers:\n      enabled: true\n')
    est_params.write_text(
        '/**:\n  ros__parameters:\n    structure:\n'
        f'      config: {EXAMPLE}\n    estimation:\n      method: static\n'
        '      max_age: 0.5\n'  # the machine may be loaded: the IMUs at rest may be older
        f'    sensors:\n      length_std: {LENGTH_NOISE}\n      imu_std: {IMU_STD}\n'
        f'      marker_std: {MARKER_NOISE}\n      gyro_std: 0.005\n')
    ns = unique_namespace('structure_estimator')
    twin, estimator, sim_base, est_base = start_structure_twin_and_estimator(
        ns, twin_params, est_params, ('measured_lengths', 'measured_rest_lengths',
                                      'measured_markers',
                                      *(f'imu/{bar}' for bar in structure.bar_names)))
    ros = RosClient('structure_estimator_test')
    out = {
        'structure': structure, 'twin': twin, 'estimator': estimator, 'ros': ros,
        'base': est_base,
        'truth': ros.subscribe(PoseArray, f'{sim_base}/poses'),
        'poses': ros.subscribe(PoseArray, f'{est_base}/poses'),
        'covariance': ros.subscribe(Float64MultiArray, f'{est_base}/pose_covariance'),
        'trust': ros.subscribe(DiagnosticArray, f'{est_base}/trust'),
        'tensions': ros.subscribe(Float64MultiArray, f'{est_base}/string_tensions'),
        'tensions_pub': ros.publisher(Float64MultiArray, f'{est_base}/measured_tensions'),
        'contacts_pub': ros.publisher(Float64MultiArray, f'{est_base}/measured_contacts'),
    }
    out['twin_params'] = ros.client(SetParameters, f'{sim_base}/set_parameters')
    out['params'] = ros.client(SetParameters, f'{est_base}/set_parameters')
    out['poses'].wait_for(1, timeout=60.0)
    yield out
    ros.close()
    codes = twin.stop(), estimator.stop()
    assert codes == (0, 0), twin.log()[-3000:] + estimator.log()[-3000:]
    assert 'internal error' not in estimator.log(), estimator.log()[-3000:]


def settled_truth(loop) -> np.ndarray:
    """The twin's (N, 4, 4) poses once they stop changing (1e-6 m between two messages)."""
    previous = [None]

    def still(msg):
        x = poses_of(msg)[:, :3]
        done = previous[0] is not None and np.abs(x - previous[0]).max() < 1e-6
        previous[0] = x
        return done

    loop['truth'].clear()
    msg = loop['truth'].wait_until(still, timeout=60.0)
    return loop['structure'].transforms(poses_of(msg))


def estimate_after(loop, condition=lambda trust: True, timeout: float = 30.0):
    """The poses (N, 4, 4), covariance (6N, 6N) and trust of an estimate published after now
    whose trust satisfies ``condition``."""
    for name in ('poses', 'covariance', 'trust'):
        loop[name].clear()
    trust = trust_of(loop['trust'].wait_until(lambda m: condition(trust_of(m)), timeout))
    loop['poses'].clear()
    loop['covariance'].clear()
    poses = loop['structure'].transforms(poses_of(loop['poses'].wait_for(1, 10.0)[-1]))
    n6 = 6 * loop['structure'].n_bodies
    covariance = np.array(loop['covariance'].wait_for(1, 10.0)[-1].data).reshape(n6, n6)
    return poses, covariance, trust


#: The components of a body's error ([dp; dw]) that a held plane motion of the whole
#: structure (along x and y, the turn about z) leaves alone: z, the turns about x and y.
OFF_THE_PLANE = [2, 3, 4]


def check_against_truth(estimate: np.ndarray, covariance: np.ndarray, truth: np.ndarray,
                        angle_bound: float = ANGLE_BOUND, judged: list[int] | None = None
                        ) -> None:
    """Every body within POSITION_BOUND / ``angle_bound`` of the truth and the truth inside the
    5-sigma bound of its covariance (over the directions the estimate determines: a held one
    has zero variance), on the components ``judged`` (all by default; with a held plane motion
    :data:`OFF_THE_PLANE`: where it is held, the anchor's own error, which no reading of this
    estimate carries, is not in the covariance: seen 1.7 deg of held turn against a std of
    0.4 deg)."""
    for i in range(truth.shape[0]):
        dp = estimate[i, :3, 3] - truth[i, :3, 3]
        dw = Rotation.from_matrix(estimate[i, :3, :3] @ truth[i, :3, :3].T).as_rotvec()
        assert np.linalg.norm(dp) < POSITION_BOUND and np.linalg.norm(dw) < angle_bound, (i, dp,
                                                                                         dw)
        keep = list(range(6)) if judged is None else judged
        C = covariance[6 * i:6 * i + 6, 6 * i:6 * i + 6][np.ix_(keep, keep)]
        eig = np.linalg.eigvalsh(C)
        assert eig[0] > -1e-12 * eig[-1]
        kept = eig > 1e-9 * eig[-1]
        e = np.concatenate([dp, dw])[keep]
        d2 = e @ np.linalg.pinv(C, rcond=1e-9, hermitian=True) @ e
        assert d2 <= chi2.ppf(FIVE_SIGMA, int(kept.sum())), (i, d2, e, np.sqrt(np.diag(C)))


def test_with_markers_every_pose_is_the_twin_s_within_its_covariance(loop):
    truth = settled_truth(loop)
    poses, covariance, trust = estimate_after(loop)
    assert 'measured_markers' in trust['inputs used'] and trust['gauge (held)'] == 'none'
    assert trust['consistent'] == 'true' and int(trust['redundancy']) > 0
    check_against_truth(poses, covariance, truth)
    names = loop['structure'].body_names
    labels = loop['covariance'].wait_for(1, 10.0)[-1].layout.dim[0].label
    assert labels.startswith('rows: [dp; dw] of each body') and f'{names[0]}.rx' in labels
    # the trust's status is named by the node's full name, its namespace with it
    assert loop['trust'].wait_for(1, 10.0)[-1].status[0].name == f"{loop['base']}: estimate"


def test_without_markers_the_plane_motion_is_held_and_named(loop):
    result = loop['ros'].set_parameter(loop['twin_params'], 'markers.enabled', False)
    assert result.successful, result.reason
    try:
        truth = settled_truth(loop)
        poses, covariance, trust = estimate_after(
            loop, lambda t: 'measured_markers' not in t['inputs used'])
        held = trust['gauge (held)']
        assert 'translation along x' in held and 'turn about z' in held, held
        assert sorted(trust['contacts'].split(', ')) == ['bar0.a', 'bar1.a', 'bar2.a']
        check_against_truth(poses, covariance, truth, HELD_ANGLE_BOUND, OFF_THE_PLANE)
    finally:
        loop['ros'].set_parameter(loop['twin_params'], 'markers.enabled', True)


def refused(loop, publisher, message, pattern: str) -> None:
    """``message`` is refused with a log line matching ``pattern`` (sent again after the
    throttle while the line has not come)."""
    for _ in range(5):
        publisher.publish(message)
        if log_has(loop['estimator'], pattern, timeout=WARN_THROTTLE_S + 1.0):
            return
    raise AssertionError(loop['estimator'].log()[-3000:])


def test_bad_input_is_refused_and_the_node_keeps_estimating(loop):
    # On inputs the twin does not stream (on a streamed one a bad message queued behind the
    # twin's newer one is passed over, newest only, and counted as skipped).
    refused(loop, loop['tensions_pub'], Float64MultiArray(data=[1.0] * 5),
            r'~/measured_tensions rejected: ~/measured_tensions: expected 9 values')
    refused(loop, loop['contacts_pub'], Float64MultiArray(data=[0.5] * 6),
            r'~/measured_contacts rejected: .*must be 1 \(on the ground\), 0 \(off it\) or NaN')
    truth = settled_truth(loop)
    poses, covariance, trust = estimate_after(loop)
    assert 'measured_tensions' not in trust['inputs used']
    check_against_truth(poses, covariance, truth)
    assert loop['estimator'].alive()


def test_the_filter_tracks_the_resting_twin(loop):
    result = loop['ros'].set_parameter(loop['params'], 'estimation.method', 'filter')
    assert result.successful, result.reason
    try:
        truth = settled_truth(loop)
        estimate_after(loop, lambda t: t['method'] == 'filter')
        poses, covariance, trust = estimate_after(loop)  # a few updates on
        assert trust['method'] == 'filter' and trust['outliers'] == 'none', trust
        check_against_truth(poses, covariance, truth)
    finally:
        loop['ros'].set_parameter(loop['params'], 'estimation.method', 'static')
