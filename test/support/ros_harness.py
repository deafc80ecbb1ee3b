"""Test and benchmark harness: start the installed node as a process, talk to it from rclpy.

Real middleware only: the node runs as a separate process started from its colcon install
location (the file ``ros2 run`` would start), and the client is a real rclpy node in a private
context whose executor spins in a background thread (``spin_until_future_complete`` busy-loops
and starves the middleware on 2 cores; see the pypi notes).

:class:`NodeFuzzer` drives a running node with the inputs of ``fuzz_inputs`` and counts what
comes back (shared by ``test/ros/test_robustness.py`` and ``bench/fuzz_node.py``).
"""

from __future__ import annotations

import gc
import itertools
import os
import re
import signal
import subprocess
import threading
import time
import uuid
from collections import Counter, deque
from collections.abc import Callable, Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from rcl_interfaces.srv import SetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from tensegrity_stiffness.ros.runtime.draining_subscription import create_draining_subscription
from tensegrity_stiffness.ros.runtime.fast_lane import FastLane

REPO = Path(__file__).resolve().parents[2]
PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'stiffness_node'



def reliable_qos(depth: int, durability: DurabilityPolicy = DurabilityPolicy.VOLATILE
                 ) -> QoSProfile:
    """Reliable, keep-last ``depth``."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                      reliability=ReliabilityPolicy.RELIABLE, durability=durability)


RELIABLE = reliable_qos(100)
#: For streams whose every message is counted: a client that stalls (a loaded 2-core machine)
#: must not lose messages from its own history (pair with the node's ``qos.depth``).
DEEP = reliable_qos(2000)
LATCHED = reliable_qos(1, DurabilityPolicy.TRANSIENT_LOCAL)
#: Default wait (s) for a node's start: its graph entities, services, worker. Generous: on the
#: 2-core machine beside other jobs a node's start took over 20 s; a wait ends at its condition.
STARTUP_TIMEOUT = 60.0
#: Default wait (s) for a message or a log line once a node runs.
MESSAGE_TIMEOUT = 15.0


def node_executable(executable: str = EXECUTABLE) -> Path:
    """``<prefix>/lib/tensegrity_stiffness/<executable>`` found through the ament index."""
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE / executable
    if not os.access(path, os.X_OK):
        raise FileNotFoundError(f'{path} is not an executable')
    return path


def sleep_until(target: float, spin_s: float = 2e-4) -> float:
    """Wait until ``time.perf_counter() >= target`` (sleeping while more than ``spin_s``
    remain, spinning for the rest, so that a paced stream keeps its rate to a few microseconds;
    ``spin_s=0``: sleep only, as a controller's timer would, some 60 us late but without taking
    a core); returns the time at which it stopped."""
    while (now := time.perf_counter()) < target:
        if target - now > spin_s:
            time.sleep(max(target - now - 0.75 * spin_s, 0.0))
    return now


def publish_paced(publisher: Any, messages: list[Any], rate: float, spin_s: float,
                  received: Callable[[], int], timeout: float = 5.0) -> list[float]:
    """Publish ``messages`` at ``rate`` Hz (``spin_s``: see :func:`sleep_until`), then wait up to
    ``timeout`` s until ``received()`` counts one answer each; returns the send times
    (time.perf_counter)."""
    sent_at = []
    period = 1.0 / rate
    start = time.perf_counter()
    for k, msg in enumerate(messages):
        sleep_until(start + k * period, spin_s)
        sent_at.append(time.perf_counter())
        publisher.publish(msg)
    deadline = time.monotonic() + timeout
    while received() < len(messages) and time.monotonic() < deadline:
        time.sleep(0.05)
    return sent_at


def latencies_in_order(outputs: Iterable[Any], arrivals: Iterable[float], expected: Any,
                       sent_at: list[float]) -> list[float]:
    """Latency of each output (in arrival order) from the send time of its input: outputs come
    in input order, so each is matched by value (rtol = atol = 1e-12) to the first expected one
    it equals after the previous match; a dropped input leaves a gap and cannot shift the
    pairing. AssertionError for an output that matches no input."""
    latencies = []
    k, n = 0, len(expected)
    for values, arrived in zip(outputs, arrivals, strict=True):
        while k < n and not np.allclose(values, expected[k], rtol=1e-12, atol=1e-12):
            k += 1
        if k == n:
            raise AssertionError('an output matches no input')
        latencies.append(arrived - sent_at[k])
        k += 1
    return latencies


def percentile(values: list[float], q: float) -> float:
    """The ``q`` quantile (0..1) of ``values``: the element at rank ``q * n`` when sorted."""
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))]


def latency_summary(name: str, seconds: list[float]) -> str:
    """One line of a latency bench: count, median, p99 and max in ms."""
    import statistics

    ms = [s * 1e3 for s in seconds]
    return (f'{name:<34} n={len(ms):>6}  median {statistics.median(ms):7.3f} ms  '
            f'p99 {percentile(ms, 0.99):7.3f} ms  max {max(ms):8.3f} ms')



def timed_service_calls(ros: RosClient, client: Any, requests: Iterable[Any],
                        timeout: float = 30.0) -> tuple[list[float], int]:
    """Each of ``requests`` (made lazily, in order) called in turn on ``client``: the round
    trips (s, ``perf_counter``) and the count of responses with ``success`` False."""
    times: list[float] = []
    failures = 0
    for request in requests:
        begin = time.perf_counter()
        response = ros.call(client, request, timeout=timeout)
        times.append(time.perf_counter() - begin)
        failures += not response.success
    return times, failures

def process_children(pid: int) -> list[int]:
    """Child process ids of ``pid`` (from /proc; [] once it is gone)."""
    children = []
    for task in Path(f'/proc/{pid}/task').glob('*'):
        try:
            children += [int(c) for c in (task / 'children').read_text().split()]
        except OSError:
            pass
    return children


def process_cmdline(pid: int) -> str:
    """The command line of ``pid`` ('' once it is gone)."""
    try:
        return Path(f'/proc/{pid}/cmdline').read_bytes().replace(b'\0', b' ').decode()
    except OSError:
        return ''


def process_alive(pid: int) -> bool:
    """True while ``pid`` exists and is not a zombie."""
    try:
        stat = Path(f'/proc/{pid}/stat').read_text()
    except OSError:
        return False
    return stat.rsplit(')', 1)[1].split()[0] != 'Z'


def pose_stamped(T: np.ndarray, frame_id: str = 'tensegrity_link1') -> Any:
    """A ``geometry_msgs/PoseStamped`` of the transform ``T`` in ``frame_id`` (zero stamp)."""
    from geometry_msgs.msg import PoseStamped

    from tensegrity_stiffness.ros import conversions

    msg = PoseStamped()
    msg.header.frame_id = frame_id
    msg.pose = conversions.transform_to_pose(T)
    return msg


def unique_namespace(prefix: str = 'test') -> str:
    return f'/{prefix}_{uuid.uuid4().hex[:8]}'


class NodeProcess:
    """The node as a child process (environment passed through unchanged, as the wheels'
    bootstrapper needs), with its output in a log file; ``executable``: which of the package's
    nodes (``stiffness_node`` by default, ``spine_node``)."""

    _starts = itertools.count()

    def __init__(self, namespace: str, params_file: Path | None = None,
                 extra_args: Iterable[str] = (), log_dir: Path | None = None,
                 new_session: bool = False, executable: str = EXECUTABLE) -> None:
        self.namespace = namespace
        self.executable = executable
        params_file = params_file or REPO / 'config' / 'default_joint.yaml'
        log_dir = log_dir or Path(os.environ.get('TMPDIR', '/tmp'))
        # One log per start (a restart in the same namespace keeps the first one).
        self.log_path = log_dir / (f'{executable}{namespace.replace("/", "_")}'
                                   f'_{os.getpid()}_{next(NodeProcess._starts)}.log')
        self._log = self.log_path.open('w')
        args = [str(node_executable(executable)), '--ros-args', '--params-file', str(params_file),
                '-r', f'__ns:={namespace}', *extra_args]
        # new_session: the node leads a process group of its own (as under a supervisor).
        self.process = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT,
                                        env=os.environ.copy(), start_new_session=new_session)

    def alive(self) -> bool:
        return self.process.poll() is None

    @property
    def pid(self) -> int:
        return self.process.pid

    def log(self) -> str:
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors='replace')

    def children(self) -> list[int]:
        """Process ids of the node's child processes (its solver worker among them)."""
        return process_children(self.process.pid)

    def worker_pid(self, timeout: float = STARTUP_TIMEOUT) -> int:
        """The pid of the node's solver worker (a spawned multiprocessing child)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for pid in self.children():
                if '--multiprocessing-fork' in process_cmdline(pid):
                    return pid
            time.sleep(0.05)
        raise TimeoutError(f'no solver worker under pid {self.process.pid}')

    def rss_bytes(self) -> int:
        """Resident memory of the node process (VmRSS of /proc/<pid>/status)."""
        with open(f'/proc/{self.process.pid}/status') as f:
            for line in f:
                if line.startswith('VmRSS:'):
                    return int(line.split()[1]) * 1024
        raise RuntimeError(f'no VmRSS for pid {self.process.pid}')

    def stop(self, timeout: float = 10.0) -> int:
        if self.alive():
            self.process.send_signal(signal.SIGINT)
            try:
                self.process.wait(timeout)
            except subprocess.TimeoutExpired:
                self.process.kill()
                self.process.wait(timeout)
        self._log.close()
        return self.process.returncode

    def kill(self) -> None:
        """SIGKILL (no clean-up in the node), then close the log."""
        if self.alive():
            self.process.kill()
            self.process.wait(10)
        self._log.close()


def start_structure_twin_and_estimator(namespace: str, twin_params: Path,
                                       estimator_params: Path, inputs: Iterable[str]
                                       ) -> tuple[NodeProcess, NodeProcess, str, str]:
    """``structure_sim_node`` and ``structure_estimator_node`` in ``namespace``, the estimator's
    ``inputs`` (names under its ``~/``) remapped to the twin's outputs of the same names.
    Returns the twin, the estimator and their fully qualified bases."""
    twin_base = f'{namespace}/structure_sim_node'
    estimator_base = f'{namespace}/structure_estimator_node'
    twin = NodeProcess(namespace, twin_params, executable='structure_sim_node')
    remaps = [arg for name in inputs
              for arg in ('-r', f'{estimator_base}/{name}:={twin_base}/{name}')]
    estimator = NodeProcess(namespace, estimator_params, executable='structure_estimator_node',
                            extra_args=remaps)
    return twin, estimator, twin_base, estimator_base


def log_has(proc: NodeProcess, pattern: str, timeout: float = MESSAGE_TIMEOUT) -> bool:
    """Whether the node's log matches ``pattern`` (re.search) within ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if re.search(pattern, proc.log()):
            return True
        time.sleep(0.1)
    return False


def wrench_stamped(W: Any, frame_id: str = '') -> Any:
    """A ``WrenchStamped`` of ``W`` ([f; m]) with its fields set directly (a NaN too: the node,
    not the test, must refuse it)."""
    from geometry_msgs.msg import WrenchStamped

    msg = WrenchStamped()
    msg.header.frame_id = frame_id
    msg.wrench.force.x, msg.wrench.force.y, msg.wrench.force.z = (float(v) for v in W[:3])
    msg.wrench.torque.x, msg.wrench.torque.y, msg.wrench.torque.z = (float(v) for v in W[3:])
    return msg


class Inbox:
    """Messages of one subscription, with their arrival times (time.perf_counter)."""

    def __init__(self) -> None:
        self.messages: list[Any] = []
        self.times: list[float] = []
        self._cond = threading.Condition()

    def __call__(self, msg: Any) -> None:
        now = time.perf_counter()
        with self._cond:
            self.messages.append(msg)
            self.times.append(now)
            self._cond.notify_all()

    def __len__(self) -> int:
        with self._cond:
            return len(self.messages)

    def wait_for(self, count: int, timeout: float = MESSAGE_TIMEOUT) -> list[Any]:
        """Wait until at least ``count`` messages arrived; returns all of them."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self.messages) < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f'{len(self.messages)} of {count} messages')
                self._cond.wait(left)
            return list(self.messages)

    def wait_until(self, predicate: Callable[[Any], bool], timeout: float = MESSAGE_TIMEOUT
                   ) -> Any:
        """Wait for a message satisfying ``predicate`` (checks old and new ones)."""
        deadline = time.monotonic() + timeout
        seen = 0
        with self._cond:
            while True:
                for msg in self.messages[seen:]:
                    if predicate(msg):
                        return msg
                seen = len(self.messages)
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError('no matching message')
                self._cond.wait(left)

    def clear(self) -> None:
        with self._cond:
            self.messages.clear()
            self.times.clear()


class StampedInbox(Inbox):
    """An :class:`Inbox` that also keeps each message's source timestamp (the publisher's write
    time, s, from rclpy's message info): gaps between publications, unlike arrival times, do
    not bunch up when this process's executor falls behind."""

    def __init__(self) -> None:
        super().__init__()
        self.source_times: list[float] = []

    def __call__(self, msg: Any, info: dict[str, Any]) -> None:  # type: ignore[override]
        with self._cond:
            self.source_times.append(info['source_timestamp'] * 1e-9)
            super().__call__(msg)

    def clear(self) -> None:
        with self._cond:
            super().clear()
            self.source_times.clear()


class RosClient:
    """A private rclpy context, node and background executor."""

    def __init__(self, name: str = 'tester') -> None:
        self.context = Context()
        rclpy.init(context=self.context)
        self.node = rclpy.create_node(f'{name}_{uuid.uuid4().hex[:6]}', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            while self.context.ok() and not self._stop.is_set():
                self.executor.spin_once(timeout_sec=0.05)
        except Exception:
            pass

    def subscribe(self, msg_type: Any, topic: str, qos: QoSProfile = RELIABLE) -> Inbox:
        inbox = Inbox()
        self.subscribe_callback(msg_type, topic, inbox, qos)
        return inbox

    def subscribe_stamped(self, msg_type: Any, topic: str,
                          qos: QoSProfile = RELIABLE) -> StampedInbox:
        """A plain subscription (one message per callback) whose inbox keeps source stamps."""
        inbox = StampedInbox()
        self.node.create_subscription(msg_type, topic, inbox, qos)
        return inbox

    def subscribe_callback(self, msg_type: Any, topic: str, callback: Callable[[Any], None],
                           qos: QoSProfile = RELIABLE) -> Any:
        """A subscription whose callback also takes the messages queued behind the current one
        (:func:`create_draining_subscription`, as the node does): at 1 kHz on 2 cores the
        client's executor, not the node, would otherwise set the pace."""
        return create_draining_subscription(self.node, msg_type, topic, callback, qos)

    def publisher(self, msg_type: Any, topic: str, qos: QoSProfile = RELIABLE) -> Any:
        return self.node.create_publisher(msg_type, topic, qos)

    def set_parameter(self, client: Any, name: str, value: Any) -> Any:
        """Set one parameter through a node's ``SetParameters`` service ``client``; its type as
        rclpy infers it from ``value`` (lists as double arrays, also when empty). Returns the
        ``SetParametersResult``."""
        if isinstance(value, list):
            parameter = Parameter(name, Parameter.Type.DOUBLE_ARRAY, [float(v) for v in value])
        else:
            parameter = Parameter(name, value=value)
        request = SetParameters.Request(parameters=[parameter.to_parameter_msg()])
        return self.call(client, request).results[0]

    def client(self, srv_type: Any, name: str, timeout: float = STARTUP_TIMEOUT) -> Any:
        client = self.node.create_client(srv_type, name)
        if not client.wait_for_service(timeout_sec=timeout):
            raise TimeoutError(f'service {name} not available after {timeout} s')
        return client

    def call(self, client: Any, request: Any, timeout: float = 10.0) -> Any:
        done = threading.Event()
        future = client.call_async(request)
        future.add_done_callback(lambda _: done.set())
        if not done.wait(timeout):
            client.remove_pending_request(future)
            raise TimeoutError(f'no answer from {client.srv_name} within {timeout} s')
        return future.result()

    def wait_for_subscribers(self, publisher: Any, count: int = 1,
                             timeout: float = STARTUP_TIMEOUT) -> None:
        deadline = time.monotonic() + timeout
        while publisher.get_subscription_count() < count:
            if time.monotonic() > deadline:
                raise TimeoutError(f'no subscriber on {publisher.topic_name}')
            time.sleep(0.02)

    def wait_for_executor(self, node: str, timeout: float = STARTUP_TIMEOUT) -> None:
        """Wait until the executor of the node named ``node`` (its full name) answers a
        service: inputs sent after this are served by a spinning node (at start-up a fast lane
        can serve its topics before the executor serves the others, e.g. latched rest lengths)."""
        from rcl_interfaces.srv import GetParameters

        client = self.client(GetParameters, f'{node}/get_parameters', timeout)
        self.call(client, GetParameters.Request(names=['qos.depth']), timeout)
        self.node.destroy_client(client)

    def wait_for_publishers(self, topic: str, count: int = 1,
                            timeout: float = STARTUP_TIMEOUT) -> None:
        """Wait until ``topic`` has ``count`` publishers and this client's own subscriptions on
        it are matched to them: the graph can list a publisher whose writer has not matched a
        new reader yet, and a message it sends then is lost to that reader."""
        deadline = time.monotonic() + timeout
        readers = [s for s in self.node.subscriptions if s.topic_name == topic]
        while (self.node.count_publishers(topic) < count
               or any(s.get_publisher_count() < count for s in readers)):
            if time.monotonic() > deadline:
                raise TimeoutError(f'no publisher on {topic}')
            time.sleep(0.02)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


# ---------------------------------------------------------------------------- first answers
def repeat_until(send: Callable[[], Any], check: Callable[[], Any], timeout: float = 30.0,
                 period: float = 0.2, explain: Callable[[], str] | None = None) -> Any:
    """``send()`` then ``check()`` every ``period`` until ``check`` returns something other than
    None, which is returned. For a first message: a node's publisher may not have matched this
    client's subscription yet when the input is sent (both sides discover each other on their
    own), and a node fills an output only while it sees a subscriber. ``explain()`` is added to
    the error on timeout (e.g. a node's log)."""
    deadline = time.monotonic() + timeout
    while True:
        send()
        time.sleep(period)
        result = check()
        if result is not None:
            return result
        if time.monotonic() > deadline:
            raise AssertionError(f'nothing came within {timeout:g} s'
                                 + (f': {explain()}' if explain is not None else ''))


def answer_every_output(send: Callable[[], Any], counts: Callable[[], dict[str, int]],
                        timeout: float = 30.0, quiet: float = 0.3) -> None:
    """Before a harness's tests: ``send()`` every 0.2 s until every output of ``counts()`` has
    answered once, then until no answer came for ``quiet`` s (so that none arrives during a
    test). A fresh node fills a topic only while it sees a subscriber there, and its view of the
    graph can lag this client's: its first inputs can go unanswered on a topic."""
    deadline = time.monotonic() + timeout
    repeat_until(send, lambda: True if min(counts().values()) else None, timeout,
                 explain=lambda: f'outputs never all answered: {counts()}')
    seen = counts()
    while True:
        time.sleep(quiet)
        now = counts()
        if now == seen:
            return
        assert time.monotonic() < deadline, f'outputs keep coming: {now}'
        seen = now


# ---------------------------------------------------------------------------- the twin
#: Settled: the last SETTLED_COUNT screws agree to SETTLED_SPREAD (rad, m).
SETTLED_SPREAD = 1e-11
SETTLED_COUNT = 20
#: How close a settled twin must be to the equilibrium a test expects (the twin matches the
#: library's equilibria to ~1e-12, test_sim_node).
SETTLED_AT_TARGET = 1e-8


def wait_settled(inbox: Inbox, timeout: float = 30.0, after: int = 0,
                 target: Any = None) -> Any:
    """The twin's screw(s) once the last SETTLED_COUNT messages (after index ``after``) agree,
    and, given a ``target`` (the equilibrium the input just sent leads to), lie within
    SETTLED_AT_TARGET of it: a loaded machine may deliver that input after the twin has
    been still for a while at the equilibrium before it."""
    import numpy as np

    deadline = time.monotonic() + timeout
    distance = None
    while time.monotonic() < deadline:
        messages = inbox.messages[after:]
        if len(messages) >= SETTLED_COUNT:
            last = np.array([m.data for m in messages[-SETTLED_COUNT:]])
            if np.ptp(last, axis=0).max() <= SETTLED_SPREAD:
                if target is None:
                    return last[-1]
                distance = float(np.abs(last[-1] - np.ravel(target)).max())
                if distance <= SETTLED_AT_TARGET:
                    return last[-1]
        time.sleep(0.1)
    raise TimeoutError('the twin did not settle' + (
        '' if distance is None else f' at the expected equilibrium ({distance:.3g} from it)'))


# ---------------------------------------------------------------------------- fuzzing
class StreamMatcher:
    """Subscription callback that matches the messages of one output topic, in arrival order,
    to the outputs expected for the inputs sent.

    The sender calls :meth:`expect` before it publishes an input that must be answered (so an
    answer can never arrive before its expectation). A message equal (rtol = atol = 1e-12) to
    the oldest expectation matches it; one equal to a later expectation (within ``LOOKAHEAD``)
    matches that one and the skipped ones count as ``missing``; one equal to none counts as
    ``wrong`` (a publication for an invalid input, or a wrong value). ``on_match(seq, t)`` gets
    each match with its arrival time (time.perf_counter). ``rtol`` / ``atol``: the tolerances of
    a match (1e-12 for closed-form outputs; a value from a linear solve is as exact as the
    system's conditioning allows).
    """

    LOOKAHEAD = 64

    def __init__(self, extract: Callable[[Any], Any],
                 on_match: Callable[[int, float], None] | None = None,
                 rtol: float = 1e-12, atol: float = 1e-12) -> None:
        import numpy as np

        self._rtol, self._atol = rtol, atol

        self._np = np
        self._extract = extract
        self._on_match = on_match
        self._expected: deque[tuple[int, Any]] = deque()
        self._cond = threading.Condition()
        self.received = 0
        self.matched = 0
        self.missing = 0
        self.skipped: list[int] = []  # seq of each expectation a later message skipped
        self.wrong = 0
        self.wrong_examples: list[str] = []

    def expect(self, seq: int, value: Any) -> None:
        with self._cond:
            self._expected.append((seq, value))

    def __call__(self, msg: Any) -> None:
        now = time.perf_counter()
        value = self._np.asarray(self._extract(msg), dtype=self._np.float64)
        np = self._np
        with self._cond:
            self.received += 1
            for j, (seq, expected) in enumerate(itertools.islice(self._expected,
                                                                 self.LOOKAHEAD)):
                if value.shape == expected.shape and np.allclose(
                        value, expected, rtol=self._rtol, atol=self._atol):
                    for _ in range(j):
                        self.skipped.append(self._expected.popleft()[0])
                    self._expected.popleft()
                    self.missing += j
                    self.matched += 1
                    if self._on_match is not None:
                        self._on_match(seq, now)
                    self._cond.notify_all()
                    return
            self.wrong += 1
            if len(self.wrong_examples) < 5:
                example = np.array2string(value, precision=6, threshold=40)
                if self._expected and self._expected[0][1].shape == value.shape:
                    seq, oldest = self._expected[0]
                    scale = max(float(np.abs(oldest).max()), self._atol)
                    example += (f' (max difference to the oldest expected, of input {seq}: '
                                f'{float(np.abs(value - oldest).max()) / scale:.3g} relative)')
                self.wrong_examples.append(example)
            self._cond.notify_all()

    def outstanding(self) -> int:
        with self._cond:
            return len(self._expected)

    def wait_outstanding(self, at_most: int, timeout: float) -> bool:
        """Wait until at most ``at_most`` expectations are open; False on timeout."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self._expected) > at_most:
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return True

    def restart(self) -> None:
        """Forget every expectation and count (after a :meth:`NodeFuzzer.prime`)."""
        with self._cond:
            self._expected.clear()
            self.received = self.matched = self.missing = self.wrong = 0
            self.skipped.clear()
            self.wrong_examples.clear()

    def give_up(self, keep: int = 0) -> int:
        """Count the oldest open expectations beyond ``keep`` as missing; returns how many."""
        with self._cond:
            n = max(0, len(self._expected) - keep)
            for _ in range(n):
                self.skipped.append(self._expected.popleft()[0])
            self.missing += n
            return n


class NodeFuzzer:
    """Drives a running node with :mod:`fuzz_inputs` cases over the real middleware and counts.

    Topic inputs are predicted by a :class:`fuzz_inputs.TopicOracle` and the node's
    ``~/stiffness`` and ``~/wrench`` are matched to the predictions by value
    (:class:`StreamMatcher`): a message that matches no valid input is a wrong publication, a
    valid input without its message is missing. Before a pose or rest lengths (whose answer
    depends on the node's state) the fuzzer waits until the node has answered everything sent:
    the node orders inputs per topic only. Service answers are judged by the ``check_*``
    functions of :mod:`fuzz_inputs`, one worker thread per service, while screws keep streaming.
    ``rate``: topic inputs per second at most; ``window``: answers outstanding at most;
    ``track_latency``: keep ``(sent, latency)`` of every matched ``~/stiffness`` in
    ``latencies`` (time.perf_counter seconds).
    """

    def __init__(self, ros: RosClient, proc: NodeProcess, base: str, oracle: Any, planar: Any,
                 rate: float = 1000.0, window: int = 50, timeout: float = 10.0,
                 track_latency: bool = False) -> None:
        from geometry_msgs.msg import PoseStamped, WrenchStamped
        from std_msgs.msg import Float64MultiArray
        from tensegrity_stiffness.srv import (
            PlanarForwardKinematics,
            PlanarInverseKinematics,
            SolveEquilibrium,
        )

        from support import fuzz_inputs
        from tensegrity_stiffness.ros import conversions

        self.fi = fuzz_inputs
        self.ros, self.proc, self.base = ros, proc, base
        self.oracle, self.planar = oracle, planar
        self.period = 1.0 / rate
        self.window, self.timeout = window, timeout
        self.sent_at: dict[int, float] = {}
        self.latencies: list[tuple[float, float]] = []
        self.track_latency = track_latency
        self.stiffness = StreamMatcher(lambda m: m.data, self._matched if track_latency else None)
        self.wrench = StreamMatcher(lambda m: conversions.msg_to_wrench(m.wrench))
        ros.subscribe_callback(Float64MultiArray, f'{base}/stiffness', self.stiffness, DEEP)
        ros.subscribe_callback(WrenchStamped, f'{base}/wrench', self.wrench, DEEP)
        self.publishers = {
            'screw': ros.publisher(Float64MultiArray, f'{base}/screw', DEEP),
            'pose': ros.publisher(PoseStamped, f'{base}/pose', DEEP),
            'rest_lengths': ros.publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED),
        }
        self.clients = {
            'forward': ros.client(PlanarForwardKinematics, f'{base}/planar_forward_kinematics'),
            'inverse': ros.client(PlanarInverseKinematics, f'{base}/planar_inverse_kinematics'),
            'equilibrium': ros.client(SolveEquilibrium, f'{base}/solve_equilibrium'),
        }
        for pub in self.publishers.values():
            ros.wait_for_subscribers(pub)
        for topic in ('stiffness', 'wrench'):
            ros.wait_for_publishers(f'{base}/{topic}')
        self.seq = 0
        self._next_send = time.perf_counter()
        self._lock = threading.Lock()
        self.sent: Counter[str] = Counter()  # '<target> valid' / '<target> invalid'
        self.case_of: dict[int, str] = {}  # seq -> '<target>/<kind> (<phase>)' of answered inputs
        self.phase = 'topics'
        self.kinds: Counter[str] = Counter()  # '<target>/<kind>'
        self.requests: Counter[str] = Counter()
        self.failed_valid: Counter[str] = Counter()  # valid requests answered success: false
        self.wrong_answers = 0
        self.wrong_answer_examples: list[str] = []
        self.generator_errors: list[str] = []  # must_reject cases the oracle accepts
        self.sync_timeouts = 0
        self.primed = 0  # inputs sent by prime(), not counted

    def _matched(self, seq: int, arrived: float) -> None:
        sent = self.sent_at.pop(seq, None)
        if sent is not None:
            self.latencies.append((sent, arrived - sent))

    # -------------------------------------------------------------- topics
    def _pace(self) -> None:
        """At most ``rate`` inputs per second and ``window`` answers outstanding."""
        if not self.stiffness.wait_outstanding(self.window, self.timeout):
            self.sync_timeouts += 1
            self.stiffness.give_up(self.window)
            self.wrench.give_up(self.window)
        now = time.perf_counter()
        if self._next_send > now:
            time.sleep(self._next_send - now)
        self._next_send = max(self._next_send + self.period, time.perf_counter() - 0.05)

    def sync(self) -> None:
        """Wait until every input sent so far has been answered (or give up after timeout)."""
        for matcher in (self.stiffness, self.wrench):
            if not matcher.wait_outstanding(0, self.timeout):
                self.sync_timeouts += 1
                matcher.give_up()

    def send(self, case: Any) -> bool:
        """Publish one topic case; True if the oracle expects an answer."""
        msg = self.fi.to_message(case)
        if case.target != 'screw':
            self.sync()  # the node's state (last screw, rest lengths) is the oracle's now
        before = self.oracle.model
        out = self.oracle.predict(case, msg)
        if case.must_reject and (out is not None or self.oracle.model is not before):
            self.generator_errors.append(f'{case.target}/{case.kind}')
        self._pace()
        self.seq += 1
        if out is not None:
            self.case_of[self.seq] = f'{case.target}/{case.kind} ({self.phase})'
            self.stiffness.expect(self.seq, out.stiffness)
            self.wrench.expect(self.seq, out.wrench)
            if self.track_latency:
                self.sent_at[self.seq] = time.perf_counter()
        self.publishers[case.target].publish(msg)
        self.sent[f'{case.target} {"valid" if out is not None else "invalid"}'] += 1
        self.kinds[f'{case.target}/{case.kind}'] += 1
        if case.target != 'screw':
            if out is not None:
                self.sync()
            elif self.oracle.model is not before:  # state changed, nothing to wait for
                time.sleep(0.05)
        return out is not None

    def prime(self, cases: Iterator[Any], timeout: float = 60.0, quiet: float = 0.3) -> None:
        """Before anything is counted: send ``cases`` (valid screws) until both outputs answered
        one, then until none came for ``quiet`` s, and start every count afresh. A fresh node
        fills a topic only while it sees a subscriber, and its view of the graph can lag this
        client's by seconds: its first answers may never be sent."""
        deadline = time.monotonic() + timeout
        while self.stiffness.received == 0 or self.wrench.received == 0:
            if time.monotonic() > deadline:
                raise AssertionError(f'no answer within {timeout:g} s: {self.proc.log()[-1500:]}')
            self.send(next(cases))
            self.primed += 1
            time.sleep(0.05)
        last = -1
        while last != (self.stiffness.received, self.wrench.received):
            last = (self.stiffness.received, self.wrench.received)
            time.sleep(quiet)
        for matcher in (self.stiffness, self.wrench):
            matcher.restart()
        self.sent.clear()
        self.kinds.clear()
        self.case_of.clear()
        self.sent_at.clear()
        self.latencies.clear()

    def run_topics(self, cases: Iterable[Any]) -> None:
        for case in cases:
            self.send(case)
        self.sync()

    # -------------------------------------------------------------- services
    def _serve(self, target: str, cases: list[Any], model: Any) -> None:
        check = {'forward': lambda c, r: self.fi.check_forward(self.planar, c, r),
                 'inverse': lambda c, r: self.fi.check_inverse(self.planar, c, r),
                 'equilibrium': lambda c, r: self.fi.check_equilibrium(model, c, r)}[target]
        client = self.clients[target]
        for case in cases:
            response = self.ros.call(client, self.fi.to_message(case), timeout=60.0)
            verdict = check(case, response)
            with self._lock:
                self.requests[target] += 1
                self.kinds[f'{target}/{case.kind}'] += 1
                if verdict is not None:
                    self.wrong_answers += 1
                    if len(self.wrong_answer_examples) < 10:
                        self.wrong_answer_examples.append(f'{target}/{case.kind}: {verdict}')
                elif not response.success and not case.must_reject:
                    self.failed_valid[f'{target}/{case.kind}'] += 1

    def run_services(self, cases: Iterable[Any], screws: Iterator[Any]) -> None:
        """Answer ``cases`` (one worker thread per service) while ``screws`` stream on."""
        self.sync()
        self.phase = 'services'
        model = self.oracle.model  # constant meanwhile: only screws are sent
        by_target: dict[str, list[Any]] = {}
        for case in cases:
            by_target.setdefault(case.target, []).append(case)
        errors: list[BaseException] = []

        def work(target: str, items: list[Any]) -> None:
            try:
                self._serve(target, items, model)
            except BaseException as exc:  # reported by the caller
                errors.append(exc)

        workers = [threading.Thread(target=work, args=item, daemon=True)
                   for item in by_target.items()]
        for w in workers:
            w.start()
        while any(w.is_alive() for w in workers):
            case = next(screws, None)
            if case is None:
                time.sleep(0.01)
            else:
                self.send(case)
        for w in workers:
            w.join()
        self.sync()
        if errors:
            raise errors[0]

    # -------------------------------------------------------------- summary
    def finish(self, quiet: float = 1.0) -> dict[str, Any]:
        """Wait for the last answers, then ``quiet`` seconds for stray ones; the figures."""
        self.sync()
        time.sleep(quiet)
        messages = sum(self.sent.values())
        return {
            'messages': messages,
            'valid messages': sum(v for k, v in self.sent.items() if k.endswith(' valid')),
            'invalid messages': sum(v for k, v in self.sent.items() if k.endswith('invalid')),
            'sent': dict(sorted(self.sent.items())),
            'requests': sum(self.requests.values()),
            'requests per service': dict(sorted(self.requests.items())),
            'stiffness received': self.stiffness.received,
            'wrench received': self.wrench.received,
            'wrong publications': max(self.stiffness.wrong, self.wrench.wrong),
            'missing answers': max(self.stiffness.missing, self.wrench.missing),
            'missing inputs': [f'{seq}: {self.case_of.get(seq, "?")}' for seq in sorted(
                set(self.stiffness.skipped) | set(self.wrench.skipped))][:10],
            'wrong examples': self.stiffness.wrong_examples + self.wrench.wrong_examples,
            'wrong answers': self.wrong_answers,
            'wrong answer examples': self.wrong_answer_examples,
            'valid requests that failed (allowed)': dict(sorted(self.failed_valid.items())),
            'generator errors': self.generator_errors,
            'sync timeouts': self.sync_timeouts,
            'node alive': self.proc.alive(),
        }


#: The benches' client receive loops (see :func:`receiving`).
CLIENT_LOOPS = ('lane', 'executor')
#: Seconds a bench client spins before each send with ``--pacing spin`` (the rest is slept).
PACING_SPIN_S = 2e-4


def add_client_arguments(parser: Any) -> None:
    """The benches' client options: ``--client-loops`` (:func:`receiving`) and ``--pacing``
    (``sleep``: a timer's way, some 60 us late, no core taken; ``spin``: the last
    :data:`PACING_SPIN_S` spun for an exact rate, which takes most of a core)."""
    parser.add_argument('--client-loops', nargs='+', choices=CLIENT_LOOPS,
                        default=list(CLIENT_LOOPS),
                        help="the client's receiving loop: a lean wait-set loop, or its executor")
    parser.add_argument('--pacing', choices=['sleep', 'spin'], default='sleep',
                        help="the client's send timing: sleep (a timer's, some 60 us late, no "
                             'core taken) or spin the last 0.2 ms (exact rate, takes a core)')


@contextmanager
def collector_paused() -> Iterator[None]:
    """A bench client's measurement window without Python's cyclic garbage collector: what
    earlier runs left is collected and frozen first, and no collection runs inside the window
    (a client in a compiled language has none; a collection of the earlier runs' leftovers
    stalled this one for 100-300 ms and made the node's outputs overflow its reader)."""
    gc.collect()
    gc.freeze()
    gc.disable()
    try:
        yield
    finally:
        gc.enable()


def pacing_spin_s(args: Any) -> float:
    """The ``spin_s`` of :func:`sleep_until` that ``args.pacing`` selects."""
    return PACING_SPIN_S if args.pacing == 'spin' else 0.0


@contextmanager
def receiving(ros: RosClient, subscriptions: Iterable[tuple[Any, str, Callable[[Any], None]]],
              loop: str) -> Iterator[None]:
    """The client's subscriptions ``(msg_type, topic, handler)`` for the duration of the block:
    on its rclpy executor (``loop='executor'``, draining callbacks), or on a lean wait-set loop
    of their own (``'lane'``: the node's :class:`FastLane`, as a compiled controller's loop
    would receive, so that the client's executor does not share the 2 cores with the node)."""
    if loop not in CLIENT_LOOPS:
        raise ValueError(f'loop must be one of {CLIENT_LOOPS}, got {loop!r}')
    lane = FastLane(ros.node, lambda topic, exc: print(f'client lane {topic}: {exc!r}')) \
        if loop == 'lane' else None
    for msg_type, topic, handler in subscriptions:
        if lane is not None:
            lane.create_subscription(msg_type, topic, handler, RELIABLE)
        else:
            ros.subscribe_callback(msg_type, topic, handler)
    if lane is not None:
        lane.start()
    try:
        yield
    finally:
        if lane is not None:
            lane.stop()


#: Seconds a bench waits between the node being reachable and the start of its stream (the
#: node's solver process warms up: imports numpy and scipy and solves once).
BENCH_SETTLE_S = 3.0


class ControllerInbox(Inbox):
    """An :class:`Inbox` that keeps each message's ``values(msg)`` and hands them to
    ``work(values)`` (a controller's use of them, e.g. ``-K e``) in the receive callback."""

    def __init__(self, values: Callable[[Any], Any],
                 work: Callable[[Any], Any] | None = None) -> None:
        super().__init__()
        self._values, self._work = values, work
        self.last_work: Any = None

    def __call__(self, msg: Any) -> None:
        value = self._values(msg)
        if self._work is not None:
            self.last_work = self._work(value)
        super().__call__(value)


def stream_latencies(ros: RosClient, publisher: Any, output: tuple[Any, str], messages: list[Any],
                     expected: Any, rate: float, loop: str, spin_s: float,
                     values: Callable[[Any], Any] = lambda m: np.asarray(m.data),
                     work: Callable[[Any], Any] | None = None,
                     others: Iterable[tuple[Any, str]] = (),
                     settle_s: float = BENCH_SETTLE_S) -> tuple[list[float], int, int]:
    """The benches' topic latency: publish ``messages`` on ``publisher`` at ``rate`` Hz while
    the client receives ``output`` (``(msg_type, topic)``) on ``loop`` (:func:`receiving`;
    ``others``: more topics taken and dropped), each message's ``values`` kept (and handed to
    ``work``); each output matched in order to ``expected`` (:func:`latencies_in_order`).
    Returns (latencies, sent, drops)."""
    inbox = ControllerInbox(values, work)
    ros.wait_for_subscribers(publisher)
    ros.wait_for_publishers(output[1])
    handlers = [(output[0], output[1], inbox),
                *((t, topic, lambda _msg: None) for t, topic in others)]
    with receiving(ros, handlers, loop):
        time.sleep(settle_s)  # a warm-up to skip, not a state to wait for
        with collector_paused():
            sent_at = publish_paced(publisher, messages, rate, spin_s, lambda: len(inbox))
    latencies = latencies_in_order(list(inbox.messages), list(inbox.times), expected, sent_at)
    n = len(messages)
    return latencies, n, n - len(latencies)
