"""``tensegrity-stiffness bag --node structure``: structure input bags written with rosbags, the
command run in-process, the output read back with rosbags and every answer checked against
:meth:`Structure.evaluate` at the rest lengths in force, with the node's layouts; and (``ros``)
the bag's output equal to what the running ``structure_node`` publishes for the
same inputs (layouts and payload bytes; the CDR padding after a label is not compared)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tensegrity_stiffness.mechanics.templates import pose_vector
from tensegrity_stiffness.nodes import structure_node
from tensegrity_stiffness.nodes.messages import pose_message_to_transform
from tensegrity_stiffness.recordings import bag
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import twist_exp

rosbags = pytest.importorskip('rosbags')
from support import REPO  # noqa: E402
from support.spine_bag_recordings import (  # noqa: E402
    FMA,
    POSE_ARRAY,
    T0,
    TYPESTORE,
    In,
    multiarray,
    read_raw,
    run_cli,
    write_bag,
)

NS = '/structure_node'
SETTINGS = bag.structure_settings()
STRUCTURE = SETTINGS.structure
N = STRUCTURE.n_bodies
STEP = 1_000_000  # 1 ms between messages


def poses_msg(transforms: np.ndarray, frame: str = '') -> Any:
    types = TYPESTORE.types
    poses = []
    for T in transforms:
        x, y, z, qx, qy, qz, qw = pose_vector(T)
        poses.append(types['geometry_msgs/msg/Pose'](
            position=types['geometry_msgs/msg/Point'](x=x, y=y, z=z),
            orientation=types['geometry_msgs/msg/Quaternion'](x=qx, y=qy, z=qz, w=qw)))
    return types[POSE_ARRAY](header=types['std_msgs/msg/Header'](
        stamp=types['builtin_interfaces/msg/Time'](sec=0, nanosec=0), frame_id=frame),
        poses=poses)


def scenario() -> tuple[list[In], list[dict[str, Any]]]:
    """Poses and pose values near the equilibrium on the ground, bad inputs, new rest lengths
    (re-publishing the last answer) and a bad rest-lengths message; the expected answers
    (log time, poses, rest lengths)."""
    rng = np.random.default_rng(3)
    eq = solve_structure_equilibrium(STRUCTURE)
    rest = STRUCTURE.rest_lengths
    msgs: list[In] = []
    expected: list[dict[str, Any]] = []
    t = T0

    def tick() -> int:
        nonlocal t
        t += STEP
        return t

    def moved() -> np.ndarray:
        return np.array([twist_exp(0.01 * rng.standard_normal(6)) @ P for P in eq.poses])

    for k in range(6):
        T = moved()
        values = np.array([pose_vector(P) for P in T])
        read = STRUCTURE.transforms(values)
        if k % 2:
            msgs.append(In('poses', tick(), poses_msg(T)))
            read = np.array([pose_message_to_transform(p) for p in poses_msg(T).poses])
        else:
            msgs.append(In('pose_values', tick(), multiarray(values.ravel())))
        expected.append({'t': t, 'T': read, 'rest': rest})
    last = expected[-1]['T']
    msgs.append(In('poses', tick(), poses_msg(eq.poses[:5])))            # 5 poses: refused
    msgs.append(In('pose_values', tick(), multiarray(np.zeros(7 * N))))   # zero quaternions
    msgs.append(In('poses', tick(), poses_msg(eq.poses, 'map')))         # another frame
    rest = 0.99 * STRUCTURE.rest_lengths
    msgs.append(In('rest_lengths', tick(), multiarray(rest)))
    expected.append({'t': t, 'T': last, 'rest': rest})                   # the re-publish
    msgs.append(In('rest_lengths', tick(), multiarray(rest[:3])))        # refused
    T = moved()
    msgs.append(In('pose_values', tick(), multiarray(np.ravel([pose_vector(P) for P in T]))))
    expected.append({'t': t, 'T': STRUCTURE.transforms(np.array([pose_vector(P) for P in T])),
                     'rest': rest})
    return msgs, expected


def outputs_by_time(path: Path) -> dict[str, dict[int, Any]]:
    out: dict[str, dict[int, Any]] = {}
    for topic, t, msgtype, raw in read_raw(path):
        assert msgtype == FMA
        out.setdefault(topic[len(NS) + 1:], {})[t] = TYPESTORE.deserialize_cdr(raw, msgtype)
    return out


def test_structure_bag_answers_every_valid_input_like_the_library(tmp_path: Path) -> None:
    msgs, expected = scenario()
    src = write_bag(tmp_path / 'in', msgs, namespace=NS)
    code, _, stderr = run_cli('bag', src, '--out', tmp_path / 'out', '--node', 'structure',
                              '--csv', tmp_path / 'out.csv')
    assert code == 0, stderr
    out = outputs_by_time(tmp_path / 'out')
    layouts = structure_node.structure_output_layouts(STRUCTURE)
    assert list(out) == list(layouts) == list(structure_node.STRUCTURE_OUTPUTS)
    nodes = structure_node.body_nodes(STRUCTURE)
    for name, layout in layouts.items():
        assert sorted(out[name]) == [e['t'] for e in expected], name
        for msg in out[name].values():
            assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == list(layout.dims)
    for e in expected:
        state = STRUCTURE.evaluate(e['T'], e['rest'])
        np.testing.assert_allclose(out['body_wrenches'][e['t']].data.reshape(N, 6),
                                   state.wrenches, rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(out['stiffness'][e['t']].data.reshape(6 * N, 6 * N),
                                   state.stiffness, rtol=1e-12,
                                   atol=1e-12 * np.abs(state.stiffness).max())
        np.testing.assert_allclose(out['string_tensions'][e['t']].data, state.tensions,
                                   rtol=1e-12, atol=1e-13)
        np.testing.assert_allclose(out['bar_forces'][e['t']].data, state.bar_forces,
                                   rtol=1e-12, atol=1e-13)
        assert out['contact_forces'][e['t']].data.shape == (3 * len(nodes),)
    lines = (tmp_path / 'out.csv').read_text().splitlines()
    assert len(lines) == 1 + len(expected)


def test_structure_bag_counts_the_refusals_by_kind(tmp_path: Path) -> None:
    msgs, expected = scenario()
    src = write_bag(tmp_path / 'in', msgs, namespace=NS)
    summary = bag.process_bag(src, tmp_path / 'out', node='structure')
    assert summary.answers == len(expected)
    assert summary.answered == {'pose_values': 4, 'poses': 3, 're-publish': 1}
    assert sum(summary.rejected.values()) == 4, summary.rejected
    assert any(k.startswith('rest_lengths') for k in summary.rejected)


def test_structure_settings_take_a_structure_file(tmp_path: Path) -> None:
    three = REPO / 'config' / 'examples' / 'three_bar.yaml'
    assert bag.structure_settings(three).structure.n_bodies == 3
    params = tmp_path / 'params.yaml'
    params.write_text('structure_node:\n  ros__parameters:\n    structure.config: '
                      'three_bar.yaml\n')
    assert bag.structure_settings(params).structure.n_bodies == 3
    params.write_text('structure_node:\n  ros__parameters:\n    structure.config: nope.yaml\n')
    with pytest.raises(bag.BagError, match=r'structure\.config'):
        bag.structure_settings(params)


@pytest.mark.ros
def test_structure_bag_output_equals_the_running_nodes_output(tmp_path: Path) -> None:
    """The scenario's valid inputs sent to the installed ``structure_node`` one by one (each
    answer awaited), its outputs serialized by rclpy, compared with the bag command's output
    of the same recording: the same layouts and the same payload bytes (bit for bit)."""
    pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
    from geometry_msgs.msg import PoseArray
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray
    from support.ros_harness import LATCHED, Inbox, NodeProcess, RosClient, unique_namespace

    ns = unique_namespace('bagstructure')
    base = f'{ns}/structure_node'
    msgs, expected = scenario()
    answered = {e['t'] for e in expected}
    src = write_bag(tmp_path / 'in', msgs, namespace=base)
    code, _, stderr = run_cli('bag', src, '--out', tmp_path / 'bag_out', '--node', 'structure',
                              '--namespace', base)
    assert code == 0, stderr
    params = tmp_path / 'params.yaml'
    params.write_text('structure_node:\n  ros__parameters:\n    structure.config: six_bar.yaml\n')
    proc = NodeProcess(ns, params, executable='structure_node')
    ros = RosClient('bag_structure_test')
    names = list(structure_node.STRUCTURE_OUTPUTS)
    got: dict[str, list[bytes]] = {name: [] for name in names}
    inboxes: dict[str, Inbox] = {}
    try:
        for name in names:
            inboxes[name] = Inbox()

            def record(msg: Any, name: str = name) -> None:
                got[name].append(bytes(serialize_message(msg)))
                inboxes[name](msg)
            ros.subscribe_callback(Float64MultiArray, f'{base}/{name}', record)
        types = {'poses': PoseArray, 'pose_values': Float64MultiArray,
                 'rest_lengths': Float64MultiArray}
        pubs = {'poses': ros.publisher(PoseArray, f'{base}/poses'),
                'pose_values': ros.publisher(Float64MultiArray, f'{base}/pose_values'),
                'rest_lengths': ros.publisher(Float64MultiArray, f'{base}/rest_lengths',
                                              LATCHED)}
        for pub in pubs.values():
            ros.wait_for_subscribers(pub)
        for name in names:
            ros.wait_for_publishers(f'{base}/{name}')
        ros.wait_for_executor(base)
        count = 0
        for m in msgs:
            if m.t not in answered and m.topic != 'rest_lengths':
                continue  # refused inputs: the bag test above counts them
            raw = bytes(TYPESTORE.serialize_cdr(m.msg, m.msgtype))
            pubs[m.topic].publish(deserialize_message(raw, types[m.topic]))
            if m.t in answered:
                count += 1
                for name in names:
                    inboxes[name].wait_for(count, timeout=20.0)
    finally:
        ros.close()
        proc.stop()
    from_bag: dict[str, list[bytes]] = {name: [] for name in names}
    for topic, _, _, raw in sorted(read_raw(tmp_path / 'bag_out'), key=lambda r: r[1]):
        from_bag[topic[len(base) + 1:]].append(raw)
    def fields(raw: bytes) -> tuple[Any, ...]:
        """A serialized Float64MultiArray's layout and payload bytes (the padding bytes after
        its labels are not part of the message: rclpy leaves them as they were)."""
        msg = TYPESTORE.deserialize_cdr(raw, FMA)
        return (tuple((d.label, d.size, d.stride) for d in msg.layout.dim),
                msg.layout.data_offset, np.asarray(msg.data, dtype='<f8').tobytes())

    for name in names:
        assert len(got[name]) == len(from_bag[name]) == len(expected), name
        for k, (node_raw, bag_raw) in enumerate(zip(got[name], from_bag[name], strict=True)):
            assert fields(node_raw) == fields(bag_raw), f'{name}[{k}]'
