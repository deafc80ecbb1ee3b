"""stiffness_node's process: clean stops on SIGINT and SIGTERM (to the node alone and to its whole
process group, as supervisors send them), and faults of its equilibrium worker (killed, stopped)
noticed at once and told apart."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from geometry_msgs.msg import Wrench  # noqa: E402
from support.ros_harness import (  # noqa: E402
    REPO,
    NodeProcess,
    RosClient,
    process_alive,
    unique_namespace,
)
from tensegrity_stiffness.srv import SolveEquilibrium  # noqa: E402

from tensegrity_stiffness.ros.services import joint_services  # noqa: E402

pytestmark = pytest.mark.ros

CONFIG = REPO / 'config' / 'default_joint.yaml'
#: The issue's bound for a stop, and the time the node's children get to disappear after it.
STOP_BOUND_S = 2.0


def wait_ready(proc: NodeProcess, timeout: float = 30.0) -> None:
    deadline = time.monotonic() + timeout
    while 'ready:' not in proc.log():
        assert proc.alive(), proc.log()
        assert time.monotonic() < deadline, proc.log()
        time.sleep(0.05)


@pytest.mark.serial  # stopped within STOP_BOUND_S
@pytest.mark.parametrize('to_group', [False, True], ids=['node', 'group'])
@pytest.mark.parametrize('sig', [signal.SIGINT, signal.SIGTERM], ids=['SIGINT', 'SIGTERM'])
def test_signal_stops_the_node_cleanly(sig: signal.Signals, to_group: bool) -> None:
    proc = NodeProcess(unique_namespace('stop'), CONFIG, new_session=True)
    try:
        wait_ready(proc)
        worker = proc.worker_pid()
        children = proc.children()
        assert worker in children
        time.sleep(0.5)  # the worker's warm-up solve is under way or done
        start = time.monotonic()
        if to_group:
            os.killpg(proc.pid, sig)
        else:
            os.kill(proc.pid, sig)
        code = proc.process.wait(timeout=10.0)
        elapsed = time.monotonic() - start
        deadline = time.monotonic() + STOP_BOUND_S
        while any(process_alive(pid) for pid in children) and time.monotonic() < deadline:
            time.sleep(0.02)
        left = [pid for pid in children if process_alive(pid)]
    finally:
        if proc.alive():
            proc.kill()
    log = proc.log()
    assert code == 0, log
    assert elapsed < STOP_BOUND_S, f'stopped after {elapsed:.2f} s'
    assert not left, f'children left behind: {left}'
    assert 'Traceback' not in log, log


#: A node built by the runner that receives SIGINT as its construction ends, before the runner
#: holds it: no one can close it, and its running thread (the fast lane, the twin's stepping) is
#: still in rclpy's C++ code when the interpreter exits (the twin's stepping thread has the same
#: guard).
INTERRUPTED_CONSTRUCTION = textwrap.dedent('''
    import importlib, os, signal, sys
    import rclpy
    from tensegrity_stiffness.ros.runtime import runner
    module, name = sys.argv[1].rsplit('.', 1)
    node_class = getattr(importlib.import_module(module), name)

    def interrupted():
        node = node_class()
        if sys.argv[2] == 'shutdown':  # what rclpy's signal thread does, before Python's handler
            rclpy.get_default_context().try_shutdown()
            return node
        os.kill(os.getpid(), signal.SIGINT)
        for _ in range(10_000):  # Python raises KeyboardInterrupt here (most of the time)
            pass
        return node

    runner.run(interrupted, sys.argv)
    print('run returned', flush=True)
''')


@pytest.mark.parametrize('how', ['sigint', 'shutdown'])
def test_sigint_during_construction_exits_cleanly(how: str) -> None:
    """Exit 0, no abort: the node's fast lane is stopped at exit although the node was never
    closed (before: "terminate called without an active exception", exit -6, every time).
    ``shutdown``: the context is down before the KeyboardInterrupt came, as rclpy's signal
    thread can leave it (before: the executor's creation raised, exit 1, once in a CI run)."""
    ns = unique_namespace('interrupted')
    node_class = 'tensegrity_stiffness.ros.stiffness_node.StiffnessNode'
    result = subprocess.run(
        [sys.executable, '-c', INTERRUPTED_CONSTRUCTION, node_class, how, '--ros-args',
         '--params-file', str(CONFIG), '-r', f'__ns:={ns}'],
        capture_output=True, text=True, timeout=60, env=os.environ.copy())
    output = result.stdout + result.stderr
    assert 'terminate called' not in output, output[-3000:]
    assert result.returncode == 0, output[-3000:]
    assert 'run returned' in output


#: A start from which the default joint's unloaded solve converges (to its equilibrium) in 9
#: Newton iterations: more than the node's try on its executor allows
#: (``joint_services.QUICK_SOLVE_ITERATIONS``), so the request is solved by the worker.
WORKER_START = [2.4408, -0.426, -1.4901, 0.0369, -0.0106, 0.0204]


def _request(wrench: list[float] | None = None,
             initial_screw: list[float] | None = None) -> SolveEquilibrium.Request:
    request = SolveEquilibrium.Request()
    if initial_screw is not None:
        request.initial_screw = list(initial_screw)
    if wrench is not None:
        f, m = wrench[:3], wrench[3:]
        request.external_wrench = Wrench()
        request.external_wrench.force.x, request.external_wrench.force.y, \
            request.external_wrench.force.z = f
        request.external_wrench.torque.x, request.external_wrench.torque.y, \
            request.external_wrench.torque.z = m
    return request


@pytest.fixture
def slow_solver_node():
    """A node whose solves may take 3 s (a load the strings cannot hold uses all of it, with
    iterations enough)."""
    proc = NodeProcess(unique_namespace('worker'), CONFIG,
                       extra_args=['-p', 'equilibrium.time_budget:=3.0',
                                   '-p', 'equilibrium.max_iterations:=10000'])
    ros = RosClient('worker_test')
    try:
        client = ros.client(SolveEquilibrium, f'{proc.namespace}/stiffness_node/solve_equilibrium')
        # Solved by the worker: it is up and serving before the test starts.
        ready = ros.call(client, _request(initial_screw=WORKER_START), timeout=30.0)
        assert ready.success and ready.iterations > joint_services.QUICK_SOLVE_ITERATIONS
        yield proc, ros, client
    finally:
        ros.close()
        assert proc.stop() == 0, proc.log()


def _call_async(ros: RosClient, client, request) -> tuple[threading.Event, list]:
    done, box = threading.Event(), []
    future = client.call_async(request)

    def finished(f) -> None:
        box.append((time.monotonic(), f.result()))
        done.set()

    future.add_done_callback(finished)
    return done, box


@pytest.mark.serial  # the worker's solve budget and 'at once' are wall time
def test_a_killed_worker_fails_its_solve_at_once_and_the_next_one_succeeds(slow_solver_node):
    proc, ros, client = slow_solver_node
    worker = proc.worker_pid()
    done, box = _call_async(ros, client, _request([100.0, 0, 0, 0, 0, 0]))
    time.sleep(0.5)
    assert not done.is_set(), 'the hopeless solve should still be running'
    killed = time.monotonic()
    os.kill(worker, signal.SIGKILL)
    assert done.wait(1.0 + 1.0), 'no answer within the budget plus 1 s of the kill'
    answered, response = box[0]
    assert not response.success
    assert 'died' in response.message and 'SIGKILL' in response.message, response.message
    assert 'overran' not in response.message
    assert answered - killed < 1.0
    again = ros.call(client, _request(), timeout=30.0)
    assert again.success, again.message
    assert proc.worker_pid() != worker
    assert proc.alive()


@pytest.mark.serial  # replaced within 4 s
def test_a_worker_killed_while_idle_is_replaced_before_the_next_request(slow_solver_node):
    proc, ros, client = slow_solver_node
    worker = proc.worker_pid()
    os.kill(worker, signal.SIGKILL)
    start = time.monotonic()
    response = ros.call(client, _request(initial_screw=WORKER_START), timeout=30.0)
    assert response.success, response.message
    assert response.iterations > joint_services.QUICK_SOLVE_ITERATIONS  # solved by the worker
    assert time.monotonic() - start < 3.0 + 1.0
    assert np.isfinite(response.screw).all()


@pytest.mark.serial  # an overrun of the solve's wall-time budget
def test_a_stopped_worker_is_an_overrun_and_is_replaced(slow_solver_node):
    proc, ros, client = slow_solver_node
    worker = proc.worker_pid()
    os.kill(worker, signal.SIGSTOP)  # alive, but never answers
    easy = ros.call(client, _request([0.0, 0.05, 0, 0, 0, 0]), timeout=30.0)
    assert easy.success, easy.message  # solved on the executor: the worker is not asked
    assert easy.iterations <= joint_services.QUICK_SOLVE_ITERATIONS
    response = ros.call(client, _request(initial_screw=WORKER_START), timeout=30.0)
    assert not response.success
    assert 'overran its budget' in response.message, response.message
    assert 'died' not in response.message
    deadline = time.monotonic() + 10.0  # killed before the answer; replaced right after
    while process_alive(worker) and proc.worker_pid() == worker:
        assert time.monotonic() < deadline, 'the stopped worker was not replaced'
        time.sleep(0.02)
    again = ros.call(client, _request(initial_screw=WORKER_START), timeout=30.0)
    assert again.success, again.message
    assert again.iterations > joint_services.QUICK_SOLVE_ITERATIONS


def _run_to_exit(executable: str, params_file, extra_args: list[str],
                 until: str | None = None) -> tuple[int | None, str]:
    """Start ``executable``; wait for its exit, or (``until``) for that text in its log and then
    stop it. Returns (exit code, log)."""
    proc = NodeProcess(unique_namespace('config'), params_file, extra_args=extra_args,
                       executable=executable)
    try:
        if until is None:
            code = proc.process.wait(timeout=60.0)
        else:
            deadline = time.monotonic() + 60.0
            while until not in proc.log():
                assert proc.alive(), proc.log()
                assert time.monotonic() < deadline, proc.log()
                time.sleep(0.05)
            code = proc.stop()
    finally:
        if proc.alive():
            proc.kill()
    return code, proc.log()


@pytest.mark.parametrize(('executable', 'config', 'key', 'hint'), [
    ('stiffness_node', CONFIG, 'joint.stifness', 'joint.stiffness'),
    ('sim_node', CONFIG, 'limits.max_forse', 'limits.max_force'),
    ('estimator_node', CONFIG, 'estimation.max_agee', 'estimation.max_age'),
    ('spine_node', REPO / 'config' / 'default_spine.yaml', 'chain.n_joint', 'chain.n_joints'),
    ('stiffness_controller', CONFIG, 'control.integral_gian', 'control.integral_gain'),
])
def test_a_misspelt_parameter_stops_the_node_by_name(tmp_path, executable, config, key, hint):
    """#39: a misspelt key under the node's own sections in a parameter file: the node refuses
    to start (one line naming the key and the nearest parameter, exit 2) rather than run with
    the default of the parameter it missed; with ``strict_parameters:=false`` (a file shared
    with other packages' nodes) it warns by name and runs."""
    import yaml

    section, name = key.split('.')
    extra = tmp_path / 'typo.yaml'
    extra.write_text(yaml.safe_dump({'/**': {'ros__parameters': {section: {name: 1.0}}}}))
    message = f'{key}: unknown key (did you mean {hint}?)'
    code, log = _run_to_exit(executable, config, ['--params-file', str(extra)])
    assert code == 2, log
    lines = [line for line in log.splitlines() if 'configuration error' in line]
    assert len(lines) == 1 and message in lines[0] and 'strict_parameters:=false' in lines[0], log
    assert 'ready:' not in log and 'Traceback' not in log, log
    code, log = _run_to_exit(executable, config, ['--params-file', str(extra), '-p',
                                                  'strict_parameters:=false'], until='ready:')
    assert code == 0, log
    assert f'{message}: ignored' in log, log


@pytest.mark.parametrize(('executable', 'args', 'problem'), [
    ('stiffness_node', ['-p', 'joint.stiffness:=[77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0, 77.0]'],
     'joint.stiffness must have 12 values (one per string), got 8'),
    ('sim_node', ['-p', 'limits.rest_length_range:=[0.04, 0.03]'],
     'limits.rest_length_range must be (min, max)'),
    ('estimator_node', ['-p', 'sensors.gravity_base:=[0.0, 0.0, 0.0]'],
     'sensors.gravity_base must be 3 finite values'),
    ('stiffness_node', ['-p', 'qos.depth:=0'], 'qos.depth'),
])
def test_a_config_error_is_one_line_and_a_nonzero_exit(executable, args, problem):
    code, log = _run_to_exit(executable, CONFIG, args)
    assert code == 2, log
    lines = [line for line in log.splitlines() if 'configuration error' in line]
    assert len(lines) == 1 and problem in lines[0], log
    assert 'Traceback' not in log, log


def test_a_parameter_file_that_is_not_yaml_is_one_line_and_a_nonzero_exit(tmp_path):
    """rclpy.init refuses it: one line naming the file, exit 2, no traceback."""
    bad = tmp_path / 'bad.yaml'
    bad.write_text('/**:\n  ros__parameters:\n    joint: {stiffness: [1, 2\n')
    code, log = _run_to_exit('stiffness_node', bad, [])
    assert code == 2, log
    lines = [line for line in log.splitlines() if 'configuration error' in line]
    assert len(lines) == 1 and "Couldn't parse params file" in lines[0], log
    assert 'Traceback' not in log, log
