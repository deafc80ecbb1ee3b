"""``record``: a rosbag2 (mcap or sqlite3) of a running node's topics, or of named topics, without
the ``ros2`` CLI: rclpy subscriptions whose serialized messages are written through rosbags with
their ROS type names. Subscribing takes rclpy, which the command line does not import: this module
checks the options and runs the recorder, :mod:`tensegrity_stiffness.ros.recorder`, as a child
process with them (a Ctrl-C reaches it; it closes the bag and exits). docs/recorded_data.md.
"""

from __future__ import annotations

import argparse
import math
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

from tensegrity_stiffness.cli.common import EXIT_BAD_INPUT, PROG, add_json, parse_number

#: ``--node``: the package's nodes by their short name.
RECORDED_NODES = {
    'stiffness': 'stiffness_node',
    'spine': 'spine_node',
    'sim': 'sim_node',
    'estimator': 'estimator_node',
    'spine_estimator': 'spine_estimator_node',
    'controller': 'stiffness_controller',
    'bridge': 'stiffness_bridge',
}
#: Topics every node has that are not its data (left out with ``--node``).
UNRECORDED_TOPICS = ('/rosout', '/parameter_events')
RECORDER_MODULE = 'tensegrity_stiffness.ros.recorder'
STORAGES = ('mcap', 'sqlite3')
#: Seconds ``record`` waits for the node (or a first topic) before it gives up (exit 2).
DEFAULT_WAIT_S = 20.0


def _seconds(text: str) -> float:
    value = parse_number(text)
    if not (math.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'must be a positive number of seconds, got {text!r}')
    return value


def add_record_arguments(p: argparse.ArgumentParser) -> None:
    """The options of ``record`` (the recorder reads them with this parser too)."""
    p.add_argument('out', metavar='OUTPUT', help='rosbag2 folder to write')
    p.add_argument('--node', choices=tuple(RECORDED_NODES),
                   help='record every topic the running node publishes or subscribes to '
                        '(those with a publisher; /rosout and /parameter_events left out): '
                        + ', '.join(f'{k} = {v}' for k, v in RECORDED_NODES.items()))
    p.add_argument('--namespace', default='/', metavar='NS',
                   help="the node's namespace (default /: the node in the root namespace)")
    p.add_argument('--topics', nargs='+', metavar='TOPIC', default=[],
                   help='record these topics (absolute names), with or instead of --node; '
                        'each once it has a publisher, with its type from the graph')
    p.add_argument('--duration', type=_seconds, metavar='S',
                   help='stop after S seconds (default: at Ctrl-C or SIGINT/SIGTERM)')
    p.add_argument('--storage', choices=STORAGES, default='mcap', help='default mcap')
    p.add_argument('--wait', type=_seconds, default=DEFAULT_WAIT_S, metavar='S',
                   help='give up (exit 2) when the node, or with --topics alone a first topic, '
                        f'is not in the graph within S seconds (default {DEFAULT_WAIT_S:g})')
    p.add_argument('--overwrite', action='store_true', help='replace OUTPUT (a rosbag2)')
    add_json(p)


def recorder_argv(args: argparse.Namespace) -> list[str]:
    """``args`` as the recorder's command line (:func:`add_record_arguments`)."""
    argv = [str(args.out), '--namespace', args.namespace, '--storage', args.storage,
            '--wait', repr(args.wait)]
    if args.node:
        argv += ['--node', args.node]
    if args.topics:
        argv += ['--topics', *args.topics]
    if args.duration is not None:
        argv += ['--duration', repr(args.duration)]
    return argv + ['--overwrite'] * args.overwrite + ['--json'] * args.json


def check_record_options(args: argparse.Namespace) -> None:
    """ValueError (exit 2) for options no recording can come from."""
    if not args.node and not args.topics:
        raise ValueError('record: give --node, --topics or both')
    for topic in [args.namespace, *args.topics]:
        if not topic.startswith('/'):
            raise ValueError(f'record: {topic!r} is not an absolute name (starts with /)')
    out = Path(args.out)
    if (out.exists() or out.is_symlink()) and not args.overwrite:
        raise ValueError(f'output {out} exists (use --overwrite to replace it)')


def _cmd_record(args: argparse.Namespace) -> int:
    check_record_options(args)
    child = subprocess.Popen([sys.executable, '-m', RECORDER_MODULE, *recorder_argv(args)])
    # A Ctrl-C reaches both processes; a SIGINT or SIGTERM sent to this one only is passed on.
    handlers = {sig: signal.signal(sig, lambda *_: child.send_signal(signal.SIGINT))
                for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        code = child.wait()
    finally:
        for sig, handler in handlers.items():
            signal.signal(sig, handler)
    if code < 0:
        print(f'{PROG}: record: the recorder ended by signal {-code}', file=sys.stderr)
        return EXIT_BAD_INPUT
    return code


def add_record_parser(sub: Any) -> None:
    """``record``."""
    p = sub.add_parser('record', help="a rosbag2 of a running node's topics (needs rclpy)",
                       description="Record a running node's topics (--node, --namespace) or "
                                   'named topics (--topics) into a rosbag2 (mcap or sqlite3) '
                                   'through rosbags, without the ros2 CLI: rclpy subscriptions, '
                                   'each with the QoS its publishers offer, written as '
                                   'serialized messages with their ROS type names at their '
                                   'receive time. Stops at --duration or Ctrl-C, then closes the '
                                   'bag and prints what it wrote. Exit 0 when a message was '
                                   'written, 1 when none was, 2 on bad input (the node not '
                                   'found).')
    add_record_arguments(p)
    p.set_defaults(handler=_cmd_record)
