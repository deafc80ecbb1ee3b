"""``stiffness_controller`` under hostile input (issue #42), one real node over the middleware:
each finding of the issue reproduced (it was accepted before; now it is refused by name, counted
on /diagnostics, or moved into range with a warning), the node running on. Bounded: one node,
inputs sent one at a time and waited on by their count on /diagnostics."""

from __future__ import annotations

import ast
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, WrenchStamped
from rcl_interfaces.srv import SetParameters
from std_msgs.msg import Float64MultiArray, MultiArrayDimension

sys.path.insert(0, str(Path(__file__).resolve().parent))
from support.ros_harness import (
    REPO,
    NodeProcess,
    RosClient,
    log_has,
    pose_stamped,
    repeat_until,
    unique_namespace,
    wrench_stamped,
)

from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.ros.runtime.topics import LATCHED_QOS
from tensegrity_stiffness.ros.stiffness_controller import STAMPS_KEY

pytestmark = [pytest.mark.ros, pytest.mark.slow]

CONFIG = REPO / 'config' / 'default_joint.yaml'
OFFSET = 0.05  # the issue's: the config's rest lengths less it are negative
TIMEOUT_S = 30.0


@pytest.fixture(scope='module')
def node():
    ns = unique_namespace('hostile_ctl')
    base = f'{ns}/stiffness_controller'
    proc = NodeProcess(ns, CONFIG, executable='stiffness_controller', extra_args=[
        '-p', 'control.rate:=100.0', '-p', 'diagnostics.period:=0.2',
        '-p', f'joint.rest_length_offsets:=[{OFFSET}]'])
    ros = RosClient('hostile_controller_test')
    out = {'proc': proc, 'ros': ros, 'base': base,
           'rest': ros.subscribe(Float64MultiArray, f'{base}/rest_lengths', LATCHED_QOS),
           'diagnostics': ros.subscribe(DiagnosticArray, '/diagnostics'),
           'params': ros.client(SetParameters, f'{base}/set_parameters')}
    yield out
    ros.close()
    assert proc.stop() == 0, proc.log()[-3000:]
    assert 'internal error' not in proc.log(), proc.log()


def controller_values(node) -> dict[str, str] | None:
    for array in reversed(node['diagnostics'].messages[-10:]):
        for status in array.status:
            if status.name.startswith(node['base']) and status.name.endswith(': controller'):
                return {v.key: v.value for v in status.values}
    return None


def rejected(node, kind: str) -> int:
    values = controller_values(node) or {}
    counts = ast.literal_eval(values.get('rejected inputs', '0'))
    return counts.get(kind, 0) if isinstance(counts, dict) else 0


def refused(node, kind: str, publisher, msg) -> None:
    """Send ``msg`` until the node has counted one more rejection of ``kind``."""
    before = rejected(node, kind)
    repeat_until(lambda: publisher.publish(msg), lambda: rejected(node, kind) > before or None,
                 timeout=TIMEOUT_S, period=0.3, explain=lambda: node['proc'].log()[-2000:])


def test_start_inside_the_range_and_parameters_whole_or_refused(node) -> None:
    model = JointModel.from_yaml(CONFIG)
    first = np.array(node['rest'].wait_for(1, timeout=TIMEOUT_S)[0].data)
    assert np.all(first >= 0.5 * model.rest_lengths * (1 - 1e-12)), first  # was -0.0119 m
    assert log_has(node['proc'], 'moved into the range', 10.0)
    ros = node['ros']
    for _ in range(2):  # the same bad value twice: refused both times, never half applied
        result = ros.set_parameter(node['params'], 'joint.rest_length_offsets', [-0.04])
        assert not result.successful and 'true rest length' in result.reason, result.reason
    result = ros.set_parameter(node['params'], 'frames.link1', '')
    assert not result.successful and 'frames.link1' in result.reason
    result = ros.set_parameter(node['params'], 'joint.rest_length_offsets', [0.0])
    assert result.successful, result.reason


def test_hostile_targets_and_state_are_refused_by_name(node) -> None:
    model = JointModel.from_yaml(CONFIG)
    ros, base = node['ros'], node['base']
    T0 = exp_se3(model.initial_screw)
    target = ros.publisher(PoseStamped, f'{base}/target_pose')
    stiffness = ros.publisher(Float64MultiArray, f'{base}/target_stiffness')
    pose = ros.publisher(PoseWithCovarianceStamped, f'{base}/pose_estimate')
    wrench = ros.publisher(WrenchStamped, f'{base}/external_wrench')
    ros.wait_for_subscribers(stiffness)
    ros.wait_for_subscribers(pose)
    rng = np.random.default_rng(42)
    A = rng.standard_normal((6, 6))
    layout = Float64MultiArray(data=np.eye(6).ravel().tolist())
    layout.layout.dim = [MultiArrayDimension(label='rows', size=3, stride=36),
                         MultiArrayDimension(label='cols', size=12, stride=12)]
    for msg in (layout,
                Float64MultiArray(data=[1e12] * 6),                       # beyond the strings
                Float64MultiArray(data=[1e308] * 36),                     # overflows
                Float64MultiArray(data=(A - A.T).ravel().tolist()),       # antisymmetric
                Float64MultiArray(data=[-100.0] * 6),                     # negative definite
                Float64MultiArray(data=[0.0] * 36)):                      # zero
        refused(node, '~/target_stiffness', stiffness, msg)

    def estimate(T: np.ndarray, sec: int | None = None) -> PoseWithCovarianceStamped:
        stamped = pose_stamped(T)
        msg = PoseWithCovarianceStamped()
        msg.header = stamped.header
        msg.header.stamp = ros.node.get_clock().now().to_msg()
        if sec is not None:
            msg.header.stamp.sec, msg.header.stamp.nanosec = sec, 0
        msg.pose.pose = stamped.pose
        return msg

    for distance in (1.0, 1e308):
        far = T0.copy()
        far[:3, 3] += [distance, 0.0, 0.0]
        refused(node, '~/pose_estimate', pose, estimate(far))
    refused(node, '~/external_wrench', wrench, wrench_stamped([1e308, 0, 0, 0, 0, 0]))
    # A stamp 1 s after the epoch: left out of the latency and counted (was 1.8e12 ms).
    target.publish(pose_stamped(T0))

    def counted() -> dict[str, str] | None:
        values = controller_values(node)
        return values if values and int(values.get(STAMPS_KEY, 0)) > 0 else None

    values = repeat_until(lambda: (target.publish(pose_stamped(T0)),
                                   pose.publish(estimate(T0, sec=1))), counted,
                          timeout=TIMEOUT_S, period=0.3,
                          explain=lambda: node['proc'].log()[-2000:])
    assert float(values.get('latency from the reading p99 [ms]', 0.0)) < 1e4
    assert node['proc'].alive()
