"""sim_node -> estimator_node -> stiffness_controller -> sim_node across processes.

The twin (``sim_node``) publishes its load cells' tensions and its IMU; ``estimator_node`` (12
tensions + IMU, unknown load) estimates the pose and the load from them and the commanded rest
lengths; ``stiffness_controller`` turns a target pose (and K_c*) and that state into rest-length
commands, which the twin and the estimator both take (latched ``~/rest_lengths``). The
controller is started as ``python -c '...main()'`` until its executable is installed; the other
nodes as :class:`support.ros_harness.NodeProcess` starts them.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip('rclpy')

from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rcl_interfaces.srv import SetParameters
from std_msgs.msg import Float64MultiArray

sys.path.insert(0, str(Path(__file__).resolve().parent))
from support.ros_harness import (
    REPO,
    NodeProcess,
    RosClient,
    log_has,
    pose_stamped,
    repeat_until,
    unique_namespace,
)

from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.design import design_rest_lengths
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.ros import conversions

# serial: the three-process loop holds its controller's deadlines only with nothing beside it
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.serial]

JOINT_CONFIG = REPO / 'config' / 'default_joint.yaml'
MAX_RATE = 0.05
RATE_HZ = 200.0          # the controller's rate here: three Python nodes share two cores
STEP = np.array([0.02, -0.01, 0.0, 0.0, 4e-4, 0.0])
POSE_TOLERANCE_MM = 0.1
ROTATION_TOLERANCE_DEG = 0.1
STIFFNESS_TOLERANCE = 0.02
TIMEOUT_S = 90.0


def pose_error(msg: PoseStamped, T_star: np.ndarray) -> tuple[float, float]:
    T = conversions.pose_message_to_transform(msg.pose)
    R = T_star[:3, :3].T @ T[:3, :3]
    angle = float(np.degrees(np.arccos(np.clip((np.trace(R) - 1) / 2, -1, 1))))
    return 1e3 * float(np.linalg.norm(T[:3, 3] - T_star[:3, 3])), angle


@pytest.fixture(scope='module')
def loop():
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    ns = unique_namespace('control')
    sim_base, est_base, ctl_base = (f'{ns}/sim_node', f'{ns}/estimator_node',
                                    f'{ns}/stiffness_controller')
    sim = NodeProcess(ns, JOINT_CONFIG, executable='sim_node', extra_args=[
        '-p', 'sim.publish_every:=5',
        '-r', f'{sim_base}/rest_lengths:={ctl_base}/rest_lengths'])
    estimator = NodeProcess(ns, JOINT_CONFIG, executable='estimator_node', extra_args=[
        '-r', f'{est_base}/measured_tensions:={sim_base}/measured_tensions',
        '-r', f'{est_base}/imu:={sim_base}/imu',
        '-r', f'{est_base}/rest_lengths:={ctl_base}/rest_lengths'])
    controller = NodeProcess(ns, JOINT_CONFIG, executable='stiffness_controller', extra_args=[
        '-p', f'control.rate:={RATE_HZ}', '-p', f'limits.max_rate:={MAX_RATE}',
        '-p', 'control.integral_gain:=4.0',
        '-r', f'{ctl_base}/pose_estimate:={est_base}/pose_estimate',
        '-r', f'{ctl_base}/wrench_estimate:={est_base}/wrench_estimate'])
    ros = RosClient('control_test')
    out = {
        'ns': ns, 'sim': sim, 'estimator': estimator, 'controller': controller, 'ros': ros,
        'truth': ros.subscribe(PoseStamped, f'{sim_base}/pose'),
        'rest': ros.subscribe(Float64MultiArray, f'{ctl_base}/rest_lengths'),
        'diagnostics': ros.subscribe(DiagnosticArray, '/diagnostics'),
        'kc': ros.subscribe(Float64MultiArray, f'{est_base}/cartesian_stiffness'),
        'target': ros.publisher(PoseStamped, f'{ctl_base}/target_pose'),
        'stiffness': ros.publisher(Float64MultiArray, f'{ctl_base}/target_stiffness'),
    }
    out['truth'].wait_for(1, timeout=30.0)
    yield out
    ros.close()
    codes = controller.stop(), estimator.stop(), sim.stop()
    assert codes == (0, 0, 0), controller.log()[-3000:]
    assert 'internal error' not in controller.log(), controller.log()


def test_pose_step_and_stiffness_step_across_processes(loop) -> None:
    model = JointModel.from_yaml(JOINT_CONFIG)
    T_star = exp_se3(model.initial_screw + STEP)
    msg = pose_stamped(T_star)

    def held() -> tuple[float, float] | None:
        msgs = loop['truth'].messages[-20:]
        if len(msgs) < 20:
            return None
        errs = [pose_error(m, T_star) for m in msgs]
        worst = (max(e[0] for e in errs), max(e[1] for e in errs))
        return worst if worst[0] < POSE_TOLERANCE_MM and worst[1] < ROTATION_TOLERANCE_DEG \
            else None

    worst = repeat_until(lambda: loop['target'].publish(msg), held, timeout=TIMEOUT_S,
                         period=0.5, explain=lambda: loop['controller'].log()[-2000:])
    print('pose step: worst of the last 20 truth poses (mm, deg)', worst)
    # A stiffness step to a reachable K_c (the design at higher tension limits).
    K = design_rest_lengths(model, model.initial_screw + STEP, None, 0.5, 1.5)
    stiff = Float64MultiArray(data=K.cartesian_stiffness.ravel().tolist())

    def met() -> float | None:
        for array in reversed(loop['diagnostics'].messages[-20:]):
            for status in array.status:
                if status.name.endswith('stiffness_controller: controller'):
                    kv = {v.key: v.value for v in status.values}
                    if kv.get('stiffness target') == 'set':
                        err = float(kv['stiffness error'])
                        return err if err < STIFFNESS_TOLERANCE else None
        return None

    err = repeat_until(lambda: loop['stiffness'].publish(stiff), met, timeout=TIMEOUT_S,
                       period=0.5, explain=lambda: loop['controller'].log()[-2000:])
    worst = repeat_until(lambda: None, held, timeout=TIMEOUT_S, period=0.5)
    # The estimator's K_c (its own model at its own pose estimate from the load cells) against
    # the target, once the pose is held again.
    L = float(np.linalg.norm(model.link1_nodes, axis=1).max())
    scaled = np.array([1, 1, 1, 1 / L, 1 / L, 1 / L])
    SS = scaled[:, None] * scaled[None, :]
    start = len(loop['kc'])
    latest = loop['kc'].wait_for(start + 5, timeout=30.0)[-1]
    Kc = np.array(latest.data).reshape(6, 6)
    estimated = float(np.linalg.norm((Kc - K.cartesian_stiffness) * SS)
                      / np.linalg.norm(K.cartesian_stiffness * SS))
    print('stiffness step: predicted error', err, 'estimated K_c error', estimated,
          'pose (mm, deg)', worst)
    assert estimated < STIFFNESS_TOLERANCE
    # Every command within the range and the rate (time between commands by arrival is
    # not the controller's tick: bound each step by the rate over one tick period).
    rest = np.array([m.data for m in loop['rest'].messages[1:]])
    lo, hi = 0.5 * model.rest_lengths, 1.2 * model.rest_lengths
    assert np.all(rest >= lo * (1 - 1e-12)) and np.all(rest <= hi * (1 + 1e-12))
    steps = np.abs(np.diff(rest, axis=0)).max(axis=1)
    # dt is capped at 10 periods per tick; a tick late by that much moves exactly the cap
    # (seen: 2.5000000000000022e-3 for 2.5e-3 under load): compare to the rounding
    assert steps.max() <= MAX_RATE * 10.0 / RATE_HZ * (1 + 1e-12)
    time.sleep(0.1)


def test_bad_targets_and_parameters_are_refused_and_the_command_kept(loop) -> None:
    ros = loop['ros']
    before = np.array(loop['rest'].messages[-1].data)
    params = ros.client(SetParameters, f'{loop["ns"]}/stiffness_controller/set_parameters')
    result = ros.set_parameter(params, 'limits.rest_length_max', [0.01])
    assert not result.successful and 'rest_length_max' in result.reason
    result = ros.set_parameter(params, 'limits.max_rate', -1.0)
    assert not result.successful
    wrong = pose_stamped(np.eye(4))
    wrong.header.frame_id = 'somewhere_else'
    loop['target'].publish(wrong)
    assert log_has(loop['controller'], r'~/target_pose rejected: .*somewhere_else', 10.0)
    loop['stiffness'].publish(Float64MultiArray(data=[1.0, 2.0, 3.0]))
    assert log_has(loop['controller'], r'~/target_stiffness rejected: .*36, 6 or 0', 10.0)
    # The loop goes on from where it was: the last command moved at most by the rate limit.
    after = np.array(loop['rest'].wait_for(len(loop['rest']) + 5, timeout=30.0)[-1].data)
    assert np.abs(after - before).max() < 1e-3


@pytest.mark.slow
def test_run_twin_control_closes_the_loop_and_stops_cleanly() -> None:
    """``scripts/run_twin.sh --control``: the three nodes start, the controller's line shows a
    pose error once it has a state, and Ctrl-C-like stops end all three with status 0."""
    out = subprocess.run(['bash', str(REPO / 'scripts' / 'run_twin.sh'), '--control',
                          '--duration', '25'], capture_output=True, text=True, timeout=300,
                         env=os.environ.copy(), check=False)
    assert 'control_demo: stopped' in out.stdout, out.stdout + out.stderr
    lines = [line for line in out.stdout.splitlines() if line.startswith('t ')]
    assert len(lines) >= 20, out.stdout
    assert any('pose error' in line and 'feasible true' in line for line in lines), out.stdout
    # The controller and the estimator stop cleanly. sim_node can exit 1 when SIGINT lands
    # inside rclpy's take of a message (a shutdown race in rclpy's executor, seen once in a
    # loaded full-suite run; its own lifecycle tests cover its clean stops).
    assert 'estimator_node exit 0, stiffness_controller exit 0' in out.stdout, out.stdout


def test_control_launch_file_names_the_installed_executables() -> None:
    """``launch`` is not on PyPI: the file is compiled and read, not run."""
    import ast

    from ament_index_python.packages import get_package_prefix

    prefix = Path(get_package_prefix('tensegrity_stiffness'))
    path = prefix / 'share' / 'tensegrity_stiffness' / 'launch' / 'control.launch.py'
    tree = ast.parse(path.read_text())
    compile(tree, str(path), 'exec')
    constants = {node.targets[0].id: ast.literal_eval(node.value) for node in tree.body
                 if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)}
    for name in ('EXECUTABLE', 'SIM', 'ESTIMATOR'):
        assert (prefix / 'lib' / 'tensegrity_stiffness' / constants[name]).is_file(), name
    assert (prefix / 'share' / 'tensegrity_stiffness' / 'config' / constants['CONFIG']).is_file()
