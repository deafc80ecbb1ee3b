"""``tensegrity-stiffness record``'s rclpy half (run by
:mod:`tensegrity_stiffness.cli.record_command` as ``python -m tensegrity_stiffness.ros.recorder``
with the command's options): subscribe to a running node's topics, or to named ones, and write
every message into a rosbag2 through rosbags.

* Which topics: with ``--node``, every topic the node publishes or subscribes to (rclpy's graph:
  ``get_publisher_names_and_types_by_node`` / ``get_subscriber_names_and_types_by_node``), less
  ``/rosout`` and ``/parameter_events``; with ``--topics``, those named. The graph is read every
  :data:`DISCOVERY_PERIOD_S`, so a topic whose publisher starts later is recorded from then on.
* A topic is subscribed once it has a publisher, with the QoS its publishers offer (as rosbag2
  records): reliable when all are reliable, else best effort; transient local when all are (a
  latched topic's last message is recorded), else volatile; keep-last :data:`DEPTH`. The offered
  profiles are written into the bag's metadata.
* Each message is taken serialized (``raw=True``: the CDR bytes ``serialize_message`` gives) and
  written with its ROS type name at its receive time (the middleware's ``received_timestamp``,
  system clock, ns), in the order the executor delivers them. Types unknown to rosbags' Jazzy
  typestore (whose definitions the bag carries) are named and left out.
* ``--duration`` or SIGINT/SIGTERM (Ctrl-C) stops it; the bag is closed, a summary printed.
"""

from __future__ import annotations

import argparse
import importlib
import json
import shutil
import signal
import sys
import threading
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from tensegrity_stiffness.cli.common import EXIT_BAD_INPUT, EXIT_NO_SOLUTION, EXIT_OK, PROG
from tensegrity_stiffness.cli.record_command import (
    RECORDED_NODES,
    UNRECORDED_TOPICS,
    add_record_arguments,
    check_record_options,
)
from tensegrity_stiffness.recordings.bag import clear_output
from tensegrity_stiffness.recordings.bag_topics import BagError, jazzy_typestore

#: Seconds between readings of the graph (new topics, new publishers).
DISCOVERY_PERIOD_S = 0.2
#: History depth of every subscription (a loaded machine's executor falling behind a 1 kHz
#: stream keeps a second of it).
DEPTH = 1000


def message_class(type_name: str) -> Any:
    """The rclpy message class of ``pkg/msg/Name`` (ImportError or AttributeError: not
    installed here)."""
    package, kind, name = type_name.split('/')
    return getattr(importlib.import_module(f'{package}.{kind}'), name)


def subscription_qos(endpoints: Sequence[Any]) -> QoSProfile:
    """The QoS that matches every publisher of ``endpoints`` (``TopicEndpointInfo``)."""
    profiles = [e.qos_profile for e in endpoints]
    reliable = all(p.reliability == ReliabilityPolicy.RELIABLE for p in profiles)
    latched = all(p.durability == DurabilityPolicy.TRANSIENT_LOCAL for p in profiles)
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE if reliable
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched
                      else DurabilityPolicy.VOLATILE)


def rosbags_qos(profile: Any) -> Any:
    """rosbags' ``Qos`` of an rclpy ``QoSProfile`` (for the bag's metadata)."""
    from rosbags.interfaces import (
        Qos,
        QosDurability,
        QosHistory,
        QosLiveliness,
        QosReliability,
        QosTime,
    )

    def duration(d: Any) -> Any:
        ns = d.nanoseconds
        return QosTime(sec=ns // 1_000_000_000, nsec=ns % 1_000_000_000)

    return Qos(history=QosHistory(int(profile.history)), depth=profile.depth,
               reliability=QosReliability(int(profile.reliability)),
               durability=QosDurability(int(profile.durability)),
               deadline=duration(profile.deadline), lifespan=duration(profile.lifespan),
               liveliness=QosLiveliness(int(profile.liveliness)),
               liveliness_lease_duration=duration(profile.liveliness_lease_duration),
               avoid_ros_namespace_conventions=profile.avoid_ros_namespace_conventions)


class Recorder:
    """Subscribes to the topics of ``node_name`` in ``namespace`` (None: none) and to
    ``topics`` as their publishers appear (:meth:`discover`), writing every message to the open
    rosbags ``writer``."""

    def __init__(self, node: Any, writer: Any, node_name: str | None, namespace: str,
                 topics: Sequence[str]) -> None:
        self.node = node
        self.writer = writer
        self.typestore = jazzy_typestore()
        self.node_name, self.namespace = node_name, namespace
        self.named = tuple(topics)
        self.counts: dict[str, int] = {}
        self.types: dict[str, str] = {}
        self.skipped: dict[str, str] = {}
        self._subscriptions: list[Any] = []

    @property
    def target(self) -> str:
        """The recorded node's full name ('' without ``--node``)."""
        if self.node_name is None:
            return ''
        return f'{self.namespace.rstrip("/")}/{self.node_name}'

    def node_found(self) -> bool:
        """Whether the node to record is in the graph (True without one)."""
        return self.node_name is None or (self.node_name, self.namespace) in \
            self.node.get_node_names_and_namespaces()

    def wanted(self) -> dict[str, str]:
        """``{topic: type}`` to record now: the node's topics and the named ones the graph
        knows."""
        graph = dict(self.node.get_topic_names_and_types())
        found = {t: types[0] for t, types in graph.items() if t in self.named and types}
        if self.node_name is not None and self.node_found():
            for lister in (self.node.get_publisher_names_and_types_by_node,
                           self.node.get_subscriber_names_and_types_by_node):
                try:
                    endpoints = lister(self.node_name, self.namespace)
                except Exception:  # the node left the graph in between
                    continue
                found.update({t: types[0] for t, types in endpoints
                              if types and t not in UNRECORDED_TOPICS})
        return found

    def discover(self) -> None:
        """Subscribe to every wanted topic not yet recorded that has a publisher."""
        for topic, type_name in sorted(self.wanted().items()):
            if topic in self.types or topic in self.skipped:
                continue
            publishers = self.node.get_publishers_info_by_topic(topic)
            if not publishers:
                continue
            self._subscribe(topic, type_name, publishers)

    def _subscribe(self, topic: str, type_name: str, publishers: Sequence[Any]) -> None:
        if type_name not in self.typestore.types:
            self.skipped[topic] = f"{type_name}: not in rosbags' Jazzy typestore"
            return
        try:
            msg_type = message_class(type_name)
        except (ImportError, AttributeError, ValueError) as exc:
            self.skipped[topic] = f'{type_name}: not importable here ({exc})'
            return
        qos = subscription_qos(publishers)
        connection = self.writer.add_connection(
            topic, type_name, typestore=self.typestore,
            offered_qos_profiles=[rosbags_qos(p.qos_profile) for p in publishers])
        self.types[topic] = type_name
        self.counts[topic] = 0

        def write(raw: bytes, info: Any) -> None:
            self.writer.write(connection, info['received_timestamp'], raw)
            self.counts[topic] += 1

        self._subscriptions.append(
            self.node.create_subscription(msg_type, topic, write, qos, raw=True))
        print(f'{PROG} record: {topic} ({type_name}, {qos.reliability.name.lower()}, '
              f'{qos.durability.name.lower()})', flush=True)

    def summary(self, out: Path, storage: str, seconds: float) -> dict[str, Any]:
        return {'output': str(out), 'storage': storage, 'node': self.target,
                'seconds': seconds, 'messages': dict(self.counts), 'types': dict(self.types),
                'total': sum(self.counts.values()), 'skipped': dict(self.skipped),
                'not_found': [t for t in self.named if t not in self.types
                              and t not in self.skipped]}


def record(args: argparse.Namespace) -> int:
    """Record as the options say (see the module docstring); the exit code."""
    from rosbags.rosbag2 import StoragePlugin, Writer

    check_record_options(args)
    out = Path(args.out)
    clear_output(out, args.overwrite, 'output')
    namespace = '/' + args.namespace.strip('/')
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    rclpy.init(args=None, signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
    node = rclpy.create_node('tensegrity_recorder', start_parameter_services=False)
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    writer = Writer(out, version=9, storage_plugin=StoragePlugin[args.storage.upper()])
    writer.open()
    recorder = Recorder(node, writer, RECORDED_NODES.get(args.node) if args.node else None,
                        namespace, args.topics)
    found = False
    try:
        deadline = time.monotonic() + args.wait
        while not stop.is_set() and not (recorder.node_found() and
                                          (recorder.node_name or recorder.types)):
            if time.monotonic() > deadline:
                what = recorder.target or f'a publisher of {", ".join(args.topics)}'
                print(f'{PROG}: error: record: no {what} in the graph within {args.wait:g} s '
                      f'(ROS_DOMAIN_ID and ROS_AUTOMATIC_DISCOVERY_RANGE as the node\'s?)',
                      file=sys.stderr)
                return EXIT_BAD_INPUT
            recorder.discover()
            executor.spin_once(timeout_sec=DISCOVERY_PERIOD_S)
        found = True
        start = time.monotonic()
        print(f'{PROG} record: recording {recorder.target or "the topics"} into {out} '
              f'({args.storage}); Ctrl-C stops', flush=True)
        next_discovery = start
        while not stop.is_set():
            now = time.monotonic()
            if args.duration is not None and now - start >= args.duration:
                break
            if now >= next_discovery:
                recorder.discover()
                next_discovery = now + DISCOVERY_PERIOD_S
            executor.spin_once(timeout_sec=min(0.05, DISCOVERY_PERIOD_S))
        seconds = time.monotonic() - start
    finally:
        executor.shutdown(timeout_sec=1.0)
        node.destroy_node()
        rclpy.try_shutdown()
        writer.close()
        if not found:  # nothing to record: no bag left behind
            shutil.rmtree(out, ignore_errors=True)
    report = recorder.summary(out, args.storage, seconds)
    _print(report, args.json)
    return EXIT_OK if report['total'] else EXIT_NO_SOLUTION


def _print(report: dict[str, Any], as_json: bool) -> None:
    if as_json:
        print(json.dumps(report, indent=2), flush=True)
        return
    print(f"wrote {report['output']} ({report['storage']}): {report['total']} messages in "
          f"{report['seconds']:.1f} s: "
          + (', '.join(f'{t} {n}' for t, n in report['messages'].items()) or 'none'),
          flush=True)
    for topic, why in report['skipped'].items():
        print(f'  not recorded: {topic} ({why})', flush=True)
    for topic in report['not_found']:
        print(f'  no publisher: {topic}', flush=True)


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m tensegrity_stiffness.ros.recorder OUTPUT [options of record]``."""
    parser = argparse.ArgumentParser(prog=f'{PROG} record')
    add_record_arguments(parser)
    args = parser.parse_args(argv)
    try:
        return record(args)
    except (ValueError, BagError, OSError) as exc:
        print(f'{PROG}: error: {exc}', file=sys.stderr)
        return EXIT_BAD_INPUT


if __name__ == '__main__':
    sys.exit(main())
