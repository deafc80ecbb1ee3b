"""What the demos (``twin_demo``, ``control_demo``) share: the package's installed executables,
their namespace, stopping a child node process, and a monitor node spun on a thread of its own.
"""

from __future__ import annotations

import os
import signal
import subprocess
import threading
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

PACKAGE = 'tensegrity_stiffness'
NAMESPACE = '/twin'
#: Seconds a node gets to stop after SIGINT before it is killed.
STOP_TIMEOUT_S = 10.0


def node_executable(name: str) -> str:
    """The installed executable ``name`` of the package (where ``ros2 run`` looks)."""
    from ament_index_python.packages import get_package_prefix

    path = Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE / name
    if not os.access(path, os.X_OK):
        raise SystemExit(f'{path} is not an executable (run scripts/setup_env.sh)')
    return str(path)


def stop_process(process: subprocess.Popen) -> int:
    """SIGINT, then a wait (killed after :data:`STOP_TIMEOUT_S`); the exit status."""
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
        try:
            process.wait(STOP_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait(STOP_TIMEOUT_S)
    return process.returncode


def stop_on_signals() -> threading.Event:
    """An event that SIGINT or SIGTERM sets (a demo's Ctrl-C, or its supervisor's stop): the
    demo's loop ends at it and stops its nodes."""
    stop = threading.Event()
    signal.signal(signal.SIGINT, lambda *_: stop.set())
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    return stop


class BackgroundSpin:
    """A demo's monitor node spun on a thread of its own until ``stop`` is set; :meth:`close`
    ends the thread, the executor, the node and rclpy."""

    def __init__(self, node: Any, stop: threading.Event) -> None:
        self.node = node
        self.executor = SingleThreadedExecutor()
        self.executor.add_node(node)
        self.thread = threading.Thread(target=spin_until_stopped, args=(self.executor, stop),
                                       daemon=True)
        self.thread.start()

    def close(self) -> None:
        self.thread.join(timeout=2.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        rclpy.try_shutdown()


def spin_until_stopped(executor: SingleThreadedExecutor, stop: threading.Event) -> None:
    """Spin ``executor`` until ``stop`` is set or the context shuts down."""
    try:
        while not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
    except (ExternalShutdownException, Exception):
        pass
