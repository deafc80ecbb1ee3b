"""``tensegrity-stiffness bag --node spine``: spine input bags written with rosbags (mcap and
sqlite3), the command run in-process, the output read back with rosbags and every answer
checked against :func:`spine_processing.spine_outputs` at the rest lengths in force, with the
node's layouts, labels, frame ids and stamps."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tensegrity_stiffness.nodes import layouts, spine_processing
from tensegrity_stiffness.recordings import bag
from tensegrity_stiffness.ros import conversions

rosbags = pytest.importorskip('rosbags')
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402
from support import REPO  # noqa: E402
from support.spine_bag_recordings import (  # noqa: E402
    ALL_OUTPUTS,
    ATOL,
    BASE,
    CHAIN,
    NS,
    SETTINGS,
    T0,
    TYPES,
    TYPESTORE,
    In,
    N,
    check_output,
    dims_of,
    multiarray,
    read_raw,
    run_cli,
    scenario,
    screws_near_rest,
    write_bag,
)


# ------------------------------------------------------------------------------ tests
@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_spine_bag_answers_every_valid_input_like_the_node(tmp_path: Path, storage: str
                                                           ) -> None:
    messages, expected, rejected = scenario()
    src = write_bag(tmp_path / 'in', messages, storage)
    code, out, err = run_cli('bag', src, '--out', tmp_path / 'out', '--node', 'spine',
                             '--json')
    assert code == 0, err
    report = json.loads(out)
    assert report['storage'] == storage and report['namespace'] == NS
    assert report['inputs'] == {'screws': 8, 'poses': 6, 'rest_lengths': 4}
    assert report['answered'] == {'screws': 2, 'poses': 3, 're-publish': 1}
    assert report['rejected'] == rejected
    assert report['written'] == {f'{NS}/{name}': len(expected)
                                 for name in ALL_OUTPUTS}
    assert 'joint 3 screw' in report['rejection_examples']['screws: outside the chart']
    assert 'joint 4 pose' in report['rejection_examples']['poses: bad quaternion']
    assert 'joint 2' in report['rejection_examples']['rest_lengths: bad rest lengths']
    assert bag._storage_of(tmp_path / 'out') == storage
    check_output(tmp_path / 'out', expected)


def test_spine_bag_messages_are_the_nodes_messages(tmp_path: Path) -> None:
    """The serialized output equals rclpy's serialization of the node's own messages
    (``SpineOutputMessages.fill``) for the same outputs and stamp, read and re-serialized by
    rosbags (Fast CDR leaves its padding bytes unset, rosbags zeroes them)."""
    from rclpy.serialization import serialize_message

    xs = screws_near_rest(2, seed=3)
    src = write_bag(tmp_path / 'in', [In('screws', T0, multiarray(xs[0].ravel())),
                                      In('screws', T0 + 5, multiarray(xs[1].ravel()))])
    bag.process_bag(src, tmp_path / 'out', node='spine')
    raw = read_raw(tmp_path / 'out')
    for i, xi in enumerate(xs):
        node = conversions.SpineOutputMessages(N, SETTINGS.tool_frame)
        node.fill(spine_processing.spine_outputs(CHAIN, xi), conversions.stamp_from_nanoseconds(
            T0 + 5 * i), BASE)
        mine = {topic: data for topic, t, _, data in raw if t == T0 + 5 * i}
        for name, msg in zip(ALL_OUTPUTS, node.messages(), strict=True):
            msgtype = TYPES[name]
            theirs = TYPESTORE.deserialize_cdr(bytes(serialize_message(msg)), msgtype)
            assert mine[f'{NS}/{name}'] == bytes(TYPESTORE.serialize_cdr(theirs, msgtype)), name


def test_spine_bag_namespace_config_topics_storage_and_csv(tmp_path: Path) -> None:
    xs = screws_near_rest(3, seed=1)
    messages = [In('screws', T0 + i, multiarray(x.ravel())) for i, x in enumerate(xs)]
    src = write_bag(tmp_path / 'in', messages, 'sqlite3', namespace='/robot/spine')
    cfg = tmp_path / 'spine.yaml'
    cfg.write_text((REPO / 'config' / 'default_spine.yaml').read_text().replace(
        'base: spine_base', 'base: robot_base'))
    code, out, err = run_cli('bag', src, '--out', tmp_path / 'out', '--node', 'spine',
                             '--namespace', 'robot/spine', '--config', cfg,
                             '--storage', 'mcap', '--topics', 'tip_wrench',
                             '/robot/spine/joint_stiffness', '--csv', tmp_path / 'a.csv')
    assert code == 0, err
    assert 'answered 3 inputs (3 screws)' in out
    raw = read_raw(tmp_path / 'out')
    assert sorted({topic for topic, *_ in raw}) == ['/robot/spine/joint_stiffness',
                                                    '/robot/spine/tip_wrench']
    assert bag._storage_of(tmp_path / 'out') == 'mcap'
    for topic, _, msgtype, data in raw:
        if topic.endswith('tip_wrench'):
            assert TYPESTORE.deserialize_cdr(data, msgtype).header.frame_id == 'robot_base'
    with (tmp_path / 'a.csv').open() as f:
        rows = list(csv.reader(f))
    assert len(rows) == 4 and len(rows[0]) == 3 + 6 * N + 6 + 36
    assert rows[0][:4] == ['log_time_ns', 'source', 'stamp_ns', 'joint_1_wx']
    for row, (i, xi) in zip(rows[1:], enumerate(xs), strict=True):
        o = spine_processing.spine_outputs(CHAIN, xi)
        assert row[:3] == [str(T0 + i), 'screws', str(T0 + i)]
        np.testing.assert_allclose(np.array(row[3:], dtype=float), np.concatenate(
            [xi.ravel(), o.tip_wrench, o.tip_stiffness_tool.ravel()]), atol=ATOL, rtol=1e-12)


def test_spine_bag_errors_exit_2_with_one_line(tmp_path: Path) -> None:
    xs = screws_near_rest(1)
    joint_bag = write_bag(tmp_path / 'joint', [In('screw', T0, multiarray(xs[0][0]))],
                          namespace='/stiffness_node')
    code, _, err = run_cli('bag', joint_bag, '--out', tmp_path / 'o1', '--node', 'spine')
    assert code == 2 and err.count('\n') == 1
    assert '/spine_node/screws' in err and '/stiffness_node/screw' in err
    src = write_bag(tmp_path / 'in', [In('screws', T0, multiarray(xs[0].ravel()))])
    code, _, err = run_cli('bag', src, '--out', tmp_path / 'o2', '--node', 'spine',
                           '--topics', 'wrench')
    assert code == 2 and "unknown output 'wrench'" in err and 'tip_stiffness_base' in err
    cfg = tmp_path / 'bad.yaml'
    cfg.write_text('frames:\n  base: ""\n')
    code, _, err = run_cli('bag', src, '--out', tmp_path / 'o3', '--node', 'spine',
                           '--config', cfg)
    assert code == 2 and 'frames.base' in err and err.count('\n') == 1
    bad = write_bag(tmp_path / 'bad', [In('screws', T0, multiarray(xs[0].ravel()[:6]))])
    code, _, err = run_cli('bag', bad, '--out', tmp_path / 'o4', '--node', 'spine')
    assert code == 2 and 'no input could be answered' in err
    assert 'screws: wrong length 1' in err and not (tmp_path / 'o4').exists()
    code, _, err = run_cli('bag', src, '--out', tmp_path / 'o5', '--node', 'nope')
    assert code == 2 and "invalid choice: 'nope'" in err


def test_spine_settings_use_the_files_joint_count() -> None:
    """A config of another ``chain.n_joints`` gets that parameter table (joint_<i>
    overrides), as the node declares it."""
    assert N == 5 and SETTINGS.values['chain.n_joints'] == 5


def test_spine_settings_of_a_three_joint_config(tmp_path: Path) -> None:
    cfg = tmp_path / 'three.yaml'
    cfg.write_text((REPO / 'config' / 'default_spine.yaml').read_text().replace(
        'n_joints: 5', 'n_joints: 3') + '    joint_3:\n      stiffness: [80.0]\n')
    settings = bag.spine_settings(cfg)
    assert settings.n_joints == 3
    assert float(np.ravel(settings.chain.joints[2].k)[0]) == 80.0
    assert float(np.ravel(settings.chain.joints[0].k)[0]) == 77.0


@pytest.mark.ros
def test_spine_bag_output_equals_the_running_spine_nodes_recorded_output(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The scenario's inputs sent to the installed ``spine_node`` one by one, its outputs
    recorded by an rclpy subscriber writing with rosbags, and compared message by message with
    the bag command's output of the same inputs. Stamps: equal where the node copies them (a
    pose's stamp, and re-publishes of it); the node's time of computation elsewhere, the log
    time in the bag."""
    pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
    import collections
    import os
    import time

    from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray
    from support.ros_harness import (
        LATCHED,
        Inbox,
        NodeProcess,
        RosClient,
        unique_namespace,
    )

    ns = unique_namespace('bagspine')
    base = f'{ns}/spine_node'
    msgs, expected, _ = scenario()
    src = write_bag(tmp_path / 'in', msgs, namespace=base)
    rcl_types = {'screws': Float64MultiArray, 'poses': PoseArray,
                 'rest_lengths': Float64MultiArray}
    from tensegrity_stiffness.msg import StampedMatrix

    rcl_out = {'tip_pose': PoseStamped, 'tip_wrench': WrenchStamped,
               **dict.fromkeys(layouts.SPINE_STAMPED_OUTPUTS, StampedMatrix)}
    names = ALL_OUTPUTS
    recorded = tmp_path / 'node_out'
    paths = [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep)
             if p and Path(p).resolve() not in (REPO, REPO / 'test')]
    with monkeypatch.context() as env:  # the installed node with its own sources
        env.setenv('PYTHONPATH', os.pathsep.join(paths))
        proc = NodeProcess(ns, REPO / 'config' / 'default_spine.yaml', executable='spine_node')
    ros = RosClient('bag_spine_test')
    try:
        # Each topic's outputs come in the order of the answered inputs: each is written at the
        # log time of the input it answers, then counted (the test waits on the counts).
        answered_at = {name: collections.deque() for name in names}
        with Writer(recorded, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = {name: writer.add_connection(f'{base}/{name}', TYPES[name],
                                                 typestore=TYPESTORE) for name in names}
            inboxes = {}
            for name in names:
                msg_type = rcl_out.get(name, Float64MultiArray)

                def record(msg: Any, name: str = name) -> None:
                    writer.write(conns[name], answered_at[name].popleft(),
                                 serialize_message(msg))
                    inboxes[name](msg)
                inboxes[name] = Inbox()
                ros.subscribe_callback(msg_type, f'{base}/{name}', record)
            pubs = {'screws': ros.publisher(Float64MultiArray, f'{base}/screws'),
                    'poses': ros.publisher(PoseArray, f'{base}/poses'),
                    'rest_lengths': ros.publisher(Float64MultiArray, f'{base}/rest_lengths',
                                                  LATCHED)}
            for pub in pubs.values():
                ros.wait_for_subscribers(pub)
            ros.wait_for_executor(base)
            for name in names:
                ros.wait_for_publishers(f'{base}/{name}')
            answered_times = {e['t'] for e in expected}
            count = 0
            for m in msgs:
                # Raw bytes and a wrong message type cannot be sent on the node's topics.
                if isinstance(m.msg, bytes) or m.msgtype != TYPESTORE_TYPES[m.topic]:
                    continue
                raw = bytes(TYPESTORE.serialize_cdr(m.msg, m.msgtype))
                if m.t in answered_times:
                    for queue in answered_at.values():
                        queue.append(m.t)
                pubs[m.topic].publish(deserialize_message(raw, rcl_types[m.topic]))
                if m.t in answered_times:
                    count += 1
                    for name in names:
                        inboxes[name].wait_for(count, timeout=10.0)
                elif m.topic == 'rest_lengths':
                    # The node orders inputs per topic only (its screws and poses are on the
                    # fast lane, rest lengths on the executor): let an unanswered state change
                    # land before the next input, as the bag's log-time order has it.
                    time.sleep(0.2)
            time.sleep(0.5)  # nothing more may come
            assert {name: len(inboxes[name]) for name in names} == dict.fromkeys(
                names, len(expected))
    finally:
        ros.close()
        proc.stop()

    code, _, stderr = run_cli('bag', src, '--out', tmp_path / 'bag_out', '--node', 'spine',
                              '--namespace', base)
    assert code == 0, stderr

    def messages(path: Path) -> list[tuple[int, str, Any]]:
        return sorted(((t, topic, TYPESTORE.deserialize_cdr(raw, msgtype))
                       for topic, t, msgtype, raw in read_raw(path)), key=lambda m: m[:2])

    node_out, bag_out = messages(recorded), messages(tmp_path / 'bag_out')
    assert len(node_out) == len(bag_out) == len(names) * len(expected)
    times = [e['t'] for e in expected]
    for (t_n, topic_n, n), (t_b, topic_b, b) in zip(node_out, bag_out, strict=True):
        assert (t_n, topic_n) == (t_b, topic_b) and t_b in times
        exp = expected[times.index(t_b)]
        name = topic_b[len(base) + 1:]
        if name in rcl_out:
            assert n.header.frame_id == b.header.frame_id == (
                SETTINGS.tool_frame if name == 'tip_stiffness_stamped' else BASE)
            if exp['stamp'] < T0:  # the scenario's pose stamps precede its log times
                assert (n.header.stamp.sec, n.header.stamp.nanosec) == (
                    b.header.stamp.sec, b.header.stamp.nanosec)
            if name == 'tip_pose':
                vn, vb = ([m.pose.position.x, m.pose.position.y, m.pose.position.z,
                           m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z,
                           m.pose.orientation.w] for m in (n, b))
            elif name == 'tip_wrench':
                vn, vb = ([m.wrench.force.x, m.wrench.force.y, m.wrench.force.z,
                           m.wrench.torque.x, m.wrench.torque.y, m.wrench.torque.z]
                          for m in (n, b))
            else:  # a stamped matrix
                assert (n.row_label, n.column_label, n.rows, n.cols) == (
                    b.row_label, b.column_label, b.rows, b.cols)
                vn, vb = n.data, b.data
            np.testing.assert_array_equal(vb, vn)
        else:
            assert dims_of(n) == dims_of(b) and n.layout.data_offset == b.layout.data_offset
            np.testing.assert_array_equal(b.data, n.data)


TYPESTORE_TYPES = dict(bag.NODE_TOPICS['spine'].inputs)
