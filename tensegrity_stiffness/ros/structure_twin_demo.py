"""``structure_twin_demo``: the structure twin's live line, in one command
(``bash scripts/run_twin.sh --structure six_bar|three_bar|FILE [--roll N] [--estimate]``).

Starts ``structure_sim_node`` (the MuJoCo twin of the structure, rolling ``--roll N`` faces by
the scripted gait) and, with ``--estimate``, ``structure_estimator_node`` wired to its sensors
(lengths, encoders, the IMUs, with sensor noise), then prints a line a second: the twin's live
line (simulated time, centre of mass, contact nodes, slack strings, the gait's phase, real-time
factor, missed steps: from its ``/diagnostics``) and, with the estimator, the estimate's error
against the twin's truth (RMS over the bodies of the position and the angle, the estimate
compared with the truth published nearest its stamp), its consistency and the estimates per
second. Ctrl-C (or ``--duration``) stops the nodes cleanly; the nodes' logs go to files.
"""

from __future__ import annotations

import argparse
import math
import os
import subprocess
import sys
import tempfile
import threading
import time
from bisect import bisect_left
from collections import deque
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray

from tensegrity_stiffness.nodes.messages import stamp_nanoseconds
from tensegrity_stiffness.nodes.structure_estimator_node import pose_errors, pose_rms
from tensegrity_stiffness.nodes.structure_node import structure_path
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.demo_processes import (
    BackgroundSpin,
    node_executable,
    stop_on_signals,
    stop_process,
)
from tensegrity_stiffness.ros.runtime.topics import output_qos
from tensegrity_stiffness.ros.twin_demo import split_node_arguments
from tensegrity_stiffness.structures.structure import Structure

NAMESPACE = '/twin'
TWIN, ESTIMATOR = 'structure_sim_node', 'structure_estimator_node'
#: The twin's sensor noise with ``--estimate`` (its defaults are zero): length sensors (m), the
#: accelerometer (m/s^2), the gyro (rad/s).
ESTIMATE_NOISE = {'lengths': 1e-3, 'accelerometer': 0.05, 'gyro': 0.01}
#: The estimator's IMU std (rad) at rest and while rolling (its accelerations, ~0.5 m/s^2 / g,
#: are in the gravity direction's error: docs/structures.md, "The recursive form").
IMU_STD_AT_REST, IMU_STD_ROLLING = 0.01, 0.1
#: The truth kept to compare the estimates with (s of the twin's publications).
TRUTH_WINDOW_S = 2.0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog='run_twin.sh --structure', description="The MuJoCo twin of a structure with its "
        'live line once a second; with --estimate the estimator node in the loop and the '
        "estimate's error (Ctrl-C stops the nodes).")
    parser.add_argument('--structure', required=True,
                        help='six_bar, three_bar (packaged examples) or a structure file')
    parser.add_argument('--roll', type=int, default=0, metavar='N',
                        help='roll N faces by the scripted gait (docs/structures.md)')
    parser.add_argument('--estimate', action='store_true',
                        help='structure_estimator_node on the twin\'s sensors')
    parser.add_argument('--method', choices=('filter', 'static'), default='filter',
                        help="the estimator's estimation.method (default filter)")
    parser.add_argument('--markers', action='store_true',
                        help='the twin publishes marker positions and the estimator uses them')
    parser.add_argument('--duration', type=float, default=None, metavar='S',
                        help='stop after S seconds (default: until Ctrl-C)')
    parser.epilog = 'Arguments after -- go to every node as ROS arguments.'
    return parser


def structure_config(name: str) -> str:
    """The value of ``structure.config`` for ``--structure``: a file as an absolute path, a
    packaged example by name (``six_bar`` -> ``six_bar.yaml``); SystemExit when neither."""
    if Path(name).is_file():
        return str(Path(name).resolve())
    example = name if name.endswith(('.yaml', '.yml')) else f'{name}.yaml'
    try:
        structure_path(example)
    except ValueError as exc:
        raise SystemExit(f'run_twin.sh --structure {name}: {exc}') from None
    return example


def commands(args: argparse.Namespace, extra: list[str]) -> dict[str, list[str]]:
    """The command line of each node (the estimator's inputs remapped onto the twin's)."""
    source = structure_config(args.structure)
    twin = [node_executable(TWIN), '--ros-args', '-r', f'__ns:={NAMESPACE}',
            '-p', f'structure.config:={source}']
    if args.roll:
        twin += ['-p', 'gait.enabled:=true', '-p', f'gait.steps:={args.roll}']
    if args.markers:
        twin += ['-p', 'markers.enabled:=true', '-p', 'noise.markers:=0.001']
    out = {TWIN: twin}
    if args.estimate:
        for kind, std in ESTIMATE_NOISE.items():
            twin += ['-p', f'noise.{kind}:={std}']
        structure = Structure.from_yaml(structure_path(source))
        inputs = ['measured_lengths', 'measured_rest_lengths', 'measured_contacts',
                  *(f'imu/{bar}' for bar in structure.bar_names)]
        if args.markers:
            inputs.append('measured_markers')
        estimator = [node_executable(ESTIMATOR), '--ros-args', '-r', f'__ns:={NAMESPACE}',
                     '-p', f'structure.config:={source}',
                     '-p', f'estimation.method:={args.method}',
                     '-p', f'sensors.length_std:={ESTIMATE_NOISE["lengths"]}',
                     '-p', f'sensors.gyro_std:={ESTIMATE_NOISE["gyro"]}',
                     '-p', f'sensors.imu_std:={IMU_STD_ROLLING if args.roll else IMU_STD_AT_REST}']
        for name in inputs:
            estimator += ['-r', f'~/{name}:={TWIN}/{name}']
        out[ESTIMATOR] = estimator
    return {name: [*command, *extra] for name, command in out.items()}


class StructureMonitor:
    """Subscribes to the twin's /diagnostics and truth and to the estimator's poses and trust;
    :meth:`line` is one line per call."""

    def __init__(self, node: Any, structure: Structure | None) -> None:
        self.structure = structure
        self._lock = threading.Lock()
        self.twin_line = 'waiting for the twin ...'
        self._truth: deque[tuple[int, np.ndarray]] = deque()
        self._errors: list[tuple[float, float]] = []
        self._consistent = ''
        qos = output_qos(100)
        node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 10)
        if structure is not None:
            node.create_subscription(PoseArray, f'{NAMESPACE}/{TWIN}/poses', self._on_truth,
                                     qos)
            node.create_subscription(PoseArray, f'{NAMESPACE}/{ESTIMATOR}/poses',
                                     self._on_estimate, qos)
            node.create_subscription(DiagnosticArray, f'{NAMESPACE}/{ESTIMATOR}/trust',
                                     self._on_trust, qos)

    def _transforms(self, msg: PoseArray) -> np.ndarray:
        return np.array([conversions.pose_message_to_transform(p) for p in msg.poses])

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for status in msg.status:
            if status.name.endswith(': structure twin'):
                with self._lock:
                    self.twin_line = status.message

    def _on_truth(self, msg: PoseArray) -> None:
        stamp = stamp_nanoseconds(msg.header.stamp)
        with self._lock:
            self._truth.append((stamp, self._transforms(msg)))
            while self._truth and self._truth[0][0] < stamp - TRUTH_WINDOW_S * 1e9:
                self._truth.popleft()

    def _on_estimate(self, msg: PoseArray) -> None:
        stamp = stamp_nanoseconds(msg.header.stamp)
        estimate = self._transforms(msg)
        with self._lock:
            if not self._truth:
                return
            stamps = [t for t, _ in self._truth]
            k = min(bisect_left(stamps, stamp), len(stamps) - 1)
            if k > 0 and abs(stamps[k - 1] - stamp) < abs(stamps[k] - stamp):
                k -= 1
            dp, angle = pose_errors(estimate, self._truth[k][1])
            self._errors.append((pose_rms(dp), pose_rms(angle)))

    def _on_trust(self, msg: DiagnosticArray) -> None:
        values = {kv.key: kv.value for kv in msg.status[0].values}
        text = f'consistent {values.get("consistent", "?")}'
        if values.get('outliers', 'none') != 'none':
            text += f' outliers {values["outliers"]}'
        with self._lock:
            self._consistent = text

    def line(self, period: float) -> str:
        """The twin's line and, with the estimator, the error of the estimates since the last
        call (RMS over bodies, mean over the estimates), their rate and consistency."""
        with self._lock:
            line, errors, self._errors = self.twin_line, self._errors, []
            consistent = self._consistent
        if self.structure is None:
            return line
        if not errors:
            return f'{line}  est -'
        dp, angle = np.mean(errors, axis=0)
        return (f'{line}  est err {1e3 * dp:.1f} mm {math.degrees(angle):.2f} deg  '
                f'{len(errors) / period:.0f}/s  {consistent}')


def main(argv: list[str] | None = None) -> int:
    own, extra = split_node_arguments(list(sys.argv[1:] if argv is None else argv))
    parser = build_parser()
    args = parser.parse_args(own)
    if args.roll < 0:
        parser.error(f'--roll must be >= 0, got {args.roll}')
    if args.duration is not None and not (math.isfinite(args.duration) and args.duration > 0):
        parser.error(f'--duration must be a positive number of seconds, got {args.duration}')
    lines = commands(args, extra)
    structure = (Structure.from_yaml(structure_path(structure_config(args.structure)))
                 if args.estimate else None)
    logs = Path(tempfile.mkdtemp(prefix='structure_twin_'))
    print(f'run_twin.sh --structure: {" + ".join(lines)} in {NAMESPACE} (ROS_DOMAIN_ID='
          f'{os.environ.get("ROS_DOMAIN_ID", "0")}); logs in {logs}', flush=True)
    stop = stop_on_signals()
    processes = {}
    for name, command in lines.items():
        with (logs / f'{name}.log').open('w') as out:
            processes[name] = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT,
                                               env=os.environ.copy(), start_new_session=True)
    rclpy.init(args=None, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node('structure_twin_monitor')
    monitor = StructureMonitor(node, structure)
    spin = BackgroundSpin(node, stop)
    start = time.monotonic()
    code = 0
    try:
        next_line = start + 1.0
        while not stop.wait(max(0.0, next_line - time.monotonic())):
            print(monitor.line(1.0), flush=True)
            next_line += 1.0
            dead = [name for name, p in processes.items() if p.poll() is not None]
            if dead:
                print(f'run_twin.sh --structure: {", ".join(dead)} exited; see {logs}',
                      flush=True)
                code = 1
                break
            if args.duration is not None and time.monotonic() - start >= args.duration:
                break
    finally:
        stop.set()
        codes = {name: stop_process(p) for name, p in processes.items()}
        spin.close()
    print('run_twin.sh --structure: stopped ('
          + ', '.join(f'{name} exit {c}' for name, c in codes.items()) + ')', flush=True)
    return code or int(any(codes.values()))


if __name__ == '__main__':
    sys.exit(main())
