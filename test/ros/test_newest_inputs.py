"""Newest readings only, across processes (issue 37, item 2): a burst of readings far faster
than the node can process them builds no backlog in ``estimator_node``, ``spine_estimator_node``
or ``stiffness_controller``: each answers the newest reading queued, passes over the older ones
and counts them on ``/diagnostics`` (``inputs skipped (a newer one was queued)``). The
controller's and the twin's rates are on ``/diagnostics`` (achieved Hz, missed ticks)."""

from __future__ import annotations

import ast

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped, WrenchStamped  # noqa: E402
from support.ros_harness import (  # noqa: E402
    REPO,
    NodeProcess,
    RosClient,
    pose_stamped,
    repeat_until,
    unique_namespace,
)

from tensegrity_stiffness.geometry.screw import exp_se3  # noqa: E402
from tensegrity_stiffness.mechanics.chain import JointChain  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402
from tensegrity_stiffness.ros.runtime.node_base import StreamingNode  # noqa: E402

JOINT_CONFIG = REPO / 'config' / 'default_joint.yaml'
SPINE_CONFIG = REPO / 'config' / 'default_spine.yaml'
SKIPPED = StreamingNode.SKIPPED_KEY
#: Readings per burst: far more than a node processes while they are sent.
BURST = 2000


def pose_reading(T: np.ndarray, k: int, frame: str) -> PoseWithCovarianceStamped:
    """A motion-capture reading of ``T`` stamped ``k`` seconds (its identity)."""
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = frame
    msg.header.stamp.sec = k
    msg.pose.pose = conversions.transform_to_pose(T)
    cov = np.diag([1e-8] * 3 + [1e-6] * 3)
    msg.pose.covariance = cov.ravel().tolist()
    return msg


def status_values(diagnostics, name: str, predicate) -> dict[str, str] | None:
    """The key-values of the newest status called ``name`` for which ``predicate`` holds, None
    if none came yet."""
    for array in reversed(diagnostics.messages):
        for status in array.status:
            if status.name == name:
                values = {v.key: v.value for v in status.values}
                if predicate(values):
                    return values
    return None


def skipped_total(values: dict[str, str]) -> int:
    raw = values.get(SKIPPED, '0')
    return 0 if raw == '0' else sum(ast.literal_eval(raw).values())


@pytest.mark.parametrize('executable', ['estimator_node', 'spine_estimator_node'])
def test_a_burst_of_readings_is_answered_by_its_newest(executable):
    """Bursts of stamped motion-capture readings (the trigger): the estimator's last estimate
    answers the burst's last reading, every estimate answers a reading newer than the one
    before (none is answered twice, none out of order), fewer estimates than readings came,
    and the readings passed over are counted on /diagnostics."""
    spine = executable == 'spine_estimator_node'
    config = SPINE_CONFIG if spine else JOINT_CONFIG
    ns = unique_namespace('newest')
    node = NodeProcess(ns, config, executable=executable, extra_args=[
        '-p', 'estimation.trigger:=measured_pose', '-p', 'estimation.max_age:=10.0',
        '-p', 'markers.max_rate:=0.0'])
    base = f'{ns}/{executable}'
    ros = RosClient('newest_test')
    try:
        if spine:
            chain = JointChain.from_yaml(config)
            screws = np.tile(chain.joints[0].initial_screw, (chain.n_joints, 1))
            T = chain.evaluate(screws).tip_transform
            frame, output = 'spine_base', f'{base}/tip_pose_estimate'
        else:
            model = JointModel.from_yaml(config)
            T = exp_se3(model.initial_screw)
            frame, output = 'tensegrity_link1', f'{base}/pose_estimate'
        estimates = ros.subscribe(PoseWithCovarianceStamped, output)
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
        readings = ros.publisher(PoseWithCovarianceStamped, f'{base}/measured_pose')
        ros.wait_for_subscribers(readings)
        # a first estimate: the node's publisher has matched this client's subscription
        repeat_until(lambda: readings.publish(pose_reading(T, 1, frame)),
                     lambda: estimates.messages[-1] if estimates.messages else None,
                     explain=node.log)
        name = f'{base}: estimator'
        sent = 1
        for burst in range(1, 4):
            estimates.clear()
            first = sent + 1
            for k in range(first, first + BURST):
                readings.publish(pose_reading(T, k, frame))
            sent = first + BURST - 1
            last = sent
            repeat_until(lambda: None, lambda last=last: True if estimates.messages and
                         estimates.messages[-1].header.stamp.sec == last else None,
                         explain=node.log)
            # The first reading was sent until answered: an answer to one of its copies
            # (stamp 1) can still arrive after the clear, before the burst's answers.
            answered = [m.header.stamp.sec for m in estimates.messages
                        if not (burst == 1 and m.header.stamp.sec == 1)]
            assert all(first <= k <= sent for k in answered), answered
            assert answered == sorted(set(answered)), answered  # in order, none twice
            assert len(answered) < BURST, (burst, len(answered))
        values = repeat_until(lambda: None, lambda: status_values(
            diagnostics, name, lambda v: skipped_total(v) > 0), explain=node.log)
        assert '~/measured_pose' in values[SKIPPED], values[SKIPPED]
        assert skipped_total(values) <= sent
    finally:
        ros.close()
        assert node.stop() == 0, node.log()[-3000:]
    assert 'internal error' not in node.log(), node.log()[-3000:]


def test_the_controller_takes_the_newest_state_and_reports_its_rate():
    """A burst of pose estimates into the controller: it passes over the older ones and counts
    them; its /diagnostics carry the rate asked for, the rate achieved and the missed ticks.
    The twin's carry its step rate asked for and achieved and its missed steps."""
    ns = unique_namespace('newest_ctl')
    ctl = NodeProcess(ns, JOINT_CONFIG, executable='stiffness_controller',
                      extra_args=['-p', 'control.rate:=200.0'])
    sim = NodeProcess(ns, JOINT_CONFIG, executable='sim_node')
    base = f'{ns}/stiffness_controller'
    ros = RosClient('newest_ctl_test')
    try:
        model = JointModel.from_yaml(JOINT_CONFIG)
        T = exp_se3(model.initial_screw)
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
        states = ros.publisher(PoseWithCovarianceStamped, f'{base}/pose_estimate')
        loads = ros.publisher(WrenchStamped, f'{base}/external_wrench')
        target = ros.publisher(PoseStamped, f'{base}/target_pose')
        ros.wait_for_subscribers(states)
        ros.wait_for_subscribers(loads)
        name = f'{base}: controller'

        def burst() -> None:
            target.publish(pose_stamped(T))
            for k in range(BURST):
                states.publish(pose_reading(T, k + 1, 'tensegrity_link1'))

        values = repeat_until(burst, lambda: status_values(
            diagnostics, name, lambda v: skipped_total(v) > 0 and int(v['commands computed'])
            > 0), explain=ctl.log)
        assert '~/pose_estimate' in values[SKIPPED], values[SKIPPED]
        assert float(values['tick rate [Hz]']) == 200.0
        assert float(values['achieved tick rate [Hz]']) > 0.0
        assert int(values['missed ticks']) >= 0 and int(values['ticks']) > 0
        assert 'command rate [Hz]' in values
        twin = repeat_until(lambda: None, lambda: status_values(
            diagnostics, f'{ns}/sim_node: twin',
            lambda v: float(v['achieved step rate [Hz]']) > 0),
            explain=sim.log)
        assert float(twin['step rate [Hz]']) > 0 and int(twin['missed steps']) >= 0
        assert 'publication rate [Hz]' in twin
    finally:
        ros.close()
        codes = ctl.stop(), sim.stop()
        assert codes == (0, 0), ctl.log()[-3000:] + sim.log()[-3000:]
    assert 'internal error' not in ctl.log(), ctl.log()[-3000:]
