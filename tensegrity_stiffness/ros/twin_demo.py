"""``twin_demo``: the whole loop without hardware, in one command (``scripts/run_twin.sh``).

Starts ``sim_node`` (the MuJoCo twin, slowly swinging a load) and ``stiffness_node`` (or, with
``--spine``, ``spine_node``) wired together in one namespace: the stiffness node's ``~/pose``
(``~/poses``) is the twin's. Then prints a one-line summary once a second: the input rate the
stiffness node gets, the pose, the smallest and largest eigenvalue of the symmetric part of
``K_c`` (the tip stiffness for a spine), the slack strings and the latency from the twin's
publication to the stiffness node's output. Ctrl-C (or ``--duration``) stops both nodes cleanly
(SIGINT, then a wait) and exits 0.

The nodes' own logs go to files (their paths are printed first), the terminal keeps the summary.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness import config
from tensegrity_stiffness.nodes.messages import stamp_nanoseconds
from tensegrity_stiffness.ros import control_demo, conversions
from tensegrity_stiffness.ros.demo_processes import (
    NAMESPACE,
    BackgroundSpin,
    node_executable,
    stop_on_signals,
    stop_process,
)
from tensegrity_stiffness.ros.runtime.draining_subscription import create_draining_subscription
from tensegrity_stiffness.ros.runtime.topics import output_qos

#: Default swinging load: amplitude (N) and period (s) for the joint and the spine.
JOINT_SWING = (0.1, 10.0)
SPINE_SWING = (0.01, 10.0)
#: The spine's twin publishes every this many steps by default (200 Hz of a 1 kHz simulation:
#: five poses and 60 tensions per publication are more than a 1 kHz Python loop carries on a
#: shared 2-core machine).
SPINE_PUBLISH_EVERY = 5
#: The joint's twin, likewise (200 Hz: a rate the stiffness node and the monitor sustain on a
#: shared 2-core machine; every step, 1 kHz, outran them there and the latency grew).
JOINT_PUBLISH_EVERY = 5
#: The live line calls the node behind when it answers less than this share of its inputs.
ANSWERED_SHARE_BEHIND = 0.95
#: With ``--duration`` (whose clock starts at the twin's first reading), the demo gives up when
#: no reading came this many seconds after the launch (the nodes' start took 9-15 s on a
#: loaded 2-core machine).
NO_READING_LIMIT_S = 60.0


def subscribe(node: Any, msg_type: Any, topic: str, callback: Any, qos: Any) -> Any:
    """A subscription that also takes what queued behind each message (the monitor gets four
    1 kHz streams: one executor wake-up per message would not keep up on a busy machine)."""
    return create_draining_subscription(node, msg_type, topic, callback, qos)


class Monitor:
    """Subscribes to the twin and the stiffness node; :meth:`summary` is one line per call."""

    def __init__(self, node: Any, spine: bool, n_strings: int) -> None:
        self.node = node
        self.spine = spine
        self.n_strings = n_strings
        self._lock = threading.Lock()
        self._inputs = 0
        self._outputs = 0
        #: When (``time.monotonic()``) the twin's first reading arrived; None until then.
        self.first_input: float | None = None
        self._pose: np.ndarray | None = None
        self._stiffness: np.ndarray | None = None
        self._tensions: np.ndarray | None = None
        self._latencies: list[float] = []
        qos = output_qos(100)
        sim, spine_node = f'{NAMESPACE}/sim_node', f'{NAMESPACE}/spine_node'
        joint_node = f'{NAMESPACE}/stiffness_node'
        if spine:
            streams = [(PoseArray, f'{sim}/poses', self._on_poses),
                       (PoseStamped, f'{spine_node}/tip_pose', self._on_tip_pose),
                       (Float64MultiArray, f'{spine_node}/tip_stiffness_base', self._on_stiffness),
                       (Float64MultiArray, f'{sim}/measured_tensions', self._on_tensions)]
        else:
            streams = [(PoseStamped, f'{sim}/pose', self._on_pose),
                       (WrenchStamped, f'{joint_node}/wrench', self._on_output),
                       (Float64MultiArray, f'{joint_node}/cartesian_stiffness',
                        self._on_stiffness),
                       (Float64MultiArray, f'{joint_node}/string_tensions', self._on_tensions)]
        for msg_type, topic, callback in streams:
            subscribe(node, msg_type, topic, callback, qos)

    def _count_input(self) -> None:
        """One reading of the twin (lock held)."""
        self._inputs += 1
        if self.first_input is None:
            self.first_input = time.monotonic()

    def _on_pose(self, msg: PoseStamped) -> None:
        with self._lock:
            self._count_input()
            self._pose = conversions.pose_message_to_transform(msg.pose)

    def _on_poses(self, msg: PoseArray) -> None:
        with self._lock:
            self._count_input()

    def _on_tip_pose(self, msg: PoseStamped) -> None:
        self._on_output(msg)
        with self._lock:
            self._pose = conversions.pose_message_to_transform(msg.pose)

    def _on_output(self, msg: Any) -> None:
        now = self.node.get_clock().now().nanoseconds
        stamp = msg.header.stamp
        latency = (now - stamp_nanoseconds(stamp)) * 1e-9
        with self._lock:
            self._outputs += 1
            self._latencies.append(latency)

    def _on_stiffness(self, msg: Float64MultiArray) -> None:
        K = np.asarray(msg.data, dtype=np.float64).reshape(6, 6)
        with self._lock:
            self._stiffness = K

    def _on_tensions(self, msg: Float64MultiArray) -> None:
        with self._lock:
            self._tensions = np.asarray(msg.data, dtype=np.float64)

    def summary(self, elapsed: float, period: float) -> str:
        """One line (:func:`summary_line`) of what arrived since the last call (and resets the
        counters of the period)."""
        with self._lock:
            inputs, self._inputs = self._inputs, 0
            outputs, self._outputs = self._outputs, 0
            latencies, self._latencies = self._latencies, []
            pose, K, tensions = self._pose, self._stiffness, self._tensions
        return summary_line(elapsed, inputs / period, pose, K, tensions, latencies,
                            spine=self.spine, n_strings=self.n_strings,
                            output_rate=outputs / period)


def summary_line(elapsed: float, input_rate: float, pose: np.ndarray | None,
                 stiffness: np.ndarray | None, tensions: np.ndarray | None,
                 latencies: list[float], *, spine: bool, n_strings: int,
                 output_rate: float | None = None) -> str:
    """The live line: time, input rate (and, given ``output_rate``, the rate of the node's
    answers, with ``behind`` when it answers less than :data:`ANSWERED_SHARE_BEHIND` of its
    inputs: the input outruns the node, newest-only inputs skip the rest, and the latency
    describes only what it answered), pose (4x4; the tip's for a spine), the smallest and
    largest eigenvalue of the symmetric part of ``stiffness`` (K_c or the tip stiffness), slack
    strings, latency median and maximum (s). A field with nothing to show is ``-``; so are the
    stiffness and the latency while no input arrives (a rate of 0 Hz: at the start, before the
    subscriptions have matched, or after the twin stopped), as they would describe old or
    unrelated messages."""
    parts = [f't {elapsed:6.1f} s', f'input {input_rate:6.0f} Hz']
    if output_rate is not None and input_rate > 0.0:
        behind = output_rate < ANSWERED_SHARE_BEHIND * input_rate
        parts.append(f'answered {output_rate:6.0f} Hz' + (
            ' (behind: the input outruns the node, inputs skipped)' if behind else ''))
    if pose is not None:
        p = pose[:3, 3] * 1e3
        angle = math.degrees(math.acos(max(-1.0, min(1.0, (np.trace(pose[:3, :3]) - 1) / 2))))
        parts.append(f'{"tip" if spine else "pose"} [{p[0]:6.2f} {p[1]:6.2f} '
                     f'{p[2]:6.2f}] mm {angle:6.2f} deg')
    else:
        parts.append('pose -')
    live = input_rate > 0.0
    label = 'K_tip' if spine else 'K_c'
    if stiffness is not None and live:
        eig = np.linalg.eigvalsh(0.5 * (stiffness + stiffness.T))
        parts.append(f'{label} eig {eig[0]:.4g} .. {eig[-1]:.4g}')
    else:
        parts.append(f'{label} -')
    slack = '-' if tensions is None else f'{int(np.count_nonzero(tensions <= 0.0))}'
    parts.append(f'slack {slack}/{n_strings}')
    if latencies and live:
        parts.append(f'latency median {statistics.median(latencies) * 1e3:.2f} ms '
                     f'max {max(latencies) * 1e3:.2f} ms')
    else:
        parts.append('latency -')
    return '  '.join(parts)


def build_parser() -> argparse.ArgumentParser:
    """The demo's command line."""
    parser = argparse.ArgumentParser(
        prog='twin_demo', description='MuJoCo twin + stiffness node, wired together, with a '
        'live one-line summary once a second (Ctrl-C stops both).')
    parser.add_argument('--spine', action='store_true',
                        help='the 5-joint spine (config/default_spine.yaml) and spine_node')
    parser.add_argument('--control', action='store_true',
                        help='the closed loop: twin -> estimator_node (12 load cells) -> '
                        'stiffness_controller -> twin, with a scripted target sequence '
                        '(docs/control.md)')
    parser.add_argument('--config', type=Path, default=None,
                        help='ROS parameter file (default: config/default_joint.yaml or '
                        'config/default_spine.yaml)')
    parser.add_argument('--duration', type=float, default=None,
                        help="stop after this many seconds of the twin's readings (the clock "
                        "starts at the first one; default: until Ctrl-C)")
    parser.add_argument('--swing', type=float, default=None,
                        help='amplitude of the swinging load, N (default 0.1 joint, 0.01 spine)')
    parser.add_argument('--swing-period', type=float, default=None,
                        help='period of the swinging load, s (default 10)')
    parser.add_argument('--rate', type=float, default=1000.0, help='simulation rate, Hz')
    parser.add_argument('--publish-every', type=int, default=None, metavar='N',
                        help='the twin publishes every N-th step (default '
                             f'{JOINT_PUBLISH_EVERY} for the joint, {SPINE_PUBLISH_EVERY} for '
                             'the spine)')
    parser.epilog = ('Arguments after -- go to every node as ROS arguments, e.g. '
                     '-- -p limits.tension_max:=3.')
    return parser


@dataclass(frozen=True)
class DemoSetup:
    """What the twin demo runs, checked: the parameter file, joint or spine, its string count,
    the swinging load (N, s), the twin's rate (Hz) and publication step, the duration (s or
    None: until Ctrl-C)."""

    params: Path
    spine: bool
    n_strings: int
    amplitude: float
    period: float
    rate: float
    publish_every: int
    duration: float | None
    #: ROS arguments given after ``--``, passed to both nodes after the demo's own.
    node_arguments: tuple[str, ...] = ()

    @property
    def stiffness_node(self) -> str:
        return 'spine_node' if self.spine else 'stiffness_node'

    def commands(self) -> tuple[list[str], list[str]]:
        """The command lines of the stiffness node and the twin, wired as
        launch/twin*.launch.py wires them: the partner's input is the twin's truth."""
        wired = '~/poses:=sim_node/poses' if self.spine else '~/pose:=sim_node/pose'
        sim_args = [node_executable('sim_node'), '--ros-args', '--params-file', str(self.params),
                    '-r', f'__ns:={NAMESPACE}', '-p', f'sim.spine:={str(self.spine).lower()}',
                    '-p', f'sim.rate:={self.rate}',
                    '-p', f'load.swing_amplitude:={self.amplitude}',
                    '-p', f'load.swing_period:={self.period}',
                    '-p', f'sim.publish_every:={self.publish_every}', *self.node_arguments]
        node_args = [node_executable(self.stiffness_node), '--ros-args', '--params-file',
                     str(self.params), '-r', f'__ns:={NAMESPACE}', '-r', wired,
                     *self.node_arguments]
        return node_args, sim_args


def demo_setup(args: argparse.Namespace, parser: argparse.ArgumentParser) -> DemoSetup:
    """The checked :class:`DemoSetup` of parsed ``args`` (``parser.error`` on a bad one)."""
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        parser.error(f'--duration must be a positive number of seconds, got {args.duration}')
    every = args.publish_every or (SPINE_PUBLISH_EVERY if args.spine else JOINT_PUBLISH_EVERY)
    if every < 1:
        parser.error(f'--publish-every must be >= 1, got {every}')
    amplitude, period = SPINE_SWING if args.spine else JOINT_SWING
    amplitude = amplitude if args.swing is None else args.swing
    period = period if args.swing_period is None else args.swing_period
    name = 'default_spine.yaml' if args.spine else 'default_joint.yaml'
    params = Path(args.config or config.packaged_config_path(name))
    if not params.is_file():
        parser.error(f'--config {params}: no such file')
    if args.spine:
        chain_doc = config.parameters(config.load_yaml(params))
        from tensegrity_stiffness.mechanics.chain import JointChain
        n_strings = sum(m.n_strings for m in JointChain.from_dict(chain_doc).joints)
    else:
        from tensegrity_stiffness.mechanics.joint import JointModel
        n_strings = JointModel.from_yaml(params).n_strings
    return DemoSetup(params, args.spine, n_strings, amplitude, period, args.rate, every,
                     args.duration)


def split_node_arguments(argv: list[str]) -> tuple[list[str], list[str]]:
    """The demo's own arguments and those after ``--`` (ROS arguments for every node:
    ``-p limits.tension_max:=3``)."""
    if '--' not in argv:
        return argv, []
    at = argv.index('--')
    return argv[:at], argv[at + 1:]


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    own, extra = split_node_arguments(list(sys.argv[1:] if argv is None else argv))
    args = parser.parse_args(own)
    if args.control:
        if args.spine:
            parser.error('--control drives the joint (the spine controller is library-only)')
        if args.config is not None and not Path(args.config).is_file():
            parser.error(f'--config {args.config}: no such file')
        return control_demo.run(args.config, args.duration, extra)
    return run_demo(replace(demo_setup(args, parser), node_arguments=tuple(extra)))


def run_demo(setup: DemoSetup) -> int:
    """Start the stiffness node and the twin, print a line a second until Ctrl-C, the
    duration or a node's exit; stop both. The exit status: 0, or 1 when a node failed."""
    stiffness = setup.stiffness_node
    node_args, sim_args = setup.commands()
    logs = Path(tempfile.mkdtemp(prefix='twin_demo_'))
    print(f'twin_demo: sim_node + {stiffness} in {NAMESPACE} (ROS_DOMAIN_ID='
          f'{os.environ.get("ROS_DOMAIN_ID", "0")}), swinging {setup.amplitude:g} N every '
          f'{setup.period:g} s; logs in {logs}', flush=True)

    stop = stop_on_signals()
    processes = []
    for exe_args, log in ((node_args, logs / f'{stiffness}.log'),
                          (sim_args, logs / 'sim_node.log')):
        with log.open('w') as out:
            # Own process group: a Ctrl-C on the terminal reaches this script, which stops them.
            processes.append(subprocess.Popen(exe_args, stdout=out, stderr=subprocess.STDOUT,
                                              env=os.environ.copy(), start_new_session=True))
    rclpy.init(args=None, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node('twin_monitor')
    monitor = Monitor(node, setup.spine, setup.n_strings)
    spin = BackgroundSpin(node, stop)
    start = time.monotonic()
    code = 0
    try:
        next_line = start + 1.0
        while not stop.is_set():
            if stop.wait(max(0.0, next_line - time.monotonic())):
                break
            now = time.monotonic()
            print(monitor.summary(now - start, 1.0), flush=True)
            next_line += 1.0
            dead = [p.args[0] for p in processes if p.poll() is not None]
            if dead:
                print(f'twin_demo: {", ".join(Path(d).name for d in dead)} exited; see {logs}',
                      flush=True)
                code = 1
                break
            if setup.duration is not None:
                first = monitor.first_input
                if first is not None and now - first >= setup.duration:
                    break
                if first is None and now - start >= NO_READING_LIMIT_S:
                    print(f'twin_demo: no reading from the twin in {NO_READING_LIMIT_S:g} s; '
                          f'see {logs}', flush=True)
                    code = 1
                    break
    finally:
        stop.set()
        codes = [stop_process(p) for p in processes]
        spin.close()
    print(f'twin_demo: stopped ({stiffness} exit {codes[0]}, sim_node exit {codes[1]})',
          flush=True)
    return code or int(any(codes))


if __name__ == '__main__':
    sys.exit(main())
