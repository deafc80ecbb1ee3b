"""structure_sim_node over the real middleware, across processes: the installed executable runs
the 3-bar twin; its poses, lengths, load cells, encoders and IMUs arrive and agree with the
structure's own model; commanded rest lengths move the encoders to them and the twin to the
library's equilibrium of them; bad input is refused with a warning and the twin keeps its state.
"""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseArray, WrenchStamped  # noqa: E402
from sensor_msgs.msg import Imu  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import (  # noqa: E402
    LATCHED,
    NodeProcess,
    RosClient,
    log_has,
    unique_namespace,
    wrench_stamped,
)

from tensegrity_stiffness import config  # noqa: E402
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium  # noqa: E402
from tensegrity_stiffness.structures.structure import Structure  # noqa: E402

EXAMPLE = 'three_bar.yaml'


def poses_of(msg: PoseArray) -> np.ndarray:
    """(N, 7) [x y z qx qy qz qw] of a PoseArray."""
    return np.array([[p.position.x, p.position.y, p.position.z, p.orientation.x,
                      p.orientation.y, p.orientation.z, p.orientation.w] for p in msg.poses])


@pytest.fixture(scope='module')
def twin(tmp_path_factory):
    structure = Structure.from_yaml(config.example_config_path(EXAMPLE))
    params = tmp_path_factory.mktemp('structure_twin') / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    structure:\n'
                      f'      config: {EXAMPLE}\n    sim:\n      publish_every: 10\n'
                      '      rest_length_rate: 0.02\n')
    ns = unique_namespace('structure_twin')
    proc = NodeProcess(ns, params, executable='structure_sim_node')
    ros = RosClient('structure_twin_test')
    base = f'{ns}/structure_sim_node'
    loop = {
        'structure': structure, 'proc': proc, 'ros': ros,
        'poses': ros.subscribe(PoseArray, f'{base}/poses'),
        'lengths': ros.subscribe(Float64MultiArray, f'{base}/measured_lengths'),
        'tensions': ros.subscribe(Float64MultiArray, f'{base}/measured_tensions'),
        'encoders': ros.subscribe(Float64MultiArray, f'{base}/measured_rest_lengths'),
        'imus': [ros.subscribe(Imu, f'{base}/imu/{name}') for name in structure.bar_names],
        'diagnostics': ros.subscribe(DiagnosticArray, '/diagnostics'),
        'rest_pub': ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED),
        'push_pub': ros.publisher(WrenchStamped, f'{base}/push'),
    }
    ros.wait_for_subscribers(loop['rest_pub'])
    ros.wait_for_subscribers(loop['push_pub'])
    loop['poses'].wait_for(1, timeout=30.0)
    yield loop
    ros.close()
    assert proc.stop() == 0, proc.log()[-3000:]


def latest(inbox) -> np.ndarray:
    return np.array(inbox.wait_for(1, timeout=10.0)[-1].data)


def settled_state(twin, rest=None):
    """The twin's poses and sensors once its encoders read ``rest`` (if given) and its poses stop
    changing (1e-7 m between two messages 0.1 s apart)."""
    if rest is not None:
        twin['encoders'].wait_until(lambda m: np.allclose(m.data, rest, atol=1e-12, rtol=0),
                                    timeout=20.0)
    previous = [None]

    def still(msg):
        x = poses_of(msg)[:, :3]
        done = previous[0] is not None and np.abs(x - previous[0]).max() < 1e-7
        previous[0] = x
        return done

    twin['poses'].clear()
    twin['poses'].wait_until(still, timeout=30.0)
    for name in ('lengths', 'tensions', 'encoders'):
        twin[name].clear()
    return (poses_of(twin['poses'].wait_for(1, timeout=10.0)[-1]), latest(twin['lengths']),
            latest(twin['tensions']), latest(twin['encoders']))


def test_poses_and_sensors_arrive_and_are_the_structure_s_model(twin):
    structure = twin['structure']
    msg = twin['poses'].wait_for(1, timeout=10.0)[-1]
    assert msg.header.frame_id == 'world' and len(msg.poses) == structure.n_bodies
    poses, lengths, tensions, encoders = settled_state(twin)
    np.testing.assert_allclose(encoders, structure.rest_lengths, rtol=0, atol=1e-15)
    state = structure.evaluate(poses, encoders)
    np.testing.assert_allclose(lengths, state.lengths, atol=1e-6)
    np.testing.assert_allclose(tensions, state.tensions, atol=1e-3)
    # At rest on the ground each bar's accelerometer reads gravity up, in its frame.
    for inbox, name, T in zip(twin['imus'], structure.bar_names, structure.transforms(poses),
                              strict=True):
        imu = inbox.wait_for(1, timeout=10.0)[-1]
        assert imu.header.frame_id == name
        a = np.array([imu.linear_acceleration.x, imu.linear_acceleration.y,
                      imu.linear_acceleration.z])
        np.testing.assert_allclose(T[:3, :3] @ a, [0, 0, 9.80665], atol=0.05)
    diag = twin['diagnostics'].wait_until(
        lambda m: any('structure twin' in s.name for s in m.status), timeout=10.0)
    values = {kv.key: kv.value for s in diag.status if 'structure twin' in s.name
              for kv in s.values}
    assert sorted(values['contact nodes'].split()) == ['bar0.a', 'bar1.a', 'bar2.a']
    assert float(values['real-time factor']) > 0.0


def test_commanded_rest_lengths_move_the_twin_as_commanded(twin):
    structure = twin['structure']
    target = structure.rest_lengths * np.where(np.arange(structure.n_strings) % 3 == 2, 0.97,
                                               1.0)  # the verticals 3 % shorter
    twin['rest_pub'].publish(Float64MultiArray(data=list(target)))
    poses, lengths, tensions, encoders = settled_state(twin, target)
    np.testing.assert_array_equal(encoders, target)
    # The library's equilibrium of the commanded rest lengths, from the twin's poses (MuJoCo's
    # friction relaxes the statically indeterminate tangential contact forces: the frictionless
    # ground's), up to the contact spheres' sinking.
    document = structure.to_dict()
    document['structure']['ground']['friction'] = 0.0
    result = solve_structure_equilibrium(Structure.from_dict(document), start=poses,
                                         rest_lengths=target)
    assert result.success
    np.testing.assert_allclose(lengths, result.state.lengths, atol=2e-4)
    np.testing.assert_allclose(tensions, result.state.tensions, atol=0.05)
    before = structure.evaluate(structure.start_poses()).lengths
    assert np.abs(lengths - before).max() > 1e-3  # it moved


def test_bad_inputs_are_refused_and_the_twin_keeps_its_state(twin):
    structure, proc = twin['structure'], twin['proc']
    encoders = latest(twin['encoders'])
    bad = encoders.copy()
    bad[4] = 1e308
    twin['rest_pub'].publish(Float64MultiArray(data=list(bad)))
    assert log_has(proc, r'rest_lengths rejected: rest length of ' + structure.string_names[4],
                   timeout=10.0), proc.log()[-2000:]
    twin['push_pub'].publish(wrench_stamped([1.0, 0, 0, 0, 0, 0], frame_id='nobody'))
    assert log_has(proc, r"push rejected: no body 'nobody'", timeout=10.0), proc.log()[-2000:]
    # An absurd push (1 MN) is refused too (its warning throttled after the last one): the
    # twin stays where it rests.
    twin['poses'].clear()
    before = poses_of(twin['poses'].wait_for(1, timeout=10.0)[-1])
    twin['push_pub'].publish(wrench_stamped([1e6, 0, 0, 0, 0, 0], frame_id='bar0'))
    twin['diagnostics'].clear()
    twin['diagnostics'].wait_for(2, timeout=10.0)  # a diagnostics period after it
    twin['poses'].clear()
    after = poses_of(twin['poses'].wait_for(1, timeout=10.0)[-1])
    np.testing.assert_allclose(after[:, :3], before[:, :3], atol=1e-4)  # the contacts' creep
    twin['encoders'].clear()
    np.testing.assert_array_equal(latest(twin['encoders']), encoders)
    assert proc.alive()


def test_a_push_moves_the_twin(twin):
    twin['poses'].clear()
    before = poses_of(twin['poses'].wait_for(1, timeout=10.0)[-1])
    twin['push_pub'].publish(wrench_stamped([0.0, 0.0, 3.0, 0, 0, 0], frame_id='bar1'))
    twin['poses'].wait_until(
        lambda m: np.abs(poses_of(m)[1, :3] - before[1, :3]).max() > 1e-3, timeout=10.0)


@pytest.mark.slow
def test_the_node_rolls_the_six_bar_with_the_gait(tmp_path):
    """gait.enabled: the node plans and runs one roll; /diagnostics shows the phases and the
    contact nodes of the planned landing face (the library's plan, computed here too)."""
    from tensegrity_stiffness.simulation.structure_gait import plan_roll_step

    structure = Structure.from_yaml(config.example_config_path('six_bar.yaml'))
    step = plan_roll_step(structure)
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    gait:\n      enabled: true\n')
    ns = unique_namespace('structure_roll')
    proc = NodeProcess(ns, params, executable='structure_sim_node')
    ros = RosClient('structure_roll_test')
    try:
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')

        def values(msg):
            for s in msg.status:
                if s.name == f'{ns}/structure_sim_node: structure twin':  # its full name
                    return {kv.key: kv.value for kv in s.values}
            return None

        phases = set()

        def rolled(msg):
            v = values(msg)
            if v is None:
                return False
            phases.add(v['gait phase'])
            # Landed and resting on a face (a report between bounces lists no contact).
            return v['gait steps done'] == '1' and bool(v['contact nodes'].split())

        msg = diagnostics.wait_until(rolled, timeout=90.0)
        assert {'tip', 'recover'} <= phases
        assert sorted(values(msg)['contact nodes'].split()) == sorted(step.landing_face)
    finally:
        ros.close()
        assert proc.stop() == 0, proc.log()[-3000:]
