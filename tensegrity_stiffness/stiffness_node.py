"""``stiffness_node``: real-time wrench and stiffness of a tensegrity joint over ROS 2.

Thin layer: validate, convert with :mod:`msg_tools`, call the library, publish. Topics,
services, parameters and QoS are documented in README.md; the conventions (frames, orderings,
signs) in :mod:`tensegrity_stiffness.joint`.

Concurrency: one single-threaded executor runs every callback, so inputs are answered in order
with the least overhead (rclpy's multi-threaded executor dropped 80% of a 1 kHz stream here).
The ``~/screw`` and ``~/pose`` callbacks also take the messages queued behind their own
(:mod:`tensegrity_stiffness.draining_subscription`): rclpy's per-callback cost exceeds the
computation itself.
The equilibrium service is a coroutine: it validates the request, hands the solve (bounded by
``equilibrium.time_budget``) to a worker process (:class:`SolverProcess`) and awaits it, so the
topics keep being served meanwhile. All the configuration a computation needs is one immutable
:class:`NodeConfig`, swapped as a whole when parameters or rest lengths change and read once per
callback: no output mixes two parameter sets.

Robustness: every callback is guarded (an unexpected exception is counted and logged, and a
service answers ``success: false``; nothing reaches the executor, which would end the node); the
outputs of one input are all computed and checked before the first is published; warnings about
bad input are throttled per kind; before ``rclpy.init`` the process bounds the memory that
oversized input messages can pin (see :func:`bound_input_memory`).
"""

from __future__ import annotations

import ctypes
import functools
import gc
import inspect
import math
import multiprocessing
import os
import sys
import tempfile
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, WrenchStamped
from rcl_interfaces.msg import (
    FloatingPointRange,
    IntegerRange,
    ParameterDescriptor,
    SetParametersResult,
)
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
from rclpy.event_handler import PublisherEventCallbacks
from rclpy.exceptions import ParameterUninitializedException
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import (
    DurabilityPolicy,
    HistoryPolicy,
    QoSProfile,
    ReliabilityPolicy,
)
from rclpy.task import Future as RclpyFuture
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

import msg_tools
from tensegrity_stiffness import config
from tensegrity_stiffness.draining_subscription import create_draining_subscription
from tensegrity_stiffness.equilibrium import (
    MAX_NEWTON_ITERATIONS,
    EquilibriumResult,
    is_stable,
    solve_equilibrium,
)
from tensegrity_stiffness.interpretation import interpretation_vector
from tensegrity_stiffness.joint import (
    JointModel,
    JointState,
)
from tensegrity_stiffness.planar import PlanarMechanism
from tensegrity_stiffness.screw import log_se3
from tensegrity_stiffness_interfaces.srv import (
    PlanarForwardKinematics,
    PlanarInverseKinematics,
    SolveEquilibrium,
)

NODE_NAME = 'stiffness_node'
#: Screws with |omega| at or beyond this are outside the chart (G is singular at 2 pi).
CHART_LIMIT = 2.0 * math.pi
#: Warnings about bad input are throttled to one per this many seconds per kind.
WARN_THROTTLE_S = 1.0
#: Window of the input-rate and compute-time statistics in /diagnostics.
STATS_WINDOW = 1000
#: Python's thread switch interval while the node runs (s): a long service solve yields the GIL
#: to the topic thread at least this often (the default, 5 ms, would dominate the p99 latency).
SWITCH_INTERVAL_S = 2e-4

#: Wall-clock time a solve may take beyond ``equilibrium.time_budget`` (process start-up, a
#: loaded machine) before it is abandoned and the solver process replaced.
SOLVER_GRACE_S = 5.0
#: Nice value of the solver process: on a busy machine the kernel favours the node's topic
#: thread (and the stack around it); a solve then gets fewer iterations within its budget.
SOLVER_NICE = 10
#: Run by the solver process when it starts (``exec``: a builtin, so nothing of the node's
#: module is imported there): the nice value above, and SIGINT ignored (Ctrl-C in a terminal
#: reaches the whole process group; the node ends its solver itself).
SOLVER_SETUP = (f'import os, signal; os.nice({SOLVER_NICE}); '
                'signal.signal(signal.SIGINT, signal.SIG_IGN)')
#: glibc ``mallopt`` parameter M_MMAP_THRESHOLD, and the threshold set (bytes).
M_MMAP_THRESHOLD = -3
MMAP_THRESHOLD_BYTES = 128 * 1024
#: Fast DDS profile of the node's process (see :func:`bound_input_memory`): readers allocate a
#: sample's memory when it arrives and free it once it is taken (``DYNAMIC``), instead of the
#: rmw_fastrtps default, a pool of buffers that each grow to the largest sample seen and are kept:
#: with it, a burst of 8 MB messages on a topic of depth 100 pins up to 800 MB for good. Writers,
#: discovery and the publication mode are those rmw_fastrtps sets by default.
FASTDDS_PROFILE = """<?xml version="1.0" encoding="UTF-8" ?>
<profiles xmlns="http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles">
  <participant profile_name="tensegrity_stiffness_participant" is_default_profile="true">
    <rtps>
      <builtin>
        <readerHistoryMemoryPolicy>PREALLOCATED_WITH_REALLOC</readerHistoryMemoryPolicy>
        <writerHistoryMemoryPolicy>PREALLOCATED_WITH_REALLOC</writerHistoryMemoryPolicy>
      </builtin>
    </rtps>
  </participant>
  <data_writer profile_name="tensegrity_stiffness_writer" is_default_profile="true">
    <qos>
      <publishMode><kind>SYNCHRONOUS</kind></publishMode>
      <data_sharing><kind>OFF</kind></data_sharing>
    </qos>
    <historyMemoryPolicy>PREALLOCATED_WITH_REALLOC</historyMemoryPolicy>
  </data_writer>
  <data_reader profile_name="tensegrity_stiffness_reader" is_default_profile="true">
    <qos>
      <data_sharing><kind>OFF</kind></data_sharing>
    </qos>
    <historyMemoryPolicy>DYNAMIC</historyMemoryPolicy>
  </data_reader>
</profiles>
"""
#: Environment variables with which a deployment configures Fast DDS itself (then the node
#: leaves Fast DDS alone).
FASTDDS_ENVIRONMENT = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'FASTDDS_DEFAULT_PROFILES_FILE',
                       'RMW_FASTRTPS_USE_QOS_FROM_XML')

TENSIONS_LABEL = 'tensions [N], strings in config order: '
INTERPRETATION_LABEL = ('stiffness interpretation of K: block Frobenius norms '
                        '[K_fw K_fv K_mw K_mv] (4), column norms [wx wy wz vx vy vz] (6), '
                        'row norms [fx fy fz mx my mz] (6)')
KC_ROW_LABEL = 'rows: wrench [fx fy fz mx my mz]'
KC_COL_LABEL = 'cols: spatial twist in {1} [dx dy dz rx ry rz] (linear first, as ROS)'

JOINT_STRING_ARRAYS = ('node_names', 'link2_node_names', 'string_names', 'string_link1_nodes',
                       'string_link2_nodes')
JOINT_DOUBLE_ARRAYS = ('link1_nodes', 'link2_nodes', 'stiffness', 'rest_lengths', 'max_lengths',
                       'initial_screw')
PLANAR_KEYS = ('L', 'K1', 'K2', 'L3_min', 'L3_max', 'theta1_min', 'theta1_max', 'theta2_min',
               'theta2_max')


class _OutputMessages:
    """One preallocated message per output topic (layouts labelled once, data refilled)."""

    def __init__(self, string_names: tuple[str, ...]) -> None:
        self.string_names = string_names
        n = len(string_names)
        self.wrench = WrenchStamped()
        self.stiffness = msg_tools.matrix_to_multiarray(np.zeros((6, 6)))
        self.cartesian_stiffness = msg_tools.matrix_to_multiarray(np.zeros((6, 6)), KC_ROW_LABEL,
                                                                  KC_COL_LABEL)
        self.tensions = msg_tools.vector_to_multiarray(np.zeros(n),
                                                       TENSIONS_LABEL + ' '.join(string_names))
        self.interpretation = msg_tools.vector_to_multiarray(np.zeros(16), INTERPRETATION_LABEL)


def _guarded(kind: str) -> Callable:
    """Decorator of a topic or timer callback: an unexpected exception is counted and logged
    (throttled) instead of reaching the executor, whose ``spin`` would re-raise it and end the
    node. Nothing has been published by then (outputs are published only once all are built)."""

    def wrap(method: Callable) -> Callable:
        @functools.wraps(method)
        def run(self: StiffnessNode, *args: Any) -> None:
            try:
                method(self, *args)
            except Exception as exc:  # the safety net: no callback may end the node
                self._internal_error(kind, exc)

        return run

    return wrap


def _guarded_service(kind: str) -> Callable:
    """Decorator of a service callback (plain or coroutine): an unexpected exception answers a
    fresh response with ``success: false`` and ``message: 'internal error: ...'``."""

    def failure(self: StiffnessNode, response: Any, exc: Exception) -> Any:
        self._internal_error(kind, exc)
        fresh = type(response)()
        fresh.success = False
        fresh.message = f'internal error: {type(exc).__name__}: {exc}'
        return fresh

    def wrap(method: Callable) -> Callable:
        if inspect.iscoroutinefunction(method):
            @functools.wraps(method)
            async def run_async(self: StiffnessNode, request: Any, response: Any) -> Any:
                try:
                    return await method(self, request, response)
                except Exception as exc:  # the safety net: no callback may end the node
                    return failure(self, response, exc)

            return run_async

        @functools.wraps(method)
        def run(self: StiffnessNode, request: Any, response: Any) -> Any:
            try:
                return method(self, request, response)
            except Exception as exc:  # the safety net: no callback may end the node
                return failure(self, response, exc)

        return run

    return wrap


class SolverProcess:
    """Equilibrium solves in one worker process.

    Not a thread of the node's process: a solve is Python and numpy holding the GIL for its
    whole budget, and the executor thread, which gives the GIL up at every wait and publish,
    then gets it back only after a switch interval each time (the convoy effect): measured here,
    back-to-back 50 ms solves on a thread cut a 1 kHz screw stream to about 250 Hz, with 100 ms
    latency and drops. Spawned, not forked (the process runs the middleware's threads). The
    result or exception of ``fn`` goes to ``on_result`` / ``on_error`` on a thread of the pool;
    :meth:`restart` abandons a solve that does not come back.
    """

    def __init__(self) -> None:
        self._context = multiprocessing.get_context('spawn')
        self._lock = threading.Lock()
        self._pool = self._new_pool()

    def _new_pool(self) -> Any:
        return self._context.Pool(1, initializer=exec, initargs=(SOLVER_SETUP,))

    def submit(self, fn: Callable, args: tuple, kwargs: dict[str, Any],
               on_result: Callable[[Any], None], on_error: Callable[[BaseException], None]
               ) -> None:
        with self._lock:
            self._pool.apply_async(fn, args, kwargs, callback=on_result,
                                   error_callback=on_error)

    def restart(self) -> None:
        with self._lock:
            old, self._pool = self._pool, self._new_pool()
        old.terminate()

    def close(self) -> None:
        with self._lock:
            self._pool.terminate()


@dataclass(frozen=True)
class NodeConfig:
    """Everything one computation needs, swapped as a whole (never mutated)."""

    model: JointModel
    planar: PlanarMechanism
    link1_frame: str
    link2_frame: str
    max_array_length: int
    equilibrium_time_budget: float
    equilibrium_max_iterations: int
    marker_period: float
    generation: int


class StiffnessNode(Node):
    """Publishes wrench, K, K_c, tensions, interpretation, markers and diagnostics per input."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self._declare_parameters()
        self._config = self._config_from_parameters({}, generation=0)
        self._state_lock = threading.Lock()
        self._last_screw: np.ndarray | None = None
        self._last_stamp = None
        self._last_solution: np.ndarray | None = None
        self._last_marker_time = -math.inf
        self._last_state: JointState | None = None
        self._input_times: deque[float] = deque(maxlen=STATS_WINDOW)
        self._compute_times: deque[float] = deque(maxlen=STATS_WINDOW)
        self._rejected: dict[str, int] = {}
        self._warned: dict[str, tuple[float, int]] = {}
        self._published = 0
        self._outputs: _OutputMessages | None = None
        self._solver = SolverProcess()
        self._wake = self.create_guard_condition(lambda: None)
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

        depth = self.get_parameter('qos.depth').value
        reliability = self.get_parameter('qos.input_reliability').value
        input_qos = QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=depth,
            reliability=(ReliabilityPolicy.BEST_EFFORT if reliability == 'best_effort'
                         else ReliabilityPolicy.RELIABLE),
            durability=DurabilityPolicy.VOLATILE)
        # Rest lengths are state: reliable + transient local, so that a restarted node gets the
        # latest value from a latched publisher.
        latched_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                                 reliability=ReliabilityPolicy.RELIABLE,
                                 durability=DurabilityPolicy.TRANSIENT_LOCAL)
        output_qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth,
                                reliability=ReliabilityPolicy.RELIABLE,
                                durability=DurabilityPolicy.VOLATILE)

        # Outputs without rclpy's default QoS-event handlers: each is one more waitable that
        # the executor rebuilds its wait set with before every callback (14 for these 7
        # publishers, a third of the per-message executor cost measured here); an incompatible
        # subscriber is still reported on its own side. The inputs keep theirs.
        def publisher(msg_type: Any, topic: str, qos: QoSProfile | int) -> Any:
            return self.create_publisher(
                msg_type, topic, qos,
                event_callbacks=PublisherEventCallbacks(use_default_callbacks=False))

        self._pub_wrench = publisher(WrenchStamped, '~/wrench', output_qos)
        self._pub_stiffness = publisher(Float64MultiArray, '~/stiffness', output_qos)
        self._pub_cartesian = publisher(Float64MultiArray, '~/cartesian_stiffness', output_qos)
        self._pub_tensions = publisher(Float64MultiArray, '~/string_tensions', output_qos)
        self._pub_interpretation = publisher(Float64MultiArray, '~/stiffness_interpretation',
                                             output_qos)
        self._pub_markers = publisher(MarkerArray, '~/markers', output_qos)
        self._pub_diagnostics = publisher(DiagnosticArray, '/diagnostics', 10)

        create_draining_subscription(
            self, Float64MultiArray, '~/screw', self._on_screw, input_qos,
            on_error=lambda exc: self._internal_error('~/screw', exc))
        create_draining_subscription(
            self, PoseStamped, '~/pose', self._on_pose, input_qos,
            on_error=lambda exc: self._internal_error('~/pose', exc))
        self.create_subscription(Float64MultiArray, '~/rest_lengths', self._on_rest_lengths,
                                 latched_qos)
        # Own group: the coroutine holds its group while it awaits the worker; the default group
        # (topics, planar services, timer) stays free.
        self.create_service(SolveEquilibrium, '~/solve_equilibrium', self._on_solve_equilibrium,
                            callback_group=MutuallyExclusiveCallbackGroup())
        self.create_service(PlanarForwardKinematics, '~/planar_forward_kinematics',
                            self._on_planar_forward)
        self.create_service(PlanarInverseKinematics, '~/planar_inverse_kinematics',
                            self._on_planar_inverse)
        self.create_timer(self.get_parameter('diagnostics.period').value,
                          self._publish_diagnostics)
        cfg = self._config
        # Warm the solver process up (imports, first solve) before the first request needs it.
        self._solver.submit(solve_equilibrium, (cfg.model, np.zeros(6)), {'time_budget': 1.0},
                            lambda _: None, lambda _: None)
        self.get_logger().info(
            f'ready: {cfg.model.n_strings} strings, force law {cfg.model.force_law}, '
            f'frames {cfg.link1_frame} -> {cfg.link2_frame}, inputs {reliability} depth {depth}')

    # ------------------------------------------------------------------ parameters
    def _declare_parameters(self) -> None:
        defaults_doc = config.load_yaml(config.packaged_config_path())
        defaults = config.parameters(defaults_doc)
        joint = config.section(defaults_doc, 'joint')

        def describe(text: str, read_only: bool = False, fp_range: tuple | None = None,
                     int_range: tuple | None = None, constraints: str = '') -> ParameterDescriptor:
            d = ParameterDescriptor(description=text, read_only=read_only,
                                    additional_constraints=constraints)
            if fp_range is not None:
                d.floating_point_range = [FloatingPointRange(
                    from_value=float(fp_range[0]), to_value=float(fp_range[1]), step=0.0)]
            if int_range is not None:
                d.integer_range = [IntegerRange(from_value=int(int_range[0]),
                                                to_value=int(int_range[1]), step=1)]
            return d

        joint_docs = {
            'node_names': 'names of the link-1 nodes (string ends refer to them)',
            'link1_nodes': 'link-1 node coordinates in {1}, flat [x y z] per node, m',
            'link2_nodes': 'link-2 node coordinates in {2}, flat [x y z] per node, m '
                           '(empty: same as link1_nodes)',
            'link2_node_names': 'names of the link-2 nodes (empty: same as node_names)',
            'string_names': 'one name per string (orders every per-string array)',
            'string_link1_nodes': 'link-1 node of each string',
            'string_link2_nodes': 'link-2 node of each string',
            'stiffness': 'string stiffness k, N/m, one per string (or one for all)',
            'rest_lengths': 'rest lengths l0, m, one per string',
            'max_lengths': 'maximum lengths lmax, m, one per string (empty: no limit)',
            'initial_screw': 'starting screw [wx wy wz vx vy vz] of equilibrium solves (rad, m)',
        }
        for key in JOINT_STRING_ARRAYS + JOINT_DOUBLE_ARRAYS:
            value = joint.get(key)
            ptype = (Parameter.Type.STRING_ARRAY if key in JOINT_STRING_ARRAYS
                     else Parameter.Type.DOUBLE_ARRAY)
            if value is None or len(value) == 0:
                value = ptype  # typed, no default
            elif ptype == Parameter.Type.DOUBLE_ARRAY:
                value = [float(v) for v in value]
            else:
                value = [str(v) for v in value]
            self.declare_parameter(f'joint.{key}', value, describe(joint_docs[key]))
        self.declare_parameter('joint.force_law', str(joint.get('force_law', 'hooke')),
                               describe('string force law', constraints='hooke | paper'))
        frames = defaults.get('frames', {})
        self.declare_parameter('frames.link1', str(frames.get('link1', 'tensegrity_link1')),
                               describe("link 1's frame: frame_id of every output"))
        self.declare_parameter('frames.link2', str(frames.get('link2', 'tensegrity_link2')),
                               describe("link 2's frame (child frame of ~/pose)"))
        planar = defaults.get('planar', {})
        planar_docs = {
            'L': ('mobile triangle side L (base side 2 L), m', (1e-9, 1e9)),
            'K1': ('stiffness K1 of the spring C2-D2, N/m', (1e-12, 1e12)),
            'K2': ('stiffness K2 of the spring C3-D3, N/m', (1e-12, 1e12)),
            'L3_min': ('actuator length lower bound, m', (0.0, 1e9)),
            'L3_max': ('actuator length upper bound, m (default 2 L)', (1e-9, 1e9)),
            'theta1_min': ('actuator angle lower bound, rad', (-2 * math.pi, 2 * math.pi)),
            'theta1_max': ('actuator angle upper bound, rad', (-2 * math.pi, 2 * math.pi)),
            'theta2_min': ('platform angle lower bound, rad', (-2 * math.pi, 2 * math.pi)),
            'theta2_max': ('platform angle upper bound, rad', (-2 * math.pi, 2 * math.pi)),
        }
        planar_defaults = {'L': 1.0, 'K1': 100.0, 'K2': 10.0, 'L3_min': 0.0, 'L3_max': 2.0,
                           'theta1_min': 0.0, 'theta1_max': math.pi, 'theta2_min': 0.0,
                           'theta2_max': math.pi}
        for key in PLANAR_KEYS:
            text, rng = planar_docs[key]
            self.declare_parameter(f'planar.{key}', float(planar.get(key, planar_defaults[key])),
                                   describe(text, fp_range=rng))
        self.declare_parameter('qos.depth', int(defaults.get('qos', {}).get('depth', 10)),
                               describe('history depth of inputs and outputs', read_only=True,
                                        int_range=(1, 10_000)))
        self.declare_parameter(
            'qos.input_reliability',
            str(defaults.get('qos', {}).get('input_reliability', 'reliable')),
            describe('QoS reliability of ~/screw and ~/pose', read_only=True,
                     constraints='reliable | best_effort'))
        self.declare_parameter('limits.max_array_length',
                               int(defaults.get('limits', {}).get('max_array_length', 1024)),
                               describe('longer Float64MultiArray inputs are rejected unread',
                                        int_range=(6, 1_000_000)))
        eq = defaults.get('equilibrium', {})
        self.declare_parameter('equilibrium.time_budget', float(eq.get('time_budget', 0.05)),
                               describe('wall-clock budget of one equilibrium solve, s',
                                        fp_range=(1e-4, 10.0)))
        self.declare_parameter('equilibrium.max_iterations',
                               int(eq.get('max_iterations', MAX_NEWTON_ITERATIONS)),
                               describe('Newton iterations per solve stage',
                                        int_range=(1, 10_000)))
        self.declare_parameter('markers.max_rate',
                               float(defaults.get('markers', {}).get('max_rate', 0.0)),
                               describe('highest ~/markers rate, Hz (0: one per input)',
                                        fp_range=(0.0, 10_000.0)))
        self.declare_parameter('diagnostics.period',
                               float(defaults.get('diagnostics', {}).get('period', 1.0)),
                               describe('/diagnostics period, s', read_only=True,
                                        fp_range=(0.01, 60.0)))

    def _parameter_values(self, overrides: Mapping[str, Any]) -> dict[str, Any]:
        names = ([f'joint.{k}' for k in JOINT_STRING_ARRAYS + JOINT_DOUBLE_ARRAYS]
                 + ['joint.force_law', 'frames.link1', 'frames.link2']
                 + [f'planar.{k}' for k in PLANAR_KEYS]
                 + ['limits.max_array_length', 'equilibrium.time_budget',
                    'equilibrium.max_iterations', 'markers.max_rate'])
        values = {}
        for name in names:
            try:
                values[name] = self.get_parameter(name).value
            except ParameterUninitializedException:  # typed array without a default
                values[name] = None
        values.update(overrides)
        return values

    def _config_from_parameters(self, overrides: Mapping[str, Any], generation: int,
                                keep_rest_lengths: np.ndarray | None = None) -> NodeConfig:
        """Build (and so validate) a whole configuration; ValueError names the bad field."""
        values = self._parameter_values(overrides)
        section = {key[len('joint.'):]: (list(value) if value is not None else [])
                   for key, value in values.items() if key.startswith('joint.')}
        section['force_law'] = values['joint.force_law']
        model = JointModel.from_dict(section)
        if keep_rest_lengths is not None and keep_rest_lengths.shape == (model.n_strings,):
            model = model.with_rest_lengths(keep_rest_lengths)
        try:
            planar = PlanarMechanism(**{k: values[f'planar.{k}'] for k in PLANAR_KEYS})
        except ValueError as exc:
            raise ValueError(f'planar.{exc}') from None
        for key in ('frames.link1', 'frames.link2'):
            if not str(values[key]).strip():
                raise ValueError(f'{key} must not be empty')
        rate = float(values['markers.max_rate'])
        return NodeConfig(model=model, planar=planar, link1_frame=str(values['frames.link1']),
                          link2_frame=str(values['frames.link2']),
                          max_array_length=int(values['limits.max_array_length']),
                          equilibrium_time_budget=float(values['equilibrium.time_budget']),
                          equilibrium_max_iterations=int(values['equilibrium.max_iterations']),
                          marker_period=0.0 if rate <= 0.0 else 1.0 / rate,
                          generation=generation)

    def _validate_parameters(self, parameters: list[Parameter]) -> SetParametersResult:
        """Validate a parameter change as a whole (no side effects)."""
        try:
            overrides = {p.name: p.value for p in parameters}
            self._config_from_parameters(overrides, generation=-1)
        except Exception as exc:  # ValueError / TypeError name the field; anything else: a bug
            reason = str(exc) if isinstance(exc, (ValueError, TypeError)) else \
                f'internal error: {type(exc).__name__}: {exc}'
            self._warn('parameter change', reason)
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, parameters: list[Parameter]) -> None:
        """After a successful set: swap in the new configuration, keeping topic rest lengths
        unless the change sets joint.rest_lengths itself."""
        names = {p.name for p in parameters}
        try:
            with self._state_lock:
                old = self._config
                keep = None if 'joint.rest_lengths' in names else old.model.rest_lengths
                self._config = self._config_from_parameters({}, old.generation + 1, keep)
        except Exception as exc:  # validated before: only a bug gets here; the old set stays
            self._internal_error('parameters', exc)
            return
        self.get_logger().info(f'parameters applied: {sorted(names)}')
        try:  # an exception here would reach the parameter service, and the executor
            self._republish_last()
        except Exception as exc:  # the safety net: no callback may end the node
            self._internal_error('re-publish', exc)

    # ------------------------------------------------------------------ inputs
    def _reject(self, kind: str, problem: str) -> None:
        self._rejected[kind] = self._rejected.get(kind, 0) + 1
        self._warn(kind, problem)

    def _warn(self, kind: str, problem: str, error: bool = False) -> None:
        """``<kind> rejected: <problem>``, at most once per ``WARN_THROTTLE_S`` per kind; the
        next one says how many were left out."""
        now = time.monotonic()
        last, left_out = self._warned.get(kind, (-math.inf, 0))
        if now - last < WARN_THROTTLE_S:
            self._warned[kind] = (last, left_out + 1)
            return
        self._warned[kind] = (now, 0)
        text = f'{kind} rejected: {problem}' + (
            f' ({left_out} more since the last warning)' if left_out else '')
        # One severity per call site: rclpy raises when a call site changes its severity.
        if error:
            self.get_logger().error(text)
        else:
            self.get_logger().warning(text)

    def _internal_error(self, kind: str, exc: BaseException) -> None:
        """An exception no validation anticipated (a bug): counted and logged, never raised."""
        key = f'{kind} internal error'
        self._rejected[key] = self._rejected.get(key, 0) + 1
        try:
            self._warn(key, f'{type(exc).__name__}: {exc}', error=True)
        except Exception:  # the safety net must not throw itself
            pass

    @_guarded('~/screw')
    def _on_screw(self, msg: Float64MultiArray) -> None:
        cfg = self._config
        try:
            xi = msg_tools.multiarray_to_array(msg, expected_length=6,
                                               max_length=cfg.max_array_length)
            if np.linalg.norm(xi[:3]) >= CHART_LIMIT:
                raise ValueError(f'|omega| = {np.linalg.norm(xi[:3]):.6g} rad is outside the '
                                 f'chart (must be < 2 pi)')
        except ValueError as exc:
            self._reject('~/screw', str(exc))
            return
        self._compute_and_publish(cfg, xi, None, '~/screw')

    @_guarded('~/pose')
    def _on_pose(self, msg: PoseStamped) -> None:
        cfg = self._config
        try:
            frame = msg.header.frame_id
            if frame and frame != cfg.link1_frame:
                raise ValueError(f"header.frame_id '{frame}' is not link 1's frame "
                                 f"'{cfg.link1_frame}'")
            T = msg_tools.pose_to_transform(msg.pose)
            reference = self._last_screw if self._last_screw is not None else \
                cfg.model.initial_screw
            xi = log_se3(T, reference=reference)
        except ValueError as exc:
            self._reject('~/pose', str(exc))
            return
        stamp = msg.header.stamp
        if stamp.sec == 0 and stamp.nanosec == 0:
            stamp = None
        self._compute_and_publish(cfg, xi, stamp, '~/pose')

    @_guarded('~/rest_lengths')
    def _on_rest_lengths(self, msg: Float64MultiArray) -> None:
        with self._state_lock:
            cfg = self._config
            try:
                rest = msg_tools.multiarray_to_array(msg, expected_length=cfg.model.n_strings,
                                                     max_length=cfg.max_array_length)
                model = cfg.model.with_rest_lengths(rest)
            except ValueError as exc:
                self._reject('~/rest_lengths', str(exc))
                return
            self._config = replace(cfg, model=model, generation=cfg.generation + 1)
        self._republish_last()

    def _republish_last(self) -> None:
        with self._state_lock:
            xi, stamp = self._last_screw, self._last_stamp
        if xi is not None:
            self._compute_and_publish(self._config, xi, stamp, 're-publish')

    # ------------------------------------------------------------------ outputs
    def _output_messages(self, cfg: NodeConfig) -> _OutputMessages:
        """Reusable output messages (their layouts depend on the string names only)."""
        names = tuple(cfg.model.string_names)
        if self._outputs is None or self._outputs.string_names != names:
            self._outputs = _OutputMessages(names)
        return self._outputs

    def _compute_and_publish(self, cfg: NodeConfig, xi: np.ndarray, stamp: Any,
                             source: str) -> None:
        start = time.perf_counter()
        # Every output is built and checked before the first is published: an input gets all
        # of its outputs or none.
        try:
            # Overflow shows as a non-finite result, which the msg_tools setters below reject
            # (ValueError naming the output; a non-finite transform makes the wrench NaN).
            with np.errstate(all='ignore'):
                state = cfg.model.evaluate(xi)
                interpretation = interpretation_vector(state.stiffness)
            if stamp is None:
                stamp = self.get_clock().now().to_msg()
            out = self._output_messages(cfg)
            out.wrench.header.stamp = stamp
            out.wrench.header.frame_id = cfg.link1_frame
            msg_tools.set_wrench(out.wrench.wrench, state.wrench)
            msg_tools.set_multiarray_data(out.stiffness, state.stiffness)
            msg_tools.set_multiarray_data(out.cartesian_stiffness, state.cartesian_stiffness)
            msg_tools.set_multiarray_data(out.tensions, state.tensions)
            msg_tools.set_multiarray_data(out.interpretation, interpretation)
            now = time.monotonic()
            markers = None
            if cfg.marker_period == 0.0 or now - self._last_marker_time >= cfg.marker_period:
                markers = self._markers(cfg, state, stamp)
        except ValueError as exc:
            self._reject(source, str(exc))
            return
        self._pub_wrench.publish(out.wrench)
        self._pub_stiffness.publish(out.stiffness)
        self._pub_cartesian.publish(out.cartesian_stiffness)
        self._pub_tensions.publish(out.tensions)
        self._pub_interpretation.publish(out.interpretation)
        if markers is not None:
            self._last_marker_time = now
            self._pub_markers.publish(markers)
        with self._state_lock:
            self._last_screw, self._last_stamp = xi, stamp
            self._last_state = state
        self._published += 1
        self._input_times.append(now)
        self._compute_times.append(time.perf_counter() - start)

    def _markers(self, cfg: NodeConfig, state: JointState, stamp: Any) -> MarkerArray:
        model = cfg.model
        saturation = model.k * model.max_stretch
        top = float(np.max(saturation)) if np.all(np.isfinite(saturation)) else None
        return msg_tools.marker_array(
            model.link1_nodes, model.link2_nodes_in_link1(state.transform), model.connections,
            state.tensions, state.slack, cfg.link1_frame, stamp, max_tension=top)

    # ------------------------------------------------------------------ services
    @_guarded_service('~/solve_equilibrium')
    async def _on_solve_equilibrium(self, request: SolveEquilibrium.Request,
                                    response: SolveEquilibrium.Response
                                    ) -> SolveEquilibrium.Response:
        """Validated here, solved on the worker thread: the executor keeps serving the topics
        while the solve (bounded by ``equilibrium.time_budget``) runs."""
        cfg = self._config
        try:
            for name in ('rest_lengths', 'initial_screw'):
                n = len(getattr(request, name))
                if n > cfg.max_array_length:  # rejected before anything is converted
                    raise ValueError(f'{name}: too many elements: {n} > max_length '
                                     f'{cfg.max_array_length}')
            W = msg_tools.msg_to_wrench(request.external_wrench)
            rest = None
            if len(request.rest_lengths):
                rest = cfg.model.validate_rest_lengths(
                    np.asarray(request.rest_lengths, dtype=np.float64), batched=False)
            if len(request.initial_screw):
                x0 = np.asarray(request.initial_screw, dtype=np.float64)
                if x0.shape != (6,):
                    raise ValueError(f'initial_screw must have 6 values, got {x0.size}')
            else:
                x0 = self._last_solution if self._last_solution is not None else \
                    cfg.model.initial_screw
            x0 = np.asarray(x0, dtype=np.float64)
            if not np.isfinite(x0).all() or np.linalg.norm(x0[:3]) >= CHART_LIMIT:
                raise ValueError('initial_screw must have finite values and |omega| < 2 pi')
            done = RclpyFuture(executor=self.executor)
            settle_lock = threading.Lock()

            def settle(result: Any = None, error: BaseException | None = None) -> None:
                with settle_lock:
                    if done.done():
                        return
                    if error is None:
                        done.set_result(result)
                    else:  # reported to the caller by `await done`
                        done.set_exception(error)
                # The executor polls the awaiting coroutine only when it wakes up: wake it.
                self._wake.trigger()

            limit = cfg.equilibrium_time_budget + SOLVER_GRACE_S

            def overrun() -> None:
                if not done.done():
                    settle(error=TimeoutError(f'no result within {limit:.3g} s'))
                    self._solver.restart()

            watchdog = threading.Timer(limit, overrun)
            watchdog.daemon = True
            watchdog.start()
            self._solver.submit(
                solve_equilibrium, (cfg.model, W),
                {'rest_lengths': rest, 'initial_screw': x0,
                 'time_budget': cfg.equilibrium_time_budget,
                 'max_iterations': cfg.equilibrium_max_iterations},
                lambda result: settle(result=result), lambda error: settle(error=error))
            try:
                result = await done
            finally:
                watchdog.cancel()
        except TimeoutError as exc:
            response.success = False
            response.message = f'solver overran its budget: {exc}; solver restarted'
            self._warn('~/solve_equilibrium', response.message, error=True)
            return response
        except ValueError as exc:
            response.success = False
            response.message = f'invalid request: {exc}'
            self._reject('~/solve_equilibrium', str(exc))
            return response
        return self._fill_equilibrium(response, result)

    def _fill_equilibrium(self, response: SolveEquilibrium.Response,
                          result: EquilibriumResult) -> SolveEquilibrium.Response:
        response.success = bool(result.success)
        response.message = result.message
        response.iterations = int(result.iterations)
        response.residual = float(result.residual) if math.isfinite(result.residual) else -1.0
        if not result.success or result.state is None:
            return response
        state = result.state
        if not (math.isfinite(result.energy) and all(np.isfinite(a).all() for a in (
                result.screw, state.transform, state.wrench, state.stiffness,
                state.cartesian_stiffness, state.tensions))):
            # e.g. a start so far out that the string lengths overflow: F evaluates to 0 there
            response.success = False
            response.message = 'no usable equilibrium: the state at the solution is not finite'
            return response
        response.screw = result.screw.tolist()
        response.pose = msg_tools.transform_to_pose(state.transform)
        response.string_wrench = msg_tools.wrench_to_msg(state.wrench)
        response.stiffness = state.stiffness.ravel().tolist()
        response.cartesian_stiffness = state.cartesian_stiffness.ravel().tolist()
        response.tensions = state.tensions.tolist()
        response.energy = float(result.energy)
        response.stable = bool(result.stable)
        self._last_solution = result.screw
        return response

    @_guarded_service('~/planar_forward_kinematics')
    def _on_planar_forward(self, request: PlanarForwardKinematics.Request,
                           response: PlanarForwardKinematics.Response
                           ) -> PlanarForwardKinematics.Response:
        planar = self._config.planar
        try:
            fk = planar.forward(request.actuator_length, request.actuator_angle)
        except ValueError as exc:
            response.success = False
            response.message = f'invalid request: {exc}'
            return response
        if not fk.actuator_in_range:
            response.success = False
            response.message = (
                f'actuator (L3 = {request.actuator_length:.6g} m, theta1 = '
                f'{request.actuator_angle:.6g} rad) is outside the actuator workspace '
                f'L3 in [{planar.L3_min:.6g}, {planar.L3_max:.6g}], theta1 in '
                f'[{planar.theta1_min:.6g}, {planar.theta1_max:.6g}]')
            return response
        values = (fk.x, fk.y, fk.theta2, fk.stiffness, fk.energy, fk.jacobian_determinant)
        if not all(math.isfinite(v) for v in values) or not np.isfinite(fk.jacobian).all():
            response.success = False
            response.message = 'no isolated equilibrium here (neutral point): every theta2 is ' \
                'an equilibrium'
            return response
        response.success = True
        response.x, response.y = float(fk.x), float(fk.y)
        response.platform_angle = float(fk.theta2)
        response.stiffness = float(fk.stiffness)
        response.energy = float(fk.energy)
        response.stable = bool(fk.stable)
        response.in_range = bool(fk.theta2_in_range)
        response.jacobian = np.asarray(fk.jacobian, dtype=np.float64).ravel().tolist()
        response.jacobian_determinant = float(fk.jacobian_determinant)
        response.singularities = list(fk.singularities)
        notes = []
        if not fk.theta2_in_range:
            notes.append('theta2 outside its allowed range')
        if fk.singularities:
            notes.append('singular: ' + ', '.join(fk.singularities))
        response.message = 'ok' + (' (' + '; '.join(notes) + ')' if notes else '')
        return response

    @_guarded_service('~/planar_inverse_kinematics')
    def _on_planar_inverse(self, request: PlanarInverseKinematics.Request,
                           response: PlanarInverseKinematics.Response
                           ) -> PlanarInverseKinematics.Response:
        try:
            solutions = self._config.planar.inverse(request.x, request.y)
        except ValueError as exc:
            response.success = False
            response.message = f'invalid request: {exc}'
            return response
        response.actuator_length = [float(s.L3) for s in solutions]
        response.actuator_angle = [float(s.theta1) for s in solutions]
        response.platform_angle = [float(s.theta2) for s in solutions]
        response.stiffness = [float(s.stiffness) for s in solutions]
        response.stable = [bool(s.stable) for s in solutions]
        response.success = len(solutions) > 0
        response.message = (f'{len(solutions)} solution(s)' if solutions
                            else f'unreachable: {solutions.reason}')
        return response

    def close_solver(self) -> None:
        self._solver.close()

    # ------------------------------------------------------------------ diagnostics
    @_guarded('diagnostics')
    def _publish_diagnostics(self) -> None:
        cfg = self._config
        with self._state_lock:
            state = self._last_state
        times = list(self._input_times)
        computes = list(self._compute_times)
        now = time.monotonic()
        recent = [t for t in times if now - t <= 1.0]
        values: list[tuple[str, Any]] = [
            ('input rate [Hz]', float(len(recent))),
            ('outputs published', self._published),
            ('compute time mean [us]', 1e6 * float(np.mean(computes)) if computes else 0.0),
            ('compute time max [us]', 1e6 * float(np.max(computes)) if computes else 0.0),
            ('rejected inputs', dict(sorted(self._rejected.items())) or 0),
            ('parameter generation', cfg.generation),
        ]
        level, message = 'OK', 'no input yet'
        if state is not None:
            names = np.array(cfg.model.string_names) if len(cfg.model.string_names) == \
                state.tensions.shape[0] else np.array([str(i) for i in range(len(state.slack))])
            slack = names[state.slack].tolist()
            saturated = names[state.saturated].tolist()
            theta = float(np.linalg.norm(state.screw[:3]))
            Kc = state.cartesian_stiffness
            sym = 0.5 * (Kc + Kc.T)
            diag = np.sqrt(np.abs(np.diag(sym))) + 1e-300
            min_eig = float(np.linalg.eigvalsh(sym / diag[:, None] / diag[None, :])[0])
            stable = is_stable(Kc)
            values += [
                ('slack strings', slack or 'none'),
                ('saturated strings', saturated or 'none'),
                ('chart margin 2pi - |omega| [rad]', CHART_LIMIT - theta),
                ('stability margin (min eig of scaled sym K_c)', min_eig),
                ('condition number of K', float(np.linalg.cond(state.stiffness))),
            ]
            problems = []
            if slack:
                problems.append(f'{len(slack)} slack')
            if saturated:
                problems.append(f'{len(saturated)} saturated')
            if not stable:
                problems.append('not stable')
            if CHART_LIMIT - theta < 0.1:
                problems.append('near the chart limit |omega| = 2 pi')
            level = 'WARN' if problems else 'OK'
            message = ', '.join(problems) if problems else 'all strings taut, stable'
        status = msg_tools.diagnostic_status(f'{self.get_name()}: joint', level, message,
                                             values, hardware_id=cfg.link1_frame)
        self._pub_diagnostics.publish(msg_tools.diagnostic_array(
            [status], self.get_clock().now().to_msg()))


def bound_input_memory() -> Path | None:
    """Keep oversized input messages from growing the process for good; call before the first
    node is created. Returns the Fast DDS profile file written (delete it once the node exists),
    or None.

    * glibc: allocations above ``MMAP_THRESHOLD_BYTES`` always by ``mmap``, so that freeing one
      returns it to the system (by default the threshold rises to the largest block freed, up to
      32 MB, and later 8 MB message buffers stay in the heap).
    * Fast DDS: unless the environment configures Fast DDS itself (``FASTDDS_ENVIRONMENT``),
      readers with per-sample memory (``FASTDDS_PROFILE``), through a profile file and
      ``RMW_FASTRTPS_USE_QOS_FROM_XML=1``; the QoS set in code still apply.
    """
    try:
        ctypes.CDLL(None).mallopt(M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES)
    except (OSError, AttributeError):  # not glibc
        pass
    rmw = os.environ.get('RMW_IMPLEMENTATION') or 'rmw_fastrtps_cpp'
    if not rmw.startswith('rmw_fastrtps') or any(os.environ.get(v) for v in FASTDDS_ENVIRONMENT):
        return None
    fd, name = tempfile.mkstemp(prefix='tensegrity_stiffness_fastdds_', suffix='.xml')
    with os.fdopen(fd, 'w') as f:
        f.write(FASTDDS_PROFILE)
    os.environ['FASTRTPS_DEFAULT_PROFILES_FILE'] = name
    os.environ['RMW_FASTRTPS_USE_QOS_FROM_XML'] = '1'
    return Path(name)


def main(args: list[str] | None = None, *,
         executor_factory: Callable[[], Any] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness stiffness_node``."""
    sys.setswitchinterval(SWITCH_INTERVAL_S)
    profile = bound_input_memory()
    rclpy.init(args=args)
    node = None
    try:
        try:
            node = StiffnessNode()
        finally:  # Fast DDS read the profile when the node's participant was created
            if profile is not None:
                profile.unlink(missing_ok=True)
        # Everything allocated so far (modules, node, config) lives as long as the process:
        # move it out of the collector's reach so that full collections stay short.
        gc.collect()
        gc.freeze()
        executor = (executor_factory or SingleThreadedExecutor)()
        executor.add_node(node)
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        if node is not None:
            node.close_solver()
            node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
