#!/usr/bin/env python3
"""The stiffness loop on the twin, three processes against one, side by side (issue 37, item 4).

Run by hand after ``source scripts/env.sh`` (uses the environment's ROS_DOMAIN_ID):

    python bench/bench_loop.py [--seconds 20] [--repeats 2] [--rate 500] [--publish-every 1]
                               [--method filter] [--kinds three,one]
                               [--blas-threads inherit,1]

Each repeat runs, alternately, the three-process loop (``sim_node`` -> ``estimator_node`` (12
load cells + IMU) -> ``stiffness_controller`` -> ``sim_node``) and the one-process loop
(``sim_node`` -> ``control_loop`` -> ``sim_node``), each through a script of ``--seconds``: hold,
a pose step, a stiffness step (the design at tensions in [0.5, 1.5] N), a load swing (0.1 N,
8 s period, on the twin's ``~/external_wrench``). At the end of each phase it prints, from the
nodes' ``/diagnostics``: the controller's tick rate asked and achieved, its command rate and
missed ticks, the latency from a reading to the first command computed from it (median, p99 of
its last 2000 ticks), ticks held on a stale state; the estimator's input rate, the readings it
passed over for newer ones and its consistent share; the twin's achieved step rate; the CPU time
of the estimator's process per estimate from the end of the hold (``cpu/est``, ms, from
``/proc``; with the controller's in the one process): the figure the machine's load moves
least. With ``--publish-every 1`` the twin publishes both inputs (load cells, IMU) at 1 kHz.
``--blas-threads``: the nodes' OPENBLAS_NUM_THREADS, each value in turn within a repeat
(``inherit``: this shell's), to set the BLAS threading side by side.
Goals: commands at >= 95 % of ``control.rate``, latency median <= 3 ms and p99 <= 10 ms (three
processes), median <= 1.5 ms (one process). Numbers only, no assertions; ``uptime`` first and last.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / 'test'))
sys.path.insert(0, str(ROOT))
os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
if 'ROS_DOMAIN_ID' not in os.environ:
    raise SystemExit('set ROS_DOMAIN_ID (source scripts/env.sh with your domain id)')

import numpy as np  # noqa: E402
from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from geometry_msgs.msg import PoseStamped, WrenchStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.ros_harness import NodeProcess, RosClient, unique_namespace  # noqa: E402

from tensegrity_stiffness import config  # noqa: E402
from tensegrity_stiffness.geometry.screw import exp_se3  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402
from tensegrity_stiffness.ros.control_demo import (  # noqa: E402
    LOAD_AMPLITUDE_N,
    LOAD_PERIOD_S,
    targets,
)

#: ``--kinds``' names of the two loops.
KINDS = {'three': 'three processes', 'one': 'one process'}
PHASES = ('hold', 'pose step', 'stiffness step', 'load swing')
CONTROLLER_KEYS = (('tick rate [Hz]', 'asked'), ('achieved tick rate [Hz]', 'achieved'),
                   ('command rate [Hz]', 'commands'), ('missed ticks', 'missed'),
                   ('latency from the reading median [ms]', 'lat med'),
                   ('latency from the reading p99 [ms]', 'lat p99'),
                   ('held ticks (stale state)', 'held'))
ESTIMATOR_KEYS = (('input rate [Hz]', 'est in'), ('inputs skipped (a newer one was queued)',
                                                  'skipped'),
                  ('consistent share', 'consistent'))


def uptime() -> str:
    return subprocess.run(['uptime'], capture_output=True, text=True, check=False).stdout.strip()


def start(kind: str, ns: str, rate: float, publish_every: int, method: str) -> list[NodeProcess]:
    joint_config = config.packaged_config_path()
    sim, est, ctl = (f'{ns}/sim_node', f'{ns}/estimator_node', f'{ns}/stiffness_controller')
    common = ['-p', f'estimation.method:={method}', '-p', f'control.rate:={rate}',
              '-p', 'control.integral_gain:=4.0', '-p', 'markers.max_rate:=0.0']
    procs = [NodeProcess(ns, joint_config, executable='sim_node', extra_args=[
        '-p', f'sim.publish_every:={publish_every}',
        '-r', f'{sim}/rest_lengths:={ctl}/rest_lengths'])]
    inputs = ['-r', f'{est}/measured_tensions:={sim}/measured_tensions',
              '-r', f'{est}/imu:={sim}/imu', '-r', f'{est}/rest_lengths:={ctl}/rest_lengths']
    if kind == 'three processes':
        procs += [NodeProcess(ns, joint_config, executable='estimator_node',
                              extra_args=[*common, *inputs]),
                  NodeProcess(ns, joint_config, executable='stiffness_controller', extra_args=[
                      *common, '-r', f'{ctl}/pose_estimate:={est}/pose_estimate',
                      '-r', f'{ctl}/wrench_estimate:={est}/wrench_estimate'])]
    else:
        procs.append(NodeProcess(ns, joint_config, executable='control_loop',
                                 extra_args=[*common, *inputs]))
    return procs


def process_cpu_s(pid: int) -> float:
    """User and system CPU time of process ``pid`` and its threads (s, /proc/<pid>/stat)."""
    with open(f'/proc/{pid}/stat') as f:
        fields = f.read().rpartition(')')[2].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def newest(diagnostics, suffix: str) -> dict[str, str]:
    for array in reversed(diagnostics.messages):
        for status in array.status:
            if status.name.endswith(suffix):
                return {v.key: v.value for v in status.values}
    return {}


def run(kind: str, seconds: float, rate: float, publish_every: int, method: str,
        blas: str = 'inherit') -> None:
    model = JointModel.from_yaml(config.packaged_config_path())
    ns = unique_namespace('bench_loop')
    procs = start(kind, ns, rate, publish_every, method)
    ros = RosClient('bench_loop')
    ctl = f'{ns}/stiffness_controller'
    try:
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
        target_pub = ros.publisher(PoseStamped, f'{ctl}/target_pose')
        stiffness_pub = ros.publisher(Float64MultiArray, f'{ctl}/target_stiffness')
        load_pub = ros.publisher(WrenchStamped, f'{ns}/sim_node/external_wrench')
        pose, stiffness, _ = targets(model)
        hold = PoseStamped()
        hold.header.frame_id = 'tensegrity_link1'
        hold.pose = conversions.transform_to_pose(exp_se3(model.initial_screw))
        # started: the controller reports
        deadline = time.monotonic() + 60.0
        while not newest(diagnostics, f'{ctl}: controller') and time.monotonic() < deadline:
            time.sleep(0.2)
        print(f'{kind} ({method}, control.rate {rate:g} Hz, readings at '
              f'{1000 / publish_every:g} Hz, OPENBLAS_NUM_THREADS {blas}, {uptime()}):')
        estimator_pid = procs[1].pid
        last_cpu, last_count = 0.0, None
        start_t = time.monotonic()
        per_phase = seconds / len(PHASES)
        for i, phase in enumerate(PHASES):
            end = start_t + (i + 1) * per_phase
            while (now := time.monotonic()) < end:
                t = now - start_t
                target_pub.publish(hold if phase == 'hold' else pose)
                if phase in ('stiffness step', 'load swing') and stiffness is not None:
                    stiffness_pub.publish(stiffness)
                if phase == 'load swing':
                    load = WrenchStamped()
                    load.header.frame_id = 'tensegrity_link1'
                    load.wrench.force.x = float(LOAD_AMPLITUDE_N *
                                                np.sin(2 * np.pi * t / LOAD_PERIOD_S))
                    load_pub.publish(load)
                time.sleep(0.1)
            c = newest(diagnostics, f'{ctl}: controller')
            e = newest(diagnostics, 'estimator_node: estimator')
            s = newest(diagnostics, 'sim_node: twin')
            cells = [f'{label} {c.get(key, "-")}' for key, label in CONTROLLER_KEYS]
            cells += [f'{label} {e.get(key, "-")}' for key, label in ESTIMATOR_KEYS]
            cells.append(f'twin {s.get("achieved step rate [Hz]", "-")} Hz')
            # CPU time of the estimator's process per estimate over the phase (with the
            # controller's for one process): a figure the machine's load hardly moves
            # (since the end of the hold: /diagnostics' count is up to a second old, a
            # longer window makes that small)
            cpu, count = process_cpu_s(estimator_pid), int(e.get('estimates', 0))
            if last_count is None:
                last_cpu, last_count = cpu, count
            elif count > last_count:
                cells.append(f'cpu/est[ms] {1e3 * (cpu - last_cpu) / (count - last_count)}')
            print(f'  {phase:<15} ' + '  '.join(_short(x) for x in cells), flush=True)
    finally:
        ros.close()
        for proc in reversed(procs):
            proc.stop()


def _short(cell: str) -> str:
    label, _, value = cell.rpartition(' ')
    try:
        return f'{label} {float(value):.4g}'
    except ValueError:
        return cell


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument('--seconds', type=float, default=20.0)
    parser.add_argument('--repeats', type=int, default=2)
    parser.add_argument('--rate', type=float, default=500.0)
    parser.add_argument('--publish-every', type=int, default=1)
    parser.add_argument('--method', default='filter', choices=('filter', 'static'))
    parser.add_argument('--kinds', default='three,one',
                        help='which loops, comma-separated: three (processes), one (process)')
    parser.add_argument('--blas-threads', default='inherit',
                        help="the nodes' OPENBLAS_NUM_THREADS, comma-separated values run in "
                             "turn ('inherit': this shell's)")
    args = parser.parse_args()
    kinds = [KINDS[k.strip()] for k in args.kinds.split(',')]
    blas_settings = [b.strip() for b in args.blas_threads.split(',')]
    for b in blas_settings:
        if b != 'inherit' and not b.isdigit():
            parser.error(f"--blas-threads: 'inherit' or a number of threads, got {b!r}")
    inherited = os.environ.get('OPENBLAS_NUM_THREADS')
    print(f'start: {uptime()}')
    for _ in range(args.repeats):
        for kind in kinds:
            for blas in blas_settings:
                value = inherited if blas == 'inherit' else blas
                if value is None:
                    os.environ.pop('OPENBLAS_NUM_THREADS', None)
                else:
                    os.environ['OPENBLAS_NUM_THREADS'] = value
                run(kind, args.seconds, args.rate, args.publish_every, args.method,
                    blas if value is None else value)
    print(f'end: {uptime()}')


if __name__ == '__main__':
    main()
