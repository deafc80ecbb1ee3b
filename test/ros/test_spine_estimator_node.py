"""sim_node (the spine twin) -> spine_estimator_node over the real middleware, across processes.

The twin of the default spine (5 joints) publishes every string's load cell with noise;
``spine_estimator_node`` (unknown tip load) is remapped to them. Once the twin has settled under a
tip wrench, the estimated tip pose and tip load lie within 3 sigma of the twin's, and the mean tip
stiffness within its published std of the library's exact one at the truth; the stamped tip
stiffness carries the estimate's stamp and frame.
"""

from __future__ import annotations

import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from geometry_msgs.msg import PoseArray, PoseWithCovarianceStamped, WrenchStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import REPO, NodeProcess, RosClient, unique_namespace  # noqa: E402
from tensegrity_stiffness.msg import StampedMatrix  # noqa: E402
from test_estimator_node import (  # noqa: E402
    TENSION_NOISE,
    THREE_SIGMA_6D,
    wrench_stamped,
)

from tensegrity_stiffness.estimation import sensor_models as sm  # noqa: E402
from tensegrity_stiffness.mechanics.chain import JointChain  # noqa: E402
from tensegrity_stiffness.ros.conversions import estimation as estimation_msgs  # noqa: E402

SPINE_CONFIG = REPO / 'config' / 'default_spine.yaml'
W_SPINE = np.array([0.03, 0.0, -0.02, 0.0, 0.0, 0.0])
SPINE_ESTIMATES = 60


def test_spine_twin_drives_spine_estimator_node() -> None:
    """The twin of the default spine (5 joints, every string's load cell with noise) ->
    spine_estimator_node (unknown tip load): once settled under a tip wrench, the estimated tip
    pose and tip load lie within 3 sigma of the twin's, and the tip stiffness is the library's
    exact one at the truth within its std."""
    chain = JointChain.from_yaml(SPINE_CONFIG)
    ns = unique_namespace('spine_estimator')
    sim_base, est_base = f'{ns}/sim_node', f'{ns}/spine_estimator_node'
    sim = NodeProcess(ns, SPINE_CONFIG, executable='sim_node', extra_args=[
        '-p', 'sim.spine:=true', '-p', 'sim.publish_every:=50',
        '-p', f'noise.tensions:={TENSION_NOISE}'])
    # The static estimator's figures (the filter's, on the twin: test_chain_filter.py).
    estimator = NodeProcess(ns, SPINE_CONFIG, executable='spine_estimator_node', extra_args=[
        '-p', 'estimation.method:=static',
        '-r', f'{est_base}/measured_tensions:={sim_base}/measured_tensions'])
    ros = RosClient('spine_estimator_test')
    try:
        screws = ros.subscribe(Float64MultiArray, f'{sim_base}/screws')
        ros.subscribe(PoseArray, f'{sim_base}/poses')
        tip_pose = ros.subscribe(PoseWithCovarianceStamped, f'{est_base}/tip_pose_estimate')
        tip_wrench = ros.subscribe(WrenchStamped, f'{est_base}/tip_wrench_estimate')
        tip_k = ros.subscribe(Float64MultiArray, f'{est_base}/tip_stiffness_base')
        tip_k_std = ros.subscribe(Float64MultiArray, f'{est_base}/tip_stiffness_base_std')
        tip_k_stamped = ros.subscribe(StampedMatrix, f'{est_base}/tip_stiffness_base_stamped')
        load_pub = ros.publisher(WrenchStamped, f'{sim_base}/external_wrench')
        ros.wait_for_subscribers(load_pub)
        tip_pose.wait_for(1, timeout=60.0)
        loop = {'screw': screws, 'load_pub': load_pub}
        before = len(screws)
        load_pub.publish(wrench_stamped(W_SPINE, 'spine_base'))
        deadline = time.monotonic() + 60.0
        x = None
        while time.monotonic() < deadline:
            messages = loop['screw'].messages[before + 5:]
            if len(messages) >= 10:
                last = np.array([m.data for m in messages[-10:]])
                if np.ptp(last, axis=0).max() <= 1e-9:
                    x = last[-1].reshape(chain.n_joints, 6)
                    break
            time.sleep(0.2)
        assert x is not None, 'the spine twin did not settle'
        time.sleep(1.0)  # estimates of the settling motion are behind us
        start = len(tip_pose)
        tip_pose.wait_for(start + SPINE_ESTIMATES, timeout=120.0)
        truth = chain.tip_transform(x)
        inside = []
        for msg in tip_pose.messages[start:start + SPINE_ESTIMATES]:
            assert msg.header.frame_id == 'spine_base'
            T, C = estimation_msgs.pose_with_covariance_to_arrays(msg.pose)
            e = sm.pose_error(T, truth)
            inside.append(float(e @ np.linalg.solve(C, e)) <= THREE_SIGMA_6D)
        assert np.mean(inside) >= 0.95, np.mean(inside)
        W = np.array([[m.wrench.force.x, m.wrench.force.y, m.wrench.force.z, m.wrench.torque.x,
                       m.wrench.torque.y, m.wrench.torque.z]
                      for m in tip_wrench.messages[-SPINE_ESTIMATES:]])
        assert np.all(np.abs(W.mean(axis=0) - W_SPINE) <= 3 * W.std(axis=0) + 1e-9)
        K = np.mean([m.data for m in tip_k.messages[-SPINE_ESTIMATES:]], axis=0).reshape(6, 6)
        std = np.array(tip_k_std.messages[-1].data).reshape(6, 6)
        K_true = chain.tip_stiffness(x, tip_wrench=W_SPINE)
        relevant = std > 1e-6 * np.abs(K_true).max()
        assert np.all(np.abs(K - K_true)[relevant] <= std[relevant])
        # the stamped tip stiffness (issue 39): the estimate's stamp and frame (its tip pose
        # estimate's header) and the data of the array published with it
        last = tip_k_stamped.wait_for(1, timeout=10.0)[-1]
        stamp = (last.header.stamp.sec, last.header.stamp.nanosec)
        pose = tip_pose.wait_until(
            lambda p: (p.header.stamp.sec, p.header.stamp.nanosec) == stamp, timeout=5.0)
        assert last.header.frame_id == pose.header.frame_id == 'spine_base'
        data = np.asarray(last.data, dtype=np.float64)
        plain = tip_k.wait_until(
            lambda m: np.array_equal(np.asarray(m.data, dtype=np.float64), data), timeout=5.0)
        assert (last.row_label, last.column_label, last.rows, last.cols) == (
            plain.layout.dim[0].label, plain.layout.dim[1].label, 6, 6)
    finally:
        ros.close()
        codes = sim.stop(), estimator.stop()
    assert codes == (0, 0), sim.log() + estimator.log()
    assert 'internal error' not in estimator.log(), estimator.log()
