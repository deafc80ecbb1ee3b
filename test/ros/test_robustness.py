"""stiffness_node under malformed input, load, restarts and run-time reconfiguration.

Each test starts the installed node as its own process (real middleware) and counts what comes
back: outputs are matched by value to the library's answer for each valid input, so a message for
an invalid input, a torn or a wrong output cannot hide. The full-size runs with the figures are
``bench/fuzz_node.py``, ``bench/burst_latency.py`` and ``bench/soak.py``.
"""

from __future__ import annotations

import contextlib
import math
import os
import re
import statistics
import threading
import time

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rcl_interfaces.srv import GetParameters, SetParameters, SetParametersAtomically  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.qos import DurabilityPolicy, ReliabilityPolicy  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support import fuzz_inputs as fi  # noqa: E402
from support.ros_harness import (  # noqa: E402
    LATCHED,
    NodeFuzzer,
    NodeProcess,
    RosClient,
    answer_every_output,
    percentile,
    reliable_qos,
    unique_namespace,
)

from tensegrity_stiffness import config  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.ros import conversions  # noqa: E402

CONFIG = fi.CONFIG
#: Size of the in-suite fuzz (the bench runs >= 100,000 messages and 10,000 requests).
FUZZ_MESSAGES = 6000
FUZZ_REQUESTS = 1500
MB = 1024 * 1024


@pytest.fixture(scope='module')
def model() -> JointModel:
    return JointModel.from_yaml(CONFIG)


#: Node arguments of the counting tests: an output history deep enough that a client stalled by
#: a loaded machine loses nothing (the node's default, 100, is 100 ms at 1 kHz).
DEEP_NODE = ['-p', 'qos.depth:=1000']
#: The torn-state test: 5 s of its 1 kHz stream. On 2 cores its client (three output topics)
#: and the node together fall up to 1 s behind during the switches; a history shorter than the
#: lag loses screws, which says nothing about torn state.
STREAM_DEPTH = 5000
STREAM = reliable_qos(STREAM_DEPTH)
#: The torn-state stream: at least this many screws at 1 kHz, on until this many switches of the
#: whole parameter set were acknowledged (about 20 in 4 s on a quiet machine), at most this many.
TORN_SCREWS = 4000
TORN_SWITCHES = 10
TORN_MAX_SCREWS = 12000


@contextlib.contextmanager
def _running_node(extra_args: list[str]):
    """A fresh node process and a client; the node must exit cleanly (code 0) at the end."""
    ns = unique_namespace('robust')
    proc = NodeProcess(ns, CONFIG, extra_args=extra_args)
    ros = None
    try:
        ros = RosClient('robust_test')
        yield proc, ros, f'{ns}/stiffness_node'
    finally:  # also when the test failed: no node outlives its test
        if ros is not None:
            ros.close()
        alive = proc.alive()
        code = proc.stop()
    assert alive, f'the node died:\n{proc.log()[-3000:]}'
    assert code == 0, f'node exit code {code}:\n{proc.log()[-3000:]}'


@pytest.fixture
def node():
    with _running_node(DEEP_NODE) as running:
        yield running


@pytest.fixture
def light_node():
    """Markers at 30 Hz instead of one per input: at 1 kHz they take half of the node's CPU,
    which on 2 cores (node, client, solver) leaves no headroom for a latency bound."""
    with _running_node([*DEEP_NODE, '-p', 'markers.max_rate:=30.0']) as running:
        yield running


def _fuzzer(proc, ros, base, model, **kw) -> NodeFuzzer:
    return NodeFuzzer(ros, proc, base, fi.TopicOracle(model), fi.planar_from_config(), **kw)


def _warm_up(fuzzer: NodeFuzzer, inputs: fi.InputFuzzer, n: int = 200) -> None:
    """The node answers this client (:meth:`NodeFuzzer.prime`), then ``n`` valid screws."""
    fuzzer.prime(iter(inputs.valid_screw_case, None))
    fuzzer.run_topics(inputs.valid_screw_case() for _ in range(n))


def _internal_errors(log: str) -> list[str]:
    return [line for line in log.splitlines() if 'internal error' in line or 'Traceback' in line]


def test_generated_inputs_agree_with_the_library(model):
    """No ROS: every input built to be invalid is invalid for the library (the oracle), and the
    valid anchors are valid; so the counts of the fuzz below mean what they say."""
    inputs = fi.InputFuzzer(model, fi.planar_from_config(), seed=99, oversized_every=50)
    oracle = fi.TopicOracle(model)
    kinds = set()
    for case in inputs.topic_cases(20_000):
        before = oracle.model
        out = oracle.predict(case, fi.to_message(case))
        kinds.add(f'{case.target}/{case.kind}')
        if case.must_reject:
            assert out is None and oracle.model is before, (case.target, case.kind)
        if case.kind == 'valid' and case.target == 'screw':
            assert out is not None
    planar = fi.planar_from_config()
    for case in inputs.service_cases(5_000):
        kinds.add(f'{case.target}/{case.kind}')
        if case.target == 'equilibrium':
            assert (fi.equilibrium_refusal(model, case) is not None) == case.must_reject, case
        elif case.must_reject:
            with pytest.raises(ValueError):
                if case.target == 'forward':
                    planar.forward(case.payload['L3'], case.payload['theta1'])
                else:
                    planar.inverse(case.payload['x'], case.payload['y'])
    for expected in ('screw/1000000 values', 'rest_lengths/1000000 values', 'screw/nan',
                     'screw/omega=2pi', 'pose/zero quaternion', 'pose/non-unit quaternion',
                     'pose/nan quaternion', 'rest_lengths/negative', 'rest_lengths/zero',
                     'forward/singular iii', 'forward/singular iv', 'forward/singular v',
                     'inverse/fold circle', 'equilibrium/wrench 1e308', 'equilibrium/all slack'):
        assert expected in kinds, expected


@pytest.mark.slow
def test_fuzz_every_input_publishes_nothing_wrong(node, model, record_property):
    """Hostile input on every subscription and service, valid input interleaved and checked
    against the library: 0 crashes, 0 publications for invalid input, 0 wrong answers."""
    proc, ros, base = node
    inputs = fi.InputFuzzer(model, fi.planar_from_config(), seed=2024, oversized_every=300)
    fuzzer = _fuzzer(proc, ros, base, model)
    _warm_up(fuzzer, inputs)
    rss_before = proc.rss_bytes()
    start = time.monotonic()
    fuzzer.run_topics(inputs.topic_cases(FUZZ_MESSAGES))
    fuzzer.run_services(inputs.service_cases(FUZZ_REQUESTS), inputs.screw_cases(10**9))
    figures = fuzzer.finish()
    figures['seconds'] = round(time.monotonic() - start, 1)
    figures['rss before [MB]'] = round(rss_before / MB, 1)
    figures['rss after [MB]'] = round(proc.rss_bytes() / MB, 1)
    for key, value in figures.items():
        record_property(key, value)
    print('\nshortened fuzz:', figures)
    assert figures['node alive'], proc.log()[-3000:]
    assert figures['generator errors'] == [], figures['generator errors']
    assert figures['wrong publications'] == 0, figures['wrong examples']
    assert figures['missing answers'] == 0 and figures['sync timeouts'] == 0, (
        figures['missing inputs'], figures, proc.log()[-3000:])
    assert figures['wrong answers'] == 0, figures['wrong answer examples']
    assert figures['messages'] >= FUZZ_MESSAGES and figures['requests'] == FUZZ_REQUESTS
    assert figures['invalid messages'] > FUZZ_MESSAGES // 3
    assert _internal_errors(proc.log()) == []
    assert figures['rss after [MB]'] - figures['rss before [MB]'] < 20.0


def _cpu_seconds(pid: int) -> float:
    with open(f'/proc/{pid}/stat') as f:
        fields = f.read().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')  # utime + stime


@pytest.mark.serial  # ~240 MB in flight through the loopback: nothing beside it
def test_oversized_arrays_are_rejected_at_once(node, model, record_property):
    """10**6-element arrays on ~/screw and ~/rest_lengths: nothing published, the node alive,
    no memory kept, the next valid input answered, the warning throttled."""
    proc, ros, base = node
    diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
    inputs = fi.InputFuzzer(model, fi.planar_from_config(), seed=7)
    fuzzer = _fuzzer(proc, ros, base, model, timeout=60.0)
    # The 8 MB screws from a writer of their own: through the valid screws' writer, each valid
    # screw waits in its reliable stream behind the 8 MB before it (on a loaded machine up to
    # 60 s: ~240 MB through the loopback), which tests the transport, not the node. The node
    # sees both writers on its one ~/screw subscription. Two per round, keep-last 2: they reach
    # the node together, so the second one's warning is throttled.
    big_screws = ros.publisher(Float64MultiArray, f'{base}/screw', reliable_qos(2))
    ros.wait_for_subscribers(big_screws)
    _warm_up(fuzzer, inputs)

    def rejected() -> int:
        """The node's count of rejected inputs, every kind (its last /diagnostics)."""
        for m in reversed(diagnostics.messages):
            values = _diagnostic_values(m)
            if values is not None:
                return sum(int(n) for n in re.findall(r': (\d+)', values['rejected inputs']))
        return 0

    def all_rejected(n: int) -> None:
        diagnostics.wait_until(lambda m: (_diagnostic_values(m) is not None
                                          and rejected() >= n), timeout=60.0)

    rss_before, cpu_before = proc.rss_bytes(), _cpu_seconds(proc.pid)
    big = np.zeros(fi.OVERSIZED)
    n_big = 0
    start = time.monotonic()

    def send_big(target: str) -> None:
        nonlocal n_big
        case = fi.Case(target, 'oversized', {'data': big}, must_reject=True)
        if target == 'screw':
            big_screws.publish(fi.to_message(case))
        else:
            fuzzer.send(case)
        n_big += 1

    for i in range(10):
        send_big('screw')
        send_big('screw')
        if i % 3 == 2:
            send_big('rest_lengths')
        fuzzer.send(inputs.valid_screw_case())
        fuzzer.sync()  # the valid screw answered
        all_rejected(n_big)  # at most three 8 MB messages in flight
    # One more after the throttle interval (a condition on the node's clock, not a state to
    # wait for): its warning counts the ones left out since the last.
    time.sleep(1.2)
    send_big('screw')
    all_rejected(n_big)
    figures = fuzzer.finish()
    elapsed = time.monotonic() - start
    rss_after = proc.rss_bytes()
    cpu_per_message = (_cpu_seconds(proc.pid) - cpu_before) / n_big
    log = proc.log()
    warnings = {kind: len(re.findall(rf'{re.escape(kind)} rejected: too many elements', log))
                for kind in ('~/screw', '~/rest_lengths')}
    record_property('rss growth [MB]', round((rss_after - rss_before) / MB, 2))
    record_property('node cpu per oversized message [ms]', round(1e3 * cpu_per_message, 1))
    print(f'\noversized: {n_big} messages of 8 MB in {elapsed:.1f} s, node RSS '
          f'{rss_before / MB:.1f} -> {rss_after / MB:.1f} MB, node CPU '
          f'{1e3 * cpu_per_message:.1f} ms per message, warnings {warnings}')
    assert figures['wrong publications'] == 0, figures['wrong examples']
    assert figures['missing answers'] == 0 and figures['valid messages'] == 200 + 10, figures
    assert proc.alive()
    assert rss_after - rss_before < 8 * MB, (rss_before, rss_after)
    # Throttled: at most one warning per kind and second (plus the first one).
    for kind, count in warnings.items():
        assert 1 <= count <= 2 + elapsed, (kind, count, elapsed)
    assert sum(warnings.values()) < n_big
    assert re.search(r'~/screw rejected: too many elements.*\((\d+) more since the last warning\)',
                     log), log[-2000:]


def _diagnostic_values(msg: DiagnosticArray) -> dict[str, str] | None:
    for status in msg.status:
        if status.name.endswith('stiffness_node: joint'):
            return {kv.key: kv.value for kv in status.values}
    return None


def test_restart_picks_up_the_latched_rest_lengths(model):
    """A latched rest-lengths publisher keeps running while the node is killed (SIGKILL) and
    restarted: the restarted node's first output uses the latest latched rest lengths."""
    ns = unique_namespace('restart')
    base = f'{ns}/stiffness_node'
    args = ['-p', 'diagnostics.period:=0.2']
    ros = RosClient('restart_test')
    procs: list[NodeProcess] = []
    try:
        rest_pub = ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED)
        screw_pub = ros.publisher(Float64MultiArray, f'{base}/screw')
        stiffness = ros.subscribe(Float64MultiArray, f'{base}/stiffness')
        diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
        rng = np.random.default_rng(3)
        for attempt, scale in enumerate((0.96, 1.03)):
            rest = model.rest_lengths * scale
            rest_pub.publish(Float64MultiArray(data=rest.tolist()))  # latched, node down
            diagnostics.clear()
            procs.append(NodeProcess(ns, CONFIG, extra_args=args))
            # The new node has its rest lengths (generation >= 1) and has published nothing.
            values = _diagnostic_values(diagnostics.wait_until(
                lambda m: (v := _diagnostic_values(m)) is not None
                and int(v['parameter generation']) >= 1 and v['outputs published'] == '0',
                timeout=30.0))
            assert values is not None
            infos = ros.node.get_subscriptions_info_by_topic(f'{base}/rest_lengths')
            assert infos and all(
                i.qos_profile.reliability == ReliabilityPolicy.RELIABLE
                and i.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL for i in infos)
            before = len(stiffness)
            xi = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3)
            deadline = time.monotonic() + 30.0
            while len(stiffness) == before:  # until the new node's subscription has matched
                assert time.monotonic() < deadline, 'no output after the restart'
                screw_pub.publish(Float64MultiArray(data=xi.tolist()))
                try:
                    stiffness.wait_for(before + 1, timeout=2.0)
                except TimeoutError:
                    pass
            first = np.asarray(stiffness.messages[before].data).reshape(6, 6)
            np.testing.assert_allclose(first, model.stiffness(xi, rest), rtol=1e-12, atol=1e-12)
            assert not np.allclose(first, model.stiffness(xi), rtol=1e-6)  # not the config's
            if attempt == 0:
                procs[-1].kill()
                assert not procs[-1].alive()
    finally:
        ros.close()
        codes = [p.stop() for p in procs]
    assert codes[-1] == 0, procs[-1].log()[-3000:]


def _set_b(model: JointModel) -> tuple[dict[str, object], JointModel]:
    """Parameter set B (geometry, k, rest lengths and force law all differ from A = the
    config), as parameters and as the library's model."""
    section = dict(config.load_section(CONFIG, 'joint'))
    changes = {
        'link1_nodes': (np.asarray(section['link1_nodes'], dtype=float) * 1.02).tolist(),
        'stiffness': [90.0] * model.n_strings,
        'rest_lengths': (model.rest_lengths * 0.97).tolist(),
        'force_law': 'paper',
    }
    return changes, JointModel.from_dict({**section, **changes})


def _set_a(changes_b: dict[str, object]) -> dict[str, object]:
    section = dict(config.load_section(CONFIG, 'joint'))
    return {key: ([float(v) for v in section[key]] if isinstance(section[key], list)
                  else section[key]) for key in changes_b}


def _atomic_request(changes: dict[str, object]) -> SetParametersAtomically.Request:
    return SetParametersAtomically.Request(parameters=[
        Parameter(f'joint.{k}' if '.' not in k else k, value=v).to_parameter_msg()
        for k, v in changes.items()])


REJECTED_CHANGES = [
    {'joint.stiffness': [90.0] * 12, 'joint.rest_lengths': [-0.03] * 12},  # one bad in a set
    {'joint.force_law': 'cubic'},
    {'joint.stiffness': [math.nan] * 12},
    {'joint.link1_nodes': [0.0] * 5},
    {'joint.max_lengths': [0.01] * 12},  # below the rest lengths
    {'joint.string_link1_nodes': ['Z'] * 12},
    {'joint.rest_lengths': [0.03] * 100_000},
    {'planar.K1': -5.0},
    {'planar.L': math.nan},
    {'qos.depth': 3},  # read-only
    {'limits.max_array_length': 2},  # below its range
]


@pytest.fixture
def stream_node():
    with _running_node(['-p', f'qos.depth:={STREAM_DEPTH}']) as running:
        yield running


@pytest.mark.slow
@pytest.mark.serial  # a 1 kHz stream on 2 cores: nothing beside it
def test_no_torn_state_under_parameter_changes_at_1khz(stream_node, model, record_property):
    """Screws at 1 kHz while the whole joint (geometry, k, rest lengths, force law) switches
    between sets A and B and rejected changes come in between: every output (K, wrench,
    tensions) is the library's for its screw under exactly one set, the sets change only at the
    re-publish a successful switch causes, and a screw sent after a switch was acknowledged is
    answered with the new set."""
    _, ros, base = stream_node
    changes_b, model_b = _set_b(model)
    changes_a = _set_a(changes_b)
    models = (model, model_b)
    inboxes = {name: ros.subscribe(Float64MultiArray, f'{base}/{name}', STREAM)
               for name in ('stiffness', 'string_tensions')}
    from geometry_msgs.msg import WrenchStamped

    inboxes['wrench'] = ros.subscribe(WrenchStamped, f'{base}/wrench', STREAM)
    pub = ros.publisher(Float64MultiArray, f'{base}/screw', STREAM)
    client = ros.client(SetParametersAtomically, f'{base}/set_parameters_atomically')
    ros.wait_for_subscribers(pub)
    for name in inboxes:
        ros.wait_for_publishers(f'{base}/{name}')
    # Every output answers before the stream (the node's publishers may not have matched these
    # subscriptions yet: a first output would be lost), then the counts start from zero.
    answer_every_output(lambda: pub.publish(Float64MultiArray(data=model.initial_screw.tolist())),
                        lambda: {name: len(inbox) for name, inbox in inboxes.items()})
    for inbox in inboxes.values():
        inbox.clear()
    rng = np.random.default_rng(11)
    screws = model.initial_screw + rng.normal(scale=[0.05] * 3 + [0.002] * 3,
                                              size=(TORN_MAX_SCREWS, 6))
    sent_at = np.full(TORN_MAX_SCREWS, np.inf)
    acks: list[float] = []  # completion times of the successful switches
    rejected: list[str] = []
    stop = threading.Event()

    def switcher() -> None:
        target = 1
        k = 0
        while not stop.wait(0.06):
            if k % 2:  # a change that must be rejected, between two switches
                bad = REJECTED_CHANGES[k // 2 % len(REJECTED_CHANGES)]
                if ros.call(client, _atomic_request(bad)).result.successful:
                    rejected.append(f'accepted: {bad}')
            else:
                res = ros.call(client, _atomic_request(changes_b if target else changes_a)).result
                assert res.successful, res.reason
                acks.append(time.perf_counter())
                target = 1 - target
            k += 1

    thread = threading.Thread(target=switcher, daemon=True)
    period = 1e-3
    start = time.perf_counter()
    n = 0  # screws sent: at least TORN_SCREWS, and on until TORN_SWITCHES switches were made
    for i in range(TORN_MAX_SCREWS):
        if i >= TORN_SCREWS and len(acks) >= TORN_SWITCHES:
            break
        target_time = start + i * period
        while (now := time.perf_counter()) < target_time:
            time.sleep(max(0.0, target_time - now - 2e-4))
        if i == 200:
            thread.start()
        sent_at[i] = time.perf_counter()
        pub.publish(Float64MultiArray(data=screws[i].tolist()))
        n = i + 1
    stop.set()
    thread.join(10.0)
    switches = len(acks)
    assert switches >= TORN_SWITCHES, f'{switches} switches in {n} screws at 1 kHz'
    screws = screws[:n]
    # The node's path (one screw at a time): the batched one rounds differently (~1e-16 rel.).
    states = [[m.evaluate(xi) for xi in screws] for m in models]
    expected = [{'stiffness': [st.stiffness for st in sts], 'wrench': [st.wrench for st in sts],
                 'string_tensions': [st.tensions for st in sts]} for sts in states]
    total = n + switches
    for inbox in inboxes.values():
        inbox.wait_for(total, timeout=30.0)
    time.sleep(0.5)
    assert rejected == [], rejected
    values = {name: [np.asarray(conversions.msg_to_wrench(m.wrench) if name == 'wrench'
                                else m.data) for m in inbox.messages]
              for name, inbox in inboxes.items()}
    assert {len(v) for v in values.values()} == {total}, {k: len(v) for k, v in values.items()}

    def same(name: str, k: int, s: int, i: int) -> bool:
        exp = expected[s][name][i].ravel()
        return bool(np.allclose(values[name][k], exp, rtol=1e-12, atol=1e-12))

    p, s, generation = 0, 0, 0
    transitions = 0
    for k in range(total):
        if p < n and same('stiffness', k, s, p):
            i = p
            p += 1
        elif p > 0 and same('stiffness', k, 1 - s, p - 1):  # the re-publish of a switch
            s, i = 1 - s, p - 1
            transitions += 1
            generation += 1
        else:
            near = [f'screw {j} under {"AB"[t]}' for t in (0, 1)
                    for j in range(max(0, p - 50), min(n, p + 50)) if same('stiffness', k, t, j)]
            pytest.fail(f'output {k} is not screw {p} under the current set {"AB"[s]} nor the '
                        f're-publish of screw {p - 1} under the other set: torn or wrong '
                        f'(it is {near or "none of the screws sent around then"})')
        for name in ('wrench', 'string_tensions'):  # the same input, the same set
            assert same(name, k, s, i), f'{name} of output {k} is not from set {"AB"[s]}'
        # A screw sent after the i-th acknowledgement is answered under a later set.
        assert generation >= int(np.searchsorted(acks, sent_at[i])), (k, i, generation)
    assert p == n and transitions == switches
    record_property('switches', switches)
    print(f'\ntorn state: {n} screws at 1 kHz, {switches} switches A <-> B, '
          f'{switches} re-publishes, every output from one set')


def test_rejected_parameter_changes_keep_the_old_set(node, model):
    proc, ros, base = node
    stiffness = ros.subscribe(Float64MultiArray, f'{base}/stiffness')
    pub = ros.publisher(Float64MultiArray, f'{base}/screw')
    atomic = ros.client(SetParametersAtomically, f'{base}/set_parameters_atomically')
    single = ros.client(SetParameters, f'{base}/set_parameters')
    get = ros.client(GetParameters, f'{base}/get_parameters')
    ros.wait_for_subscribers(pub)
    ros.wait_for_publishers(f'{base}/stiffness')
    xi = model.initial_screw + np.r_[0.03, -0.01, 0.02, 0.001, 0.0, -0.001]
    answer_every_output(lambda: pub.publish(Float64MultiArray(data=xi.tolist())),
                        lambda: {'stiffness': len(stiffness)})
    answered = len(stiffness)  # 1, or more if the first answer was only late
    names = ['joint.stiffness', 'joint.rest_lengths', 'joint.force_law', 'planar.K1']
    before = ros.call(get, GetParameters.Request(names=names)).values
    for changes in REJECTED_CHANGES + [{'joint.stiffness': 'not an array'},
                                       {'no.such.parameter': 1.0}]:
        request = _atomic_request(changes)
        result = ros.call(atomic, request).result
        assert not result.successful, changes
        if len(changes) == 1:  # one by one (SetParameters applies each on its own)
            results = ros.call(single, SetParameters.Request(
                parameters=request.parameters)).results
            assert not results[0].successful, changes
        assert proc.alive()
    after = ros.call(get, GetParameters.Request(names=names)).values
    assert [str(v) for v in after] == [str(v) for v in before]
    time.sleep(0.3)
    assert len(stiffness) == answered  # a rejected change re-publishes nothing
    pub.publish(Float64MultiArray(data=xi.tolist()))
    out = stiffness.wait_for(answered + 1, timeout=10.0)[answered]
    np.testing.assert_allclose(np.reshape(out.data, (6, 6)), model.stiffness(xi), rtol=1e-12,
                               atol=1e-12)




@pytest.mark.slow
@pytest.mark.serial  # answers within a solve's 50 ms: nothing beside it
def test_equilibrium_burst_does_not_stall_the_screws(light_node, model, record_property):
    """A burst of equilibrium requests that each use up the solve's time budget (50 ms) while
    screws stream at 1 kHz: every screw is answered, and the answers keep coming *while* each
    solve runs (a solve on the executor would hold them back until its response). No timed
    bound: the latency figures are printed here and measured by bench/burst_latency.py."""
    proc, ros, base = light_node
    diagnostics = ros.subscribe(DiagnosticArray, '/diagnostics')
    inputs = fi.InputFuzzer(model, fi.planar_from_config(), seed=5)
    # At most 8 answers outstanding: the latency then shows the node, not a backlog of the
    # client, whose matching is slower than 1 kHz on the 2-core CI machine (with 200 the
    # backlog alone was 100-470 ms, longer than a solve).
    fuzzer = _fuzzer(proc, ros, base, model, track_latency=True, window=8)
    _warm_up(fuzzer, inputs)
    fuzzer.latencies.clear()
    client = fuzzer.clients['equilibrium']
    hard = fi.Case('equilibrium', 'wrench 50 N', {
        'wrench': np.r_[50.0, 0, 0, 0, 0, 0], 'rest_lengths': np.empty(0),
        'initial_screw': model.initial_screw, 'easy': False})
    solves: list[tuple[float, float]] = []  # (request sent, response received)
    window: list[float] = []

    answers: list[str] = []  # the solves' messages that were not the budget's

    def burst() -> None:
        window.append(time.perf_counter())
        for _ in range(40):
            t = time.perf_counter()
            res = ros.call(client, fi.to_message(hard), timeout=30.0)
            solves.append((t, time.perf_counter()))
            if res.success or 'budget' not in res.message:
                answers.append(res.message)
        window.append(time.perf_counter())

    thread = threading.Thread(target=burst, daemon=True)
    deadline = time.monotonic() + 300.0
    i = 0
    # Screws stream from before the burst until its last solve returned (however long the
    # machine takes for 40 solves).
    while i <= 500 or thread.is_alive():
        assert time.monotonic() < deadline, f'the burst did not end: {len(solves)} of 40 solves'
        if i == 500:
            thread.start()
        fuzzer.send(inputs.valid_screw_case())
        i += 1
    thread.join()
    assert not answers and len(window) == 2, answers
    figures = fuzzer.finish(quiet=0.3)
    # The node's own count says which side lost an answer: inputs it never answered, or
    # outputs the middleware did not deliver to this client (on 2 cores, a reader starved
    # beside the node and its solver loses a few of 3,000 reliable samples: seen 9 in one of
    # five runs). The node must answer every screw; the transport's loss is reported and
    # bounded (1 %), not the node's fault.
    valid = figures['valid messages']

    def published(m) -> int | None:
        values = _diagnostic_values(m)
        return None if values is None else int(values['outputs published'])

    diagnostics.clear()
    try:
        status = diagnostics.wait_until(lambda m: (published(m) or 0) >= valid, 10.0)
        node_published = published(status)
    except TimeoutError:
        last = next((published(m) for m in reversed(diagnostics.messages)
                     if published(m) is not None), None)
        pytest.fail(f'the node answered {last} of {valid} valid screws; {figures}; its log '
                    f'ends: {proc.log()[-1500:]}')
    record_property('answers lost in transport', figures['missing answers'])
    assert figures['wrong publications'] == 0, figures['wrong examples']
    # every screw counted, and those prime() sent that the node answered
    assert valid <= node_published <= valid + fuzzer.primed, (node_published, valid,
                                                              fuzzer.primed)
    assert figures['missing answers'] <= 0.01 * valid, (
        f'{figures["missing answers"]} of {valid} answers published by the node never reached '
        f'the client: {figures}')
    during = [lat for sent, lat in fuzzer.latencies if window[0] <= sent <= window[1]]
    before = [lat for sent, lat in fuzzer.latencies if sent < window[0]]
    durations = [end - start for start, end in solves]
    # Screws sent and answered strictly inside one solve's round trip.
    inside_sent = inside_answered = 0
    for sent, lat in fuzzer.latencies:
        for start, end in solves:
            if start <= sent <= end:
                inside_sent += 1
                inside_answered += sent + lat <= end
                break
    worst = max(during)
    record_property('burst worst latency [ms]', round(1e3 * worst, 2))
    record_property('answered within the solve', f'{inside_answered}/{inside_sent}')
    print(f'\nburst: {len(durations)} solves, median {1e3 * statistics.median(durations):.1f} ms;'
          f' screw latency during the burst: n={len(during)} median '
          f'{1e3 * statistics.median(during):.2f} ms p99 {1e3 * percentile(during, 0.99):.2f} ms'
          f' max {1e3 * worst:.2f} ms (before: p99 {1e3 * percentile(before, 0.99):.2f} ms, '
          f'max {1e3 * max(before):.2f} ms); screws sent during a solve and answered before its '
          f'response: {inside_answered}/{inside_sent}')
    assert len(durations) == 40 and statistics.median(durations) > 0.03  # hard: budget used
    assert len(during) > 500 and inside_sent > 300  # enough screws to judge by
    # A blocking solve answers none of them before its response; half is a wide margin for a
    # loaded machine.
    assert inside_answered > inside_sent / 2, (
        f'only {inside_answered} of {inside_sent} screws sent during a solve were answered '
        'before the solve returned')
