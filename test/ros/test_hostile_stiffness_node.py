"""stiffness_node under hostile input (issue #42), one real node over the middleware: a burst
of equilibrium requests all answered or refused with a message (was: past 10 outstanding,
never answered), absurd requests refused by name (rest lengths of 1e-6 m, a pose 1 m away,
a screw with v = 1e300), and the natural frequencies labelled with the pose's stability and
the overdamped modes. Bounded: one node, every wait on a condition."""

from __future__ import annotations

import re
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Float64MultiArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
from support.ros_harness import (
    REPO,
    NodeProcess,
    RosClient,
    pose_stamped,
    repeat_until,
    unique_namespace,
)

from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.services.joint_services import SERVICE_QUEUE_DEPTH

pytestmark = [pytest.mark.ros, pytest.mark.slow]

CONFIG = REPO / 'config' / 'default_joint.yaml'
BURST = 200
TIMEOUT_S = 120.0


def test_hostile_requests_and_inputs() -> None:
    from tensegrity_stiffness.srv import SolveEquilibrium

    model = JointModel.from_yaml(CONFIG)
    ns = unique_namespace('hostile_node')
    base = f'{ns}/stiffness_node'
    proc = NodeProcess(ns, CONFIG, extra_args=[
        '-p', 'dynamics.enabled:=true', '-p', 'dynamics.string_damping:=5.0'])
    ros = RosClient('hostile_node_test')
    try:
        qos = QoSProfile(depth=SERVICE_QUEUE_DEPTH, reliability=ReliabilityPolicy.RELIABLE)
        client = ros.node.create_client(SolveEquilibrium, f'{base}/solve_equilibrium',
                                        qos_profile=qos)
        assert client.wait_for_service(timeout_sec=30.0)
        # absurd rest lengths: refused by name (they 'converged' before)
        bad = SolveEquilibrium.Request(rest_lengths=[1e-6] * model.n_strings)
        answer = ros.call(client, bad, timeout=30.0)
        assert not answer.success and 'below the range' in answer.message, answer.message
        # a burst: every request answered, solved or refused with a message
        rng = np.random.default_rng(11)
        answers: list = []
        lock, done = threading.Lock(), threading.Event()

        def record(future) -> None:
            with lock:
                answers.append(future.result())
                if len(answers) == BURST:
                    done.set()

        for _ in range(BURST):
            start = model.initial_screw + rng.uniform(-1, 1, 6) * [1.5, 1.5, 1.5, 0.03, 0.03,
                                                                   0.03]
            request = SolveEquilibrium.Request(
                external_wrench=conversions.wrench_to_msg(rng.normal(scale=0.5, size=6)
                                                          * [1, 1, 1, 0.01, 0.01, 0.01]),
                initial_screw=start.tolist())
            client.call_async(request).add_done_callback(record)
        assert done.wait(TIMEOUT_S), f'{len(answers)} of {BURST} answered'
        assert all(a.success or a.message for a in answers)
        print('burst:', sum(a.success for a in answers), 'solved,',
              sum(a.message.startswith('busy') for a in answers), 'refused as busy')
        # a screw with v = 1e300 and a pose 1 m away: refused by name
        screw = ros.publisher(Float64MultiArray, f'{base}/screw')
        pose = ros.publisher(PoseStamped, f'{base}/pose')
        ros.wait_for_subscribers(screw)
        ros.wait_for_subscribers(pose)
        # each sent until its refusal is logged: the node's subscription may match this
        # publisher after the publisher matched it (discovery is one-sided), so a single
        # message can be lost
        far = np.r_[model.initial_screw[:3], [1e300, 0.0, 0.0]]
        repeat_until(lambda: screw.publish(Float64MultiArray(data=far.tolist())),
                     lambda: re.search(r'~/screw rejected: screw: .* outside the range',
                                       proc.log()), explain=lambda: proc.log()[-2000:])
        T = exp_se3(model.initial_screw)
        T[0, 3] += 1.0
        repeat_until(lambda: pose.publish(pose_stamped(T)),
                     lambda: re.search(r'~/pose rejected: pose: .* outside the range',
                                       proc.log()), explain=lambda: proc.log()[-2000:])
        # the frequencies say stable or not and which modes are overdamped (5 N s/m: all)
        frequencies = ros.subscribe(Float64MultiArray, f'{base}/natural_frequencies')
        msg = repeat_until(
            lambda: screw.publish(Float64MultiArray(data=model.initial_screw.tolist())),
            lambda: frequencies.messages[-1] if len(frequencies) else None, timeout=30.0)
        label = msg.layout.dim[0].label
        assert '; stable: yes' in label and 'overdamped (0 Hz)' in label, label
        assert np.all(np.asarray(msg.data) == 0.0)
        assert proc.alive()
    finally:
        ros.close()
        code = proc.stop()
    assert code == 0, proc.log()[-3000:]
    assert 'internal error' not in proc.log(), proc.log()[-3000:]
