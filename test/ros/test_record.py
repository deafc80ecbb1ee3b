"""``tensegrity-stiffness record``: rclpy subscriptions written through rosbags (mcap), from a
running twin; the documented calibration recording (``scripts/record_calibration.sh``: the twin,
``record --node sim``, a seeded sequence of holds, stopped with SIGINT) read by ``bag`` and by
``calibrate``, which recovers the twin's true stiffness and rest-length offsets."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from support import REPO

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from support.ros_harness import NodeProcess, unique_namespace

from tensegrity_stiffness.cli import main as cli_main

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: The "true" joint the twin runs: every string 80 N/m (the config's 77) and 0.5 mm longer
#: than commanded.
TRUE_STIFFNESS = 80.0
TRUE_OFFSET = 5e-4
HOLDS = 12


def command(*args: str, timeout: float = 300.0) -> subprocess.CompletedProcess:
    return subprocess.run(['tensegrity-stiffness', *args], capture_output=True, text=True,
                          env=os.environ.copy(), timeout=timeout)


def read_bag(path: Path) -> dict[str, list[Any]]:
    """``{topic: [(log time, message)]}`` of a rosbag2, deserialized by rosbags."""
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    out: dict[str, list[Any]] = {}
    with Reader(path) as reader:
        for connection, timestamp, raw in reader.messages():
            out.setdefault(connection.topic, []).append(
                (timestamp, typestore.deserialize_cdr(raw, connection.msgtype)))
    return out


def test_calibration_recording_from_the_twin_is_read_by_bag_and_calibrate(tmp_path: Path
                                                                          ) -> None:
    ns = unique_namespace('calib')
    bag = tmp_path / 'calibration'
    ran = subprocess.run(
        ['bash', str(REPO / 'scripts' / 'record_calibration.sh'), str(bag), '--namespace', ns,
         '--holds', str(HOLDS), '--hold', '1.0', '--seed', '3', '--',
         '-p', f'joint.stiffness:=[{TRUE_STIFFNESS}]',
         '-p', f'joint.rest_length_offsets:=[{TRUE_OFFSET}]'],
        capture_output=True, text=True, env=os.environ.copy(), timeout=300)
    assert ran.returncode == 0, ran.stdout[-4000:] + ran.stderr[-4000:]
    assert f'hold {HOLDS}/{HOLDS}' in ran.stdout, ran.stdout[-3000:]
    base = f'{ns}/sim_node'
    messages = read_bag(bag)
    assert len(messages[f'{base}/rest_lengths']) == HOLDS
    poses = messages[f'{base}/pose']
    assert len(poses) > 50 * HOLDS and poses[0][1].header.frame_id == 'tensegrity_link1'
    assert [t for t, _ in poses] == sorted(t for t, _ in poses)

    answered = command('bag', str(bag), '--out', str(tmp_path / 'answers'), '--namespace',
                       base, '--json')
    assert answered.returncode == 0, answered.stderr
    summary = json.loads(answered.stdout)
    assert summary['inputs']['pose'] == len(poses)
    assert summary['answers'] >= len(poses)  # poses and screws, each answered

    calibrated = command('calibrate', str(bag), '--pose-topic', f'{base}/pose',
                         '--rest-lengths-topic', f'{base}/rest_lengths', '--tensions-topic',
                         f'{base}/measured_tensions', '--wrench-topic',
                         f'{base}/external_wrench', '--json')
    assert calibrated.returncode == 0, calibrated.stderr
    report = json.loads(calibrated.stdout)
    assert report['success'] and report['samples'] == HOLDS, report['message']
    fitted, std = report['parameters'], report['std']
    for j in range(12):
        for name, truth in ((f'stiffness[{j}]', TRUE_STIFFNESS),
                            (f'rest_length_offset[{j}]', TRUE_OFFSET)):
            assert abs(fitted[name] - truth) < 4.0 * std[name], (name, fitted[name], std[name])
    k = np.array([fitted[f'stiffness[{j}]'] for j in range(12)])
    assert abs(k.mean() - TRUE_STIFFNESS) < 1.0  # the nominal 77 is 3 N/m away


def test_record_duration_and_named_topics(tmp_path: Path) -> None:
    """``--duration`` ends it; ``--topics`` records only those, with their types, at increasing
    receive times; the messages are the twin's (frame, stamps)."""
    ns = unique_namespace('rec')
    twin = NodeProcess(ns, REPO / 'config' / 'default_joint.yaml',
                       ['-p', 'sim.publish_every:=10'], executable='sim_node')
    try:
        out = tmp_path / 'pose_only'
        ran = command('record', str(out), '--topics', f'{ns}/sim_node/pose',
                      f'{ns}/nobody/here', '--duration', '2', '--json', timeout=120)
        assert ran.returncode == 0, ran.stdout + ran.stderr
        report = json.loads(ran.stdout[ran.stdout.index('{'):])
        assert report['types'] == {f'{ns}/sim_node/pose': 'geometry_msgs/msg/PoseStamped'}
        assert report['not_found'] == [f'{ns}/nobody/here']
        assert 1.9 <= report['seconds'] < 10.0
        poses = read_bag(out)[f'{ns}/sim_node/pose']
        assert len(poses) == report['messages'][f'{ns}/sim_node/pose'] > 10
        assert all(msg.header.frame_id == 'tensegrity_link1' for _, msg in poses)
        stamps = [msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec for _, msg in poses]
        assert stamps == sorted(stamps) and all(t >= s for (t, _), s in zip(poses, stamps,
                                                                             strict=True))
        again = command('record', str(out), '--node', 'sim', '--namespace', ns,
                        '--duration', '1', timeout=120)
        assert again.returncode == 2 and 'exists' in again.stderr  # no --overwrite
    finally:
        assert twin.stop() == 0, twin.log()


def test_record_names_a_missing_node_and_bad_options(tmp_path: Path, capsys: Any) -> None:
    missing = command('record', str(tmp_path / 'none'), '--node', 'sim', '--namespace',
                      unique_namespace('absent'), '--wait', '1', timeout=120)
    assert missing.returncode == 2 and 'sim_node in the graph within 1 s' in missing.stderr
    assert not (tmp_path / 'none').exists()  # no empty bag left behind
    for args, why in ((['record', str(tmp_path / 'x')], 'give --node, --topics or both'),
                      (['record', str(tmp_path / 'x'), '--topics', 'pose'], 'absolute name'),
                      (['record', str(tmp_path), '--node', 'sim'], 'exists')):
        assert cli_main(args) == 2
        assert why in capsys.readouterr().err
    assert cli_main(['record', str(tmp_path / 'x'), '--node', 'sim', '--duration', '-1']) == 2
    assert 'positive number of seconds' in capsys.readouterr().err
