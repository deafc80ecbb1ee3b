"""spine_node over the real middleware: the installed executable runs as a separate process with
``--ros-args --params-file config/default_spine.yaml``; a test node publishes inputs, reads every
output and calls the service, and every value is checked against the library
(:mod:`tensegrity_stiffness.mechanics.chain`). Ends with a shortened seeded fuzz of hostile and
valid inputs on every topic and the service."""

from __future__ import annotations

import math
import os
import signal
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import Pose, PoseArray, PoseStamped, WrenchStamped  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    DEEP,
    LATCHED,
    REPO,
    NodeProcess,
    RosClient,
    StreamMatcher,
    answer_every_output,
    unique_namespace,
)
from tensegrity_stiffness.srv import SolveChainEquilibrium  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from tensegrity_stiffness.geometry.screw import exp_se3  # noqa: E402
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium  # noqa: E402
from tensegrity_stiffness.nodes import parameters  # noqa: E402
from tensegrity_stiffness.nodes.layouts import (  # noqa: E402
    CARTESIAN_STIFFNESS_COL_LABEL,
    JOINTS_LABEL,
    STIFFNESS_COL_LABEL,
    STIFFNESS_ROW_LABEL,
    TIP_STIFFNESS_LABELS,
    WRENCH_LABEL,
)
from tensegrity_stiffness.nodes.spine_node import (  # noqa: E402
    poses_input,
    rest_lengths_input,
    screws_input,
    spine_outputs,
)
from tensegrity_stiffness.ros import conversions  # noqa: E402

CONFIG = REPO / 'config' / 'default_spine.yaml'
EXECUTABLE = 'spine_node'
N = 5
QUIET_S = 0.4  # how long "nothing is published" is watched after a bad input
OUTPUT_TOPICS = {
    'joint_wrenches': Float64MultiArray, 'joint_stiffness': Float64MultiArray,
    'joint_cartesian_stiffness': Float64MultiArray, 'tip_pose': PoseStamped,
    'tip_wrench': WrenchStamped, 'tip_stiffness': Float64MultiArray,
    'tip_stiffness_base': Float64MultiArray, 'markers': MarkerArray,
}
#: A tip load the default spine holds (forces ~0.1 N, moments ~2 mN m).
TIP_WRENCH = np.array([0.05, -0.1, 0.02, 0.001, 0.0, -0.002])


def wrench_msg(W):
    msg = WrenchStamped().wrench
    msg.force.x, msg.force.y, msg.force.z = (float(v) for v in W[:3])
    msg.torque.x, msg.torque.y, msg.torque.z = (float(v) for v in W[3:])
    return msg


def pose_array(transforms, frame_id: str = '') -> PoseArray:
    msg = PoseArray(poses=[conversions.transform_to_pose(T) for T in transforms])
    msg.header.frame_id = frame_id
    return msg


class Harness:
    def __init__(self) -> None:
        self.ns = unique_namespace('spine')
        self.proc = NodeProcess(self.ns, CONFIG, extra_args=['-p', 'markers.max_rate:=0.0'],
                                executable=EXECUTABLE)
        self.ros = RosClient('spine_test')
        self.base = base = f'{self.ns}/spine_node'
        self.inbox = {name: self.ros.subscribe(t, f'{base}/{name}')
                      for name, t in OUTPUT_TOPICS.items()}
        self.diagnostics = self.ros.subscribe(DiagnosticArray, '/diagnostics')
        self.screws_pub = self.ros.publisher(Float64MultiArray, f'{base}/screws')
        self.poses_pub = self.ros.publisher(PoseArray, f'{base}/poses')
        self.rest_pub = self.ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED)
        self.solve = self.ros.client(SolveChainEquilibrium, f'{base}/solve_equilibrium')
        self.set_params = self.ros.client(SetParameters, f'{base}/set_parameters')
        for pub in (self.screws_pub, self.poses_pub, self.rest_pub):
            self.ros.wait_for_subscribers(pub)
        for name in OUTPUT_TOPICS:
            self.ros.wait_for_publishers(f'{base}/{name}')
        # the first screws of a fresh node went unanswered on a topic (a loaded full-suite run)
        unloaded = JointChain.from_yaml(CONFIG).unloaded_screws()
        answer_every_output(lambda: self.send_screws(unloaded), self.counts)

    def counts(self) -> dict[str, int]:
        return {name: len(inbox) for name, inbox in self.inbox.items()}

    def send_screws(self, values) -> None:
        self.screws_pub.publish(Float64MultiArray(data=[float(v) for v in np.ravel(values)]))

    def next_outputs(self, before: dict[str, int], timeout: float = 10.0) -> dict[str, object]:
        return {name: self.inbox[name].wait_for(before[name] + 1, timeout)[before[name]]
                for name in OUTPUT_TOPICS}

    def outputs_of(self, screws) -> dict[str, object]:
        before = self.counts()
        self.send_screws(screws)
        return self.next_outputs(before)

    def assert_quiet(self, before: dict[str, int]) -> None:
        time.sleep(QUIET_S)
        assert self.counts() == before, 'published for an invalid input'
        assert self.proc.alive(), self.proc.log()

    def set_parameter(self, name: str, value) -> object:
        return self.ros.set_parameter(self.set_params, name, value)

    def call(self, **fields) -> SolveChainEquilibrium.Response:
        request = SolveChainEquilibrium.Request()
        for name, value in fields.items():
            setattr(request, name, value)
        return self.ros.call(self.solve, request, timeout=30.0)

    def close(self) -> int:
        self.ros.close()
        return self.proc.stop()


@pytest.fixture(scope='module')
def harness():
    h = Harness()
    yield h
    code = h.close()
    assert code == 0, f'node exit code {code}:\n{h.proc.log()}'


@pytest.fixture(scope='module')
def chain() -> JointChain:
    return JointChain.from_yaml(CONFIG)


@pytest.fixture(scope='module')
def loaded(chain):
    """A configuration solved under TIP_WRENCH (no weights: the default spine has no masses)."""
    res = solve_chain_equilibrium(chain, TIP_WRENCH, np.zeros(3), tolerance=1e-13)
    assert res.success, res.message
    return res


def data(msg) -> np.ndarray:
    return np.asarray(msg.data, dtype=np.float64)


def pose_matrix(pose) -> np.ndarray:
    return conversions.pose_message_to_transform(pose)


def check_outputs(out: dict, chain: JointChain, screws, rest=None) -> None:
    """Every output at ``screws`` against the library (evaluate, implied_tip_wrench,
    tip_stiffness in both frames)."""
    state = chain.evaluate(screws, rest)
    W = chain.implied_tip_wrench(screws, rest_lengths=rest)
    scale = np.abs(state.stiffness).max()
    np.testing.assert_allclose(data(out['joint_wrenches']).reshape(N, 6), state.wrenches,
                               rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(data(out['joint_stiffness']).reshape(N, 6, 6), state.stiffness,
                               rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(data(out['joint_cartesian_stiffness']).reshape(N, 6, 6),
                               state.cartesian_stiffness, rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(pose_matrix(out['tip_pose'].pose), state.tip_transform,
                               atol=1e-12)
    np.testing.assert_allclose(conversions.msg_to_wrench(out['tip_wrench'].wrench), W,
                               rtol=1e-12, atol=1e-15)
    for name, frame in (('tip_stiffness', 'tool'), ('tip_stiffness_base', 'base')):
        K = chain.tip_stiffness_from_state(state, W, frame=frame)
        np.testing.assert_allclose(data(out[name]).reshape(6, 6), K, rtol=1e-10,
                                   atol=1e-10 * np.abs(K).max(), err_msg=name)
    for name in ('tip_pose', 'tip_wrench'):
        assert out[name].header.frame_id == 'spine_base'
    assert len(out['markers'].markers) == 4 * N
    assert {m.header.frame_id for m in out['markers'].markers} == {'spine_base'}


# ---------------------------------------------------------------------------- outputs
def test_every_output_against_the_library(harness, chain, loaded):
    out = harness.outputs_of(loaded.screws)
    check_outputs(out, chain, loaded.screws)
    # The configuration solved under a known tip wrench implies that wrench.
    np.testing.assert_allclose(conversions.msg_to_wrench(out['tip_wrench'].wrench), TIP_WRENCH,
                               atol=1e-9)
    np.testing.assert_allclose(data(out['tip_stiffness_base']).reshape(6, 6),
                               loaded.tip_stiffness, rtol=1e-8,
                               atol=1e-8 * np.abs(loaded.tip_stiffness).max())
    np.testing.assert_allclose(data(out['tip_stiffness']).reshape(6, 6),
                               loaded.tip_stiffness_tool, rtol=1e-8,
                               atol=1e-8 * np.abs(loaded.tip_stiffness_tool).max())


def test_layouts(harness, loaded):
    out = harness.outputs_of(loaded.screws)

    def dims(name):
        return [(d.label, d.size, d.stride) for d in out[name].layout.dim]

    assert dims('joint_wrenches') == [(JOINTS_LABEL, N, 6 * N), (WRENCH_LABEL, 6, 6)]
    assert dims('joint_stiffness') == [(JOINTS_LABEL, N, 36 * N), (STIFFNESS_ROW_LABEL, 6, 36),
                                       (STIFFNESS_COL_LABEL, 6, 6)]
    assert dims('joint_cartesian_stiffness') == [
        (JOINTS_LABEL, N, 36 * N), (STIFFNESS_ROW_LABEL, 6, 36),
        (CARTESIAN_STIFFNESS_COL_LABEL, 6, 6)]
    for name, frame in (('tip_stiffness', 'tool'), ('tip_stiffness_base', 'base')):
        rows, cols = TIP_STIFFNESS_LABELS[frame]
        assert dims(name) == [(rows, 6, 36), (cols, 6, 6)]


def test_pose_input_gives_the_outputs_of_its_screws(harness, chain, loaded):
    xi = loaded.screws
    harness.outputs_of(xi)  # the reference branch: the last screws
    for frame_id in ('', 'spine_base'):
        before = harness.counts()
        harness.poses_pub.publish(pose_array(exp_se3(xi), frame_id))
        out = harness.next_outputs(before)
        check_outputs(out, chain, xi)
        np.testing.assert_allclose(conversions.msg_to_wrench(out['tip_wrench'].wrench),
                                   TIP_WRENCH, atol=1e-9)


def test_diagnostics_per_joint_and_chain(harness, loaded):
    harness.outputs_of(loaded.screws)
    msg = harness.diagnostics.wait_until(lambda m: any(
        s.name.endswith('spine_node: joint 5') and s.hardware_id == 'spine_base'
        for s in m.status), timeout=10.0)
    names = [s.name.split(': ', 1)[1] for s in msg.status]
    assert names == ['chain'] + [f'joint {i}' for i in range(1, N + 1)]
    chain_values = {v.key: v.value for v in msg.status[0].values}
    assert chain_values['joints'] == '5' and 'compute time mean [us]' in chain_values
    joint = {v.key for v in msg.status[1].values}
    assert {'slack strings', 'chart margin 2pi - |omega| [rad]'} <= joint


# ---------------------------------------------------------------------------- service
def test_service_against_the_library(harness, chain, loaded):
    x0 = chain.unloaded_screws()
    response = harness.call(tip_wrench=wrench_msg(TIP_WRENCH),
                            initial_screws=x0.ravel().tolist())
    assert response.success, response.message
    expected = solve_chain_equilibrium(chain, TIP_WRENCH, np.zeros(3), initial_screws=x0,
                                       time_budget=0.1)
    np.testing.assert_allclose(np.reshape(response.screws, (N, 6)), loaded.screws, atol=1e-8)
    np.testing.assert_allclose(response.screws, expected.screws.ravel(), atol=1e-10)
    xi = np.reshape(response.screws, (N, 6))
    state = chain.evaluate(xi)
    np.testing.assert_allclose(pose_matrix(response.tip_pose), state.tip_transform, atol=1e-12)
    for name, frame in (('tip_stiffness', 'tool'), ('tip_stiffness_base', 'base')):
        K = chain.tip_stiffness(xi, TIP_WRENCH, frame=frame)
        np.testing.assert_allclose(np.reshape(getattr(response, name), (6, 6)), K, rtol=1e-8,
                                   atol=1e-8 * np.abs(K).max(), err_msg=name)
    np.testing.assert_allclose(np.reshape(response.joint_wrenches, (N, 6)), state.wrenches,
                               rtol=1e-12, atol=1e-15)
    assert response.stable and 0.0 <= response.residual < 1e-9 and response.iterations >= 1
    # Its solution, on the topic, implies the wrench it was solved under.
    out = harness.outputs_of(response.screws)
    np.testing.assert_allclose(conversions.msg_to_wrench(out['tip_wrench'].wrench), TIP_WRENCH,
                               atol=1e-9)
    # Empty initial screws: from the last solution (converges at once).
    again = harness.call(tip_wrench=wrench_msg(TIP_WRENCH), use_gravity=True)
    assert again.success and again.iterations <= 2, again.message
    np.testing.assert_allclose(again.screws, response.screws, atol=1e-10)


@pytest.mark.parametrize('fields, match', [
    ({'initial_screws': [0.0] * 29}, 'initial_screws: expected 6 N = 30'),
    ({'initial_screws': [math.nan] * 30}, 'finite'),
    ({'initial_screws': [7.0, 0, 0, 0, 0, 0] * 5}, 'joint 1 screw'),
    ({'rest_lengths': [0.03] * 59}, 'rest_lengths: expected 60'),
    ({'rest_lengths': [-0.03] * 60}, 'rest_lengths: joint 1'),
    ({'tip_wrench': wrench_msg([math.inf, 0, 0, 0, 0, 0])}, 'wrench'),
])
def test_service_rejections(harness, fields, match):
    response = harness.call(**fields)
    assert not response.success and response.message.startswith('invalid request')
    assert match in response.message, response.message
    assert harness.proc.alive()


def test_service_a_load_the_strings_cannot_hold(harness):
    response = harness.call(tip_wrench=wrench_msg([0.0, 50.0, 0.0, 0.0, 0.0, 0.0]))
    assert not response.success and response.message
    assert harness.proc.alive()


# ---------------------------------------------------------------------------- bad input
def _screws_with(index: int, value: float, loaded) -> np.ndarray:
    xi = loaded.screws.copy().ravel()
    xi[index] = value
    return xi


BAD_SCREWS = {
    'empty': lambda loaded: np.zeros(0),
    'one joint short': lambda loaded: loaded.screws.ravel()[:-6],
    'one value short': lambda loaded: loaded.screws.ravel()[:-1],
    'one value more': lambda loaded: np.r_[loaded.screws.ravel(), 0.0],
    'nan': lambda loaded: _screws_with(14, math.nan, loaded),
    'inf': lambda loaded: _screws_with(3, math.inf, loaded),
    'outside the chart': lambda loaded: _screws_with(18, 7.0, loaded),
    'oversized': lambda loaded: np.zeros(5000),
}


@pytest.mark.parametrize('kind', sorted(BAD_SCREWS))
def test_bad_screws_publish_nothing_and_the_state_stays(harness, chain, loaded, kind):
    harness.outputs_of(loaded.screws)
    before = harness.counts()
    harness.send_screws(BAD_SCREWS[kind](loaded))
    harness.assert_quiet(before)
    # State unchanged: the rest lengths re-published (the same ones) answer for the last
    # valid screws.
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=np.concatenate(
        [m.rest_lengths for m in chain.joints]).tolist()))
    check_outputs(harness.next_outputs(before), chain, loaded.screws)


def _bad_poses(kind: str, loaded) -> PoseArray:
    T = exp_se3(loaded.screws)
    if kind == 'four poses':
        return pose_array(T[:4])
    if kind == 'six poses':
        return pose_array(np.concatenate([T, T[:1]]))
    if kind == 'no poses':
        return pose_array(T[:0])
    msg = pose_array(T)
    pose: Pose = msg.poses[2]
    if kind == 'zero quaternion':
        pose.orientation.x = pose.orientation.y = pose.orientation.z = 0.0
        pose.orientation.w = 0.0
    elif kind == 'non-unit quaternion':  # (w is about 0: the vertebra turns by pi)
        o = pose.orientation
        o.x, o.y, o.z, o.w = 2.0 * o.x, 2.0 * o.y, 2.0 * o.z, 2.0 * o.w
    elif kind == 'nan quaternion':
        pose.orientation.x = math.nan
    elif kind == 'nan position':
        pose.position.y = math.nan
    elif kind == 'wrong frame':
        msg.header.frame_id = 'world'
    return msg


@pytest.mark.parametrize('kind', ['four poses', 'six poses', 'no poses', 'zero quaternion',
                                  'non-unit quaternion', 'nan quaternion', 'nan position',
                                  'wrong frame'])
def test_bad_poses_publish_nothing(harness, chain, loaded, kind):
    harness.outputs_of(loaded.screws)
    before = harness.counts()
    harness.poses_pub.publish(_bad_poses(kind, loaded))
    harness.assert_quiet(before)


def test_rejections_are_warned_about_naming_the_joint(harness, loaded):
    harness.send_screws(_screws_with(18, 7.0, loaded))
    deadline = time.monotonic() + 5.0
    while 'joint 4 screw' not in harness.proc.log():
        assert time.monotonic() < deadline, harness.proc.log()
        time.sleep(0.05)


# ---------------------------------------------------------------------------- rest lengths
def test_rest_lengths_update_republishes_and_bad_ones_are_refused(harness, chain, loaded):
    harness.outputs_of(loaded.screws)
    rest = [m.rest_lengths.copy() for m in chain.joints]
    rest[1] = rest[1] * 1.02
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=np.concatenate(rest).tolist()))
    check_outputs(harness.next_outputs(before), chain, loaded.screws, rest)
    for bad in (np.concatenate(rest)[:-1], np.r_[np.concatenate(rest)[:-1], -1.0],
                np.r_[math.nan, np.concatenate(rest)[1:]]):
        before = harness.counts()
        harness.rest_pub.publish(Float64MultiArray(data=bad.tolist()))
        harness.assert_quiet(before)
    # The updated rest lengths stay in force for new screws.
    xi = loaded.screws + 0.002
    check_outputs(harness.outputs_of(xi), chain, xi, rest)
    default = np.concatenate([m.rest_lengths for m in chain.joints])
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=default.tolist()))
    check_outputs(harness.next_outputs(before), chain, xi)


# ---------------------------------------------------------------------------- parameters
def test_parameter_change_accepted_and_rejected(harness, chain, loaded):
    xi = loaded.screws
    harness.outputs_of(xi)
    ok = harness.set_parameter('joint_3.stiffness', [90.0] * 12)
    assert ok.successful, ok.reason
    values = parameters.values_from_config(CONFIG, parameters.SPINE_NODE_PARAMETERS)
    values['joint_3.stiffness'] = [90.0] * 12
    stiffer = parameters.spine_node_settings(values).chain
    before = harness.counts()
    harness.send_screws(xi)
    check_outputs(harness.next_outputs(before), stiffer, xi)
    for name, value, match in (('chain.link_offsets', [0.0] * 5, 'chain.link_offsets'),
                               ('joint.stiffness', [-1.0] * 12, 'stiffness'),
                               ('chain.gravity', [0.0, 1.0], 'gravity'),
                               ('chain.n_joints', 4, '')):
        result = harness.set_parameter(name, value)
        assert not result.successful and match in result.reason, (name, result.reason)
    before = harness.counts()
    harness.send_screws(xi)
    check_outputs(harness.next_outputs(before), stiffer, xi)  # the rejected sets changed nothing
    ok = harness.set_parameter('joint_3.stiffness', [])
    assert ok.successful, ok.reason
    before = harness.counts()
    harness.send_screws(xi)
    check_outputs(harness.next_outputs(before), chain, xi)


# ---------------------------------------------------------------------------- clean stop
def _wait_ready(proc: NodeProcess, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while 'ready:' not in proc.log():
        assert proc.alive(), proc.log()
        assert time.monotonic() < deadline, proc.log()
        time.sleep(0.05)


@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_signal_stops_the_node_cleanly(sig):
    proc = NodeProcess(unique_namespace('spine_stop'), CONFIG, new_session=True,
                       executable=EXECUTABLE)
    try:
        _wait_ready(proc)
        worker = proc.worker_pid()
        time.sleep(0.5)
        os.kill(proc.pid, sig)
        code = proc.process.wait(timeout=10.0)
        assert code == 0, proc.log()
        deadline = time.monotonic() + 5.0
        while os.path.exists(f'/proc/{worker}') and time.monotonic() < deadline:
            time.sleep(0.05)
        assert not os.path.exists(f'/proc/{worker}') or \
            open(f'/proc/{worker}/stat').read().rsplit(')', 1)[1].split()[0] == 'Z'
    finally:
        proc.kill()


# ---------------------------------------------------------------------------- fuzz
HOSTILE = (math.nan, math.inf, -math.inf, 1e308, -1e308, 5e-324, 1e154, 0.0)


class SpineFuzz:
    """Seeded hostile and valid inputs for the spine's topics and service, with the library's
    answer: :meth:`case` gives ``(target, kind, message)``; :meth:`predict` the expected
    ``~/tip_stiffness`` data (None: nothing may be published), mirroring the node's state."""

    def __init__(self, chain: JointChain, seed: int) -> None:
        self.chain = chain
        self.rng = np.random.default_rng(seed)
        self.center = chain.unloaded_screws()
        self.rest_default = [m.rest_lengths for m in chain.joints]
        self.rest = None
        self.last = None
        self.max_length = parameters.defaults(
            parameters.SPINE_NODE_PARAMETERS)['limits.max_array_length']

    def valid_screws(self) -> np.ndarray:
        return self.center + self.rng.normal(scale=[0.05] * 3 + [0.001] * 3, size=(N, 6))

    def case(self) -> tuple[str, str, object]:
        r = self.rng
        u = r.random()
        if u < 0.55:
            xi = self.valid_screws().ravel()
            kind = 'valid' if r.random() < 0.4 else str(r.choice(
                ['length', 'hostile', 'chart', 'oversized']))
            if kind == 'length':
                xi = xi[:int(r.choice([0, 1, 5, 6, 24, 29]))] if r.random() < 0.5 else \
                    np.r_[xi, np.zeros(int(r.choice([1, 6, 30])))]
            elif kind == 'hostile':
                xi[r.integers(xi.size)] = r.choice(HOSTILE)
            elif kind == 'chart':
                j = r.integers(N)
                xi[6 * j:6 * j + 3] *= r.choice([2 * math.pi, 2 * math.pi + 1e-9, 1e3]) / \
                    np.linalg.norm(xi[6 * j:6 * j + 3])
            elif kind == 'oversized':
                xi = np.zeros(self.max_length + 1)
            return 'screws', kind, Float64MultiArray(data=xi.tolist())
        if u < 0.85:
            T = exp_se3(self.valid_screws())
            msg = pose_array(T)
            kind = 'valid' if r.random() < 0.4 else str(r.choice(
                ['count', 'quaternion', 'position', 'frame']))
            j = int(r.integers(N))
            if kind == 'count':
                msg.poses = msg.poses[:int(r.choice([0, 4]))] if r.random() < 0.5 else \
                    msg.poses + msg.poses[:2]
            elif kind == 'quaternion':
                q = msg.poses[j].orientation
                q.x, q.y, q.z, q.w = (float(v) for v in r.choice(
                    [[0, 0, 0, 0], [1, 1, 0, 0], [math.nan, 0, 0, 1], [0, 0, 0, 1.01]]))
            elif kind == 'position':
                msg.poses[j].position.x = float(r.choice(HOSTILE))
            elif kind == 'frame':
                msg.header.frame_id = 'world'
            return 'poses', kind, msg
        if u < 0.92:
            rest = np.concatenate(self.rest_default) * r.uniform(0.98, 1.02, size=12 * N)
            kind = 'valid' if r.random() < 0.5 else str(r.choice(['length', 'hostile']))
            if kind == 'length':
                rest = rest[:-1]
            elif kind == 'hostile':
                rest[r.integers(rest.size)] = r.choice([-0.01, 0.0, math.nan, math.inf])
            return 'rest_lengths', kind, Float64MultiArray(data=rest.tolist())
        request = SolveChainEquilibrium.Request()
        kind = str(r.choice(['valid', 'huge', 'nan', 'length']))
        W = r.normal(scale=[0.03] * 3 + [0.0006] * 3)
        if kind == 'huge':
            W[r.integers(6)] = 1e6
        elif kind == 'nan':
            W[r.integers(6)] = math.nan
        elif kind == 'length':
            request.initial_screws = [0.0] * int(r.choice([1, 29, 31]))
        request.tip_wrench = wrench_msg(W)
        return 'service', kind, request

    def _outputs(self, xi: np.ndarray) -> np.ndarray | None:
        try:
            out = spine_outputs(self.chain, xi, self.rest)
        except ValueError:
            return None
        values = [out.tip_stiffness_tool, out.tip_stiffness_base, out.tip_wrench,
                  out.state.wrenches, out.state.stiffness, out.state.cartesian_stiffness,
                  out.state.tip_transform]
        if not all(np.isfinite(v).all() for v in values):
            return None
        self.last = xi
        return out.tip_stiffness_tool.ravel()

    def predict(self, target: str, msg) -> np.ndarray | None:
        with np.errstate(all='ignore'):
            return self._predict(target, msg)

    def _predict(self, target: str, msg) -> np.ndarray | None:
        try:
            if target == 'screws':
                xi = screws_input(conversions.multiarray_to_array(
                    msg, max_length=self.max_length), N)
            elif target == 'poses':
                ref = self.last if self.last is not None else np.array(
                    [m.initial_screw for m in self.chain.joints])
                xi = poses_input(msg.header.frame_id, msg.poses, 'spine_base', ref,
                                 conversions.pose_message_to_transform)
            else:
                self.rest = list(rest_lengths_input(conversions.multiarray_to_array(
                    msg, max_length=self.max_length), self.chain))
                return None if self.last is None else self._outputs(self.last)
        except ValueError:
            return None
        return self._outputs(xi)


def run_fuzz(harness: Harness, chain: JointChain, n_cases: int, seed: int) -> dict:
    fuzz = SpineFuzz(chain, seed)
    # The tip stiffness comes from a 6N x 6N solve: the node's and this process's BLAS may sum in
    # another order (threads), which its conditioning turns into ~1e-11 relative at worst seen.
    matcher = StreamMatcher(lambda m: m.data, rtol=1e-9, atol=1e-12)
    harness.ros.subscribe_callback(Float64MultiArray, f'{harness.base}/tip_stiffness', matcher,
                                   DEEP)
    time.sleep(0.5)  # the subscription is matched
    # A known state: a valid configuration (the previous rest lengths may differ from the
    # defaults: nothing is expected for it), then the default rest lengths (re-published for it).
    xi = fuzz.valid_screws()
    harness.send_screws(xi)
    time.sleep(0.3)
    matcher.give_up()
    matcher.wrong = 0
    fuzz.rest = list(fuzz.rest_default)
    matcher.expect(0, fuzz._outputs(xi))
    harness.rest_pub.publish(Float64MultiArray(data=np.concatenate(fuzz.rest_default).tolist()))
    if not matcher.wait_outstanding(0, 10.0):
        raise AssertionError('no answer to the initial rest lengths')
    answers = {'service ok': 0, 'service refused': 0, 'service wrong': []}
    for seq in range(1, n_cases + 1):
        target, kind, msg = fuzz.case()
        if target == 'service':  # answered while the node's state stays the oracle's
            response = harness.ros.call(harness.solve, msg, timeout=60.0)
            if kind in ('nan', 'length') and response.success:
                answers['service wrong'].append(kind)
            elif response.success:
                answers['service ok'] += 1
                W = conversions.msg_to_wrench(msg.tip_wrench)
                xi = np.reshape(response.screws, (N, 6))
                if np.abs(chain.residuals(xi, W, np.zeros(3), fuzz.rest)).max() > 1e-8:
                    answers['service wrong'].append('residual')
            else:
                answers['service refused'] += 1
            continue
        if target != 'screws':  # the node's state must be the oracle's: wait for the answers
            matcher.wait_outstanding(0, 10.0)
        expected = fuzz.predict(target, msg)
        if expected is not None:
            matcher.expect(seq, expected)
        {'screws': harness.screws_pub, 'poses': harness.poses_pub,
         'rest_lengths': harness.rest_pub}[target].publish(msg)
        if target == 'rest_lengths':
            if expected is None:
                time.sleep(0.05)
            matcher.wait_outstanding(0, 10.0)
        elif target == 'poses' and expected is not None:
            # Answered before the next screws are sent: the node orders inputs per topic only,
            # and screws that overtook the poses would be the reference of their log map.
            matcher.wait_outstanding(0, 10.0)
        time.sleep(0.002)
        if not matcher.wait_outstanding(20, 10.0):
            break
    matcher.wait_outstanding(0, 10.0)
    time.sleep(0.5)
    return {'matched': matcher.matched, 'missing': matcher.missing, 'wrong': matcher.wrong,
            'wrong examples': matcher.wrong_examples, 'outstanding': matcher.outstanding(),
            'alive': harness.proc.alive(), **answers}


def _check_fuzz(report: dict) -> None:
    assert report['alive'], report
    assert report['wrong'] == 0, report
    assert report['missing'] == 0 and report['outstanding'] == 0, report
    assert not report['service wrong'], report
    assert report['matched'] > 0 and report['service ok'] + report['service refused'] > 0


def test_shortened_fuzz(harness, chain):
    _check_fuzz(run_fuzz(harness, chain, 300, seed=14))


@pytest.mark.slow
def test_longer_fuzz(harness, chain):
    _check_fuzz(run_fuzz(harness, chain, 3000, seed=1414))
