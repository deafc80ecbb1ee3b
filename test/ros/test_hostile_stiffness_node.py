"""stiffness_node under hostile input (issue #42), one real node over the middleware: a burst
of equilibrium requests all answered or refused with a message (was: past 10 outstanding,
never answered), absurd requests refused by name (rest lengths of 1e-6 m, a pose 1 m away,
a screw with v = 1e300, rest lengths of 1e-6 m on ``~/rest_lengths``, link 2's mass or the
strings' damping outside the joint's range as parameters), and the natural frequencies labelled
with the pose's stability and the overdamped modes. Bounded: one node, every wait on a
condition."""

from __future__ import annotations

import re
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from geometry_msgs.msg import PoseStamped
from rcl_interfaces.srv import GetParameters, SetParameters
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
from tensegrity_stiffness.ros.runtime.topics import LATCHED_QOS
from tensegrity_stiffness.ros.services.joint_services import SERVICE_QUEUE_DEPTH

pytestmark = [pytest.mark.ros, pytest.mark.slow]

CONFIG = REPO / 'config' / 'default_joint.yaml'
BURST = 200
TIMEOUT_S = 120.0


DAMPING = 5.0


@pytest.fixture(scope='module')
def node():
    ns = unique_namespace('hostile_node')
    proc = NodeProcess(ns, CONFIG, extra_args=[
        '-p', 'dynamics.enabled:=true', '-p', f'dynamics.string_damping:={DAMPING}'])
    ros = RosClient('hostile_node_test')
    yield {'proc': proc, 'ros': ros, 'base': f'{ns}/stiffness_node'}
    ros.close()
    code = proc.stop()
    assert code == 0, proc.log()[-3000:]
    assert 'internal error' not in proc.log(), proc.log()[-3000:]


def test_hostile_requests_and_inputs(node) -> None:
    from tensegrity_stiffness.srv import SolveEquilibrium

    model = JointModel.from_yaml(CONFIG)
    proc, ros, base = node['proc'], node['ros'], node['base']
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


def test_rest_lengths_and_dynamics_outside_the_joints_range_change_nothing(node) -> None:
    """Rest lengths of 1e-6 m on ``~/rest_lengths`` are refused with the range the equilibrium
    service uses (they were accepted: the topic checked only > 0) and the previous ones stay in
    force; link 2's mass of 1e-12 kg and a damping of 1e9 N s/m are refused as parameters with
    the reason (the table advertised [1e-12, 1e9] and [0, 1e9] while the library refused them)
    and the old values stay."""
    model = JointModel.from_yaml(CONFIG)
    proc, ros, base = node['proc'], node['ros'], node['base']
    rest = ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED_QOS)
    screw = ros.publisher(Float64MultiArray, f'{base}/screw')
    tensions = ros.subscribe(Float64MultiArray, f'{base}/string_tensions')
    ros.wait_for_subscribers(rest)
    ros.wait_for_subscribers(screw)
    xi = model.initial_screw
    good = 1.01 * model.rest_lengths
    expected = model.with_rest_lengths(good).evaluate(xi).tensions

    def published_tensions() -> np.ndarray | None:
        screw.publish(Float64MultiArray(data=xi.tolist()))
        return None if not len(tensions) else np.asarray(tensions.messages[-1].data)

    def in_force() -> bool:
        last = published_tensions()
        return last is not None and np.allclose(last, expected, rtol=1e-9, atol=1e-12)

    repeat_until(lambda: rest.publish(Float64MultiArray(data=good.tolist())), in_force,
                 explain=lambda: proc.log()[-2000:])
    tiny = Float64MultiArray(data=[1e-6] * model.n_strings)
    repeat_until(lambda: rest.publish(tiny),
                 lambda: re.search(r'~/rest_lengths rejected: rest_lengths: \w+ = 1e-06 m is '
                                   r'below the range of this joint \(at least', proc.log()),
                 explain=lambda: proc.log()[-2000:])
    tensions.clear()
    repeat_until(lambda: None, in_force, explain=lambda: proc.log()[-2000:])
    # dynamics parameters: refused by the joint's range, the old values kept
    set_client = ros.client(SetParameters, f'{base}/set_parameters')
    get_client = ros.client(GetParameters, f'{base}/get_parameters')
    names = ['joint.link2_mass', 'dynamics.string_damping']
    before = [v.double_value for v in ros.call(
        get_client, GetParameters.Request(names=names)).values]
    assert before[1] == DAMPING
    for name, value, reason in (('joint.link2_mass', 1e-12, r'joint\.link2_mass.*range.*1e-06'),
                                ('dynamics.string_damping', 1e9,
                                 r'dynamics\.string_damping: 1e\+09 N s/m is outside the '
                                 r'range of this joint')):
        result = ros.set_parameter(set_client, name, value)
        assert not result.successful and re.search(reason, result.reason), result.reason
    after = [v.double_value for v in ros.call(
        get_client, GetParameters.Request(names=names)).values]
    assert after == before
    tensions.clear()
    repeat_until(lambda: None, in_force, explain=lambda: proc.log()[-2000:])
    assert proc.alive()
