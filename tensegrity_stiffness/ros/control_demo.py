"""``twin_demo --control`` (``bash scripts/run_twin.sh --control``): the stiffness control loop
without hardware. ``sim_node`` (the MuJoCo twin) -> ``estimator_node`` (its 12 load cells and
IMU) -> ``stiffness_controller`` -> ``sim_node`` (the commanded rest lengths), wired as
``launch/control.launch.py`` wires them, and a scripted target sequence: hold the unloaded pose,
a pose step, a stiffness step (the design with every tension in [0.5, 1.5] N: a stiffer
prestress, designed by the controller's own QP at the stepped pose, so that a ring's spin,
which its strings do not hold, is left out as in the loop), a swinging load.
The controller runs at its default rate (``control.rate``, 500 Hz). Once a second a line from
the nodes' ``/diagnostics``: the phase, the pose error, the ``K_c`` error, the saturated
strings, the tick time, the controller's achieved tick rate (of the rate asked), its missed
ticks, the latency from a reading to the first command computed from it (median / p99) and the
estimator's share of consistent estimates (blank until the controller has a state), and the
true pose error (the twin's own pose against the target) beside the estimate's; an infeasible
tick shows the controller's reason (its ``/diagnostics`` message). ``--config FILE`` runs any
joint; arguments after ``--`` go to every node (``-p limits.tension_max:=3``). A stiffness step
whose design fails (``design_rest_lengths`` without ``success``: the joint's strings cannot
reach the step's tensions: the QP infeasible) is announced and no stiffness target is
published. Ctrl-C (or
``duration``) stops the three nodes and exits 0.
"""

from __future__ import annotations

import os
import subprocess
import tempfile
import threading
import time
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness import config
from tensegrity_stiffness.control.controller import (
    ActuatorLimits,
    ControlCommand,
    ControlTarget,
    StiffnessController,
)
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.control_demo_line import control_line, pose_error
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.demo_processes import (
    NAMESPACE,
    BackgroundSpin,
    node_executable,
    stop_on_signals,
    stop_process,
)

#: The script: (start time s, phase name). The pose step and the load are the test's.
PHASES = ((0.0, 'hold'), (4.0, 'pose step'), (10.0, 'stiffness step'), (16.0, 'load swing'))
POSE_STEP = np.array([0.02, -0.01, 0.0, 0.0, 4e-4, 0.0])
#: The stiffness step's design: its tension limits (N).
STIFFNESS_TENSIONS = (0.5, 1.5)
#: The rest-length floor of the stiffness step's design (m): no actuator range, only > 0.
MIN_REST_LENGTH = 1e-9
#: What the controller adds to the message of a tick it refuses (not part of the design's).
HELD_SUFFIX = '; the last command is kept'
LOAD_AMPLITUDE_N = 0.1
LOAD_PERIOD_S = 8.0


def phase_at(t: float) -> str:
    """The script's phase at ``t`` seconds."""
    return [name for start, name in PHASES if t >= start][-1]


class ControlMonitor:
    """The controller's and the estimator's last diagnostic values (``/diagnostics``)."""

    def __init__(self, node: Any, model: JointModel | None = None) -> None:
        self._lock = threading.Lock()
        self._values: dict[str, str] = {}
        self._message = ''
        self._estimator: dict[str, str] = {}
        self._true_pose: np.ndarray | None = None
        #: The pose the controller is asked to hold now (4x4), set by the script.
        self.target: np.ndarray | None = None
        node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        if model is not None:
            node.create_subscription(PoseStamped, f'{NAMESPACE}/sim_node/pose',
                                     self._on_true_pose, 10)

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name == f'{NAMESPACE}/stiffness_controller: controller':
                with self._lock:
                    self._values = {v.key: v.value for v in status.values}
                    self._message = status.message
            elif status.name.endswith('estimator_node: estimator'):
                with self._lock:
                    self._estimator = {v.key: v.value for v in status.values}

    def _on_true_pose(self, msg: PoseStamped) -> None:
        T = conversions.pose_message_to_transform(msg.pose)
        with self._lock:
            self._true_pose = T

    def true_error(self) -> tuple[float, float] | None:
        """The twin's own pose against the target: (position error m, rotation error rad),
        None before both are known."""
        with self._lock:
            T, target = self._true_pose, self.target
        if T is None or target is None:
            return None
        return pose_error(target, T)

    def line(self, t: float) -> str:
        """The live line at ``t`` s (:func:`~tensegrity_stiffness.nodes.control_demo_line.
        control_line`)."""
        with self._lock:
            v = dict(self._values)
            e = dict(self._estimator)
            message = self._message
        return control_line(f't {t:5.1f} s  {phase_at(t):15s}', v, message, e,
                            self.true_error())


def stiffness_design(model: JointModel, screw: np.ndarray) -> ControlCommand:
    """The stiffness step's design at ``screw`` under no load: one tick of the controller
    without feedback, tensions in :data:`STIFFNESS_TENSIONS` and each string's caps, no
    actuator range (the optimum of ``design_rest_lengths`` for a joint that holds all six
    directions, tested equal; on a ring the spin its strings do not hold is left out, as the
    loop leaves it out). ``feasible`` false: no tensions hold the pose."""
    lengths = model.evaluate(screw).lengths
    limits = ActuatorLimits(MIN_REST_LENGTH, 10.0 * float(lengths.max()), 1.0,
                            *STIFFNESS_TENSIONS)
    start = np.clip(model.rest_lengths, MIN_REST_LENGTH, 10.0 * float(lengths.max()))
    return StiffnessController(model, limits, start).update(1.0, ControlTarget(screw=screw))


def targets(model: JointModel, frame_id: str = 'tensegrity_link1'
            ) -> tuple[PoseStamped, Float64MultiArray | None, str]:
    """The script's targets: the pose step's pose, the stiffness step's K_c
    (:func:`stiffness_design` there) and the design's message. The K_c is None when the
    design fails (never a target from a failed design, whose K_c is NaN)."""
    xi = model.initial_screw + POSE_STEP
    pose = PoseStamped()
    pose.header.frame_id = frame_id
    pose.pose = conversions.transform_to_pose(exp_se3(xi))
    design = stiffness_design(model, xi)
    K = design.predicted_cartesian_stiffness
    if not design.feasible or not np.all(np.isfinite(K)):
        return pose, None, design.message.removesuffix(HELD_SUFFIX) or 'the design failed'
    return pose, Float64MultiArray(data=K.ravel().tolist()), ''


def node_command_lines(params: Path, extra: list[str] = ()) -> list[tuple[str, list[str]]]:
    """The three nodes' command lines; ``extra`` (ROS arguments: ``-p name:=value``) goes to
    each after the demo's own, so it overrides them."""
    sim, est, ctl = 'sim_node', 'estimator_node', 'stiffness_controller'
    common = ['--ros-args', '--params-file', str(params), '-r', f'__ns:={NAMESPACE}']
    return [
        (sim, [*common, '-p', 'sim.publish_every:=5',
               '-r', f'~/rest_lengths:={ctl}/rest_lengths', *extra]),
        (est, [*common, '-r', f'~/measured_tensions:={sim}/measured_tensions',
               '-r', f'~/imu:={sim}/imu', '-r', f'~/rest_lengths:={ctl}/rest_lengths', *extra]),
        (ctl, [*common, '-p', 'control.integral_gain:=4.0',
               '-r', f'~/pose_estimate:={est}/pose_estimate',
               '-r', f'~/wrench_estimate:={est}/wrench_estimate', *extra]),
    ]


def run(config_path: Path | None, duration: float | None, extra: list[str] = ()) -> int:
    """The demo on the joint of ``config_path`` (default the packaged one), ``extra`` ROS
    arguments to every node; the exit status (0 after a clean stop of the three nodes)."""
    extra = list(extra)
    params = Path(config_path or config.packaged_config_path())
    model = JointModel.from_yaml(params)
    logs = Path(tempfile.mkdtemp(prefix='control_demo_'))
    print(f'control_demo: sim_node -> estimator_node -> stiffness_controller in {NAMESPACE} '
          f'(ROS_DOMAIN_ID={os.environ.get("ROS_DOMAIN_ID", "0")}); logs in {logs}', flush=True)
    stop = stop_on_signals()
    processes = []
    for name, args in node_command_lines(params, extra):
        with (logs / f'{name}.log').open('w') as out:
            processes.append(subprocess.Popen([node_executable(name), *args], stdout=out,
                                              stderr=subprocess.STDOUT, env=os.environ.copy(),
                                              start_new_session=True))
    rclpy.init(args=None, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node('control_monitor')
    monitor = ControlMonitor(node, model)
    monitor.target = exp_se3(model.initial_screw)
    pose_pub = node.create_publisher(PoseStamped, f'{NAMESPACE}/stiffness_controller/target_pose',
                                     10)
    stiffness_pub = node.create_publisher(
        Float64MultiArray, f'{NAMESPACE}/stiffness_controller/target_stiffness', 10)
    load_pub = node.create_publisher(WrenchStamped, f'{NAMESPACE}/sim_node/external_wrench', 10)
    pose, stiffness, refused = targets(model)
    if stiffness is None:
        print(f'control_demo: no stiffness step: its design (tensions in {STIFFNESS_TENSIONS} '
              f'N) failed: {refused}', flush=True)
    spin = BackgroundSpin(node, stop)
    start = time.monotonic()
    code = 0
    try:
        next_line = start + 1.0
        while not stop.wait(max(0.0, next_line - time.monotonic())):
            t = time.monotonic() - start
            phase = phase_at(t)
            if phase != 'hold':  # targets are re-sent each second (a late subscriber gets them)
                pose_pub.publish(pose)
                monitor.target = conversions.pose_message_to_transform(pose.pose)
            if phase in ('stiffness step', 'load swing') and stiffness is not None:
                stiffness_pub.publish(stiffness)
            if phase == 'load swing':
                f = LOAD_AMPLITUDE_N * np.sin(2 * np.pi * t / LOAD_PERIOD_S)
                load = WrenchStamped()
                load.header.frame_id = 'tensegrity_link1'
                load.wrench.force.x = float(f)
                load_pub.publish(load)
            print(monitor.line(t), flush=True)
            next_line += 1.0
            dead = [Path(p.args[0]).name for p in processes if p.poll() is not None]
            if dead:
                print(f'control_demo: {", ".join(dead)} exited; see {logs}', flush=True)
                code = 1
                break
            if duration is not None and t >= duration:
                break
    finally:
        stop.set()
        codes = [stop_process(p) for p in processes]
        spin.close()
    print('control_demo: stopped (' + ', '.join(
        f'{name} exit {c}' for (name, _), c in zip(node_command_lines(params, extra), codes,
                                                    strict=True))
        + ')', flush=True)
    return code or int(any(codes))
