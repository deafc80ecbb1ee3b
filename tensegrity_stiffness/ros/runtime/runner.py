"""Run a node in its own process, from start-up to a clean stop.

``run`` is the body of every executable of the package: it bounds the memory oversized messages
can pin (:mod:`.middleware`), creates the node, moves what lives as long as the process out of the
garbage collector's reach, spins, and on SIGINT or SIGTERM (rclpy's signal handlers shut the
context down; Ctrl-C and supervisors that signal the whole process group alike) closes the node's
workers and exits with status 0. ``--help`` prints the node's usage and starts nothing. A bad
configuration (the node's construction raises one of :data:`CONFIG_ERRORS`) is one line naming
the problem and exit status 2, not a traceback.
"""

from __future__ import annotations

import gc
import signal
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import rclpy
import rclpy.logging
from rclpy.exceptions import ParameterException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor

from tensegrity_stiffness.nodes.parameter_docs import asks_for_help, node_usage
from tensegrity_stiffness.ros.runtime.middleware import bound_input_memory

#: What a node's construction raises for a bad configuration (the settings' ValueError naming the
#: field; rclpy's refusal of a parameter file's value for a declared type or range): reported in
#: one line, and the process exits with :data:`CONFIG_ERROR_EXIT_CODE` (as it does when
#: ``rclpy.init`` refuses the arguments, e.g. a parameter file that is not YAML).
CONFIG_ERRORS = (ValueError, ParameterException)
CONFIG_ERROR_EXIT_CODE = 2
#: Python's thread switch interval while a node runs (s): a thread that holds the GIL (a
#: service, the worker's reader) yields it to the executor thread at least this often (the
#: default, 5 ms, would dominate the p99 latency).
SWITCH_INTERVAL_S = 2e-4


def run(node_factory: Callable[[], Any], args: list[str] | None = None, *,
        executor_factory: Callable[[], Any] | None = None, usage: str | None = None) -> None:
    """Create the node with ``node_factory`` (after ``rclpy.init(args=args)``) and spin it until
    shutdown (also one that lands inside rclpy's own calls); then ``node.close()`` (if it has
    one), destroy it and shut rclpy down. SIGINT is ignored from the clean-up on: ``run`` is the
    last thing its process does. With ``-h``/``--help`` before ``--ros-args`` it prints the
    node's usage (``usage``, else ``nodes.parameter_docs.node_usage``; the node is named by the
    module of ``node_factory``) and returns without starting rclpy. ``node_factory`` may return
    several nodes (a tuple: one process, one executor; each closed and destroyed)."""
    if asks_for_help(sys.argv if args is None else args):
        sys.stdout.write(usage if usage is not None else
                         node_usage(node_factory.__module__.rpartition('.')[2]))
        return
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    profile = bound_input_memory()
    try:
        rclpy.init(args=args)
    except RuntimeError as exc:  # rcl refused the arguments: a parameter file it cannot parse
        if profile is not None:
            profile.unlink(missing_ok=True)
        report_config_error(exc)
        sys.exit(CONFIG_ERROR_EXIT_CODE)
    nodes: tuple[Any, ...] = ()
    config_error = False
    try:
        # The executor before the nodes: a signal once the node said 'ready:' cannot then cut
        # the executor's construction short (rclpy's Executor.__del__ of a half-built executor
        # prints a traceback: AttributeError '_sigint_gc').
        executor = (executor_factory or SingleThreadedExecutor)()
        try:
            made = node_factory()
            nodes = made if isinstance(made, tuple) else (made,)
        except CONFIG_ERRORS as exc:
            config_error = True
            report_config_error(exc)
            return
        finally:  # Fast DDS read the profile when the node's participant was created
            if profile is not None:
                profile.unlink(missing_ok=True)
        # Everything allocated so far (modules, node, settings) lives as long as the process:
        # out of the collector's reach, full collections stay short.
        gc.collect()
        gc.freeze()
        for node in nodes:
            executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # rclpy's signal handler shuts the context down on a thread of its own: a call past its
        # check of the context (the executor's creation, a spin's wait set) raises RCLError, a
        # RuntimeError, instead (ros2/rclpy#398, ros2/ros2cli#854). Anything else is a fault.
        if rclpy.ok():
            raise
    finally:
        # Nothing cuts the clean-up short: the KeyboardInterrupt of the SIGINT that shut the
        # context down can surface after the spin ended by ExternalShutdownException, and a
        # second Ctrl-C may follow; either, raised in close(), left the fast lane's thread
        # running into the interpreter's exit (an abort, exit -6).
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        for node in nodes:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
        if config_error:
            sys.exit(CONFIG_ERROR_EXIT_CODE)


def report_config_error(exc: BaseException) -> None:
    """One line naming the problem of a node's configuration (the executable's name, the
    ValueError of the settings' validation or rclpy's refusal of a parameter's type or range),
    on the log's error stream: no traceback."""
    name = Path(sys.argv[0]).name or 'node'
    text = ' '.join(str(exc).split())
    rclpy.logging.get_logger(name).fatal(f'configuration error: {text}; not started')
