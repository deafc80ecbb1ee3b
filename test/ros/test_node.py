"""stiffness_node over the real middleware: the installed executable runs as a separate process,
started with ``--ros-args --params-file``; a test node publishes inputs, reads outputs and calls
the services, and every value is checked against the library."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from rcl_interfaces.srv import GetParameters, SetParameters  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    LATCHED,
    REPO,
    NodeProcess,
    RosClient,
    answer_every_output,
    unique_namespace,
)
from tensegrity_stiffness.srv import (  # noqa: E402
    DesignRestLengths,
    PlanarForwardKinematics,
    PlanarInverseKinematics,
    SolveEquilibrium,
)
from visualization_msgs.msg import MarkerArray  # noqa: E402

from tensegrity_stiffness.geometry.screw import exp_se3, log_se3  # noqa: E402
from tensegrity_stiffness.mechanics.design import design_rest_lengths  # noqa: E402
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium, stability_margin  # noqa: E402
from tensegrity_stiffness.mechanics.interpretation import interpret_stiffness  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.mechanics.planar import PlanarMechanism  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402

CONFIG = REPO / 'config' / 'default_joint.yaml'
QUIET_S = 0.4  # how long "nothing is published" is watched after a bad input
OUTPUT_TOPICS = {
    'wrench': WrenchStamped, 'stiffness': Float64MultiArray,
    'cartesian_stiffness': Float64MultiArray, 'string_tensions': Float64MultiArray,
    'stiffness_interpretation': Float64MultiArray, 'markers': MarkerArray,
}


class Harness:
    def __init__(self) -> None:
        self.ns = unique_namespace('node')
        # Markers once per input, so that every output can be checked per input.
        self.proc = NodeProcess(self.ns, CONFIG, extra_args=['-p', 'markers.max_rate:=0.0'])
        self.ros = RosClient('node_test')
        base = f'{self.ns}/stiffness_node'
        self.base = base
        self.inbox = {name: self.ros.subscribe(t, f'{base}/{name}')
                      for name, t in OUTPUT_TOPICS.items()}
        self.diagnostics = self.ros.subscribe(DiagnosticArray, '/diagnostics')
        self.screw_pub = self.ros.publisher(Float64MultiArray, f'{base}/screw')
        self.pose_pub = self.ros.publisher(PoseStamped, f'{base}/pose')
        self.rest_pub = self.ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED)
        self.solve = self.ros.client(SolveEquilibrium, f'{base}/solve_equilibrium')
        self.design = self.ros.client(DesignRestLengths, f'{base}/design_rest_lengths')
        self.fk = self.ros.client(PlanarForwardKinematics, f'{base}/planar_forward_kinematics')
        self.ik = self.ros.client(PlanarInverseKinematics, f'{base}/planar_inverse_kinematics')
        self.set_params = self.ros.client(SetParameters, f'{base}/set_parameters')
        self.get_params = self.ros.client(GetParameters, f'{base}/get_parameters')
        for pub in (self.screw_pub, self.pose_pub, self.rest_pub):
            self.ros.wait_for_subscribers(pub)
        for name in OUTPUT_TOPICS:
            self.ros.wait_for_publishers(f'{base}/{name}')
        initial = JointModel.from_yaml(CONFIG).initial_screw
        answer_every_output(lambda: self.send_screw(initial), self.counts)

    def counts(self) -> dict[str, int]:
        return {name: len(inbox) for name, inbox in self.inbox.items()}

    def send_screw(self, values) -> None:
        self.screw_pub.publish(Float64MultiArray(data=[float(v) for v in values]))

    def next_outputs(self, before: dict[str, int], timeout: float = 5.0) -> dict[str, object]:
        """The first output on every topic after the counts in ``before``."""
        return {name: self.inbox[name].wait_for(before[name] + 1, timeout)[before[name]]
                for name in OUTPUT_TOPICS}

    def assert_quiet(self, before: dict[str, int]) -> None:
        time.sleep(QUIET_S)
        assert self.counts() == before, 'published for an invalid input'
        assert self.proc.alive(), self.proc.log()

    def set_parameter(self, name: str, value) -> object:
        return self.ros.set_parameter(self.set_params, name, value)

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
def model():
    return JointModel.from_yaml(CONFIG)


def data(msg) -> np.ndarray:
    return np.asarray(msg.data, dtype=np.float64)


def wrench_of(msg: WrenchStamped) -> np.ndarray:
    return conversions.msg_to_wrench(msg.wrench)


def check_outputs(out, model, xi, rest=None):
    state = model.evaluate(xi, rest)
    np.testing.assert_allclose(wrench_of(out['wrench']), state.wrench, atol=1e-12)
    assert out['wrench'].header.frame_id == 'tensegrity_link1'
    K = out['stiffness']
    np.testing.assert_allclose(data(K).reshape(6, 6), state.stiffness, rtol=1e-12, atol=1e-12)
    dims = K.layout.dim
    assert [(d.size, d.stride) for d in dims] == [(6, 36), (6, 6)]
    assert 'fx fy fz mx my mz' in dims[0].label and 'wx wy wz vx vy vz' in dims[1].label
    Kc = out['cartesian_stiffness']
    np.testing.assert_allclose(data(Kc).reshape(6, 6), state.cartesian_stiffness, rtol=1e-12,
                               atol=1e-12)
    assert 'fx fy fz mx my mz' in Kc.layout.dim[0].label
    assert 'dx dy dz rx ry rz' in Kc.layout.dim[1].label
    tensions = out['string_tensions']
    np.testing.assert_allclose(data(tensions), state.tensions, atol=1e-12)
    assert tensions.layout.dim[0].size == 12 and 'cross_AA' in tensions.layout.dim[0].label
    it = interpret_stiffness(state.stiffness)
    interp = out['stiffness_interpretation']
    np.testing.assert_allclose(data(interp), np.r_[it.block_norms, it.column_norms,
                                                   it.row_norms], rtol=1e-12)
    assert interp.layout.dim[0].size == 16 and 'K_fw K_fv K_mw K_mv' in interp.layout.dim[0].label
    markers = out['markers'].markers
    assert all(m.header.frame_id == 'tensegrity_link1' for m in markers)
    points = np.array([[p.x, p.y, p.z] for m in markers if m.ns == 'link2_nodes'
                       for p in m.points])
    np.testing.assert_allclose(points, model.link2_nodes_in_link1(state.transform), atol=1e-12)
    return state


def test_screw_input_publishes_every_output(harness, model):
    xi = model.initial_screw + np.r_[0.05, -0.02, 0.03, 0.001, -0.002, 0.0005]
    before = harness.counts()
    t0 = harness.ros.node.get_clock().now().nanoseconds
    harness.send_screw(xi)
    out = harness.next_outputs(before)
    check_outputs(out, model, xi)
    stamp = conversions.stamp_to_nanoseconds(out['wrench'].header.stamp)
    assert t0 - 1e9 < stamp < t0 + 5e9  # stamped "now" for a Float64MultiArray input


def test_pose_input_uses_the_branch_nearest_the_last_screw(harness, model):
    # At the rest pose |omega| = pi: the log map has two branches, +pi u and -pi u.
    xi = model.initial_screw
    before = harness.counts()
    harness.send_screw(xi)
    harness.next_outputs(before)  # answered (the harness's warm-up sent this screw too)
    T = exp_se3(xi)
    pose = PoseStamped()
    pose.header.frame_id = 'tensegrity_link1'
    pose.header.stamp.sec, pose.header.stamp.nanosec = 1234, 5678
    pose.pose = conversions.transform_to_pose(T)
    before = harness.counts()
    harness.pose_pub.publish(pose)
    out = harness.next_outputs(before)
    state = model.evaluate(xi)
    np.testing.assert_allclose(data(out['stiffness']).reshape(6, 6), state.stiffness, atol=1e-8)
    assert out['wrench'].header.stamp.sec == 1234 and out['wrench'].header.stamp.nanosec == 5678
    # Now from the other branch: the same pose is also exp of a screw with omega = -pi u.
    other = log_se3(T, reference=np.r_[-xi[:3], xi[3:]])
    np.testing.assert_allclose(other[:3], -xi[:3], atol=1e-9)
    np.testing.assert_allclose(exp_se3(other), T, atol=1e-12)
    before = harness.counts()
    harness.send_screw(other)
    harness.next_outputs(before)
    before = harness.counts()
    harness.pose_pub.publish(pose)
    out = harness.next_outputs(before)
    np.testing.assert_allclose(data(out['stiffness']).reshape(6, 6), model.stiffness(other),
                               atol=1e-8)
    assert not np.allclose(model.stiffness(other), state.stiffness, atol=1e-3)


def test_rest_lengths_republish_for_the_last_configuration(harness, model):
    xi = model.initial_screw + np.r_[0.01, 0, 0, 0, 0.001, 0]
    before = harness.counts()
    harness.send_screw(xi)
    harness.next_outputs(before)
    rest = model.rest_lengths * 0.97
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=rest.tolist()))
    out = harness.next_outputs(before)
    check_outputs(out, model, xi, rest)
    # Restore.
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=model.rest_lengths.tolist()))
    harness.next_outputs(before)


def test_solve_equilibrium_service(harness, model):
    W = np.r_[0.05, -0.03, 0.02, 0.001, 0.0005, -0.0008]
    req = SolveEquilibrium.Request(external_wrench=conversions.wrench_to_msg(W))
    res = harness.ros.call(harness.solve, req)
    expected = solve_equilibrium(model, W)
    assert res.success, res.message
    np.testing.assert_allclose(res.screw, expected.screw, atol=1e-9)
    np.testing.assert_allclose(conversions.msg_to_wrench(res.string_wrench), -W, atol=1e-9)
    np.testing.assert_allclose(np.reshape(res.stiffness, (6, 6)),
                               model.stiffness(res.screw), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(np.reshape(res.cartesian_stiffness, (6, 6)),
                               model.cartesian_stiffness(res.screw), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(res.tensions, model.tensions(res.screw), atol=1e-12)
    np.testing.assert_allclose(conversions.pose_message_to_transform(res.pose), exp_se3(res.screw),
                               atol=1e-9)
    assert res.stable and res.residual <= 1e-9 and res.iterations >= 1
    assert res.energy == pytest.approx(model.energy(res.screw))
    # Explicit rest lengths and initial screw.
    rest = model.rest_lengths * 0.98
    req = SolveEquilibrium.Request(external_wrench=conversions.wrench_to_msg(np.zeros(6)),
                                   rest_lengths=rest.tolist(),
                                   initial_screw=model.initial_screw.tolist())
    res = harness.ros.call(harness.solve, req)
    assert res.success
    np.testing.assert_allclose(model.wrench(res.screw, rest), 0.0, atol=1e-9)


@pytest.mark.parametrize(('request_fields', 'match'), [
    ({'rest_lengths': [0.03] * 11}, 'rest_lengths must have shape'),
    ({'rest_lengths': [-0.03] * 12}, 'rest_lengths must be > 0'),
    ({'initial_screw': [0.0] * 5}, 'initial_screw must have 6 values'),
    ({'initial_screw': [9.0, 0, 0, 0, 0, 0]},
     'initial_screw: |omega| = 9 rad is outside the chart'),
    ({'external_wrench_values': [math.nan, 0, 0, 0, 0, 0]}, 'NaN'),
    # beyond what the strings can balance but within 10 x their capacity: the solver's residual
    ({'external_wrench_values': [60.0, 0, 0, 0, 0, 0]}, 'residual'),
    # beyond 10 x their capacity (184.8 N): refused by range before any work (issue #42)
    ({'external_wrench_values': [500.0, 0, 0, 0, 0, 0]}, 'outside the range of this joint'),
])
def test_solve_equilibrium_rejections(harness, request_fields, match):
    fields = dict(request_fields)
    W = fields.pop('external_wrench_values', [0.0] * 6)
    req = SolveEquilibrium.Request(**fields)
    req.external_wrench.force.x, req.external_wrench.force.y, req.external_wrench.force.z = W[:3]
    req.external_wrench.torque.x = W[3]
    res = harness.ros.call(harness.solve, req)
    assert not res.success
    assert match in res.message, res.message
    assert harness.proc.alive()


def test_design_rest_lengths_service(harness, model):
    target = model.initial_screw + np.array([0.05, 0.0, 0.0, 0.0, 0.001, 0.0])
    W = np.array([0.0, 0.2, 0.0, 0.0, 0.0, 0.001])
    request = DesignRestLengths.Request(target_screw=target.tolist(), tension_min=0.1,
                                        tension_max=1.5)
    request.external_wrench = conversions.wrench_to_msg(W)
    response = harness.ros.call(harness.design, request)
    expected = design_rest_lengths(model, target, W, tension_min=0.1, tension_max=1.5)
    assert response.success and expected.success, response.message
    np.testing.assert_allclose(response.rest_lengths, expected.rest_lengths, rtol=1e-12)
    np.testing.assert_allclose(response.tensions, expected.tensions, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(np.reshape(response.cartesian_stiffness, (6, 6)),
                               expected.cartesian_stiffness, rtol=1e-12, atol=1e-12)
    assert response.stable == expected.stable
    # it computes only: the equilibrium with the designed rest lengths is the target
    check = solve_equilibrium(model, W, rest_lengths=np.asarray(response.rest_lengths),
                              initial_screw=target + 1e-3)
    np.testing.assert_allclose(check.screw, target, atol=1e-9)
    # the node's own rest lengths are unchanged
    before = harness.counts()
    harness.send_screw(model.initial_screw)
    out = harness.next_outputs(before)
    np.testing.assert_allclose(data(out['stiffness']).reshape(6, 6),
                               model.stiffness(model.initial_screw), rtol=1e-12, atol=1e-12)
    # the pose form gives the same answer
    pose = conversions.transform_to_pose(exp_se3(target))
    by_pose = harness.ros.call(harness.design, DesignRestLengths.Request(
        target_pose=pose, external_wrench=request.external_wrench, tension_min=0.1,
        tension_max=1.5))
    np.testing.assert_allclose(by_pose.rest_lengths, response.rest_lengths, rtol=1e-9)


@pytest.mark.parametrize(('fields', 'match'), [
    ({'target_screw': [0.0] * 5, 'tension_min': 0.1, 'tension_max': 1.5}, 'target_screw'),
    ({'target_screw': [2.2214, 0, -2.2214, 0.0167, 0, 0.0167], 'tension_min': 1.0,
      'tension_max': 0.5}, 'tension_max'),
    ({'target_screw': [7.0, 0, 0, 0, 0, 0], 'tension_min': 0.1, 'tension_max': 1.5},
     'chart'),
])
def test_design_rest_lengths_rejections(harness, fields, match):
    response = harness.ros.call(harness.design, DesignRestLengths.Request(**fields))
    assert not response.success
    assert response.message.startswith('invalid request') and match in response.message, \
        response.message
    assert harness.proc.alive()


def test_design_rest_lengths_infeasible(harness, model):
    response = harness.ros.call(harness.design, DesignRestLengths.Request(
        target_screw=model.initial_screw.tolist(), tension_min=0.1, tension_max=1.5,
        external_wrench=conversions.wrench_to_msg([0.0, 50.0, 0.0, 0.0, 0.0, 0.0])))
    assert not response.success
    assert not response.message.startswith(('invalid request', 'internal error')), \
        response.message
    assert list(response.rest_lengths) == []


def test_planar_services(harness):
    planar = PlanarMechanism(L=1.0, K1=100.0, K2=10.0)
    fk = harness.ros.call(harness.fk, PlanarForwardKinematics.Request(actuator_length=1.2,
                                                                      actuator_angle=0.7))
    ref = planar.forward(1.2, 0.7)
    assert fk.success, fk.message
    assert (fk.x, fk.y, fk.platform_angle) == pytest.approx((ref.x, ref.y, ref.theta2),
                                                            abs=1e-12)
    assert fk.stiffness == pytest.approx(ref.stiffness, rel=1e-12)
    assert fk.energy == pytest.approx(ref.energy, rel=1e-12, abs=1e-12)
    np.testing.assert_allclose(np.reshape(fk.jacobian, (2, 2)), ref.jacobian, atol=1e-12)
    assert fk.jacobian_determinant == pytest.approx(ref.jacobian_determinant, abs=1e-12)
    assert list(fk.singularities) == list(ref.singularities)
    assert fk.stable == ref.stable and fk.in_range == ref.theta2_in_range
    ik = harness.ros.call(harness.ik, PlanarInverseKinematics.Request(x=fk.x, y=fk.y))
    assert ik.success and len(ik.actuator_length) >= 1
    ref_ik = planar.inverse(fk.x, fk.y)
    np.testing.assert_allclose(ik.actuator_length, [s.L3 for s in ref_ik], atol=1e-12)
    np.testing.assert_allclose(ik.actuator_angle, [s.theta1 for s in ref_ik], atol=1e-12)
    np.testing.assert_allclose(ik.platform_angle, [s.theta2 for s in ref_ik], atol=1e-12)
    np.testing.assert_allclose(ik.stiffness, [s.stiffness for s in ref_ik], atol=1e-9)
    assert list(ik.stable) == [s.stable for s in ref_ik]
    assert any(abs(a - 1.2) < 1e-9 and abs(b - 0.7) < 1e-9
               for a, b in zip(ik.actuator_length, ik.actuator_angle, strict=True))


def test_planar_service_rejections(harness):
    out = harness.ros.call(harness.fk, PlanarForwardKinematics.Request(actuator_length=5.0,
                                                                       actuator_angle=0.5))
    assert not out.success and 'outside the actuator workspace' in out.message
    out = harness.ros.call(harness.fk, PlanarForwardKinematics.Request(actuator_length=math.nan,
                                                                       actuator_angle=0.5))
    assert not out.success and 'L3' in out.message
    out = harness.ros.call(harness.ik, PlanarInverseKinematics.Request(x=50.0, y=50.0))
    assert not out.success and out.message.startswith('unreachable')
    assert len(out.actuator_length) == 0
    out = harness.ros.call(harness.ik, PlanarInverseKinematics.Request(x=math.inf, y=0.0))
    assert not out.success and 'invalid request' in out.message
    assert harness.proc.alive()


BAD_SCREWS = [
    ('five values', [0.1] * 5), ('seven values', [0.1] * 7), ('empty', []),
    ('NaN', [0.1, math.nan, 0, 0, 0, 0]), ('inf', [0.1, 0, -math.inf, 0, 0, 0]),
    ('outside the chart', [2 * math.pi, 0, 0, 0, 0, 0]),
    ('beyond the chart', [5.0, 5.0, 0, 0, 0, 0]),
    ('collapsed strings', [0, 0, 0, 0, 0, 0]),
    ('oversized', [0.0] * 5000),
]


@pytest.mark.parametrize(('kind', 'values'), BAD_SCREWS, ids=[k for k, _ in BAD_SCREWS])
def test_bad_screws_publish_nothing_and_the_node_keeps_going(harness, model, kind, values):
    before = harness.counts()
    harness.send_screw(values)
    harness.assert_quiet(before)
    xi = model.initial_screw + np.r_[0.0, 0.001 * (len(values) % 13), 0, 0, 0, 0]
    harness.send_screw(xi)
    check_outputs(harness.next_outputs(before), model, xi)


def _pose(q, p=(0.0, -0.015, 0.0), frame='tensegrity_link1'):
    msg = PoseStamped()
    msg.header.frame_id = frame
    msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = p
    (msg.pose.orientation.x, msg.pose.orientation.y, msg.pose.orientation.z,
     msg.pose.orientation.w) = q
    return msg


BAD_POSES = [
    ('zero quaternion', _pose((0.0, 0.0, 0.0, 0.0))),
    ('non-unit quaternion', _pose((0.0, 0.0, 0.0, 2.0))),
    ('NaN quaternion', _pose((math.nan, 0.0, 0.0, 1.0))),
    ('NaN position', _pose((0.0, 0.0, 0.0, 1.0), p=(math.nan, 0.0, 0.0))),
    ('wrong frame', _pose((0.0, 0.0, 0.0, 1.0), frame='map')),
]


@pytest.mark.parametrize(('kind', 'pose'), BAD_POSES, ids=[k for k, _ in BAD_POSES])
def test_bad_poses_publish_nothing(harness, model, kind, pose):
    before = harness.counts()
    harness.pose_pub.publish(pose)
    harness.assert_quiet(before)
    xi = model.initial_screw
    harness.send_screw(xi)
    check_outputs(harness.next_outputs(before), model, xi)


@pytest.mark.parametrize('rest', [[0.03] * 11, [-0.03] * 12, [0.0] * 12, [math.nan] * 12,
                                  [0.03] * 13])
def test_bad_rest_lengths_keep_the_old_ones(harness, model, rest):
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=rest))
    harness.assert_quiet(before)
    xi = model.initial_screw + np.r_[0, 0, 0.02, 0, 0, 0]
    harness.send_screw(xi)
    check_outputs(harness.next_outputs(before), model, xi)  # default rest lengths still hold


def test_parameters_validated_as_a_whole(harness, model):
    ok = harness.set_parameter('joint.stiffness', [90.0] * 12)
    assert ok.successful, ok.reason
    xi = model.initial_screw + np.r_[0.02, 0, 0, 0, 0, 0]
    stiffer = JointModel.from_dict({**_section(), 'stiffness': [90.0] * 12})
    before = harness.counts()
    harness.send_screw(xi)
    check_outputs(harness.next_outputs(before), stiffer, xi)
    bad = harness.set_parameter('joint.stiffness', [-1.0] * 12)
    assert not bad.successful and 'joint.stiffness must be > 0' in bad.reason
    bad = harness.set_parameter('joint.rest_lengths', [0.03] * 5)
    assert not bad.successful and 'joint.rest_lengths must have 12 values' in bad.reason
    bad = harness.set_parameter('joint.force_law', 'cubic')
    assert not bad.successful and 'force_law' in bad.reason
    bad = harness.set_parameter('planar.K1', -5.0)
    assert not bad.successful
    ro = harness.set_parameter('qos.depth', 3)  # the right type: refused for being read-only
    assert not ro.successful and 'read-only' in ro.reason, ro.reason
    before = harness.counts()
    harness.send_screw(xi)
    check_outputs(harness.next_outputs(before), stiffer, xi)  # rejected sets changed nothing
    ok = harness.set_parameter('joint.stiffness', [77.0] * 12)
    assert ok.successful


def _section():
    from tensegrity_stiffness import config

    return dict(config.load_section(CONFIG, 'joint'))


def test_diagnostics(harness, model):
    def joint_status(msg):
        return next((s for s in msg.status if s.name.endswith('stiffness_node: joint')), None)

    def margin_is(margin: float):
        def check(msg) -> bool:
            status = joint_status(msg)
            values = {} if status is None else {kv.key: kv.value for kv in status.values}
            key = 'chart margin 2pi - |omega| [rad]'
            return key in values and abs(float(values[key]) - margin) <= 1e-5 * margin
        return check

    before = harness.counts()
    harness.send_screw(model.initial_screw)
    harness.next_outputs(before)  # so that the next test's counts do not race these outputs
    theta = float(np.linalg.norm(model.initial_screw[:3]))
    # the first status computed after this screw (its chart margin says which screw it saw)
    msg = harness.diagnostics.wait_until(margin_is(2 * math.pi - theta), timeout=5.0)
    status = joint_status(msg)
    values = {kv.key: kv.value for kv in status.values}
    # the last configuration is the unloaded equilibrium: all strings taut, stable, level OK
    assert status.level == DiagnosticStatus.OK and status.message == 'all strings taut, stable'
    assert values['slack strings'] == 'none' and values['saturated strings'] == 'none'
    assert float(values['stability margin (min eig of scaled sym K_c)']) == pytest.approx(
        stability_margin(model.cartesian_stiffness(model.initial_screw)), rel=1e-5)
    assert float(values['compute time mean [us]']) > 0.0
    assert int(values['outputs published']) >= 1
    assert status.hardware_id == 'tensegrity_link1'
    # a bent configuration with slack strings is a warning naming them
    bent = np.array([2.3963, 0.4857, -2.3963, 0.0198, -0.0033, 0.0161])
    slack = [name for name, s in zip(model.string_names, model.evaluate(bent).slack,
                                     strict=True) if s]
    assert slack
    before = harness.counts()
    harness.send_screw(bent)
    harness.next_outputs(before)
    msg = harness.diagnostics.wait_until(
        margin_is(2 * math.pi - float(np.linalg.norm(bent[:3]))), timeout=5.0)
    status = joint_status(msg)
    assert status.level == DiagnosticStatus.WARN
    assert f'{len(slack)} slack' in status.message
    values = {kv.key: kv.value for kv in status.values}
    assert all(name in values['slack strings'] for name in slack)


def test_markers_mark_slack_strings(harness, model):
    xi = model.initial_screw
    rest = model.rest_lengths.copy()
    rest[:4] = 0.05  # the cross strings (0.0452 m long at rest) go slack
    before = harness.counts()
    harness.send_screw(xi)
    harness.next_outputs(before)
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=rest.tolist()))
    out = harness.next_outputs(before)
    state = check_outputs(out, model, xi, rest)
    assert state.slack[:4].all() and not state.slack[4:].any()
    by_ns = {m.ns: m for m in out['markers'].markers}
    assert len(by_ns['slack_strings'].points) == 2 * 4
    assert len(by_ns['strings'].points) == 2 * 8 and len(by_ns['strings'].colors) == 2 * 8
    before = harness.counts()
    harness.rest_pub.publish(Float64MultiArray(data=model.rest_lengths.tolist()))
    out = harness.next_outputs(before)
    assert len({m.ns: m for m in out['markers'].markers}['slack_strings'].points) == 0


def test_rate_limited_markers_follow_the_last_input_once(harness, model):
    """With ``markers.max_rate`` > 0 the markers come from a timer that runs while ~/markers
    has a subscriber (this harness): one MarkerArray for the last configuration, not repeated
    while no new input arrives."""
    assert harness.set_parameter('markers.max_rate', 20.0).successful
    try:
        time.sleep(1.0)  # the watch (every 0.5 s) starts the marker timer
        xi = model.initial_screw + np.array([0.03, 0.0, 0.0, 0.0, 0.001, 0.0])
        before = harness.counts()
        harness.send_screw(xi)
        markers = harness.inbox['markers'].wait_for(before['markers'] + 1, 5.0)
        out = markers[before['markers']]
        state = model.evaluate(xi)
        points = np.array([[p.x, p.y, p.z] for m in out.markers if m.ns == 'link2_nodes'
                           for p in m.points])
        np.testing.assert_allclose(points, model.link2_nodes_in_link1(state.transform),
                                   atol=1e-12)
        time.sleep(0.5)  # ten timer periods: no second MarkerArray for the same input
        assert len(harness.inbox['markers']) == before['markers'] + 1
    finally:
        assert harness.set_parameter('markers.max_rate', 0.0).successful
