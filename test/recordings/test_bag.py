"""``tensegrity-stiffness bag``: input bags written with rosbags (mcap and sqlite3), the command
run in-process and as a subprocess, the output read back with rosbags and every answer checked
against the library at the rest lengths in force."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from tensegrity_stiffness.cli.progress import ProgressBar
from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.mechanics.interpretation import interpretation_vector
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.recordings import bag

rosbags = pytest.importorskip('rosbags')
from rosbags.rosbag2 import Reader, StoragePlugin, Writer  # noqa: E402
from support import REPO  # noqa: E402
from support.bag_recordings import (  # noqa: E402
    ATOL,
    ATOL_K,
    FMA,
    FRAME,
    NS,
    OUTPUTS,
    POSE,
    T0,
    TYPESTORE,
    In,
    check_output,
    default_model,
    multiarray,
    pose_msg,
    read_bag,
    run_cli,
    scenario,
    screw_stream,
    write_bag,
)


# ------------------------------------------------------------------------------ tests
@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_bag_answers_every_valid_input_like_the_node(tmp_path: Path, storage: str) -> None:
    msgs, expected, rejected = scenario()
    src = write_bag(tmp_path / 'in', msgs, storage)
    out = tmp_path / 'out'
    code, stdout, stderr = run_cli('bag', src, '--out', out, '--json')
    assert code == 0, stderr
    report = json.loads(stdout)
    assert report['storage'] == storage
    with Reader(out) as reader:  # same storage as the input by default
        assert {c.msgtype for c in reader.connections} == {
            'geometry_msgs/msg/WrenchStamped', FMA, 'tensegrity_stiffness/msg/StampedMatrix'}
    assert report['answers'] == len(expected)
    assert report['answered'] == {'screw': 9, 'pose': 3, 're-publish': 2}
    assert report['inputs'] == {'screw': 14, 'pose': 5, 'rest_lengths': 4}
    assert report['rejected'] == rejected
    assert report['written'] == {f'{NS}/{name}': len(expected) for name in OUTPUTS}
    check_output(out, expected)


def test_bag_storage_option_csv_and_text_summary(tmp_path: Path) -> None:
    msgs, expected, rejected = scenario()
    src = write_bag(tmp_path / 'in', msgs, 'mcap')
    out, table = tmp_path / 'out', tmp_path / 'answers.csv'
    code, stdout, stderr = run_cli('bag', src, '--out', out, '--storage', 'sqlite3',
                                   '--csv', table)
    assert code == 0, stderr
    assert (out / 'out.db3').is_file() or list(out.glob('*.db3'))
    check_output(out, expected)
    for kind, n in rejected.items():  # the summary names each kind
        assert f'  {kind}: {n}' in stdout
    assert f'answered {len(expected)} inputs' in stdout
    import csv as csv_module

    with table.open() as f:
        rows = list(csv_module.reader(f))
    header, rows = rows[0], rows[1:]
    model = default_model()
    assert header[:9] == ['log_time_ns', 'source', 'stamp_ns', 'wx', 'wy', 'wz', 'vx', 'vy',
                          'vz']
    assert len(header) == 3 + 6 + 6 + 36 + 36 + model.n_strings
    assert header[-1] == f'tension_{model.string_names[-1]}'
    assert len(rows) == len(expected)
    for row, exp in zip(rows, expected, strict=True):
        assert int(row[0]) == exp['t'] and row[1] == exp['source'] and int(row[2]) == \
            exp['stamp']
        values = np.array(row[3:], dtype=float)
        state = model.with_rest_lengths(exp['rest']).evaluate(exp['xi'])
        np.testing.assert_allclose(values[:6], exp['xi'], rtol=1e-15, atol=1e-15)
        np.testing.assert_allclose(values[6:12], state.wrench, rtol=1e-12, atol=ATOL)
        np.testing.assert_allclose(values[12:48], state.stiffness.ravel(), rtol=1e-12,
                                   atol=ATOL_K)
        np.testing.assert_allclose(values[48:84], state.cartesian_stiffness.ravel(),
                                   rtol=1e-12, atol=ATOL_K)
        np.testing.assert_allclose(values[84:], state.tensions, rtol=1e-12, atol=ATOL)


def test_bag_batches_split_at_rejections_and_rest_length_changes(tmp_path: Path) -> None:
    """Small chunks, a long stream: screws outside the chart and poses between them (whose
    branch depends on the last answered screw) land at chunk boundaries and inside chunks."""
    model = default_model()
    rng = np.random.default_rng(11)
    screws = screw_stream(300, seed=5)
    msgs, expected = [], []
    rest = model.rest_lengths
    last = model.initial_screw
    t = T0
    for i, xi in enumerate(screws):
        t += 1000
        kind = rng.integers(0, 10)
        if kind == 0:  # outside the chart: rejected, the next pose's branch is unchanged
            msgs.append(In('screw', t, multiarray([0, 0, 6.5, 0, 0, 0])))
        elif kind <= 3:  # a pose at theta near pi: the branch matters
            T = exp_se3(xi)
            msgs.append(In('pose', t, pose_msg(T), POSE))
            last = log_se3(T, reference=last)
            expected.append({'source': 'pose', 't': t, 'stamp': t, 'xi': last, 'rest': rest})
        elif kind == 4 and i % 3 == 0:
            rest = model.rest_lengths * (1 + 0.1 * rng.random())
            msgs.append(In('rest_lengths', t, multiarray(rest)))
            expected.append({'source': 're-publish', 't': t, 'stamp': expected[-1]['stamp'],
                             'xi': last, 'rest': rest})
        else:
            msgs.append(In('screw', t, multiarray(xi)))
            last = xi
            expected.append({'source': 'screw', 't': t, 'stamp': t, 'xi': xi, 'rest': rest})
    src = write_bag(tmp_path / 'in', msgs)
    from tensegrity_stiffness.recordings import bag

    summary = bag.process_bag(src, tmp_path / 'out', chunk_size=7)
    assert summary.answers == len(expected)
    check_output(tmp_path / 'out', expected)


def test_bag_namespace_config_and_topics(tmp_path: Path) -> None:
    """Another namespace, a parameter file with another frame id and array limit (the rest
    from the packaged config), and a subset of the outputs."""
    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    frames:\n      link1: base\n'
                      '    limits:\n      max_array_length: 6\n')
    model = default_model()
    xi = screw_stream(2, seed=1)
    msgs = [In('screw', T0, multiarray(xi[0])),
            In('rest_lengths', T0 + 1, multiarray(model.rest_lengths)),  # 12 > 6: rejected
            In('pose', T0 + 2, pose_msg(exp_seq := exp_se3(xi[1]), frame='base'), POSE),
            In('/other/screw', T0 + 3, multiarray(xi[1]))]
    src = write_bag(tmp_path / 'in', msgs, namespace='/robot/j1/stiffness_node')
    code, stdout, stderr = run_cli('bag', src, '--out', tmp_path / 'out', '--config', params,
                                   '--namespace', 'robot/j1/stiffness_node/', '--topics',
                                   'wrench', '/robot/j1/stiffness_node/string_tensions',
                                   '--json')
    assert code == 0, stderr
    report = json.loads(stdout)
    assert report['rejected'] == {'rest_lengths: oversized array': 1}
    got = read_bag(tmp_path / 'out')
    assert [topic for topic, _, _ in got] == [
        '/robot/j1/stiffness_node/wrench', '/robot/j1/stiffness_node/string_tensions'] * 2
    assert got[0][2].header.frame_id == 'base'
    state = model.evaluate(log_se3(exp_seq, reference=xi[0]))
    np.testing.assert_allclose(got[3][2].data, state.tensions, rtol=1e-12)


def test_bag_names_outputs_by_the_node_that_would_publish_them(tmp_path: Path) -> None:
    """#39: inputs read under the twin's name (/twin/sim_node) are answered under the stiffness
    node's (/twin/stiffness_node), not the simulator's; --output-namespace chooses."""
    xi = screw_stream(2, seed=3)
    src = write_bag(tmp_path / 'in', [In('screw', T0, multiarray(xi[0]))],
                    namespace='/twin/sim_node')
    code, stdout, stderr = run_cli('bag', src, '--out', tmp_path / 'out', '--namespace',
                                   '/twin/sim_node', '--json')
    assert code == 0, stderr
    report = json.loads(stdout)
    assert report['output_namespace'] == '/twin/stiffness_node'
    assert {topic for topic, _, _ in read_bag(tmp_path / 'out')} == {
        f'/twin/stiffness_node/{name}' for name in OUTPUTS}
    code, stdout, stderr = run_cli('bag', src, '--out', tmp_path / 'out2', '--namespace',
                                   '/twin/sim_node', '--output-namespace', '/lab/joint',
                                   '--topics', 'wrench', '--json')
    assert code == 0, stderr
    assert [topic for topic, _, _ in read_bag(tmp_path / 'out2')] == ['/lab/joint/wrench']
    assert bag.publisher_prefix('/robot/j1/stiffness_node', 'stiffness') == \
        '/robot/j1/stiffness_node'
    assert bag.publisher_prefix('/a/spine_estimator_node', 'spine') == '/a/spine_node'
    assert bag.publisher_prefix('', 'stiffness') == ''


def test_bag_errors_exit_2_with_one_line(tmp_path: Path) -> None:
    msgs, _, _ = scenario()
    src = write_bag(tmp_path / 'in', msgs)
    other = write_bag(tmp_path / 'other', [In('/camera/points', T0, multiarray([1.0]))])
    (tmp_path / 'plain').mkdir()
    (tmp_path / 'exists').mkdir()
    (tmp_path / 'exists' / 'keep.txt').write_text('not a bag')
    write_bag(tmp_path / 'old_out', [In('screw', T0, multiarray([0.0] * 6))])
    bad_only = write_bag(tmp_path / 'bad_only', [In('screw', T0, multiarray([1.0] * 3))])
    typo = tmp_path / 'typo.yaml'  # #39: not the default joint's 77 N/m for a misspelt key
    typo.write_text('joint:\n  stifness: 120.0\n')
    cases = [
        (['bag', src, '--out', tmp_path / 'o8', '--config', typo],
         'joint.stifness: unknown key (did you mean joint.stiffness?)'),
        (['bag', tmp_path / 'missing', '--out', tmp_path / 'o1'], 'no such rosbag2'),
        (['bag', tmp_path / 'plain', '--out', tmp_path / 'o2'], 'not a rosbag2'),
        (['bag', tmp_path / 'exists' / 'keep.txt', '--out', tmp_path / 'o3'], 'not a rosbag2'),
        (['bag', other, '--out', tmp_path / 'o4'], '/camera/points'),
        (['bag', src, '--out', tmp_path / 'old_out'], 'exists (use --overwrite'),
        (['bag', src, '--out', tmp_path / 'exists', '--overwrite'], 'not a rosbag2; not'),
        (['bag', src, '--out', tmp_path / 'o5', '--storage', 'rosbag1'], 'unknown storage'),
        (['bag', src, '--out', tmp_path / 'o6', '--topics', 'markers'], 'unknown output'),
        (['bag', bad_only, '--out', tmp_path / 'o7'], 'no input could be answered'),
    ]
    for argv, text in cases:
        code, stdout, stderr = run_cli(*argv)
        assert code == 2, (argv, stderr)
        assert stderr.count('\n') == 1 and text in stderr, (argv, stderr)
        assert stdout == ''
    assert 'none of the topics' in run_cli('bag', other, '--out', tmp_path / 'o4')[2]
    assert not (tmp_path / 'o7').exists()
    assert (tmp_path / 'exists' / 'keep.txt').is_file()
    # --overwrite replaces an earlier output bag
    code, _, stderr = run_cli('bag', src, '--out', tmp_path / 'old_out', '--overwrite')
    assert code == 0, stderr
    assert len(read_bag(tmp_path / 'old_out')) == len(OUTPUTS) * 14


def test_bag_command_as_a_subprocess(tmp_path: Path) -> None:
    msgs, expected, rejected = scenario()
    src = write_bag(tmp_path / 'in', msgs, 'sqlite3')
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(
        [str(REPO), os.environ.get('PYTHONPATH', '')]))
    result = subprocess.run([sys.executable, '-m', 'tensegrity_stiffness.cli', 'bag', str(src),
                             '--out', str(tmp_path / 'out'), '--json'],
                            capture_output=True, text=True, env=env, timeout=120, check=False)
    assert result.returncode == 0, result.stderr
    assert result.stderr == ''  # no progress bar when stderr is not a terminal
    assert json.loads(result.stdout)['rejected'] == rejected
    check_output(tmp_path / 'out', expected)
    result = subprocess.run([sys.executable, '-m', 'tensegrity_stiffness.cli', 'bag',
                             str(tmp_path / 'nothing'), '--out', str(tmp_path / 'o')],
                            capture_output=True, text=True, env=env, timeout=120, check=False)
    assert result.returncode == 2
    assert result.stderr.count('\n') == 1 and 'no such rosbag2' in result.stderr


def test_rate_progress_shows_rate_and_eta() -> None:
    import io

    class Tty(io.StringIO):
        def isatty(self) -> bool:
            return True

    stream = Tty()
    progress = ProgressBar('bag', unit='inputs', stream=stream)
    progress(50, 100)
    progress(100, 100)
    text = stream.getvalue()
    last = text.split('\r')[-1]
    assert last.startswith('bag: 100%') and '100/100' in last and 'inputs/s' in last
    assert '<' in last  # elapsed < time left
    assert text.endswith('\n')


# ------------------------------------------------------------------------------ the running node
@pytest.mark.ros
def test_bag_output_equals_the_running_nodes_recorded_output(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """The scenario's inputs sent to the installed node one by one; its outputs recorded by an
    rclpy subscriber writing with rosbags; that recording and the bag command's output of the
    same inputs compared message by message. Stamps: equal where the node copies them (poses,
    re-publishes of poses); the node's time of computation elsewhere, the log time in the bag."""
    pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
    from geometry_msgs.msg import PoseStamped
    from rclpy.serialization import deserialize_message, serialize_message
    from std_msgs.msg import Float64MultiArray
    from support.ros_harness import LATCHED, NodeProcess, RosClient, unique_namespace

    ns = unique_namespace('bag')
    base = f'{ns}/stiffness_node'
    msgs, expected, _ = scenario()
    src = write_bag(tmp_path / 'in', msgs, namespace=base)
    rcl_types = {'screw': Float64MultiArray, 'pose': PoseStamped,
                 'rest_lengths': Float64MultiArray}
    from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES

    out_types = {name: RCLPY_TYPES.classes[t] for name, t in TYPESTORE_NAMES.items()}
    recorded = tmp_path / 'node_out'
    # The installed node with its own sources: this checkout's are left off its PYTHONPATH.
    paths = [p for p in os.environ.get('PYTHONPATH', '').split(os.pathsep)
             if p and Path(p).resolve() not in (REPO, REPO / 'test')]
    with monkeypatch.context() as env:
        env.setenv('PYTHONPATH', os.pathsep.join(paths))
        proc = NodeProcess(ns, REPO / 'config' / 'default_joint.yaml')
    ros = RosClient('bag_test')
    try:
        log_time = [0]
        with Writer(recorded, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            conns = {name: writer.add_connection(f'{base}/{name}', TYPESTORE_NAMES[name],
                                                 typestore=TYPESTORE) for name in OUTPUTS}
            inboxes = {}
            for name in OUTPUTS:
                def record(msg: Any, name: str = name) -> None:
                    writer.write(conns[name], log_time[0], serialize_message(msg))
                inboxes[name] = ros.subscribe(out_types[name], f'{base}/{name}')
                ros.subscribe_callback(out_types[name], f'{base}/{name}', record)
            pubs = {'screw': ros.publisher(Float64MultiArray, f'{base}/screw'),
                    'pose': ros.publisher(PoseStamped, f'{base}/pose'),
                    'rest_lengths': ros.publisher(Float64MultiArray, f'{base}/rest_lengths',
                                                  LATCHED)}
            for pub in pubs.values():
                ros.wait_for_subscribers(pub)
            ros.wait_for_executor(base)
            for name in OUTPUTS:
                ros.wait_for_publishers(f'{base}/{name}')
            answered_times = {e['t'] for e in expected}
            count = 0
            for m in msgs:
                if isinstance(m.msg, bytes):  # undecodable: cannot be sent over ROS
                    continue
                log_time[0] = m.t
                raw = bytes(TYPESTORE.serialize_cdr(m.msg, m.msgtype))
                pubs[m.topic].publish(deserialize_message(raw, rcl_types[m.topic]))
                if m.t in answered_times:
                    count += 1
                    for name in OUTPUTS:
                        inboxes[name].wait_for(count, timeout=10.0)
                elif m.topic == 'rest_lengths':
                    # The node orders inputs per topic only (screws and poses on its fast lane,
                    # rest lengths on the executor): an unanswered state change lands first.
                    time.sleep(0.2)
            time.sleep(0.5)  # nothing more may come
            assert {name: len(inboxes[name]) for name in OUTPUTS} == dict.fromkeys(
                OUTPUTS, len(expected))
    finally:
        ros.close()
        proc.stop()

    code, _, stderr = run_cli('bag', src, '--out', tmp_path / 'bag_out', '--namespace', base)
    assert code == 0, stderr
    # One input's outputs share a log time; the recording holds them in the order its
    # subscriptions' callbacks ran, which the middleware does not fix across topics (a
    # fresh-clone run: string_tensions before stiffness_interpretation): both by (time, topic).
    node_out, bag_out = (sorted(read_bag(path), key=lambda m: (m[1], m[0]))
                         for path in (recorded, tmp_path / 'bag_out'))
    assert len(node_out) == len(bag_out) == len(OUTPUTS) * len(expected)
    for k, ((topic_n, t_n, n), (topic_b, t_b, b)) in enumerate(
            zip(node_out, bag_out, strict=True)):
        exp = expected[k // len(OUTPUTS)]
        assert topic_n == topic_b and t_n == t_b == exp['t'], k
        if topic_b.endswith('/wrench'):
            assert n.header.frame_id == b.header.frame_id == FRAME
            copied = exp['stamp'] != exp['t'] and (exp['source'] == 'pose' or any(
                e['source'] == 'pose' and e['stamp'] == exp['stamp'] for e in expected))
            if copied:
                assert (n.header.stamp.sec, n.header.stamp.nanosec) == (
                    b.header.stamp.sec, b.header.stamp.nanosec)
            vn = [n.wrench.force.x, n.wrench.force.y, n.wrench.force.z,
                  n.wrench.torque.x, n.wrench.torque.y, n.wrench.torque.z]
            vb = [b.wrench.force.x, b.wrench.force.y, b.wrench.force.z,
                  b.wrench.torque.x, b.wrench.torque.y, b.wrench.torque.z]
            np.testing.assert_allclose(vb, vn, rtol=1e-12, atol=ATOL)
        elif topic_b.endswith('_stamped'):
            assert n.header.frame_id == b.header.frame_id == FRAME
            assert (n.row_label, n.column_label, n.rows, n.cols) == (
                b.row_label, b.column_label, b.rows, b.cols)
            np.testing.assert_allclose(b.data, n.data, rtol=1e-12, atol=ATOL_K)
        else:
            assert [(d.label, d.size, d.stride) for d in n.layout.dim] == \
                [(d.label, d.size, d.stride) for d in b.layout.dim]
            assert n.layout.data_offset == b.layout.data_offset
            np.testing.assert_allclose(b.data, n.data, rtol=1e-12, atol=ATOL_K)


TYPESTORE_NAMES = dict(bag.NODE_TOPICS['stiffness'].outputs)


# ------------------------------------------------------------------------------ batched parts
def _rewrite_message_by_message(src: Path, dst: Path, storage: str) -> None:
    """The messages of the bag ``src`` written again one ``Writer.write`` at a time."""
    with Reader(src) as reader, Writer(dst, version=9,
                                       storage_plugin=StoragePlugin[storage.upper()]) as writer:
        conns = {c.id: writer.add_connection(c.topic, c.msgtype, typestore=TYPESTORE)
                 for c in reader.connections}
        for c, t, raw in reader.messages():
            writer.write(conns[c.id], t, raw)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_blocks_are_written_as_rosbags_writes_them_message_by_message(
        tmp_path: Path, storage: str) -> None:
    """Chunks of 333 answers (``write_blocks``) across mcap chunk boundaries (about 1.1 kB per
    input, 1 MiB chunks), two inputs per log time: the bag is byte for byte the one rosbags'
    Writer writes when the messages read back are written again one at a time, in the order
    read (sqlite3: the same messages and metadata read back)."""
    from tensegrity_stiffness.recordings import bag

    screws = screw_stream(2500, seed=9)
    src = write_bag(tmp_path / 'in', [In('screw', T0 + 1000 * (i // 2), multiarray(xi))
                                      for i, xi in enumerate(screws)], storage)
    out, again = tmp_path / 'out', tmp_path / 'again' / 'out'  # same name: same metadata
    bag.process_bag(src, out, chunk_size=333)
    _rewrite_message_by_message(out, again, storage)
    if storage == 'mcap':
        assert (out / 'out.mcap').read_bytes() == (again / 'out.mcap').read_bytes()
    else:
        def raw_messages(path: Path) -> list[tuple[str, int, bytes]]:
            with Reader(path) as reader:
                return [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]

        assert raw_messages(out) == raw_messages(again)
    assert (out / 'metadata.yaml').read_text() == (again / 'metadata.yaml').read_text()


def test_plain_screws_decoded_in_blocks_equal_the_nodes_decoding(tmp_path: Path) -> None:
    """Screws of the plain layout (decoded with frombuffer) and of other layouts (a labelled
    dimension, a data offset; deserialized), NaN and out-of-chart ones among them: the same
    answers and the node's rejection texts."""
    from tensegrity_stiffness.recordings import bag

    types = TYPESTORE.types
    screws = screw_stream(40, seed=4)
    msgs, expected = [], []
    for i, xi in enumerate(screws):
        t = T0 + 1000 * i
        if i % 7 == 3:
            msgs.append(In('screw', t, multiarray([math.inf, *xi[1:]])))
        elif i % 7 == 5:
            msgs.append(In('screw', t, multiarray([0, 0, 6.4, 0, 0, 0])))
        elif i % 5 == 1:
            labelled = multiarray(xi)
            labelled.layout.dim = [types['std_msgs/msg/MultiArrayDimension'](
                label='screw', size=6, stride=6)]
            msgs.append(In('screw', t, labelled))
            expected.append({'source': 'screw', 't': t, 'stamp': t, 'xi': xi,
                             'rest': default_model().rest_lengths})
        elif i % 5 == 2:
            msgs.append(In('screw', t, multiarray([9.0, *xi], data_offset=1)))
            expected.append({'source': 'screw', 't': t, 'stamp': t, 'xi': xi,
                             'rest': default_model().rest_lengths})
        else:
            msgs.append(In('screw', t, multiarray(xi)))
            expected.append({'source': 'screw', 't': t, 'stamp': t, 'xi': xi,
                             'rest': default_model().rest_lengths})
    plain = bytes(TYPESTORE.serialize_cdr(multiarray(screws[0]), FMA))
    assert len(plain) == bag.PLAIN_SCREW_SIZE
    np.testing.assert_array_equal(bag.plain_screw_values([plain])[0], screws[0])
    src = write_bag(tmp_path / 'in', msgs)
    summary = bag.process_bag(src, tmp_path / 'out', chunk_size=8)
    check_output(tmp_path / 'out', expected)
    assert summary.rejected == {'screw: NaN or inf': 6, 'screw: outside the chart': 5}
    assert summary.rejection_examples['screw: NaN or inf'] == 'array contains NaN or inf'
    assert summary.rejection_examples['screw: outside the chart'] == (
        'screw: |omega| = 6.4 rad is outside the chart (must be < 2 pi)')


def test_interpretation_vector_of_a_batch_matches_interpret_stiffness() -> None:
    from tensegrity_stiffness.mechanics.interpretation import interpret_stiffness

    rng = np.random.default_rng(21)
    K = rng.normal(size=(3, 50, 6, 6)) * 10.0 ** rng.uniform(-6, 6, size=(3, 50, 6, 6))
    got = interpretation_vector(K)
    assert got.shape == (3, 50, 16)
    for index in np.ndindex(3, 50):
        it = interpret_stiffness(K[index])
        ref = np.concatenate([it.block_norms, it.column_norms, it.row_norms])
        np.testing.assert_allclose(got[index], ref, rtol=1e-13, atol=0.0)
        np.testing.assert_allclose(got[index], interpretation_vector(K[index]), rtol=1e-14)
    assert interpretation_vector(np.zeros((0, 6, 6))).shape == (0, 16)
    for shape in [(36,), (6, 5), (4, 6, 5)]:
        with pytest.raises(ValueError, match='stiffness must have shape'):
            interpretation_vector(np.zeros(shape))


def test_batched_processing_agrees_with_the_node_functions() -> None:
    from tensegrity_stiffness.nodes import processing

    model = default_model()
    screws = screw_stream(64, seed=8)
    screws[5] = [0, 0, 7.0, 0, 0, 0]
    screws[9] = [0, 0, 2 * math.pi, 0, 0, 0]
    accepted, problems = processing.screw_inputs(screws)
    assert np.flatnonzero(~accepted).tolist() == [5, 9] and sorted(problems) == [5, 9]
    for i, problem in problems.items():
        with pytest.raises(ValueError) as exc:
            processing.screw_input(screws[i])
        assert str(exc.value) == str(problem) and exc.value.kind == problem.kind
    good = screws[accepted]
    batch = processing.joint_outputs_batch(model, good)
    assert processing.finite_rows(batch).all()
    for i, xi in enumerate(good):
        one = processing.joint_outputs(model, xi)
        np.testing.assert_allclose(batch.state.wrench[i], one.state.wrench, atol=ATOL)
        np.testing.assert_allclose(batch.state.stiffness[i], one.state.stiffness, atol=ATOL_K)
        np.testing.assert_allclose(batch.interpretation[i], one.interpretation, atol=ATOL_K)
    unlimited = model_without_max_lengths()  # far out, the tensions overflow
    far = processing.joint_outputs_batch(unlimited, np.array([good[0], [0, 0, 0, 1e300, 0, 0]]))
    assert processing.finite_rows(far).tolist() == [True, False]


def model_without_max_lengths() -> JointModel:
    from tensegrity_stiffness.nodes import parameters

    values = parameters.defaults(parameters.STIFFNESS_NODE_PARAMETERS)
    values['joint.max_lengths'] = []
    return parameters.joint_node_settings(values).model


def test_non_finite_result_splits_the_chunk_with_the_nodes_message(tmp_path: Path) -> None:
    """A screw whose outputs overflow (no max lengths): rejected with the text of the node's
    publisher check, the inputs around it answered, a pose after it on the branch of the last
    answer."""
    from tensegrity_stiffness.recordings import bag

    params = tmp_path / 'params.yaml'
    params.write_text('joint:\n  max_lengths: []\n')
    model = model_without_max_lengths()
    screws = screw_stream(6, seed=12)
    msgs = [In('screw', T0 + i, multiarray(xi)) for i, xi in enumerate(screws[:3])]
    msgs.append(In('screw', T0 + 3, multiarray([0, 0, 0, 1e300, 0, 0])))
    T = exp_se3(screws[3])
    msgs.append(In('pose', T0 + 4, pose_msg(T), POSE))
    msgs += [In('screw', T0 + 5 + i, multiarray(xi)) for i, xi in enumerate(screws[4:])]
    src = write_bag(tmp_path / 'in', msgs)
    summary = bag.process_bag(src, tmp_path / 'out', config_path=params)
    assert summary.rejected == {'screw: non-finite result': 1}
    assert summary.rejection_examples['screw: non-finite result'] == \
        'wrench contains NaN or inf'
    got = read_bag(tmp_path / 'out')
    answered = [e for e in got if e[0].endswith('/wrench')]
    assert [t for _, t, _ in answered] == [T0, T0 + 1, T0 + 2, T0 + 4, T0 + 5, T0 + 6]
    xi_pose = log_se3(T, reference=screws[2])
    tensions = [e[2].data for e in got if e[0].endswith('/string_tensions')]
    np.testing.assert_allclose(tensions[3], model.evaluate(xi_pose).tensions, rtol=1e-12,
                               atol=ATOL)


def test_settings_come_from_the_parameter_table_and_ignore_undeclared_names(
        tmp_path: Path) -> None:
    from tensegrity_stiffness.nodes import parameters
    from tensegrity_stiffness.recordings import bag

    params = tmp_path / 'params.yaml'
    params.write_text('/**:\n  ros__parameters:\n    use_sim_time: false\n'
                      '    qos_overrides:\n      /parameter_events:\n        publisher:\n'
                      '          depth: 1000\n'
                      '    frames:\n      link1: base\n    joint:\n      stiffness: [80.0]\n')
    settings = bag.node_settings(params)
    assert settings.link1_frame == 'base'
    np.testing.assert_array_equal(settings.model.k, np.full(12, 80.0))
    values = parameters.values_from_config(params, parameters.STIFFNESS_NODE_PARAMETERS)
    assert 'use_sim_time' not in values and values['frames.link1'] == 'base'
    default = bag.node_settings(None)
    assert default.max_array_length == 1024 and default.link1_frame == FRAME
    np.testing.assert_array_equal(default.model.rest_lengths, default_model().rest_lengths)
    params.write_text('frames:\n  link1: 3\n')
    with pytest.raises(bag.BagError, match=r'config .*frames\.link1 must be a string'):
        bag.node_settings(params)
    params.write_text('limits:\n  max_array_length: 2\n')
    with pytest.raises(bag.BagError, match=r'limits\.max_array_length'):
        bag.node_settings(params)


def test_single_threaded_blas_holds_blas_to_one_thread_and_restores_it() -> None:
    from threadpoolctl import threadpool_info

    np.ones((64, 64)) @ np.ones((64, 64))  # numpy's BLAS is loaded
    before = [p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas']
    assert before, 'no BLAS library found by threadpoolctl'
    with bag.single_threaded_blas():
        assert all(p['num_threads'] == 1 for p in threadpool_info() if p['user_api'] == 'blas')
    after = [p['num_threads'] for p in threadpool_info() if p['user_api'] == 'blas']
    assert after == before
