"""The skeleton of the package's streaming nodes (``stiffness_node``, ``spine_node``): a node
declares only what differs (its parameters and settings, its streamed inputs, its outputs and
services); :class:`StreamingNode` wires the rest the same way for both.

Concurrency: the streamed inputs are served in order (or, with ``NEWEST_INPUT_ONLY``, only the
newest of each input's queue, the others counted: the estimators) on a thread of their own
(:mod:`.fast_lane`: rclpy's executor costs more per message than the computation itself; with
``realtime.fast_lane: false`` the executor serves them, draining the queue behind each message).
A single-threaded executor runs everything else. Services that need the solver are coroutines:
they validate the request, hand the work to the worker process (:class:`.SolverWorker`) and
await it, so the topics keep being served meanwhile. All the configuration a computation needs is
one immutable settings object, swapped as a whole when parameters or rest lengths change and read
once per input; outputs are built and published under one lock, so no output mixes two sets and
the two threads never interleave a publication.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable, Iterable, Mapping
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.interpretation import principal_stiffnesses
from tensegrity_stiffness.nodes.layouts import STIFFNESS_EIGENVALUES_LABEL
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.runtime.declared_parameters import ParameterBinding
from tensegrity_stiffness.ros.runtime.draining_subscription import (
    SkippedCounts,
    create_draining_subscription,
)
from tensegrity_stiffness.ros.runtime.fast_lane import FastLane
from tensegrity_stiffness.ros.runtime.last_input import LastInput
from tensegrity_stiffness.ros.runtime.reporting import Reporter, guarded
from tensegrity_stiffness.ros.runtime.solver_worker import SolverWorker, WorkerDiedError
from tensegrity_stiffness.ros.runtime.tf_broadcast import FrameBroadcaster
from tensegrity_stiffness.ros.runtime.topics import (
    LATCHED_QOS,
    create_output_publisher,
    input_qos,
    output_qos,
)
from tensegrity_stiffness.ros.runtime.worker_calls import (
    SOLVER_GRACE_S,
    WorkerCalls,
    answer_worker_failure,
)
from tensegrity_stiffness.ros.services.responses import fail

#: A streamed input: message type, topic, handler (called on the fast lane's thread or by the
#: executor).
Stream = tuple[Any, str, Callable[[Any], None]]


#: Seconds between checks whether ``~/markers`` has a subscriber (the marker timer runs only
#: then; a new subscriber gets its first markers at most this much later).
MARKER_WATCH_PERIOD_S = 0.5


class StreamingNode(Node):
    """Publishes all outputs of every streamed input, under one lock, from one settings object.

    A node declares, as class attributes: ``OUTPUT_TOPICS`` (``(type, topic)`` in the order of
    its messages object's ``messages()``), ``WORKER_NAME``, ``WORKER_FUNCTIONS`` (what its
    services run in the worker: their modules are imported before the worker is ready),
    ``_build_settings(values,
    generation=0)`` (the settings of a whole parameter set; ValueError names the field) and
    ``_output_frame(settings)`` (the frame of the outputs' headers); and the methods
    :meth:`_parameter_table`, :meth:`_streams`, :meth:`_output_messages`, :meth:`_outputs`,
    :meth:`_markers`, :meth:`_keep_topic_rest_lengths`, :meth:`_with_rest_lengths` and
    :meth:`_diagnostic_statuses`, and its frames on ``/tf`` (:meth:`_frame_transforms`,
    :meth:`_static_frame_transforms`: a mixin of :mod:`.tf_broadcast`). Its ``__init__`` calls
    ``super().__init__``, creates its services, then calls :meth:`_start`.
    """

    OUTPUT_TOPICS: tuple[tuple[Any, str], ...] = ()
    #: The topic of the principal stiffnesses of :meth:`_cartesian_stiffness` ('' : none).
    EIGENVALUES_TOPIC = ''
    WORKER_NAME = 'worker'
    #: The functions the node's services run in the worker (their modules preloaded).
    WORKER_FUNCTIONS: tuple[Callable[..., Any], ...] = ()
    #: Whether the node serves solver calls (services): only then does it run a worker process.
    SERVES_SOLVES = True
    #: Whether each streamed input is taken newest only (the older messages queued behind it
    #: passed over and counted on /diagnostics: sensor readings, where only the latest state
    #: matters) instead of every message in order (one output per input).
    NEWEST_INPUT_ONLY = False
    #: The /diagnostics key of the inputs passed over for a newer one, per topic.
    SKIPPED_KEY = 'inputs skipped (a newer one was queued)'
    #: Whether ``~/rest_lengths`` is served on the fast lane (when the node runs one), every
    #: message in order, instead of by the executor: a node that takes a controller's commands
    #: (500 Hz) would otherwise pay an executor wake-up for each (0.35-0.6 ms a callback,
    #: docs/nodes.md "QoS"), competing with its inputs for the GIL.
    REST_LENGTHS_ON_LANE = False
    _build_settings: Callable[..., Any]
    _output_frame: Callable[[Any], str]

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        self.reporter = Reporter(self.get_logger(), context=self.context)
        # Publication lock: the fast lane and the executor both publish; settings are swapped
        # (and re-published) under it too. Re-entrant: a swap re-publishes.
        self._output_lock = threading.RLock()
        self._binding = ParameterBinding(
            self, self._parameter_table(), self._build_settings, self._apply_parameters,
            lambda reason: self.reporter.warn('parameter change', reason))
        self._settings = self._binding.build(self._binding.values())
        self._last = LastInput()
        #: Called with ``(outputs, stamp)`` after every input's outputs are published, under the
        #: output lock: a consumer in the same process (``control_loop``'s controller) takes them
        #: without a topic in between.
        self.output_listeners: list[Callable[[Any, Any], None]] = []
        self._last_solution: np.ndarray | None = None
        self._clock = self.get_clock()
        self._messages = self._output_messages(self._settings)
        self._solver = SolverWorker(
            self.WORKER_NAME, preload=tuple(dict.fromkeys(
                f.__module__ for f in self.WORKER_FUNCTIONS))) if self.SERVES_SOLVES else None
        self._in_worker = WorkerCalls(self, self._solver) if self._solver is not None else None

        values = self._settings.values
        depth = values['qos.depth']
        out_qos = output_qos(depth)
        self._output_publishers = [create_output_publisher(self, t, topic, out_qos)
                                   for t, topic in self.OUTPUT_TOPICS]
        self._pub_markers = create_output_publisher(self, MarkerArray, '~/markers', out_qos)
        self._pub_eigenvalues = create_output_publisher(
            self, Float64MultiArray, self.EIGENVALUES_TOPIC, out_qos) \
            if self.EIGENVALUES_TOPIC else None
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics', 10)
        self._frames = FrameBroadcaster(self)

        qos = input_qos(depth, values['qos.input_reliability'])
        self._lane = FastLane(self, self.reporter.internal_error) \
            if values['realtime.fast_lane'] else None
        self.skipped = SkippedCounts()
        skipped = self.skipped if self.NEWEST_INPUT_ONLY else None
        for msg_type, topic, callback in self._streams():
            if self._lane is not None:
                self._lane.create_subscription(msg_type, topic, callback, qos, skipped)
            else:
                create_draining_subscription(
                    self, msg_type, topic, callback, qos,
                    on_error=lambda exc, t=topic: self.reporter.internal_error(t, exc),
                    skipped=skipped)
        if self._lane is not None and self.REST_LENGTHS_ON_LANE:
            self._lane.create_subscription(Float64MultiArray, '~/rest_lengths',
                                           self._on_rest_lengths, LATCHED_QOS)
        else:
            self.create_subscription(Float64MultiArray, '~/rest_lengths',
                                     self._on_rest_lengths, LATCHED_QOS)

    def _start(self, warm_up: Callable[..., Any], warm_up_args: tuple, summary: str) -> None:
        """After the node's services: the timers, a first job for the worker (``warm_up(
        *warm_up_args, time_budget=1.0)``: imports and a first solve before the first request
        needs them), the fast lane, and the ``ready: <summary>, inputs ...; <kernel>`` log line
        (which implementation of the library evaluates, :func:`kernel.status`)."""
        values = self._settings.values
        self.create_timer(values['diagnostics.period'], self._publish_diagnostics)
        # The marker timer runs only while ~/markers has a subscriber (_watch_markers): each of
        # its ticks costs the executor a wait-set rebuild that competes with the fast lane.
        self._marker_timer = self.create_timer(
            self._settings.marker_period or 1.0, self._publish_markers)
        self._marker_timer.cancel()
        self.create_timer(MARKER_WATCH_PERIOD_S, self._watch_markers)
        if self._solver is not None:
            self._solver.submit(warm_up, warm_up_args, {'time_budget': 1.0},
                                lambda _: None, lambda _: None, deadline_s=1.0 + SOLVER_GRACE_S)
        if self._lane is not None:
            self._lane.start()
        self._send_static_frames(self._settings)
        self.get_logger().info(
            f'ready: {summary}, inputs {values["qos.input_reliability"]} depth '
            f'{values["qos.depth"]}; {kernel.status()}; {self._frames.status}')

    def close(self) -> None:
        """End the fast lane and the worker process (called by the runner before the node is
        destroyed)."""
        if self._lane is not None:
            self._lane.stop()
        if self._solver is not None:
            self._solver.close()

    # ------------------------------------------------------------------ what a node declares
    def _parameter_table(self) -> Iterable[ParameterSpec]:
        """The node's parameters, declared from this table."""
        raise NotImplementedError

    def _streams(self) -> Iterable[Stream]:
        """The streamed inputs (the fast lane's, or draining subscriptions on the executor)."""
        raise NotImplementedError

    def _output_messages(self, settings: Any) -> Any:
        """The preallocated output messages for ``settings`` (``fill``, ``messages()``)."""
        raise NotImplementedError

    def _outputs(self, settings: Any, xi: np.ndarray, wanted: tuple[bool, ...]) -> Any:
        """Every output of the screws ``xi`` (ValueError: nothing is published); those not
        ``wanted`` (:meth:`_wanted_outputs`) need not be computed."""
        raise NotImplementedError

    def _markers(self, settings: Any, state: Any, stamp: Any) -> MarkerArray:
        """The markers of a configuration's ``state``."""
        raise NotImplementedError

    def _keep_topic_rest_lengths(self, old: Any, settings: Any, names: set[str]) -> Any:
        """``settings`` built after a parameter change of ``names``, with the rest lengths of
        ``old`` that a topic set, unless the change sets rest lengths itself."""
        raise NotImplementedError

    def _with_rest_lengths(self, settings: Any, msg: Float64MultiArray) -> Any:
        """``settings`` with the rest lengths of a ``~/rest_lengths`` message (ValueError
        names the problem)."""
        raise NotImplementedError

    def _diagnostic_statuses(self, settings: Any, outputs: Any,
                             values: list[tuple[str, Any]]) -> list[Any]:
        """The /diagnostics statuses of the last ``outputs`` (None: no input yet); ``values``:
        the node's own key-value pairs (input rates, rejections, generation, restarts)."""
        raise NotImplementedError

    def _frame_transforms(self, settings: Any, state: Any) -> tuple[Any, ...]:
        """The frames of a configuration's ``state`` on ``/tf`` (none unless a mixin of
        :mod:`.tf_broadcast` gives them)."""
        return ()

    def _static_frame_transforms(self, settings: Any) -> tuple[Any, ...]:
        """The frames fixed under ``settings``, on ``/tf_static``."""
        return ()

    def _send_static_frames(self, settings: Any) -> None:
        """The fixed frames on ``/tf_static`` (at the start and after a parameter change), with
        ``tf.enabled``."""
        if settings.values['tf.enabled']:
            self._frames.send_static(self._static_frame_transforms(settings),
                                     self._clock.now().to_msg())

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, values: Mapping[str, Any], names: set[str]) -> None:
        """After a successful set: swap in the new settings (and output messages), keeping
        topic rest lengths unless the change sets rest lengths itself, and re-publish the last
        configuration under them; no input is published in between (the output lock)."""
        with self._output_lock:
            try:
                old = self._settings
                settings = self._keep_topic_rest_lengths(
                    old, self._binding.build(values, old.generation + 1), names)
                self._messages = self._output_messages(settings)
                self._settings = settings
                if 'markers.max_rate' in names:
                    self._marker_timer.timer_period_ns = int(
                        1e9 * (settings.marker_period or 1.0))
                    if not self._marker_timer.is_canceled():
                        self._marker_timer.reset()
                    self._watch_markers()  # at once: 0 (one per input) stops the timer
            except Exception as exc:  # validated before: only a bug gets here; the old set stays
                self.reporter.internal_error('parameters', exc)
                return
            self.get_logger().info(f'parameters applied: {sorted(names)}')
            try:  # an exception here would reach the parameter service, and the executor
                self._send_static_frames(settings)
                self._republish_last()
            except Exception as exc:  # the safety net: no callback may end the node
                self.reporter.internal_error('re-publish', exc)

    # ------------------------------------------------------------------ inputs
    @guarded('~/rest_lengths')
    def _on_rest_lengths(self, msg: Float64MultiArray) -> None:
        with self._output_lock:  # the swap and its re-publish, with no input in between
            settings = self._settings
            try:
                updated = self._with_rest_lengths(settings, msg)
            except ValueError as exc:
                self.reporter.reject('~/rest_lengths', str(exc))
                return
            self._settings = replace(updated, generation=settings.generation + 1)
            self._republish_last()

    def _republish_last(self) -> None:
        if self._last.screws is not None:
            self._compute_and_publish(self._last.screws, self._last.stamp, 're-publish')

    # ------------------------------------------------------------------ outputs
    def _compute_and_publish(self, xi: np.ndarray, stamp: Any, source: str) -> None:
        """Build and check every output under the current settings, then publish them all (an
        input gets all of its outputs or none); topics nobody subscribes to are not filled (a
        publication there reaches no one: the outputs are volatile)."""
        with self._output_lock:
            settings = self._settings
            start = time.perf_counter()
            messages = self._messages
            try:
                wanted = self._wanted_outputs(settings)
                outputs = self._outputs(settings, xi, wanted)
                if stamp is None:
                    stamp = self._clock.now().to_msg()
                messages.fill(outputs, stamp, self._output_frame(settings), wanted)
                markers = None
                # one per input while someone subscribes (some 1.5 ms an estimate: issue 37);
                # else _publish_markers
                if settings.marker_period == 0.0 and \
                        self._pub_markers.get_subscription_count() > 0:
                    markers = self._markers(settings, outputs.state, stamp)
                frames = self._frames.message(self._frame_transforms(
                    settings, outputs.state), stamp) if settings.values['tf.enabled'] else None
            except ValueError as exc:
                self.reporter.reject(source, str(exc))
                return
            for publisher, msg, publish in zip(self._output_publishers, messages.messages(),
                                               wanted, strict=True):
                if publish:
                    publisher.publish(msg)
            if markers is not None:
                self._pub_markers.publish(markers)
            if frames is not None:
                self._frames.publish(frames)
            self._publish_eigenvalues(outputs)
            self._publish_extras(settings, xi, outputs)
            self._last.record(xi, stamp, outputs, start)
            for listener in self.output_listeners:
                listener(outputs, stamp)

    def _cartesian_stiffness(self, outputs: Any) -> np.ndarray:
        """The Cartesian stiffness (linear first) whose principal stiffnesses go on
        ``EIGENVALUES_TOPIC``."""
        raise NotImplementedError

    def _publish_eigenvalues(self, outputs: Any) -> None:
        """``EIGENVALUES_TOPIC`` (6 values, :func:`principal_stiffnesses`), while someone
        subscribes (two 3x3 eigenvalue problems: some 20 us)."""
        publisher = self._pub_eigenvalues
        if publisher is None or publisher.get_subscription_count() == 0:
            return
        publisher.publish(conversions.vector_to_multiarray(
            principal_stiffnesses(self._cartesian_stiffness(outputs)),
            STIFFNESS_EIGENVALUES_LABEL))

    def _publish_extras(self, settings: Any, xi: np.ndarray, outputs: Any) -> None:
        """Outputs a node publishes after the per-input ones, only when configured (none by
        default); a problem there is warned about and leaves the input's outputs published."""

    def _wanted_outputs(self, settings: Any) -> tuple[bool, ...]:
        """Which of ``OUTPUT_TOPICS`` to compute, fill and publish under ``settings``: those
        with a subscriber (asked once per input)."""
        return tuple(p.get_subscription_count() > 0 for p in self._output_publishers)

    @guarded('~/markers')
    def _watch_markers(self) -> None:
        """Every :data:`MARKER_WATCH_PERIOD_S`: run the marker timer while ``~/markers`` has a
        subscriber and the markers are rate-limited (``markers.max_rate`` > 0), else stop it."""
        wanted = (self._settings.marker_period != 0.0
                  and self._pub_markers.get_subscription_count() > 0)
        if wanted == self._marker_timer.is_canceled():
            if wanted:
                self._marker_timer.reset()
            else:
                self._marker_timer.cancel()

    @guarded('~/markers')
    def _publish_markers(self) -> None:
        """At most ``markers.max_rate`` Hz, on the executor's thread (markers cost as much as all
        other outputs together, milliseconds for a spine): the last configuration, once. The
        timer runs only while someone listens (:meth:`_watch_markers`)."""
        settings = self._settings
        last = self._last.unmarked()
        if last is None:
            return
        outputs, stamp = last
        self._pub_markers.publish(self._markers(
            settings, outputs.state, stamp if stamp is not None else self._clock.now().to_msg()))

    # ------------------------------------------------------------------ services
    def _invalid_request(self, kind: str, response: Any, exc: ValueError) -> Any:
        """``success: false`` for a request refused as invalid (counted and warned about)."""
        self.reporter.reject(kind, str(exc))
        return fail(response, f'invalid request: {exc}')

    async def _in_worker_or_fail(self, kind: str, response: Any, fn: Callable[..., Any],
                                 args: tuple, kwargs: dict[str, Any], deadline_s: float, *,
                                 may_refuse: bool = False) -> Any:
        """``fn(*args, **kwargs)`` computed in the worker; None when it failed and ``response``
        says why: the worker overran or died, or (``may_refuse``) the library refused the
        request with a ValueError, answered as an invalid request."""
        try:
            return await self._in_worker(fn, args, kwargs, deadline_s)
        except ValueError as exc:
            if not may_refuse:
                raise
            self._invalid_request(kind, response, exc)
        except (TimeoutError, WorkerDiedError) as exc:
            answer_worker_failure(self.reporter, kind, response, exc)
        return None

    # ------------------------------------------------------------------ diagnostics
    @guarded('diagnostics')
    def _publish_diagnostics(self) -> None:
        settings = self._settings
        values: list[tuple[str, Any]] = [
            *self._last.statistics(),
            ('rejected inputs', dict(sorted(self.reporter.rejected.items())) or 0),
            *([(self.SKIPPED_KEY, self.skipped.counts() or 0)] if self.NEWEST_INPUT_ONLY
              else []),
            ('parameter generation', settings.generation),
            ('equilibrium worker restarts', 0 if self._solver is None else self._solver.restarts),
            ('library', 'compiled kernel' if kernel.available() else 'numpy'),
        ]
        statuses = self._diagnostic_statuses(settings, self._last.outputs, values)
        self._pub_diagnostics.publish(conversions.diagnostic_array(
            statuses, self.get_clock().now().to_msg()))
