"""``sim_node``: the MuJoCo digital twin of a joint or a spine over ROS 2.

Thin layer around :mod:`tensegrity_stiffness.simulation.twin`: it steps the twin on a thread of its
own (paced by the wall clock, or as fast as possible publishing ``/clock``), validates and hands
on the inputs, and publishes the truth in exactly the input formats of ``stiffness_node``
(``~/screw``, ``~/pose``) or ``spine_node`` (``~/screws``, ``~/poses``) and the simulated sensors
with their noise (``~/measured_lengths``, ``~/measured_tensions``, ``~/imu``). Parameters:
:func:`tensegrity_stiffness.nodes.sim_node.sim_node_parameters` (``sim.*``, ``load.*``,
``noise.*``,
``limits.*`` and the model's own, from the same config files as the other nodes).

Inputs are taken by the executor (``~/rest_lengths``, latched as the stiffness node's;
``~/external_wrench``): validated there (bad input: a throttled warning naming the problem, the
twin keeps its state and keeps running) and handed to the stepping thread, which applies them
before its next step. Only the stepping thread touches the simulation.
"""

from __future__ import annotations

import math
import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, PoseStamped, WrenchStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.geometry.validation import require_frame
from tensegrity_stiffness.nodes.frames import (
    FrameTransform,
    joint_frame_transforms,
    spine_frame_transforms,
    spine_tool_transform,
)
from tensegrity_stiffness.nodes.parameter_specs import by_name
from tensegrity_stiffness.nodes.shared_parameters import (
    CHAIN_PARAMETERS,
    rest_length_offsets,
)
from tensegrity_stiffness.nodes.sim_node import (
    SIM_PARAMETERS,
    SimNodeSettings,
    sim_node_parameters,
    sim_node_settings,
)
from tensegrity_stiffness.nodes.spine_node import rest_lengths_input
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.declared_parameters import ParameterBinding
from tensegrity_stiffness.ros.runtime.pacing import SPIN_S  # noqa: F401 (the name kept)
from tensegrity_stiffness.ros.runtime.reporting import Reporter, guarded
from tensegrity_stiffness.ros.runtime.tf_broadcast import FrameBroadcaster
from tensegrity_stiffness.ros.runtime.topics import (
    LATCHED_QOS,
    create_output_publisher,
    input_qos,
    output_qos,
)
from tensegrity_stiffness.ros.runtime.twin_stepping import SteppingTwin
from tensegrity_stiffness.simulation.twin import ChainSimulation, JointSimulation
from tensegrity_stiffness.simulation.twin_model import checked_wrench
from tensegrity_stiffness.simulation.twin_sensors import SensorNoise

NODE_NAME = 'sim_node'
#: Seconds between the questions which outputs have a subscriber (outputs nobody reads are
#: neither filled nor published).
SUBSCRIBERS_PERIOD_S = 0.25
#: Seconds between /diagnostics messages (steps, missed steps, real-time factor, rejections).
DIAGNOSTICS_PERIOD_S = 1.0
#: Label of the measured arrays (string order of the config, joint-major for a spine).
LENGTHS_LABEL = 'measured string lengths [m], string order of the config'
TENSIONS_LABEL = 'measured string tensions [N], string order of the config'


def _declared_layout(node: Node) -> tuple[bool, int]:
    """``sim.spine`` and ``chain.n_joints`` as the parameter file sets them (the table depends
    on them), read before the table is declared."""
    spine_spec = by_name(SIM_PARAMETERS)['sim.spine']
    spine = spine_spec.check(node.declare_parameter(spine_spec.name, False).value)
    node.undeclare_parameter(spine_spec.name)
    if not spine:
        return False, 1
    n_spec = by_name(CHAIN_PARAMETERS)['chain.n_joints']
    n = n_spec.check(node.declare_parameter(n_spec.name, n_spec.default).value)
    node.undeclare_parameter(n_spec.name)
    return True, n


def swing_plane(gravity: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two orthonormal directions normal to ``gravity`` (normal to y of the base without it)."""
    axis = gravity / np.linalg.norm(gravity) if np.any(gravity) else np.array([0.0, 1.0, 0.0])
    helper = np.array([1.0, 0.0, 0.0]) if abs(axis[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    e1 = np.cross(axis, helper)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(axis, e1)


def swing_wrenches(gravity: np.ndarray, origin: np.ndarray) -> np.ndarray:
    """(2, 6): the wrenches ``[e; origin x e]`` of a unit force along each direction of
    :func:`swing_plane` acting at ``origin`` (the swinging load is their combination)."""
    return np.array([np.concatenate([e, np.cross(origin, e)]) for e in swing_plane(gravity)])


class SimNode(SteppingTwin, Node):
    """Steps the twin and publishes its truth and its sensors (see the module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.reporter = Reporter(self.get_logger(), context=self.context)
        spine, n_joints = _declared_layout(self)
        self._binding = ParameterBinding(
            self, sim_node_parameters(spine, n_joints), sim_node_settings,
            self._apply_parameters, lambda reason: self.reporter.warn('parameter change', reason))
        settings = self._binding.build(self._binding.values())
        values = settings.values
        self._use_settings(settings)
        self._period = 1.0 / values['sim.rate']
        self._real_time = values['sim.real_time']
        self._rng = np.random.default_rng(values['noise.seed'])
        self._build_twin(settings, None)
        # Inputs handed from the executor to the stepping thread (one reference each: an
        # assignment is atomic; the thread takes and clears it).
        self._pending_rest: Any = None
        self._pending_settings: tuple[SimNodeSettings, bool] | None = None
        self._topic_wrench = np.zeros(6)
        self._swing_origin = self._load_point()
        self.publications = 0

        depth = values['qos.depth']
        out = output_qos(depth)
        if spine:
            self._pub_truth = create_output_publisher(self, Float64MultiArray, '~/screws', out)
            self._pub_pose = create_output_publisher(self, PoseArray, '~/poses', out)
        else:
            self._pub_truth = create_output_publisher(self, Float64MultiArray, '~/screw', out)
            self._pub_pose = create_output_publisher(self, PoseStamped, '~/pose', out)
        self._pub_lengths = create_output_publisher(self, Float64MultiArray,
                                                    '~/measured_lengths', out)
        self._pub_tensions = create_output_publisher(self, Float64MultiArray,
                                                     '~/measured_tensions', out)
        self._pub_imu = create_output_publisher(self, Imu, '~/imu', out)
        self._pub_clock = None if self._real_time else create_output_publisher(
            self, Clock, '/clock', 10)
        self._wanted_until = -math.inf
        self._wanted_cache: tuple[bool, ...] = ()
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics',
                                                        10)
        self._frames = FrameBroadcaster(self)
        self._send_static_frames()
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        self._diagnosed = (time.perf_counter(), 0, 0.0, 0)
        self.create_subscription(Float64MultiArray, '~/rest_lengths', self._on_rest_lengths,
                                 LATCHED_QOS)
        self.create_subscription(WrenchStamped, '~/external_wrench', self._on_external_wrench,
                                 input_qos(depth, 'reliable'))
        kind = f'spine of {n_joints} joints' if spine else 'joint'
        # Logged before the stepping starts: a client that got its first outputs finds the
        # line in the log (on a busy machine the thread's first publications came first).
        self.get_logger().info(
            f'ready: MuJoCo twin of the {kind}, {values["sim.rate"]:g} Hz '
            f'{"real time" if self._real_time else "as fast as possible (/clock)"}, publishing '
            f'every {values["sim.publish_every"]} steps, max_length {values["sim.max_length"]}; '
            f'{self._frames.status}')
        self._start_stepping('sim_node stepping')

    # ------------------------------------------------------------------ construction
    def _build_twin(self, settings: SimNodeSettings, screws: np.ndarray | None) -> None:
        """The twin at ``screws`` (None: its unloaded configuration); the swinging load's
        wrench directions follow its gravity at the next swing step."""
        options = settings.twin_options()
        if settings.chain is not None:
            self._sim: JointSimulation | ChainSimulation = ChainSimulation(
                settings.chain, initial_screws=screws, **options)
        else:
            self._sim = JointSimulation(settings.model, initial_screw=None if screws is None
                                        else screws[0], **options)
        self._swing_wrenches: np.ndarray | None = None
        self._held_wrench: np.ndarray | None = None  # the topic's wrench object the twin holds

    def _use_settings(self, settings: SimNodeSettings) -> None:
        """The settings in force, the noise model and the reused output messages they fix."""
        self._settings = settings
        self._noise = SensorNoise(**settings.noise())
        n = settings.n_strings
        width = 6 * (settings.chain.n_joints if settings.chain is not None else 1)
        self._msg_truth = conversions.vector_to_multiarray(np.zeros(width),
                                                           conversions.SCREW_LABEL)
        self._msg_lengths = conversions.vector_to_multiarray(np.zeros(n), LENGTHS_LABEL)
        self._msg_tensions = conversions.vector_to_multiarray(np.zeros(n), TENSIONS_LABEL)
        self._msg_imu = conversions.imu_message(settings.imu_frame, self._noise.gyro,
                                              self._noise.accelerometer)

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, values: Any, names: set[str]) -> None:
        """A validated change: swapped in by the stepping thread before its next step; a
        change of the model (``joint*.*``, ``chain.*``) rebuilds the twin at its current
        configuration."""
        try:
            settings = self._binding.build(values)
        except Exception as exc:  # validated before: only a bug gets here; the old set stays
            self.reporter.internal_error('parameters', exc)
            return
        rebuild = any(name.startswith(('joint', 'chain.')) for name in names)
        self._pending_settings = (settings, rebuild)
        self.get_logger().info(f'parameters applied: {sorted(names)}')

    # ------------------------------------------------------------------ inputs
    @guarded('~/rest_lengths')
    def _on_rest_lengths(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            values = conversions.multiarray_to_array(
                msg, expected_length=settings.n_strings,
                max_length=settings.values['limits.max_array_length'])
            if settings.chain is not None:
                rest: Any = list(rest_lengths_input(values, settings.chain))
            else:  # commanded: the twin's rest lengths are c + d (joint.rest_length_offsets)
                rest = settings.model.validate_rest_lengths(
                    values + rest_length_offsets(settings.values, settings.n_strings),
                    batched=False)
            self._sim.validated_rest_lengths(rest)  # the twin's range (its bounds are fixed)
        except ValueError as exc:
            self.reporter.reject('~/rest_lengths', str(exc))
            return
        self._pending_rest = rest

    @guarded('~/external_wrench')
    def _on_external_wrench(self, msg: WrenchStamped) -> None:
        settings = self._settings
        values = settings.values
        try:
            require_frame(msg.header.frame_id, settings.base_frame, 'the base frame')
            W = checked_wrench(conversions.msg_to_wrench(msg.wrench),
                               values['limits.max_force'], values['limits.max_moment'],
                               ('limits.max_force', 'limits.max_moment'))
        except ValueError as exc:
            self.reporter.reject('~/external_wrench', str(exc))
            return
        self._topic_wrench = W

    # ------------------------------------------------------------------ stepping
    def _load_point(self) -> np.ndarray:
        """Where the swinging load hangs: the origin of the last link at the start."""
        sim = self._sim
        pose = sim.link_poses()[-1] if isinstance(sim, ChainSimulation) else sim.pose()
        return pose[:3, 3].copy()

    def _take_inputs(self) -> None:
        pending = self._pending_settings
        if pending is not None:
            self._pending_settings = None
            settings, rebuild = pending
            if rebuild:
                sim = self._sim
                screws = sim.screws() if isinstance(sim, ChainSimulation) else sim.screw()[None]
                self._build_twin(settings, screws)
            self._use_settings(settings)
            self._send_static_frames()
        rest = self._pending_rest
        if rest is not None:
            self._pending_rest = None
            rate = self._settings.values['sim.rest_length_rate']
            try:  # checked on arrival; a model rebuilt since may have other strings
                self._sim.set_rest_lengths(rest, rate=rate if rate > 0.0 else math.inf)
            except ValueError as exc:
                self.reporter.reject('~/rest_lengths', f'{exc} (the model changed)')

    def _wrench_at(self, sim_time: float) -> np.ndarray:
        """The topic's wrench plus the swinging load at ``sim_time``."""
        values = self._settings.values
        amplitude = values['load.swing_amplitude']
        W = self._topic_wrench
        if amplitude <= 0.0:
            return W
        basis = self._swing_wrenches
        if basis is None:  # once per twin: its gravity and the load point are fixed
            basis = self._swing_wrenches = swing_wrenches(self._sim.gravity, self._swing_origin)
        phase = 2.0 * math.pi * sim_time / values['load.swing_period']
        return W + amplitude * (math.cos(phase) * basis[0] + math.sin(phase) * basis[1])

    def _advance(self, n: int) -> None:
        """``n`` steps under the current inputs (the swinging load updated every step)."""
        self._take_inputs()
        sim = self._sim
        if self._settings.values['load.swing_amplitude'] > 0.0:
            for _ in range(n):
                sim.apply_wrench(self._wrench_at(sim.time))
                sim.step()
            self._held_wrench = None
        else:
            # each message brings a new array: hand it on once, not compare it every step
            if self._held_wrench is not self._topic_wrench:
                self._held_wrench = self._topic_wrench
                sim.apply_wrench(self._held_wrench)
            sim.step(n)
        self.steps += n

    def _publish_due(self) -> None:
        self._publish()

    # ------------------------------------------------------------------ outputs
    def _wanted(self) -> tuple[bool, ...]:
        """Which outputs have a subscriber, asked at most every :data:`SUBSCRIBERS_PERIOD_S`
        (each question costs microseconds; a new subscriber waits at most that long)."""
        now = time.perf_counter()
        if now >= self._wanted_until:
            self._wanted_cache = tuple(p.get_subscription_count() > 0 for p in (
                self._pub_truth, self._pub_pose, self._pub_lengths, self._pub_tensions,
                self._pub_imu))
            self._wanted_until = now + SUBSCRIBERS_PERIOD_S
        return self._wanted_cache

    def _frame_transforms(self) -> tuple[FrameTransform, ...]:
        """The twin's frames now: link 1 -> link 2, or base -> every link of the spine."""
        settings, sim = self._settings, self._sim
        if isinstance(sim, ChainSimulation):
            return spine_frame_transforms(settings.base_frame, sim.link_poses())
        return joint_frame_transforms(settings.base_frame, settings.child_frame, sim.pose())

    def _send_static_frames(self) -> None:
        """A spine's tool frame, fixed in link N, on ``/tf_static`` (with ``tf.enabled``)."""
        settings = self._settings
        if settings.chain is not None and settings.values['tf.enabled']:
            self._frames.send_static(
                [spine_tool_transform(settings.base_frame, settings.chain.n_joints,
                                      settings.child_frame, settings.chain.tool)],
                self.get_clock().now().to_msg())

    def _publish(self) -> None:
        settings, sim = self._settings, self._sim
        stamp = self._stamp()
        if self._pub_clock is not None:
            self._pub_clock.publish(Clock(clock=stamp))
        if settings.values['tf.enabled']:
            self._frames.send(self._frame_transforms(), stamp)
        spine = isinstance(sim, ChainSimulation)
        truth, pose, lengths_wanted, tensions_wanted, imu_wanted = self._wanted()
        if truth:
            screws = sim.screws() if spine else sim.screw()
            conversions.set_multiarray_data(self._msg_truth, screws.ravel())
            self._pub_truth.publish(self._msg_truth)
        if pose:
            if spine:
                msg = PoseArray()
                msg.header.stamp = stamp
                msg.header.frame_id = settings.base_frame
                msg.poses = [conversions.transform_to_pose(T) for T in sim.joint_transforms()]
            else:
                msg = PoseStamped()
                msg.header.stamp = stamp
                msg.header.frame_id = settings.base_frame
                msg.pose = conversions.transform_to_pose(sim.pose())
            self._pub_pose.publish(msg)
        noise, rng = self._noise, self._rng
        if lengths_wanted:
            lengths = noise.add(np.ravel(sim.string_lengths()), 'lengths', rng)
            conversions.set_multiarray_data(self._msg_lengths, lengths)
            self._pub_lengths.publish(self._msg_lengths)
        if tensions_wanted:
            tensions = noise.add(np.ravel(sim.tensions()), 'tensions', rng)
            conversions.set_multiarray_data(self._msg_tensions, tensions)
            self._pub_tensions.publish(self._msg_tensions)
        if imu_wanted:
            imu = sim.imu()
            conversions.write_imu(self._msg_imu, noise.add(imu.angular_velocity, 'gyro', rng),
                                noise.add(imu.specific_force, 'accelerometer', rng), stamp)
            self._pub_imu.publish(self._msg_imu)
        self.publications += 1


    @guarded('diagnostics')
    def _publish_diagnostics(self) -> None:
        """The step rate asked for and achieved (steps in the last period: of simulated time
        per wall-clock second in real time, more as fast as possible), steps, missed steps, the
        publication rate, publications, simulated time and the real-time factor of the last
        period, the rejected inputs."""
        now, steps, sim_time = time.perf_counter(), self.steps, self.steps * self._period
        publications = self.publications
        then, steps_then, sim_then, publications_then = self._diagnosed
        self._diagnosed = (now, steps, sim_time, publications)
        elapsed = now - then
        factor = (sim_time - sim_then) / elapsed if elapsed > 0 else 0.0
        step_rate = (steps - steps_then) / elapsed if elapsed > 0 else 0.0
        publication_rate = (publications - publications_then) / elapsed if elapsed > 0 else 0.0
        rejected = self.reporter.rejected
        level = 'WARN' if self.missed_steps and self._real_time else 'OK'
        values = [('step rate [Hz]', 1.0 / self._period), ('achieved step rate [Hz]', step_rate),
                  ('steps', steps), ('missed steps', self.missed_steps),
                  ('publication rate [Hz]', publication_rate),
                  ('publications', publications), ('simulated time', sim_time),
                  ('real-time factor', factor), ('rejected inputs', rejected or 0)]
        message = (f'{steps} steps, {self.missed_steps} missed, real-time factor {factor:.3g}')
        self._pub_diagnostics.publish(conversions.diagnostic_array(
            [conversions.diagnostic_status(
                f'{self.get_fully_qualified_name()}: twin', level, message, values,
                hardware_id=self._settings.base_frame)],
            self.get_clock().now().to_msg()))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness sim_node``."""
    runner.run(SimNode, args)


if __name__ == '__main__':
    main()
