"""Test and benchmark harness: start the installed node as a process, talk to it from rclpy.

Real middleware only: the node runs as a separate process started from its colcon install
location (the file ``ros2 run`` would start), and the client is a real rclpy node in a private
context whose executor spins in a background thread (``spin_until_future_complete`` busy-loops
and starves the middleware on 2 cores; see the pypi notes).
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
import time
import uuid
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

REPO = Path(__file__).resolve().parents[1]
PACKAGE = 'tensegrity_stiffness'
EXECUTABLE = 'stiffness_node'

RELIABLE = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def node_executable() -> Path:
    """``<prefix>/lib/tensegrity_stiffness/stiffness_node`` found through the ament index."""
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE / EXECUTABLE
    if not os.access(path, os.X_OK):
        raise FileNotFoundError(f'{path} is not an executable')
    return path


def unique_namespace(prefix: str = 'test') -> str:
    return f'/{prefix}_{uuid.uuid4().hex[:8]}'


class NodeProcess:
    """The node as a child process (environment passed through unchanged, as the wheels'
    bootstrapper needs), with its output in a log file."""

    def __init__(self, namespace: str, params_file: Path | None = None,
                 extra_args: Iterable[str] = (), log_dir: Path | None = None) -> None:
        self.namespace = namespace
        params_file = params_file or REPO / 'config' / 'default_joint.yaml'
        log_dir = log_dir or Path(os.environ.get('TMPDIR', '/tmp'))
        self.log_path = log_dir / f'stiffness_node{namespace.replace("/", "_")}.log'
        self._log = self.log_path.open('w')
        args = [str(node_executable()), '--ros-args', '--params-file', str(params_file),
                '-r', f'__ns:={namespace}', *extra_args]
        self.process = subprocess.Popen(args, stdout=self._log, stderr=subprocess.STDOUT,
                                        env=os.environ.copy())

    def alive(self) -> bool:
        return self.process.poll() is None

    def log(self) -> str:
        self._log.flush()
        return self.log_path.read_text(errors='replace')

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
        if self.alive():
            self.process.kill()
            self.process.wait(10)


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

    def wait_for(self, count: int, timeout: float = 5.0) -> list[Any]:
        """Wait until at least ``count`` messages arrived; returns all of them."""
        deadline = time.monotonic() + timeout
        with self._cond:
            while len(self.messages) < count:
                left = deadline - time.monotonic()
                if left <= 0:
                    raise TimeoutError(f'{len(self.messages)} of {count} messages')
                self._cond.wait(left)
            return list(self.messages)

    def wait_until(self, predicate: Callable[[Any], bool], timeout: float = 5.0) -> Any:
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
        self.node.create_subscription(msg_type, topic, inbox, qos)
        return inbox

    def publisher(self, msg_type: Any, topic: str, qos: QoSProfile = RELIABLE) -> Any:
        return self.node.create_publisher(msg_type, topic, qos)

    def client(self, srv_type: Any, name: str, timeout: float = 20.0) -> Any:
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

    def wait_for_subscribers(self, publisher: Any, count: int = 1, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while publisher.get_subscription_count() < count:
            if time.monotonic() > deadline:
                raise TimeoutError(f'no subscriber on {publisher.topic_name}')
            time.sleep(0.02)

    def wait_for_publishers(self, topic: str, count: int = 1, timeout: float = 20.0) -> None:
        deadline = time.monotonic() + timeout
        while self.node.count_publishers(topic) < count:
            if time.monotonic() > deadline:
                raise TimeoutError(f'no publisher on {topic}')
            time.sleep(0.02)

    def close(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)
