"""``structure_sim_node``: the MuJoCo twin of any structure over ROS 2.

Thin layer around :mod:`tensegrity_stiffness.simulation.structure_twin` (and the scripted roll
of :mod:`tensegrity_stiffness.simulation.structure_gait`): it steps the twin on a thread of its
own (paced by the wall clock, or as fast as possible publishing ``/clock``), validates and hands
on the inputs, and publishes the truth and the simulated sensors with their noise. Parameters:
:data:`tensegrity_stiffness.nodes.structure_sim_node.STRUCTURE_SIM_PARAMETERS`.

The twin starts at rest at the structure's equilibrium on its ground
(:func:`~tensegrity_stiffness.structures.equilibrium.resting_poses`).
Outputs: ``~/poses`` (``geometry_msgs/PoseArray`` in ``frames.world``, the structure's body
order), ``~/measured_lengths``, ``~/measured_tensions`` (load cells), ``~/measured_rest_lengths``
(motor encoders; ``Float64MultiArray``, string order), ``~/measured_contacts`` (1 per body
node on the ground, 0 off it, node order; while someone subscribes), ``~/imu/<bar>``
(``sensor_msgs/Imu`` in the bar's frame, frame_id the bar's name), ``~/measured_markers`` (with
``markers.enabled``),
``/diagnostics`` (centre of mass, contact nodes, slack strings, steps and the real-time factor,
the gait's phase). Inputs (taken by the executor, validated there, applied by the stepping
thread before its next step; bad input: a throttled warning naming the problem, the twin keeps
its state): ``~/rest_lengths`` (``Float64MultiArray``, latched; the motors' targets),
``~/loads`` (``Float64MultiArray`` of 6 values per body: constant wrenches in the world about its
origin), ``~/push`` (``WrenchStamped``, ``header.frame_id`` the body's name, the wrench in the
world about its origin for ``push.duration`` s).

Sensor faults (``faults.*``, at run time: a broken length sensor, a flipped IMU) are staged by the
parameter callback and put into the readings by the stepping thread from its next publication
on; the first publication with them is logged and reported on /diagnostics (``faults``,
``faults since [s]`` in simulated time, ``faults since stamp``: its header stamp).
"""

from __future__ import annotations

import math
import sys
import threading
import time
from dataclasses import replace
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseArray, WrenchStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness.nodes.structure_sim_node import (
    CONTACTS_LABEL,
    ENCODERS_LABEL,
    IDLE,
    LENGTHS_LABEL,
    MARKERS_LABEL,
    NODE_NAME,
    STRUCTURE_SIM_PARAMETERS,
    TENSIONS_LABEL,
    StructureSimSettings,
    TwinReport,
    live_line,
    loads_label,
    structure_sim_settings,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.runtime.declared_parameters import ParameterBinding
from tensegrity_stiffness.ros.runtime.reporting import Reporter, guarded
from tensegrity_stiffness.ros.runtime.topics import (
    LATCHED_QOS,
    create_output_publisher,
    input_qos,
    output_qos,
)
from tensegrity_stiffness.ros.runtime.twin_stepping import SteppingTwin
from tensegrity_stiffness.simulation.structure_gait import (
    DONE,
    REST_SPEED,
    RollGait,
    plan_roll_step,
)
from tensegrity_stiffness.simulation.structure_twin import StructureSimulation
from tensegrity_stiffness.simulation.twin_model import checked_wrench
from tensegrity_stiffness.structures.equilibrium import resting_poses

#: Seconds between /diagnostics messages (and live lines).
DIAGNOSTICS_PERIOD_S = 1.0


class StructureSimNode(SteppingTwin, Node):
    """Steps the structure twin and publishes its truth and sensors (module docstring)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(NODE_NAME, **kwargs)
        self.reporter = Reporter(self.get_logger(), context=self.context)
        self._binding = ParameterBinding(
            self, STRUCTURE_SIM_PARAMETERS, structure_sim_settings, self._apply_parameters,
            lambda reason: self.reporter.warn('parameter change', reason))
        settings: StructureSimSettings = self._binding.build(self._binding.values())
        for line in settings.deprecations:
            self.get_logger().warning(line)
        self._settings = settings
        values = settings.values
        structure = settings.structure
        # The node checks every load and push against its own limits.* (changeable at run
        # time): the twin's own bound would only repeat that check.
        self._sim = StructureSimulation(structure, replace(settings.options, max_force=math.inf,
                                                           max_moment=math.inf),
                                        poses=resting_poses(structure))
        self._period = settings.options.timestep
        self._real_time = values['sim.real_time']
        self._rng = np.random.default_rng(values['noise.seed'])
        self._pending_rest: np.ndarray | None = None
        self._pending_loads: np.ndarray | None = None
        self._pending_pushes: list[tuple[str, np.ndarray, float]] = []
        self._pending_settings: StructureSimSettings | None = None
        # The faults in the published readings: (names, simulated time, stamp) of the first
        # publication with them (the stepping thread's).
        self._faults: tuple[tuple[str, ...], float | None, str] = ((), None, '')
        self.publications = 0
        self._state_line = ''
        # What /diagnostics reports of the twin, taken by the stepping thread at each
        # publication: only that thread touches MuJoCo's data (a contact force runs
        # mj_forwardSkip, which must not run beside mj_step).
        self._twin_report = self._report_of_twin()
        # The gait: planned on a thread of its own (a plan takes a fraction of a second), run
        # by the stepping thread on the twin's contacts.
        self._gait: RollGait | None = None
        self._gait_steps_left = values['gait.steps'] if values['gait.enabled'] else 0
        self._planning: threading.Thread | None = None
        self._planned: Any = None
        self._heading = settings.gait_direction
        self.gait_phase = IDLE
        self.gait_steps_done = 0

        depth = values['qos.depth']
        out = output_qos(depth)
        self._pub_poses = create_output_publisher(self, PoseArray, '~/poses', out)
        self._pub_lengths = create_output_publisher(self, Float64MultiArray,
                                                    '~/measured_lengths', out)
        self._pub_tensions = create_output_publisher(self, Float64MultiArray,
                                                     '~/measured_tensions', out)
        self._pub_encoders = create_output_publisher(self, Float64MultiArray,
                                                     '~/measured_rest_lengths', out)
        self._pub_contacts = create_output_publisher(self, Float64MultiArray,
                                                     '~/measured_contacts', out)
        self._pub_markers = create_output_publisher(self, Float64MultiArray,
                                                    '~/measured_markers', out)
        self._pub_imus = [create_output_publisher(self, Imu, f'~/imu/{name}', out)
                          for name in self._sim.imu_bodies]
        self._pub_clock = None if self._real_time else create_output_publisher(
            self, Clock, '/clock', 10)
        self._pub_diagnostics = create_output_publisher(self, DiagnosticArray, '/diagnostics',
                                                        10)
        self._use_settings(settings)
        self.create_subscription(Float64MultiArray, '~/rest_lengths', self._on_rest_lengths,
                                 LATCHED_QOS)
        self.create_subscription(Float64MultiArray, '~/loads', self._on_loads,
                                 input_qos(depth, 'reliable'))
        self.create_subscription(WrenchStamped, '~/push', self._on_push,
                                 input_qos(depth, 'reliable'))
        self.create_timer(DIAGNOSTICS_PERIOD_S, self._publish_diagnostics)
        self._diagnosed = (time.perf_counter(), 0)
        # Logged before the stepping starts (as sim_node's).
        self.get_logger().info(
            f'ready: MuJoCo twin of {settings.source} ({structure.n_bodies} bodies, '
            f'{structure.n_strings} strings, {len(self._sim.imu_bodies)} IMUs), '
            f'{1.0 / self._period:g} Hz '
            f'{"real time" if self._real_time else "as fast as possible (/clock)"}, publishing '
            f'every {values["sim.publish_every"]} steps'
            + (f'; rolling {values["gait.steps"]} faces' if values['gait.enabled'] else ''))
        self._start_stepping('structure_sim_node stepping')

    def _use_settings(self, settings: StructureSimSettings) -> None:
        """The settings in force and the reused output messages they fix."""
        self._settings = settings
        n = settings.structure.n_strings
        self._msg_lengths = conversions.vector_to_multiarray(np.zeros(n), LENGTHS_LABEL)
        self._msg_tensions = conversions.vector_to_multiarray(np.zeros(n), TENSIONS_LABEL)
        self._msg_encoders = conversions.vector_to_multiarray(np.zeros(n), ENCODERS_LABEL)
        self._msg_contacts = conversions.vector_to_multiarray(
            np.zeros(len(self._sim.marker_names)), CONTACTS_LABEL)
        self._msg_markers = conversions.vector_to_multiarray(
            np.zeros(3 * len(self._sim.marker_names)), MARKERS_LABEL)
        noise = settings.noise
        self._msg_imus = [conversions.imu_message(name, noise.gyro, noise.accelerometer)
                          for name in self._sim.imu_bodies]

    # ------------------------------------------------------------------ parameters
    def _apply_parameters(self, values: Any, names: set[str]) -> None:
        """A validated change (noise, rates, limits, frames): swapped in by the stepping thread
        before its next step (the structure and the pacing are read-only)."""
        try:
            settings = self._binding.build(values)
        except Exception as exc:  # validated before: only a bug gets here; the old set stays
            self.reporter.internal_error('parameters', exc)
            return
        self._pending_settings = settings
        self.get_logger().info(f'parameters applied: {sorted(names)}')

    # ------------------------------------------------------------------ inputs
    @guarded('~/rest_lengths')
    def _on_rest_lengths(self, msg: Float64MultiArray) -> None:
        settings = self._settings
        try:
            values = conversions.multiarray_to_array(
                msg, expected_length=settings.structure.n_strings,
                max_length=settings.values['limits.max_array_length'])
            rest = self._sim.validated_rest_lengths(values)  # its bounds are fixed
        except ValueError as exc:
            self.reporter.reject('~/rest_lengths', str(exc))
            return
        self._pending_rest = rest

    def _checked_wrench(self, wrench: np.ndarray) -> np.ndarray:
        values = self._settings.values
        return checked_wrench(wrench, values['limits.max_force'], values['limits.max_moment'],
                              ('limits.max_force', 'limits.max_moment'))

    @guarded('~/loads')
    def _on_loads(self, msg: Float64MultiArray) -> None:
        structure = self._settings.structure
        try:
            values = conversions.multiarray_to_array(
                msg, expected_length=6 * structure.n_bodies,
                max_length=self._settings.values['limits.max_array_length'])
            W = values.reshape(structure.n_bodies, 6)
            for name, row in zip(structure.body_names, W, strict=True):
                try:
                    self._checked_wrench(row)
                except ValueError as exc:
                    raise ValueError(f'load on {name}: {exc}') from None
        except ValueError as exc:
            self.reporter.reject('~/loads', f'{exc} ({loads_label(structure)})')
            return
        self._pending_loads = W

    @guarded('~/push')
    def _on_push(self, msg: WrenchStamped) -> None:
        structure = self._settings.structure
        try:
            body = msg.header.frame_id
            structure.body_index(body)
            W = self._checked_wrench(conversions.msg_to_wrench(msg.wrench))
        except ValueError as exc:
            self.reporter.reject('~/push', f'{exc} (header.frame_id names the body: '
                                 f'{", ".join(structure.body_names)})')
            return
        self._pending_pushes.append((body, W, self._settings.values['push.duration']))

    # ------------------------------------------------------------------ stepping
    def _advance(self, n: int) -> None:
        """``n`` steps under the inputs taken first."""
        self._take_inputs()
        self._sim.step(n)
        self.steps += n

    def _publish_due(self) -> None:
        """The gait's step, then the truth and the sensors."""
        self._run_gait()
        self._publish()

    def _take_inputs(self) -> None:
        sim = self._sim
        settings = self._pending_settings
        if settings is not None:
            self._pending_settings = None
            self._use_settings(settings)
        rate = self._settings.values['sim.rest_length_rate']
        rest = self._pending_rest
        if rest is not None:
            self._pending_rest = None
            sim.set_rest_lengths(rest, rate=rate if rate > 0.0 else math.inf)
        loads = self._pending_loads
        if loads is not None:
            self._pending_loads = None
            sim.apply_loads(loads)
        while self._pending_pushes:
            body, W, duration = self._pending_pushes.pop(0)
            sim.push(body, W, duration)

    def _plan(self, poses: np.ndarray, direction: np.ndarray) -> None:
        """A roll's plan from ``poses`` (the planning thread)."""
        try:
            self._planned = plan_roll_step(self._settings.structure, poses, direction)
        except Exception as exc:
            self._planned = exc

    def _run_gait(self) -> None:
        """The gait's step (stepping thread): plan when due, then follow the contacts."""
        sim = self._sim
        if self._gait is None:
            if self._gait_steps_left <= 0:
                return
            if self._planning is None:
                self.gait_phase = 'plan'
                direction = (self._settings.gait_direction if self.gait_steps_done == 0
                             else self._heading)
                self._planning = threading.Thread(target=self._plan, args=(
                    sim.poses(), direction), name='structure_sim_node gait plan', daemon=True)
                self._planning.start()
                return
            if self._planning.is_alive():
                return
            planned, self._planning, self._planned = self._planned, None, None
            if isinstance(planned, Exception):
                self.reporter.warn('gait', f'no roll: {planned}')
                self._gait_steps_left, self.gait_phase = 0, IDLE
                return
            if self.gait_steps_done == 0:
                self._heading = planned.com_step
            self._gait = RollGait(planned)
            rate = self._settings.values['sim.rest_length_rate']
            sim.set_rest_lengths(self._gait.start(sim.time), rate=rate if rate > 0 else math.inf)
        gait = self._gait
        settled = not sim.moving and float(np.abs(sim.data.qvel).max()) <= REST_SPEED
        command = gait.update(sim.time, sim.contact_nodes(), settled)
        if command is not None:
            rate = self._settings.values['sim.rest_length_rate']
            sim.set_rest_lengths(command, rate=rate if rate > 0 else math.inf)
        self.gait_phase = gait.phase
        if gait.phase == DONE:
            self._gait = None
            self.gait_steps_done += 1
            self._gait_steps_left = 0 if gait.failed else self._gait_steps_left - 1
            self.gait_phase = 'failed' if gait.failed else IDLE

    # ------------------------------------------------------------------ outputs
    def _publish(self) -> None:
        settings, sim = self._settings, self._sim
        stamp = self._stamp()
        noise, rng, faults = settings.noise, self._rng, settings.faults
        if faults.names != self._faults[0]:
            self._faults = (faults.names, sim.time, f'{stamp.sec}.{stamp.nanosec:09d}')
            self.get_logger().info(
                f'sensor faults: {", ".join(faults.names) or "none"} from the publication at '
                f'simulated time {sim.time:.4f} s (stamp {self._faults[2]}, gait phase '
                f'{self.gait_phase})')
        if self._pub_clock is not None:
            self._pub_clock.publish(Clock(clock=stamp))
        poses = PoseArray()
        poses.header.stamp = stamp
        poses.header.frame_id = settings.world_frame
        poses.poses = [conversions.transform_to_pose(T) for T in sim.poses()]
        self._pub_poses.publish(poses)
        for msg, pub, kind, values in (
                (self._msg_lengths, self._pub_lengths, 'lengths',
                 faults.lengths(settings.structure, sim.string_lengths())),
                (self._msg_tensions, self._pub_tensions, 'tensions', sim.tensions()),
                (self._msg_encoders, self._pub_encoders, 'encoders', sim.rest_lengths)):
            conversions.set_multiarray_data(msg, noise.add(values, kind, rng))
            pub.publish(msg)
        for msg, pub, reading, body in zip(self._msg_imus, self._pub_imus, sim.imus(),
                                           sim.imu_bodies, strict=True):
            sign = faults.imu_sign(body)
            conversions.write_imu(msg, sign * noise.add(reading.angular_velocity, 'gyro', rng),
                                  sign * noise.add(reading.specific_force, 'accelerometer', rng),
                                  stamp)
            pub.publish(msg)
        report = self._twin_report = self._report_of_twin()
        if self._pub_contacts.get_subscription_count():
            touching = set(report.contact_nodes)
            conversions.set_multiarray_data(self._msg_contacts, [
                float(name in touching) for name in sim.marker_names])
            self._pub_contacts.publish(self._msg_contacts)
        if settings.values['markers.enabled']:
            conversions.set_multiarray_data(self._msg_markers,
                                            noise.add(sim.markers(), 'markers', rng).ravel())
            self._pub_markers.publish(self._msg_markers)
        self.publications += 1

    def _report_of_twin(self) -> TwinReport:
        """The twin's state /diagnostics reports (the stepping thread, or ``__init__`` before
        it starts)."""
        sim = self._sim
        slack = tuple(name for name, s in zip(sim.structure.string_names, sim.slack(),
                                              strict=True) if s)
        return TwinReport(sim.time, sim.centre_of_mass(), tuple(sim.contact_nodes()), slack,
                          *self._faults)

    @guarded('diagnostics')
    def _publish_diagnostics(self) -> None:
        """Centre of mass, contact nodes, slack strings, steps and the real-time factor, the
        gait's phase (and a live line with ``--live``), from the stepping thread's last
        report (this timer never touches the twin)."""
        now, steps = time.perf_counter(), self.steps
        then, steps_then = self._diagnosed
        self._diagnosed = (now, steps)
        factor = (steps - steps_then) * self._period / (now - then) if now > then else 0.0
        report = self._twin_report
        com, contacts, slack = report.centre_of_mass, report.contact_nodes, report.slack_strings
        line = live_line(report.time, com, contacts, slack, self.gait_phase, factor,
                         self.missed_steps)
        self._state_line = line
        level = ('WARN' if (self.missed_steps and self._real_time) or slack or report.faults
                 else 'OK')
        values = [('centre of mass', ' '.join(f'{v:.6g}' for v in com)),
                  ('contact nodes', ' '.join(contacts)), ('slack strings', ' '.join(slack)),
                  ('steps', steps), ('missed steps', self.missed_steps),
                  ('publications', self.publications), ('simulated time', report.time),
                  ('real-time factor', factor), ('gait phase', self.gait_phase),
                  ('gait steps done', self.gait_steps_done),
                  ('rejected inputs', self.reporter.rejected or 0),
                  ('faults', ', '.join(report.faults) or 'none'),
                  ('faults since [s]', '' if report.faults_since is None or not report.faults
                   else f'{report.faults_since:.4f}'),
                  ('faults since stamp', report.faults_stamp if report.faults else '')]
        name = f'{self.get_fully_qualified_name()}: structure twin'
        self._pub_diagnostics.publish(conversions.diagnostic_array(
            [conversions.diagnostic_status(name, level, line, values,
                                           hardware_id=self._settings.world_frame)],
            self.get_clock().now().to_msg()))
        if LIVE:
            print(line, flush=True)


#: ``--live`` on the command line: print the live line every diagnostics period.
LIVE = False


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness structure_sim_node`` (``--live``: print
    the live line every second)."""
    global LIVE
    argv = list(sys.argv if args is None else args)
    if '--live' in argv:
        LIVE = True
        argv.remove('--live')
    runner.run(StructureSimNode, argv)


if __name__ == '__main__':
    main()
