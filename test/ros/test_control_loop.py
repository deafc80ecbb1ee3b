"""``control_loop`` (estimator_node and stiffness_controller in one process, the estimates handed
over without a topic) against the two nodes as processes, fed the same readings and targets
side by side: the same estimates and, once settled, the same commands; the one-process
controller has no state subscription and computes its commands from the handed-over estimates
(issue 37, item 3)."""

from __future__ import annotations

import threading

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, PoseWithCovarianceStamped  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    REPO,
    NodeProcess,
    RosClient,
    pose_stamped,
    repeat_until,
    unique_namespace,
)

from tensegrity_stiffness.geometry.screw import exp_se3  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402
from tensegrity_stiffness.ros.conversions import estimation as estimation_msgs  # noqa: E402

JOINT_CONFIG = REPO / 'config' / 'default_joint.yaml'
#: Both loops: the static estimator (deterministic for the same readings) and a controller
#: without feedback gains (its command a function of the target alone), so that the two must
#: agree to rounding however their ticks fall.
COMMON = ['-p', 'estimation.method:=static', '-p', 'control.integral_gain:=0.0',
          '-p', 'control.rate:=200.0', '-p', 'markers.max_rate:=0.0']
READING_RATE_HZ = 100.0


def wiring(ns: str) -> list[str]:
    ctl = f'{ns}/stiffness_controller'
    return ['-r', f'{ns}/estimator_node/rest_lengths:={ctl}/rest_lengths']


def test_one_process_answers_as_the_two_nodes():
    model = JointModel.from_yaml(JOINT_CONFIG)
    xi = model.initial_screw
    T = exp_se3(xi)
    tensions = model.tensions(xi)
    specific_force = T[:3, :3].T @ np.array([0.0, 9.81, 0.0])  # at rest: -g in {2}
    one, two = unique_namespace('loop_one'), unique_namespace('loop_two')
    nodes = [
        NodeProcess(one, JOINT_CONFIG, executable='control_loop',
                    extra_args=[*COMMON, *wiring(one)]),
        NodeProcess(two, JOINT_CONFIG, executable='estimator_node',
                    extra_args=[*COMMON, *wiring(two)]),
        NodeProcess(two, JOINT_CONFIG, executable='stiffness_controller', extra_args=[
            *COMMON, '-r', f'{two}/stiffness_controller/pose_estimate:='
            f'{two}/estimator_node/pose_estimate']),
    ]
    ros = RosClient('control_loop_test')
    stop = threading.Event()
    try:
        inbox = {ns: {
            'pose': ros.subscribe(PoseWithCovarianceStamped, f'{ns}/estimator_node/pose_estimate'),
            'rest': ros.subscribe(Float64MultiArray, f'{ns}/stiffness_controller/rest_lengths'),
        } for ns in (one, two)}
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
        publishers = {ns: (ros.publisher(Float64MultiArray, f'{ns}/estimator_node/'
                                         'measured_tensions'),
                           ros.publisher(Imu, f'{ns}/estimator_node/imu'),
                           ros.publisher(PoseStamped, f'{ns}/stiffness_controller/target_pose'))
                      for ns in (one, two)}
        for ns in (one, two):
            for publisher in publishers[ns]:
                ros.wait_for_subscribers(publisher)
        imu = conversions.imu_message('tensegrity_link2')
        conversions.write_imu(imu, np.zeros(3), specific_force,
                              ros.node.get_clock().now().to_msg())
        readings = Float64MultiArray(data=tensions.tolist())
        target = pose_stamped(T)

        def feed() -> None:  # both loops, the same readings, side by side
            while not stop.wait(1.0 / READING_RATE_HZ):
                for ns in (one, two):
                    tensions_pub, imu_pub, target_pub = publishers[ns]
                    imu.header.stamp = ros.node.get_clock().now().to_msg()
                    imu_pub.publish(imu)
                    tensions_pub.publish(readings)
                    target_pub.publish(target)

        feeder = threading.Thread(target=feed, daemon=True)
        feeder.start()

        def settled(ns: str) -> np.ndarray | None:
            rest = inbox[ns]['rest'].messages[-5:]
            if len(rest) < 5:
                return None
            values = np.array([m.data for m in rest])
            return values[-1] if np.ptp(values, axis=0).max() == 0.0 else None

        commands = {ns: repeat_until(lambda: None, lambda ns=ns: settled(ns), timeout=60.0,
                                     explain=lambda: nodes[0].log()[-2000:])
                    for ns in (one, two)}
        np.testing.assert_allclose(commands[one], commands[two], rtol=0, atol=1e-12)
        # the same estimates of the same readings under the same commanded rest lengths
        for ns in (one, two):
            inbox[ns]['pose'].clear()
        poses = {ns: repeat_until(lambda: None, lambda ns=ns: inbox[ns]['pose'].messages[-1]
                                  if len(inbox[ns]['pose'].messages) >= 3 else None)
                 for ns in (one, two)}
        (T1, C1), (T2, C2) = (estimation_msgs.pose_with_covariance_to_arrays(poses[ns].pose)
                              for ns in (one, two))
        np.testing.assert_allclose(T1, T2, rtol=0, atol=1e-9)
        # The covariance is linearised where each fit stopped (within 0.03 std of the optimum,
        # from warm starts that depend on which readings each process passed over): a few %.
        np.testing.assert_allclose(C1, C2, rtol=0.1, atol=1e-18)
        # the one-process controller: no state subscription, commands from the handed-over
        # estimates (a latency from the reading to its command)
        assert ros.node.count_subscribers(f'{one}/estimator_node/pose_estimate') == 1  # this
        name = f'{one}/stiffness_controller: controller'

        def from_estimates():
            for array in reversed(diagnostics.messages):
                for status in array.status:
                    values = {v.key: v.value for v in status.values}
                    if status.name == name and int(values.get('commands computed', 0)) > 0 \
                            and 'latency from the reading median [ms]' in values:
                        return values
            return None

        values = repeat_until(lambda: None, from_estimates, explain=lambda: nodes[0].log())
        assert values['held ticks (stale state)'] == '0' or int(values['commands computed']) > 0
    finally:
        stop.set()
        ros.close()
        codes = [node.stop() for node in nodes]
    assert codes == [0, 0, 0], [node.log()[-2000:] for node in nodes]
    for node in nodes:
        assert 'internal error' not in node.log(), node.log()[-3000:]
