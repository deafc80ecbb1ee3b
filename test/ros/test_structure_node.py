"""structure_node over the real middleware: the installed executable runs as a separate process
on the packaged 6-bar (on the ground, under gravity); a test node publishes poses, reads every
output and calls the services, and every value is checked against the library
(:meth:`Structure.evaluate`, :func:`solve_structure_equilibrium`, :func:`check_structure`)."""

from __future__ import annotations

import json
import re
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseArray  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    LATCHED,
    NodeProcess,
    RosClient,
    answer_every_output,
    repeat_until,
    unique_namespace,
)
from tensegrity_stiffness.srv import SolveStructureEquilibrium, StructureReport  # noqa: E402
from visualization_msgs.msg import MarkerArray  # noqa: E402

from tensegrity_stiffness.config import example_config_path  # noqa: E402
from tensegrity_stiffness.mechanics.templates import pose_vector  # noqa: E402
from tensegrity_stiffness.nodes import structure_node as processing  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402
from tensegrity_stiffness.ros.runtime.tf_broadcast import tf_message_type  # noqa: E402
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium  # noqa: E402
from tensegrity_stiffness.structures.report import check_structure  # noqa: E402
from tensegrity_stiffness.structures.structure import Structure  # noqa: E402

EXECUTABLE = 'structure_node'
QUIET_S = 0.4  # how long "nothing is published" is watched after a bad input
OUTPUTS = processing.STRUCTURE_OUTPUTS
TOPICS = {**dict.fromkeys(OUTPUTS, Float64MultiArray), 'markers': MarkerArray}


class Harness:
    def __init__(self, tmp_path) -> None:
        self.ns = unique_namespace('structure')
        params = tmp_path / 'structure_node.yaml'
        params.write_text('structure_node:\n  ros__parameters:\n'
                          '    structure.config: six_bar.yaml\n    markers.max_rate: 0.0\n'
                          '    diagnostics.period: 0.2\n'
                          # the solves' correctness is tested, not their speed: a budget that
                          # three test workers on 2 cores do not exhaust (a fresh-clone run: the
                          # ground's equilibrium stopped after 2 iterations)
                          '    equilibrium.time_budget: 5.0\n')
        self.proc = NodeProcess(self.ns, params, executable=EXECUTABLE)
        self.ros = RosClient('structure_test')
        self.base = base = f'{self.ns}/structure_node'
        self.inbox = {name: self.ros.subscribe(t, f'{base}/{name}') for name, t in TOPICS.items()}
        self.diagnostics = self.ros.subscribe(DiagnosticArray, '/diagnostics')
        tf = tf_message_type()
        self.tf = self.ros.subscribe(tf, '/tf') if tf is not None else None
        self.poses_pub = self.ros.publisher(PoseArray, f'{base}/poses')
        self.values_pub = self.ros.publisher(Float64MultiArray, f'{base}/pose_values')
        self.rest_pub = self.ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED)
        self.solve = self.ros.client(SolveStructureEquilibrium, f'{base}/solve_equilibrium')
        self.report = self.ros.client(StructureReport, f'{base}/report')
        for pub in (self.poses_pub, self.values_pub, self.rest_pub):
            self.ros.wait_for_subscribers(pub)
        for name in TOPICS:
            self.ros.wait_for_publishers(f'{base}/{name}')
        self.structure = Structure.from_yaml(example_config_path('six_bar.yaml'))
        start = self.structure.start_poses()
        answer_every_output(lambda: self.send_poses(start), self.counts)

    def counts(self) -> dict[str, int]:
        return {name: len(inbox) for name, inbox in self.inbox.items()}

    def send_poses(self, transforms, frame_id: str = '') -> None:
        msg = PoseArray(poses=[conversions.transform_to_pose(T) for T in transforms])
        msg.header.frame_id = frame_id
        self.poses_pub.publish(msg)

    def send_values(self, values) -> None:
        self.values_pub.publish(Float64MultiArray(data=[float(v) for v in np.ravel(values)]))

    def next_outputs(self, before: dict[str, int], timeout: float = 10.0) -> dict[str, object]:
        return {name: self.inbox[name].wait_for(before[name] + 1, timeout)[before[name]]
                for name in TOPICS}

    def settled_counts(self, quiet: float = 0.3) -> dict[str, int]:
        """The counts once no output came for ``quiet`` s (the last input's markers follow its
        other outputs)."""
        seen = self.counts()
        deadline = time.monotonic() + 30
        while True:
            time.sleep(quiet)
            now = self.counts()
            if now == seen:
                return now
            assert time.monotonic() < deadline, f'outputs keep coming: {now}'
            seen = now

    def assert_quiet(self, before: dict[str, int]) -> None:
        time.sleep(QUIET_S)
        assert self.counts() == before, 'published for an invalid input'
        assert self.proc.alive(), self.proc.log()

    def close(self) -> int:
        self.ros.close()
        return self.proc.stop()


@pytest.fixture(scope='module')
def harness(tmp_path_factory):
    h = Harness(tmp_path_factory.mktemp('structure_node'))
    yield h
    code = h.close()
    assert code == 0, f'node exit code {code}:\n{h.proc.log()}'


@pytest.fixture(scope='module')
def equilibrium(harness):
    result = solve_structure_equilibrium(harness.structure)
    assert result.success, result.message
    return result


def data(msg) -> np.ndarray:
    return np.asarray(msg.data, dtype=np.float64)


def disturbed(T: np.ndarray, seed: int, scale: float = 0.01) -> np.ndarray:
    """The poses turned and moved by small seeded twists."""
    from tensegrity_stiffness.structures.structure import twist_exp

    rng = np.random.default_rng(seed)
    return np.array([twist_exp(scale * rng.standard_normal(6)) @ P for P in T])


def check_outputs(out: dict, structure: Structure, T: np.ndarray) -> None:
    """Every array output at the poses ``T`` against :meth:`Structure.evaluate` (to 1e-12)."""
    state = structure.evaluate(T)
    n = structure.n_bodies
    scale = np.abs(state.stiffness).max()
    np.testing.assert_allclose(data(out['body_wrenches']).reshape(n, 6), state.wrenches,
                               rtol=1e-12, atol=1e-12 * np.abs(state.wrenches).max())
    np.testing.assert_allclose(data(out['stiffness']).reshape(6 * n, 6 * n), state.stiffness,
                               rtol=1e-12, atol=1e-12 * scale)
    np.testing.assert_allclose(data(out['string_tensions']), state.tensions, rtol=1e-12,
                               atol=1e-12 * state.tensions.max())
    np.testing.assert_allclose(data(out['bar_forces']), state.bar_forces, rtol=1e-12,
                               atol=1e-12 * np.abs(state.bar_forces).max())


def as_read(T: np.ndarray) -> np.ndarray:
    """The transforms the node gets from PoseArray messages of ``T``."""
    return np.array([conversions.pose_message_to_transform(conversions.transform_to_pose(P))
                     for P in T])


# ---------------------------------------------------------------------------- outputs
def test_every_output_against_the_library(harness, equilibrium):
    for seed in range(3):
        T = as_read(disturbed(equilibrium.poses, seed))
        before = harness.counts()
        harness.send_poses(T)
        check_outputs(harness.next_outputs(before), harness.structure, T)


def test_pose_values_give_the_same_outputs(harness, equilibrium):
    T = disturbed(equilibrium.poses, 7)
    values = np.array([pose_vector(P) for P in T])
    before = harness.counts()
    harness.send_values(values)
    out = harness.next_outputs(before)
    check_outputs(out, harness.structure, harness.structure.transforms(values))


def test_contact_forces_at_the_equilibrium_on_the_ground(harness, equilibrium):
    before = harness.counts()
    harness.send_values(np.array([pose_vector(P) for P in equilibrium.poses]))
    out = harness.next_outputs(before)
    nodes = processing.body_nodes(harness.structure)
    forces = data(out['contact_forces']).reshape(len(nodes), 3)
    expected = np.zeros_like(forces)
    for name, f in equilibrium.contacts.items():
        expected[nodes.index(name)] = f
    # the equilibrium's residuals are below 1e-9 (N, N m)
    np.testing.assert_allclose(forces, expected, atol=1e-8)
    arrows = [m for m in out['markers'].markers
              if m.ns == 'contact_forces' and m.type == m.ARROW and m.action == m.ADD]
    assert len(arrows) == len(equilibrium.contacts)
    assert {m.ns for m in out['markers'].markers} >= {'nodes', 'strings', 'slack_strings', 'bars'}


def test_labels_and_layouts(harness):
    before = harness.counts()
    harness.send_poses(harness.structure.start_poses())
    out = harness.next_outputs(before)
    for name, layout in processing.structure_output_layouts(harness.structure).items():
        dims = [(d.label, d.size, d.stride) for d in out[name].layout.dim]
        assert dims == list(layout.dims), name
    rows, cols = out['stiffness'].layout.dim
    assert rows.label.startswith('rows: wrench on each body') and 'x1.fx' in rows.label
    assert 'z2.mz]' in rows.label and 'x1.dx' in cols.label and 'z2.rz]' in cols.label
    assert rows.size == cols.size == 36


def test_rest_lengths_are_applied_and_re_published(harness, equilibrium):
    s = harness.structure
    T = as_read(equilibrium.poses)
    harness.send_poses(T)
    commanded = s.rest_lengths * 0.98
    state = s.evaluate(T, commanded)
    inbox = harness.inbox['string_tensions']

    def applied():
        last = inbox.messages[-1] if len(inbox) else None
        return True if last is not None and np.allclose(
            data(last), state.tensions, rtol=1e-12, atol=0.0) else None

    repeat_until(lambda: harness.rest_pub.publish(Float64MultiArray(data=commanded.tolist())),
                 applied, explain=lambda: harness.proc.log()[-2000:])
    harness.rest_pub.publish(Float64MultiArray(data=s.rest_lengths.tolist()))
    back = s.evaluate(T).tensions
    inbox.wait_until(lambda m: np.allclose(data(m), back, rtol=1e-12, atol=0.0), timeout=20)


# ---------------------------------------------------------------------------- bad input
@pytest.mark.parametrize('send, log', [
    (lambda h: h.send_poses(h.structure.start_poses()[:5]), r'expected N = 6 poses'),
    (lambda h: h.send_poses(h.structure.start_poses(), 'map'), r'frame'),
    (lambda h: h.send_values(np.zeros(41)), r'expected 7 N = 42 values'),
    (lambda h: h.send_values(np.r_[np.zeros(41), np.nan]), r'NaN or inf'),
    (lambda h: h.send_values(np.tile([0, 0, 0, 0, 0, 0, 2.0], 6)), r'quaternion|rotation|unit'),
])
def test_bad_input_is_refused_with_a_specific_log(harness, send, log):
    before = harness.settled_counts()
    refused_until_logged(harness, lambda: send(harness), log)
    harness.assert_quiet(before)


def refused_until_logged(harness, send, pattern: str) -> None:
    """``send()`` again until the node's log has a rejection matching ``pattern`` (the node
    logs one rejection per topic and second)."""
    start = len(harness.proc.log())
    repeat_until(send, lambda: True if re.search(
        r'rejected: .*' + pattern, harness.proc.log()[start:]) else None, timeout=30,
        period=0.3, explain=lambda: harness.proc.log()[-2000:])


def test_bad_rest_lengths_are_refused(harness):
    before = harness.settled_counts()
    refused_until_logged(harness, lambda: harness.rest_pub.publish(
        Float64MultiArray(data=[0.1] * 5)), r'expected 24 values')
    harness.assert_quiet(before)
    harness.rest_pub.publish(Float64MultiArray(data=harness.structure.rest_lengths.tolist()))


# ---------------------------------------------------------------------------- services
def test_equilibrium_on_the_ground(harness, equilibrium):
    request = SolveStructureEquilibrium.Request()
    request.start = [v for P in harness.structure.start_poses() for v in pose_vector(P)]
    response = harness.ros.call(harness.solve, request, timeout=60.0)
    assert response.success, response.message
    expected = solve_structure_equilibrium(harness.structure)
    np.testing.assert_allclose(np.reshape(response.poses, (6, 7)),
                               [pose_vector(P) for P in expected.poses], atol=1e-12)
    assert list(response.contact_nodes) == list(expected.contacts)
    np.testing.assert_allclose(np.reshape(response.contact_forces, (-1, 3)),
                               list(expected.contacts.values()), atol=1e-12)
    assert response.stable and abs(response.stability_margin - expected.stability_margin) < 1e-12
    np.testing.assert_allclose(response.tensions, expected.state.tensions, atol=1e-12)
    assert len(response.tangent_stiffness) == 36 * 36


def test_equilibrium_without_gravity_and_ground_is_the_prestressed_one(harness):
    request = SolveStructureEquilibrium.Request(without_gravity=True, without_ground=True)
    request.start = [v for P in harness.structure.start_poses() for v in pose_vector(P)]
    response = harness.ros.call(harness.solve, request, timeout=60.0)
    assert response.success, response.message
    assert list(response.contact_nodes) == []


def test_bad_equilibrium_request_names_the_field(harness):
    response = harness.ros.call(harness.solve, SolveStructureEquilibrium.Request(
        loads=[0.0] * 5), timeout=60.0)
    assert not response.success and 'loads' in response.message


def test_the_analysis_report(harness):
    response = harness.ros.call(harness.report, StructureReport.Request(), timeout=120.0)
    assert response.success, response.message
    report = json.loads(response.report_json)
    expected = check_structure(harness.structure)
    assert response.sound == expected['sound'] and report['sound'] == expected['sound']
    assert report['body_counts'] == expected['body_counts']
    assert report['analysis']['self_stresses'] == expected['analysis']['self_stresses']
    assert report['contacts'].keys() == expected['contacts'].keys()


# ---------------------------------------------------------------------------- diagnostics, TF
def test_diagnostics_name_stability_and_the_tangent_eigenvalue(harness, equilibrium):
    harness.send_values(np.array([pose_vector(P) for P in equilibrium.poses]))

    def values_of(msg):
        # the status is named by the node's full name, its namespace with it
        return next(({k.key: k.value for k in s.values} for s in msg.status
                     if s.name == f'{harness.base}: structure'), {})

    def of_this_input(msg):
        # The report of the poses sent here (an earlier test's input may be reported first):
        # its ground contacts are the equilibrium's.
        values = values_of(msg)
        return ('smallest eigenvalue of the tangent stiffness' in values and set(
            values.get('ground contacts', '').strip('[]').split()) == set(equilibrium.contacts))

    def settled():
        # an earlier test's input with the same contacts may be reported after this one's was
        # sent (a fresh-clone run: slack strings of another pose): the report of the
        # equilibrium, sent until it comes, has no slack string
        for msg in reversed(harness.diagnostics.messages[-20:]):
            if of_this_input(msg) and values_of(msg).get('slack strings') == 'none':
                return values_of(msg)
        return None

    values = repeat_until(
        lambda: harness.send_values(np.array([pose_vector(P) for P in equilibrium.poses])),
        settled, timeout=30.0, period=0.3)
    assert float(values['smallest eigenvalue of the tangent stiffness']) > 0.0


def test_a_tf_frame_per_body(harness):
    if harness.tf is None:
        pytest.skip('tf2_msgs is not installed')
    T = harness.structure.start_poses()
    harness.send_poses(T)
    msg = harness.tf.wait_until(lambda m: len(m.transforms) == 6, timeout=20)
    assert [t.child_frame_id for t in msg.transforms] == harness.structure.body_names
    assert {t.header.frame_id for t in msg.transforms} == {'world'}
