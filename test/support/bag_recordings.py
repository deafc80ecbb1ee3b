"""Recordings for ``stiffness_node``'s bag command: input bags written with rosbags, a scenario
of every input kind (with its expected answers and rejections) and the check of an output bag
against the library."""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.rosbag2 import Reader, StoragePlugin, Writer

from tensegrity_stiffness import cli, config
from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.mechanics.interpretation import interpretation_vector
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import layouts
from tensegrity_stiffness.recordings.bag import jazzy_typestore

NS = '/stiffness_node'
TYPESTORE = jazzy_typestore()  # with the package's StampedMatrix
FMA = 'std_msgs/msg/Float64MultiArray'
POSE = 'geometry_msgs/msg/PoseStamped'
FRAME = 'tensegrity_link1'
T0 = 1_700_000_000_000_000_000  # log time of the first message (ns)
#: Batched and single-screw evaluations differ by rounding (summation order): absolute
#: tolerances for wrench and tensions (N, N m; |F| ~ 1) and for K, K_c (entries up to ~500).
ATOL = 1e-13
ATOL_K = 1e-10


def default_model() -> JointModel:
    return JointModel.from_yaml(config.packaged_config_path())


# ------------------------------------------------------------------------------ input bags
@dataclass
class In:
    """One input message: topic ('screw', 'pose', 'rest_lengths' or a full name), log time,
    and the message (a rosbags message) or raw bytes."""

    topic: str
    t: int
    msg: Any
    msgtype: str = FMA


def multiarray(values: Iterable[float], data_offset: int = 0) -> Any:
    types = TYPESTORE.types
    return types[FMA](layout=types['std_msgs/msg/MultiArrayLayout'](dim=[],
                                                                    data_offset=data_offset),
                      data=np.asarray(list(values), dtype=np.float64))


def pose_msg(T: np.ndarray, stamp_ns: int = 0, frame: str = FRAME,
             quaternion: Sequence[float] | None = None) -> Any:
    types = TYPESTORE.types
    q = rotation_to_quaternion(T[:3, :3]) if quaternion is None else quaternion
    return types[POSE](
        header=types['std_msgs/msg/Header'](
            stamp=types['builtin_interfaces/msg/Time'](sec=stamp_ns // 1_000_000_000,
                                                       nanosec=stamp_ns % 1_000_000_000),
            frame_id=frame),
        pose=types['geometry_msgs/msg/Pose'](
            position=types['geometry_msgs/msg/Point'](x=float(T[0, 3]), y=float(T[1, 3]),
                                                      z=float(T[2, 3])),
            orientation=types['geometry_msgs/msg/Quaternion'](
                x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3]))))


def write_bag(path: Path, messages: Sequence[In], storage: str = 'mcap',
              namespace: str = NS) -> Path:
    """A rosbag2 with ``messages`` (one connection per topic and type)."""
    with Writer(path, version=9, storage_plugin=StoragePlugin[storage.upper()]) as writer:
        connections: dict[tuple[str, str], Any] = {}
        for m in messages:
            topic = m.topic if m.topic.startswith('/') else f'{namespace}/{m.topic}'
            key = (topic, m.msgtype)
            if key not in connections:
                connections[key] = writer.add_connection(topic, m.msgtype, typestore=TYPESTORE)
            raw = m.msg if isinstance(m.msg, bytes) else bytes(
                TYPESTORE.serialize_cdr(m.msg, m.msgtype))
            writer.write(connections[key], m.t, raw)
    return path


def read_bag(path: Path) -> list[tuple[str, int, Any]]:
    """(topic, log time, deserialized message) of every message, in log-time order."""
    with Reader(path) as reader:
        return [(c.topic, t, TYPESTORE.deserialize_cdr(raw, c.msgtype))
                for c, t, raw in reader.messages()]


def screw_stream(n: int, seed: int = 0, scale: float = 0.05) -> np.ndarray:
    """n screws near the default joint's unloaded equilibrium (seeded)."""
    rng = np.random.default_rng(seed)
    xi0 = default_model().initial_screw
    return xi0 + scale * rng.standard_normal((n, 6)) * np.array([1, 1, 1, 0.02, 0.02, 0.02])


# ------------------------------------------------------------------------------ the scenario
def scenario() -> tuple[list[In], list[dict[str, Any]], dict[str, int]]:
    """Inputs with screws, poses, rest-length changes and one bad message of each kind; the
    expected answers (source, log time, stamp, screw, rest lengths in force) computed from the
    library the way the node answers; the expected rejection counts."""
    model = default_model()
    n = model.n_strings
    rest0 = model.rest_lengths.copy()
    rest1 = rest0 * 1.05
    screws = screw_stream(12, seed=3)
    msgs: list[In] = []
    expected: list[dict[str, Any]] = []
    t = T0
    rest = rest0

    def tick() -> int:
        nonlocal t
        t += 1_000_000  # 1 ms
        return t

    last: tuple[np.ndarray, int] | None = None

    def answer(source: str, xi: np.ndarray, log_time: int, stamp: int) -> None:
        nonlocal last
        expected.append({'source': source, 't': log_time, 'stamp': stamp, 'xi': xi.copy(),
                         'rest': rest.copy()})
        last = (xi.copy(), stamp)

    for xi in screws[:4]:
        msgs.append(In('screw', tick(), multiarray(xi)))
        answer('screw', xi, t, t)
    # a pose with a stamp, on the branch nearest the last screw
    T = exp_se3(screws[4])
    msgs.append(In('pose', tick(), pose_msg(T, stamp_ns=T0 - 5), POSE))
    answer('pose', log_se3(T, reference=last[0]), t, T0 - 5)
    # a pose without a stamp and without a frame id: stamped with its log time
    T = exp_se3(screws[5])
    msgs.append(In('pose', tick(), pose_msg(T, frame=''), POSE))
    answer('pose', log_se3(T, reference=last[0]), t, t)
    # bad messages of each kind
    bad = [
        In('screw', tick(), multiarray([0.1] * 5)),                        # wrong length
        In('screw', tick(), multiarray([0.1, math.nan, 0, 0, 0, 0])),      # NaN
        In('screw', tick(), multiarray([7.0, 0, 0, 0, 0, 0])),             # outside the chart
        In('screw', tick(), multiarray([0.0] * 2000)),                     # oversized
        In('pose', tick(), pose_msg(np.eye(4), quaternion=[0, 0, 0, 2.0]), POSE),  # quaternion
        In('pose', tick(), pose_msg(np.eye(4), frame='world'), POSE),      # wrong frame id
        In('rest_lengths', tick(), multiarray([-0.01] * n)),               # rest lengths <= 0
        In('rest_lengths', tick(), multiarray([0.03] * (n - 1))),          # wrong length
        In('screw', tick(), b'\x00\x01\x00\x00\x07'),                     # undecodable
    ]
    msgs += bad
    # a screw between the bad ones, then new rest lengths: re-publish of the last answer
    msgs.append(In('screw', tick(), multiarray(screws[6])))
    answer('screw', screws[6], t, t)
    rest = rest1
    msgs.append(In('rest_lengths', tick(), multiarray(rest1)))
    answer('re-publish', last[0], t, last[1])
    for xi in screws[7:10]:
        msgs.append(In('screw', tick(), multiarray(xi)))
        answer('screw', xi, t, t)
    # a pose after the change: reference the last screw
    T = exp_se3(screws[10])
    msgs.append(In('pose', tick(), pose_msg(T, stamp_ns=T0 + 123_456_789), POSE))
    answer('pose', log_se3(T, reference=last[0]), t, T0 + 123_456_789)
    # back to the first rest lengths, then a screw logged at the same time as another
    rest = rest0
    msgs.append(In('rest_lengths', tick(), multiarray(rest0)))
    answer('re-publish', last[0], t, last[1])
    msgs.append(In('screw', tick(), multiarray(screws[11])))
    answer('screw', screws[11], t, t)
    rejected = {'screw: wrong length': 1, 'screw: NaN or inf': 1, 'screw: outside the chart': 1,
                'screw: oversized array': 1, 'screw: undecodable': 1,
                'pose: bad quaternion': 1, 'pose: wrong frame_id': 1,
                'rest_lengths: bad rest lengths': 1, 'rest_lengths: wrong length': 1}
    return msgs, expected, rejected


def check_output(out: Path, expected: list[dict[str, Any]], frame: str = FRAME,
                 namespace: str = NS) -> None:
    """Every output message of ``out`` against the library, in order."""
    model = default_model()
    got = read_bag(out)
    names = [f'{namespace}/{name}' for name in OUTPUTS]
    n = len(OUTPUTS)
    assert len(got) == n * len(expected)
    for k, exp in enumerate(expected):
        group = got[n * k: n * k + n]
        assert [topic for topic, _, _ in group] == names
        assert all(t == exp['t'] for _, t, _ in group)
        m = model.with_rest_lengths(exp['rest'])
        state = m.evaluate(exp['xi'])
        wrench, K, Kc, tensions, interp, K_stamped, Kc_stamped = (msg for _, _, msg in group)
        for stamped, array in ((K_stamped, K), (Kc_stamped, Kc)):  # #39: stamped like the wrench
            assert stamped.header.frame_id == frame
            assert (stamped.header.stamp.sec, stamped.header.stamp.nanosec) == (
                wrench.header.stamp.sec, wrench.header.stamp.nanosec)
            assert [stamped.row_label, stamped.column_label] == [d.label for d in
                                                                 array.layout.dim]
            assert (stamped.rows, stamped.cols) == (6, 6)
            np.testing.assert_array_equal(stamped.data, array.data)
        assert wrench.header.frame_id == frame
        assert wrench.header.stamp.sec * 1_000_000_000 + wrench.header.stamp.nanosec == \
            exp['stamp']
        w = wrench.wrench
        got_w = [w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y, w.torque.z]
        np.testing.assert_allclose(got_w, state.wrench, rtol=1e-12, atol=ATOL)
        check_layout(K, layouts.matrix_dims(6, 6, layouts.STIFFNESS_ROW_LABEL,
                                            layouts.STIFFNESS_COL_LABEL))
        check_layout(Kc, layouts.matrix_dims(6, 6, layouts.STIFFNESS_ROW_LABEL,
                                             layouts.CARTESIAN_STIFFNESS_COL_LABEL))
        check_layout(tensions, layouts.vector_dims(m.n_strings,
                                                   layouts.tensions_label(m.string_names)))
        check_layout(interp, layouts.vector_dims(layouts.INTERPRETATION_SIZE,
                                                 layouts.INTERPRETATION_LABEL))
        np.testing.assert_allclose(K.data, state.stiffness.ravel(), rtol=1e-12,
                                   atol=ATOL_K)
        np.testing.assert_allclose(Kc.data, state.cartesian_stiffness.ravel(), rtol=1e-12,
                                   atol=ATOL_K)
        np.testing.assert_allclose(tensions.data, state.tensions, rtol=1e-12, atol=ATOL)
        np.testing.assert_allclose(interp.data, interpretation_vector(state.stiffness),
                                   rtol=1e-12, atol=ATOL_K)


OUTPUTS = ('wrench', 'stiffness', 'cartesian_stiffness', 'string_tensions',
           'stiffness_interpretation', 'stiffness_stamped', 'cartesian_stiffness_stamped')


def check_layout(msg: Any, dims: list[tuple[str, int, int]]) -> None:
    assert [(d.label, d.size, d.stride) for d in msg.layout.dim] == dims
    assert msg.layout.data_offset == 0


def run_cli(*args: str) -> tuple[int, str, str]:
    """``cli.main`` in-process with its stdout and stderr."""
    import contextlib
    import io

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main([str(a) for a in args])
    return code, out.getvalue(), err.getvalue()
