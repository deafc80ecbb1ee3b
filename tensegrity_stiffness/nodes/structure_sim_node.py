"""The ROS-free half of ``structure_sim_node`` (the MuJoCo twin of a structure over ROS 2,
:mod:`tensegrity_stiffness.ros.structure_sim_node`): its parameter table, the settings built
from it, the labels of its arrays, its ``--help`` text and its live line.

The structure comes from ``structure.config``, as for every structure node
(:func:`~tensegrity_stiffness.nodes.structure_node.structure_path`): a YAML file with a
``structure:`` section (a structure file of ``new-config --template``, or a ROS parameter file
whose ``<node>: ros__parameters:`` holds that section) or the name of a packaged example
(``config/examples/``, default ``six_bar.yaml``). ``structure.file`` and ``structure.example``,
the twin's names before, are deprecated aliases of it (:data:`DEPRECATED_ALIASES`): they still
work, and the node warns.

``faults.*`` injects sensor faults into the published readings at run time (:class:`SensorFaults`:
a broken length sensor, a flipped IMU), for proving that an estimator names them.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec
from tensegrity_stiffness.nodes.shared_parameters import COMMON_PARAMETERS
from tensegrity_stiffness.nodes.structure_node import STRUCTURE_PARAMETERS, structure_path
from tensegrity_stiffness.simulation.structure_twin import StructureTwinOptions
from tensegrity_stiffness.simulation.twin_model import (
    DEFAULT_JOINT_DAMPING,
    DEFAULT_MAX_FORCE,
    DEFAULT_MAX_MOMENT,
    DEFAULT_TENDON_DAMPING,
)
from tensegrity_stiffness.simulation.twin_sensors import SensorNoise
from tensegrity_stiffness.structures.structure import Structure

NODE_NAME = 'structure_sim_node'
#: The deprecated names of ``structure.config`` (the twin's before): alias -> what it held.
DEPRECATED_ALIASES = {'structure.file': 'a YAML file', 'structure.example':
                      'a packaged example of config/examples'}
#: Sensor kinds with a noise parameter (the fields of :class:`~.twin.SensorNoise`).
STRUCTURE_NOISE_KINDS = ('lengths', 'tensions', 'encoders', 'gyro', 'accelerometer', 'markers')
_NOISE_UNITS = {'lengths': 'm', 'tensions': 'N', 'encoders': 'm', 'gyro': 'rad/s',
                'accelerometer': 'm/s^2', 'markers': 'm'}
#: Labels of the published arrays.
LENGTHS_LABEL = 'measured string lengths [m], string order of the structure'
TENSIONS_LABEL = 'measured string tensions (load cells) [N], string order of the structure'
ENCODERS_LABEL = 'measured rest lengths (motor encoders) [m], string order of the structure'
MARKERS_LABEL = 'measured marker positions [m] x y z per body node, node order of the structure'
CONTACTS_LABEL = ('ground contacts: 1 on the ground, 0 off it, per body node, node order of the '
                  'structure')
#: The gait's phases shown when no roll runs.
IDLE = 'idle'

STRUCTURE_SIM_PARAMETERS: tuple[ParameterSpec, ...] = (
    STRUCTURE_PARAMETERS[0],  # structure.config: the structure node's
    *(ParameterSpec(alias, 'string', '', f'deprecated alias of structure.config ({what}; '
                    'empty: structure.config)', read_only=True)
      for alias, what in DEPRECATED_ALIASES.items()),
    ParameterSpec('sim.rate', 'double', 1000.0,
                  'simulation rate, Hz (the MuJoCo time step is 1 / rate)', read_only=True,
                  range=(100.0, 100_000.0)),
    ParameterSpec('sim.real_time', 'bool', True,
                  'true: paced by the wall clock; false: as fast as possible, publishing /clock',
                  read_only=True),
    ParameterSpec('sim.publish_every', 'int', 10, 'publish every this many steps',
                  range=(1, 1_000_000)),
    ParameterSpec('sim.joint_damping', 'double', DEFAULT_JOINT_DAMPING,
                  'damping of each free-joint dof against the world, N s/m and N m s/rad',
                  read_only=True, range=(0.0, 1e6)),
    ParameterSpec('sim.string_damping', 'double', DEFAULT_TENDON_DAMPING,
                  'damping of the strings whose structure gives none, N s/m', read_only=True,
                  range=(0.0, 1e6)),
    ParameterSpec('sim.rest_length_rate', 'double', 0.02,
                  'motor speed: largest change of a rest length per second, m/s (0: at once)',
                  range=(0.0, 1e3)),
    *(ParameterSpec(f'noise.{kind}', 'double', 0.0,
                    f'standard deviation of the simulated {kind} sensor, {_NOISE_UNITS[kind]}',
                    range=(0.0, 1e3)) for kind in STRUCTURE_NOISE_KINDS),
    ParameterSpec('noise.seed', 'int', 0, 'seed of the sensor noise', read_only=True,
                  range=(0, 2**31 - 1)),
    ParameterSpec('markers.enabled', 'bool', False,
                  'publish ~/measured_markers (every body node in the world)'),
    ParameterSpec('push.duration', 'double', 0.1,
                  'how long a ~/push wrench acts, s', range=(1e-4, 100.0)),
    ParameterSpec('gait.enabled', 'bool', False,
                  'roll: plan and run the scripted gait (docs/structures.md) from the start',
                  read_only=True),
    ParameterSpec('gait.steps', 'int', 1, 'faces to roll over', read_only=True,
                  range=(1, 1000)),
    ParameterSpec('gait.direction', 'double_array', [1.0, 0.0, 0.0],
                  'the direction of the first roll in the ground plane (world)',
                  read_only=True),
    ParameterSpec('limits.max_force', 'double', DEFAULT_MAX_FORCE,
                  'a load or push with a larger force is rejected as absurd, N',
                  range=(0.0, 1e9)),
    ParameterSpec('limits.max_moment', 'double', DEFAULT_MAX_MOMENT,
                  'a load or push with a larger moment (about the world origin) is rejected, N m',
                  range=(0.0, 1e9)),
    ParameterSpec('limits.rest_length_range', 'double_array', None,
                  '[min, max] of the rest lengths the twin takes, m (empty: each string\'s '
                  'physical range)', read_only=True),
    ParameterSpec('frames.world', 'string', 'world', 'frame_id of the poses and markers'),
    ParameterSpec('faults.broken_length', 'string', '',
                  "the string whose length sensor is broken: ~/measured_lengths reads it "
                  "faults.length_offset off ('': none); an estimator names it length[<string>]"),
    ParameterSpec('faults.length_offset', 'double', 0.02,
                  "what the broken length sensor reads over the string's length, m (not 0)",
                  range=(-1.0, 1.0)),
    ParameterSpec('faults.flipped_imu', 'string', '',
                  "the bar whose IMU is flipped: its accelerometer and gyro read every axis "
                  "with the wrong sign ('': none); an estimator names it imu[<bar>]"),
    *(s for s in COMMON_PARAMETERS if s.name in ('qos.depth', 'limits.max_array_length')),
)


@dataclass(frozen=True)
class SensorFaults:
    """The sensor faults injected into the twin's published readings (``faults.*``): the
    string whose length sensor reads ``length_offset`` (m) off (``broken_length``, '' none) and
    the bar whose IMU reads every axis with the wrong sign (``flipped_imu``, '' none)."""

    broken_length: str = ''
    length_offset: float = 0.0
    flipped_imu: str = ''

    @property
    def names(self) -> tuple[str, ...]:
        """The faulty sensors as the structure estimator names its readings
        (``length[<string>]``, ``imu[<bar>]``)."""
        return ((f'length[{self.broken_length}]',) if self.broken_length else ()) + (
            (f'imu[{self.flipped_imu}]',) if self.flipped_imu else ())

    def lengths(self, structure: Structure, values: np.ndarray) -> np.ndarray:
        """The string lengths ``values`` (string order) as the sensors read them."""
        if not self.broken_length:
            return values
        out = np.array(values, dtype=float)
        out[list(structure.string_names).index(self.broken_length)] += self.length_offset
        return out

    def imu_sign(self, body: str) -> float:
        """-1 for the flipped IMU's readings, else 1."""
        return -1.0 if body == self.flipped_imu else 1.0


def sensor_faults(structure: Structure, values: Mapping[str, Any]) -> SensorFaults:
    """The :class:`SensorFaults` of checked ``faults.*`` values; ValueError naming the parameter
    and the names it may take (the structure's strings; the bars with an IMU: every free bar)."""
    broken = values['faults.broken_length'].strip()
    if broken and broken not in structure.string_names:
        raise ValueError(f'faults.broken_length: no string {broken!r} (the strings: '
                         f'{", ".join(structure.string_names)})')
    offset = values['faults.length_offset']
    if broken and offset == 0.0:
        raise ValueError('faults.length_offset must not be 0 while faults.broken_length is set')
    flipped = values['faults.flipped_imu'].strip()
    imus = [structure.body_names[i] for i in structure.bar_indices if not structure.fixed[i]]
    if flipped and flipped not in imus:
        raise ValueError(f'faults.flipped_imu: no IMU on {flipped!r} (the IMUs: '
                         f'{", ".join(imus)})')
    return SensorFaults(broken, offset if broken else 0.0, flipped)


@dataclass(frozen=True)
class StructureSimSettings:
    """Everything ``structure_sim_node`` needs: the ``structure`` (and where it came from),
    the twin's ``options``, the ``noise``, the world frame, the checked ``values`` and the
    injected ``faults``."""

    structure: Structure
    source: str
    options: StructureTwinOptions
    noise: SensorNoise
    world_frame: str
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)
    #: The sensor faults injected into the published readings (``faults.*``).
    faults: SensorFaults = SensorFaults()
    #: The warnings of deprecated parameters used (the node logs them).
    deprecations: tuple[str, ...] = ()

    @property
    def gait_direction(self) -> np.ndarray:
        """(3,) the first roll's direction."""
        return np.array(self.values['gait.direction'], dtype=float)


def structure_source(values: Mapping[str, Any]) -> tuple[Path, tuple[str, ...]]:
    """The structure file of ``structure.config`` or of a deprecated alias
    (:data:`DEPRECATED_ALIASES`, used only while ``structure.config`` is at its default), and the
    warnings of the aliases used; ValueError naming the parameter."""
    used = [alias for alias in DEPRECATED_ALIASES if values[alias].strip()]
    if not used:
        return structure_path(values['structure.config']), ()
    if len(used) > 1 or values['structure.config'] != STRUCTURE_PARAMETERS[0].default:
        raise ValueError(f'{" and ".join(used)} (deprecated) and structure.config name the '
                         'structure: set only structure.config')
    alias = used[0]
    name = values[alias].strip()
    if alias == 'structure.file':
        if not Path(name).is_file():
            raise ValueError(f'structure.file: no file {name!r}')
        path = Path(name)
    else:
        try:
            path = config.example_config_path(name)
        except ValueError as exc:
            raise ValueError(f'structure.example: {exc}') from None
    return path, (f'{alias} is deprecated: use structure.config:={name} (a path or a packaged '
                  'example)',)


def structure_sim_settings(values: Mapping[str, Any], generation: int = 0
                           ) -> StructureSimSettings:
    """Validate a whole parameter set of ``structure_sim_node``; ValueError names the bad field
    (``generation`` for symmetry with the other nodes' builders)."""
    checked = {spec.name: spec.check(values[spec.name]) for spec in STRUCTURE_SIM_PARAMETERS}
    source, deprecations = structure_source(checked)
    try:
        structure = Structure.from_yaml(source)
    except ValueError as exc:
        raise ValueError(f'structure {source}: {exc}') from None
    if structure.force_law != 'hooke':
        raise ValueError(f"structure {source}: the twin simulates Hooke's law only (force_law: "
                         f'{structure.force_law})')
    if not checked['frames.world'].strip():
        raise ValueError('frames.world must not be empty')
    direction = checked['gait.direction']
    if len(direction) != 3 or not any(direction):
        raise ValueError(f'gait.direction must be 3 values, not all zero, got {direction}')
    bounds = checked['limits.rest_length_range']
    if bounds and (len(bounds) != 2 or not 0.0 < bounds[0] < bounds[1]):
        raise ValueError(f'limits.rest_length_range must be [min, max] with 0 < min < max, got '
                         f'{bounds}')
    rate = checked['sim.rest_length_rate']
    options = StructureTwinOptions(
        timestep=1.0 / checked['sim.rate'], joint_damping=checked['sim.joint_damping'],
        string_damping=checked['sim.string_damping'],
        rest_length_rate=rate if rate > 0.0 else None,
        rest_length_range=(bounds[0], bounds[1]) if bounds else None,
        max_force=checked['limits.max_force'], max_moment=checked['limits.max_moment'])
    noise = SensorNoise(**{kind: checked[f'noise.{kind}'] for kind in STRUCTURE_NOISE_KINDS})
    return StructureSimSettings(structure, str(source), options, noise, checked['frames.world'],
                                values=checked, faults=sensor_faults(structure, checked),
                                deprecations=deprecations)


def loads_label(structure: Structure) -> str:
    """The label of ``~/loads``: 6 values per body."""
    return (f'loads [fx fy fz mx my mz] per body in the world about its origin [N, N m], body '
            f'order: {" ".join(structure.body_names)}')


@dataclass(frozen=True)
class TwinReport:
    """What /diagnostics and the live line report of the twin, taken by the node's stepping
    thread at a publication (the only thread that touches MuJoCo's data)."""

    time: float
    """Simulated time (s)."""
    centre_of_mass: np.ndarray
    """(3,) the structure's centre of mass in the world (m)."""
    contact_nodes: tuple[str, ...]
    """The nodes touching the ground (config order)."""
    slack_strings: tuple[str, ...]
    """The strings at or below their rest length."""
    faults: tuple[str, ...] = ()
    """The faulty sensors of the published readings (:attr:`SensorFaults.names`)."""
    faults_since: float | None = None
    """Simulated time (s) of the first publication with ``faults`` (None: no fault)."""
    faults_stamp: str = ''
    """Its header stamp, ``sec.nanosec`` ('' no fault)."""


def live_line(time: float, com: np.ndarray, contacts: Sequence[str], slack: Sequence[str],
              phase: str, factor: float, missed: int = 0) -> str:
    """One line of the twin's state: simulated time, centre of mass (m), contact nodes, slack
    strings, the gait's phase, the real-time factor and the steps missed so far."""
    return (f't {time:7.2f} s  com [{com[0]:+.3f} {com[1]:+.3f} {com[2]:+.3f}] m  contacts '
            f'{",".join(contacts) or "-"}  slack {",".join(slack) or "-"}  gait {phase}  '
            f'rtf {factor:.2f}  missed {missed}')
