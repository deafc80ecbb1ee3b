"""#39 item 4 across processes: the stamped outputs pair with their input by stamp, and two
joints in two namespaces report under distinct /diagnostics names."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from support import REPO
from support.ros_harness import NodeProcess, RosClient, unique_namespace
from tensegrity_stiffness.msg import StampedMatrix

from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import layouts
from tensegrity_stiffness.ros import conversions

pytestmark = pytest.mark.ros

CONFIG = REPO / 'config' / 'default_joint.yaml'
FRAME = 'tensegrity_link1'  # frames.link1 of the config


def test_stamped_stiffness_pairs_with_its_pose_and_diagnostic_names_are_distinct():
    """Poses with distinct stamps to one node: each ~/cartesian_stiffness_stamped (and
    ~/stiffness_stamped) carries the stamp of the pose it was computed from, the frame and the
    labels, and its data is the library's K_c at that pose; a second node in another namespace
    reports on /diagnostics under its own full name."""
    model = JointModel.from_yaml(CONFIG)
    namespaces = [unique_namespace('stamped'), unique_namespace('stamped')]
    procs = [NodeProcess(ns, CONFIG) for ns in namespaces]
    ros = RosClient('stamped_test')
    try:
        base = f'{namespaces[0]}/stiffness_node'
        kc = ros.subscribe(StampedMatrix, f'{base}/cartesian_stiffness_stamped')
        k = ros.subscribe(StampedMatrix, f'{base}/stiffness_stamped')
        wrench = ros.subscribe(WrenchStamped, f'{base}/wrench')
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
        pose_pub = ros.publisher(PoseStamped, f'{base}/pose')
        ros.wait_for_subscribers(pose_pub)
        for name in ('cartesian_stiffness_stamped', 'stiffness_stamped', 'wrench'):
            ros.wait_for_publishers(f'{base}/{name}')
        rng = np.random.default_rng(39)
        sent = {}
        for i in range(5):
            xi = model.initial_screw + 0.01 * rng.standard_normal(6)
            stamp_ns = 1_000_000_000 * (100 + i) + 1000 * i
            msg = PoseStamped(pose=conversions.transform_to_pose(exp_se3(xi)))
            msg.header.stamp = conversions.stamp_from_nanoseconds(stamp_ns)
            msg.header.frame_id = FRAME
            sent[stamp_ns] = xi
            pose_pub.publish(msg)
            kc.wait_for(i + 1, timeout=10.0)
        got = kc.wait_for(len(sent), timeout=10.0)
        wrenches = wrench.wait_for(len(sent), timeout=10.0)
        stiffness = k.wait_for(len(sent), timeout=10.0)
        labels = layouts.joint_output_layouts(model.string_names)['cartesian_stiffness'].dims
        for msg, w, K in zip(got, wrenches, stiffness, strict=True):
            stamp_ns = conversions.stamp_to_nanoseconds(msg.header.stamp)
            assert stamp_ns in sent  # paired with its pose by the stamp alone
            assert conversions.stamp_to_nanoseconds(w.header.stamp) == stamp_ns
            assert conversions.stamp_to_nanoseconds(K.header.stamp) == stamp_ns
            assert msg.header.frame_id == FRAME
            assert (msg.row_label, msg.rows) == labels[0][:2]
            assert (msg.column_label, msg.cols) == labels[1][:2]
            xi = log_se3(exp_se3(sent[stamp_ns]), reference=sent[stamp_ns])
            state = model.evaluate(xi)
            np.testing.assert_allclose(np.asarray(msg.data).reshape(6, 6),
                                       state.cartesian_stiffness, rtol=1e-9, atol=1e-9)
            np.testing.assert_allclose(np.asarray(K.data).reshape(6, 6), state.stiffness,
                                       rtol=1e-9, atol=1e-9)
        assert sorted(conversions.stamp_to_nanoseconds(m.header.stamp) for m in got) == \
            sorted(sent)
        wanted = {f'{ns}/stiffness_node: joint' for ns in namespaces}
        seen: set[str] = set()

        def both_named(array: DiagnosticArray) -> bool:
            seen.update(s.name for s in array.status)
            return wanted <= seen

        diagnostics.wait_until(both_named, timeout=20.0)
    finally:
        ros.close()
        for proc in procs:
            proc.stop()
