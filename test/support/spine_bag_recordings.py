"""Recordings for ``spine_node``'s bag command: input bags, a scenario of every input kind
(with its expected answers and rejections) and the check of an output bag against the
library."""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from tensegrity_stiffness import cli
from tensegrity_stiffness.geometry.quaternion import quaternion_to_rotation, rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.nodes import layouts, spine_processing
from tensegrity_stiffness.recordings import bag
from tensegrity_stiffness.ros import conversions

NS = '/spine_node'
TYPESTORE = bag.jazzy_typestore()  # with the package's StampedMatrix
FMA = 'std_msgs/msg/Float64MultiArray'
POSE_ARRAY = 'geometry_msgs/msg/PoseArray'
T0 = 1_700_000_000_000_000_000  # log time of the first message (ns)
#: Screws from poses differ from the screws they were built from by the round trip
#: exp -> quaternion -> log (~1e-15); K entries are up to ~1e3.
ATOL = 1e-9

SETTINGS = bag.spine_settings()
CHAIN = SETTINGS.chain
N = CHAIN.n_joints
BASE = SETTINGS.base_frame


@dataclass
class In:
    """One input message: topic (relative to the namespace), log time, message or raw bytes."""

    topic: str
    t: int
    msg: Any
    msgtype: str = ''

    def __post_init__(self) -> None:
        self.msgtype = self.msgtype or (POSE_ARRAY if self.topic == 'poses' else FMA)


def multiarray(values: Iterable[float]) -> Any:
    types = TYPESTORE.types
    return types[FMA](layout=types['std_msgs/msg/MultiArrayLayout'](dim=[], data_offset=0),
                      data=np.asarray(list(values), dtype=np.float64))


def poses_msg(screws: np.ndarray, stamp_ns: int = 0, frame: str = '',
              quaternions: Sequence[Sequence[float]] | None = None) -> Any:
    """A PoseArray of the transforms exp(screws[i]) (or these quaternions)."""
    types = TYPESTORE.types
    poses = []
    for i, xi in enumerate(screws):
        T = exp_se3(xi)
        q = rotation_to_quaternion(T[:3, :3]) if quaternions is None else quaternions[i]
        poses.append(types['geometry_msgs/msg/Pose'](
            position=types['geometry_msgs/msg/Point'](x=float(T[0, 3]), y=float(T[1, 3]),
                                                      z=float(T[2, 3])),
            orientation=types['geometry_msgs/msg/Quaternion'](
                x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))))
    return types[POSE_ARRAY](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=stamp_ns // 1_000_000_000,
                                                       nanosec=stamp_ns % 1_000_000_000),
            frame_id=frame),
        poses=poses)


def write_bag(path: Path, messages: Sequence[In], storage: str = 'mcap',
              namespace: str = NS) -> Path:
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()]) as writer:
        connections: dict[tuple[str, str], Any] = {}
        for m in messages:
            key = (f'{namespace}/{m.topic}', m.msgtype)
            if key not in connections:
                connections[key] = writer.add_connection(*key, typestore=TYPESTORE)
            raw = m.msg if isinstance(m.msg, bytes) else bytes(
                TYPESTORE.serialize_cdr(m.msg, m.msgtype))
            writer.write(connections[key], m.t, raw)
    return path


def read_raw(path: Path) -> list[tuple[str, int, str, bytes]]:
    with Reader(path) as reader:
        return [(c.topic, t, c.msgtype, bytes(raw)) for c, t, raw in reader.messages()]


def run_cli(*args: Any) -> tuple[int, str, str]:
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()


def screws_near_rest(k: int, seed: int = 0) -> list[np.ndarray]:
    """k spine configurations (N, 6) near the vertebrae's unloaded equilibrium (seeded)."""
    rng = np.random.default_rng(seed)
    xi0 = np.array([model.initial_screw for model in CHAIN.joints])
    scale = np.array([1, 1, 1, 0.02, 0.02, 0.02]) * 0.05
    return [xi0 + scale * rng.standard_normal((N, 6)) for _ in range(k)]


# ------------------------------------------------------------------------------ scenario
def scenario() -> tuple[list[In], list[dict[str, Any]], dict[str, int]]:
    """Inputs of every kind, good and bad, and the answers the node gives (library)."""
    xs = screws_near_rest(6)
    rest0 = [model.rest_lengths for model in CHAIN.joints]
    rest1 = [r * (1.0 + 0.02 * (i + 1)) for i, r in enumerate(rest0)]
    rest2 = [r * 0.99 for r in rest0]
    messages: list[In] = []
    expected: list[dict[str, Any]] = []
    clock = [T0]

    def tick() -> int:
        clock[0] += 1_000_000
        return clock[0]

    def answer(source: str, xi: np.ndarray, t: int, stamp: int, rest: list) -> None:
        expected.append({'source': source, 'screws': xi, 't': t, 'stamp': stamp,
                         'rest': rest})

    bad_omega = xs[0].copy()
    bad_omega[2, :3] *= 7.0 / np.linalg.norm(bad_omega[2, :3])
    nan_screws = xs[0].ravel().copy()
    nan_screws[8] = np.nan
    zero_q = [[0.0, 0.0, 0.0, 1.0]] * N
    zero_q[3] = [0.0, 0.0, 0.0, 0.0]
    negative = np.concatenate(rest0)
    negative[13] = -0.01

    # Before any answer: a rest-length change re-publishes nothing.
    messages.append(In('rest_lengths', t := tick(), multiarray(np.concatenate(rest2))))
    rest = rest2
    messages.append(In('screws', t := tick(), multiarray(xs[0].ravel())))
    answer('screws', xs[0], t, t, rest)
    messages.append(In('screws', tick(), multiarray(xs[0].ravel()[:-6])))       # wrong length
    messages.append(In('screws', tick(), multiarray(nan_screws)))               # NaN
    messages.append(In('screws', tick(), multiarray(bad_omega.ravel())))        # chart
    messages.append(In('screws', tick(), multiarray(np.zeros(1030))))           # oversized
    messages.append(In('screws', tick(), b'\x00\x01\x00\x00\xff'))              # undecodable
    messages.append(In('screws', tick(), poses_msg(xs[1]), POSE_ARRAY))         # wrong type
    stamp = 1_600_000_000_123_456_789
    messages.append(In('poses', t := tick(), poses_msg(xs[1], stamp_ns=stamp)))
    answer('poses', xs[1], t, stamp, rest)
    messages.append(In('poses', t := tick(), poses_msg(xs[2], frame=BASE)))     # zero stamp
    answer('poses', xs[2], t, t, rest)
    messages.append(In('poses', tick(), poses_msg(xs[3][:-1])))                 # N - 1 poses
    messages.append(In('poses', tick(), poses_msg(xs[3], frame='elsewhere')))   # frame_id
    messages.append(In('poses', tick(), poses_msg(xs[3], quaternions=zero_q)))  # quaternion
    messages.append(In('rest_lengths', tick(), multiarray(np.concatenate(rest1)[:-1])))
    messages.append(In('rest_lengths', tick(), multiarray(negative)))
    messages.append(In('rest_lengths', t := tick(), multiarray(np.concatenate(rest1))))
    rest = rest1
    answer('re-publish', xs[2], t, expected[-1]['stamp'], rest)
    messages.append(In('screws', t := tick(), multiarray(xs[4].ravel())))
    answer('screws', xs[4], t, t, rest)
    messages.append(In('poses', t := tick(), poses_msg(xs[5], stamp_ns=stamp + 7)))
    answer('poses', xs[5], t, stamp + 7, rest)
    rejected = {'screws: wrong length': 1, 'screws: NaN or inf': 1,
                'screws: outside the chart': 1, 'screws: oversized array': 1,
                'screws: undecodable': 1, 'screws: wrong message type': 1,
                'poses: wrong length': 1, 'poses: wrong frame_id': 1,
                'poses: bad quaternion': 1, 'rest_lengths: wrong length': 1,
                'rest_lengths: bad rest lengths': 1}
    return messages, expected, rejected


def dims_of(msg: Any) -> list[tuple[str, int, int]]:
    return [(d.label, int(d.size), int(d.stride)) for d in msg.layout.dim]


#: The layouts of the node's messages (rclpy, tensegrity_stiffness.ros.conversions) and,
#: independently, from the labels.
NODE_MESSAGES = conversions.SpineOutputMessages(N)
EXPECTED_DIMS = {
    'joint_wrenches': [(layouts.JOINTS_LABEL, N, 6 * N), (layouts.WRENCH_LABEL, 6, 6)],
    'joint_stiffness': [(layouts.JOINTS_LABEL, N, 36 * N),
                        (layouts.STIFFNESS_ROW_LABEL, 6, 36),
                        (layouts.STIFFNESS_COL_LABEL, 6, 6)],
    'joint_cartesian_stiffness': [(layouts.JOINTS_LABEL, N, 36 * N),
                                  (layouts.STIFFNESS_ROW_LABEL, 6, 36),
                                  (layouts.CARTESIAN_STIFFNESS_COL_LABEL, 6, 6)],
    'tip_stiffness': [(layouts.TIP_STIFFNESS_LABELS['tool'][0], 6, 36),
                      (layouts.TIP_STIFFNESS_LABELS['tool'][1], 6, 6)],
    'tip_stiffness_base': [(layouts.TIP_STIFFNESS_LABELS['base'][0], 6, 36),
                           (layouts.TIP_STIFFNESS_LABELS['base'][1], 6, 6)],
}
TYPES = dict(bag.NODE_TOPICS['spine'].outputs)
#: Every output of the spine node (the arrays and stamped messages, then the stamped matrices).
ALL_OUTPUTS = tuple(TYPES)


def check_output(out: Path, expected: list[dict[str, Any]], names: Sequence[str] =
                 ALL_OUTPUTS, namespace: str = NS) -> None:
    """Every output message of ``out`` against the library's answer to its input."""
    by_topic: dict[str, list[tuple[int, Any]]] = {}
    for topic, t, msgtype, raw in read_raw(out):
        name = topic[len(namespace) + 1:]
        assert topic == f'{namespace}/{name}' and msgtype == TYPES[name]
        by_topic.setdefault(name, []).append((t, TYPESTORE.deserialize_cdr(raw, msgtype)))
    assert sorted(by_topic) == sorted(names)
    for name in names:
        got = by_topic[name]
        assert len(got) == len(expected), name
        k = ALL_OUTPUTS.index(name)
        for (t, msg), e in zip(got, expected, strict=True):
            assert t == e['t']
            outputs = spine_processing.spine_outputs(CHAIN, e['screws'], e['rest'])
            value = spine_processing.output_arrays(outputs)[NODE_MESSAGES.array_index[k]]
            if name == 'tip_pose':
                p, q = msg.pose.position, msg.pose.orientation
                np.testing.assert_allclose([p.x, p.y, p.z], value[:3, 3], atol=ATOL, rtol=0)
                np.testing.assert_allclose(quaternion_to_rotation([q.x, q.y, q.z, q.w]),
                                           value[:3, :3], atol=ATOL, rtol=0)
            elif name == 'tip_wrench':
                f, m = msg.wrench.force, msg.wrench.torque
                np.testing.assert_allclose([f.x, f.y, f.z, m.x, m.y, m.z], value,
                                           atol=ATOL, rtol=0)
            elif TYPES[name] == layouts.STAMPED_MATRIX:
                of = layouts.SPINE_STAMPED_OUTPUTS[name]
                assert [(msg.row_label, msg.rows), (msg.column_label, msg.cols)] == [
                    (label, size) for label, size, _ in EXPECTED_DIMS[of]]
                assert msg.header.frame_id == (bag.spine_settings().tool_frame
                                               if name == 'tip_stiffness_stamped' else BASE)
                stamp = msg.header.stamp
                assert stamp.sec * 1_000_000_000 + stamp.nanosec == e['stamp']
                np.testing.assert_allclose(msg.data, value.ravel(), atol=ATOL, rtol=1e-12)
            else:
                assert dims_of(msg) == EXPECTED_DIMS[name] == dims_of(NODE_MESSAGES.messages()[k])
                assert msg.layout.data_offset == 0
                np.testing.assert_allclose(msg.data, value.ravel(), atol=ATOL, rtol=1e-12)
            if name in ('tip_pose', 'tip_wrench'):
                assert msg.header.frame_id == BASE
                stamp = msg.header.stamp
                assert stamp.sec * 1_000_000_000 + stamp.nanosec == e['stamp']
