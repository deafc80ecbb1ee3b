"""``sim_node``'s parameters without ROS (:mod:`tensegrity_stiffness.ros.sim_node` runs the
MuJoCo twin with them): its table (:func:`sim_node_parameters`: the joint's model and frames,
or a spine's, then the twin's own) and its settings (:func:`sim_node_settings`). No ROS import.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.plausibility import check_dynamics
from tensegrity_stiffness.nodes.frames import spine_link_frame
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name
from tensegrity_stiffness.nodes.shared_parameters import (
    CHAIN_PARAMETERS,
    COMMON_PARAMETERS,
    DYNAMICS_PARAMETER_NAMES,
    FRAME_PARAMETERS,
    JOINT_PARAMETERS,
    LINK2_PARAMETERS,
    REST_LENGTH_OFFSET_PARAMETERS,
    SPINE_FRAME_PARAMETERS,
    STRING_DAMPING_PARAMETER,
    TF_PARAMETERS,
    chain_document,
    joint_from_values,
    joint_override_parameters,
    link2_inertia_from_values,
)
from tensegrity_stiffness.simulation.twin_model import (
    DEFAULT_MAX_FORCE,
    DEFAULT_MAX_MOMENT,
    SimulationOptions,
)

#: Noise kinds of the simulated sensors (fields of simulation.SensorNoise).
NOISE_KINDS = ('lengths', 'tensions', 'gyro', 'accelerometer')
_NOISE_UNITS = {'lengths': 'm', 'tensions': 'N', 'gyro': 'rad/s', 'accelerometer': 'm/s^2'}

SIM_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('sim.spine', 'bool', False,
                  'simulate the spine of the joint.*, joint_<i>.* and chain.* parameters (a '
                  'spine config) instead of the joint', read_only=True),
    ParameterSpec('sim.rate', 'double', 1000.0,
                  'simulation rate, Hz (the MuJoCo time step is 1 / rate)', read_only=True,
                  range=(1.0, 100_000.0)),
    ParameterSpec('sim.real_time', 'bool', True,
                  'true: paced by the wall clock; false: as fast as possible, publishing /clock '
                  '(stamps are simulated time)', read_only=True),
    ParameterSpec('sim.publish_every', 'int', 1, 'publish every this many steps',
                  range=(1, 1_000_000)),
    ParameterSpec('sim.max_length', 'string', 'limit',
                  "strings past their maximum length: 'limit' an inextensible stop, 'ignore' "
                  "Hooke's law goes on", read_only=True, choices=('limit', 'ignore')),
    replace(STRING_DAMPING_PARAMETER, read_only=True),
    ParameterSpec('sim.joint_damping', 'double', 1e-3,
                  'damping of each free-joint dof of every link against the world, N s/m and '
                  'N m s/rad', read_only=True, range=(0.0, 1e6)),
    ParameterSpec('sim.link_mass', 'double', 0.01,
                  "dynamic mass of every spine link whose config gives none, kg (its weight is "
                  "compensated: the library applies none; a joint's link 2: joint.link2_mass)",
                  read_only=True, range=(1e-9, 1e6)),
    ParameterSpec('sim.rest_length_rate', 'double', 0.0,
                  'largest change of a rest length per second, m/s, like a motor (0: at once)',
                  range=(0.0, 1e3)),
    ParameterSpec('load.swing_amplitude', 'double', 0.0,
                  'a force of this size (N) turning in the plane normal to gravity, added to '
                  '~/external_wrench: the twin swings a load (0: off)', range=(0.0, 1e3)),
    ParameterSpec('load.swing_period', 'double', 10.0, 'period of the swinging load, s',
                  range=(1e-2, 1e6)),
    *(ParameterSpec(f'noise.{kind}', 'double', 0.0,
                    f'standard deviation of the simulated {kind} sensor, {_NOISE_UNITS[kind]}',
                    range=(0.0, 1e3)) for kind in NOISE_KINDS),
    ParameterSpec('noise.seed', 'int', 0, 'seed of the sensor noise', read_only=True,
                  range=(0, 2**31 - 1)),
    ParameterSpec('limits.max_force', 'double', DEFAULT_MAX_FORCE,
                  '~/external_wrench with a larger force is rejected as absurd, N',
                  range=(0.0, 1e9)),
    ParameterSpec('limits.max_moment', 'double', DEFAULT_MAX_MOMENT,
                  '~/external_wrench with a larger moment is rejected as absurd, N m',
                  range=(0.0, 1e9)),
    ParameterSpec('limits.rest_length_range', 'double_array', None,
                  '[min, max] of the rest lengths the twin takes (c + d of ~/rest_lengths), m '
                  '(empty: each string\'s physical range, docs/simulation.md)', read_only=True),
    ParameterSpec('frames.imu', 'string', '',
                  'frame_id of ~/imu (empty: frames.link2 for the joint, '
                  '"<frames.base>_link_<N>" for a spine)'),
)

#: The common parameters the twin reads (output depth, array size limit).
_SIM_COMMON = tuple(s for s in COMMON_PARAMETERS
                    if s.name in ('qos.depth', 'limits.max_array_length'))


def sim_node_parameters(spine: bool = False, n_joints: int = 5) -> tuple[ParameterSpec, ...]:
    """Every parameter of ``sim_node``: the joint's model and frames, or (``spine``) the
    spine's, then the twin's own."""
    model = (JOINT_PARAMETERS + joint_override_parameters(n_joints) + CHAIN_PARAMETERS
             + SPINE_FRAME_PARAMETERS) if spine else (
                 JOINT_PARAMETERS + REST_LENGTH_OFFSET_PARAMETERS + LINK2_PARAMETERS
                 + FRAME_PARAMETERS)
    return model + TF_PARAMETERS + SIM_PARAMETERS + _SIM_COMMON


@dataclass(frozen=True)
class SimNodeSettings:
    """Everything ``sim_node`` needs, swapped as a whole: the model (``model`` for the joint,
    ``chain`` for a spine: exactly one is set), frames, pacing, loads, noise and limits."""

    model: JointModel | None
    chain: JointChain | None
    base_frame: str
    child_frame: str
    imu_frame: str
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def spine(self) -> bool:
        return self.chain is not None

    @property
    def n_strings(self) -> int:
        """Strings of the whole model (the length of the measured arrays)."""
        if self.chain is not None:
            return sum(m.n_strings for m in self.chain.joints)
        return self.model.n_strings

    def noise(self) -> dict[str, float]:
        """``{kind: standard deviation}`` of the simulated sensors."""
        return {kind: self.values[f'noise.{kind}'] for kind in NOISE_KINDS}

    @property
    def rest_length_range(self) -> tuple[float, float] | None:
        """``limits.rest_length_range`` as ``(min, max)`` (None: the twin's physical range)."""
        bounds = self.values['limits.rest_length_range']
        return (bounds[0], bounds[1]) if bounds else None

    def twin_options(self) -> dict[str, Any]:
        """The twin's :class:`~tensegrity_stiffness.simulation.twin.SimulationOptions` as
        keywords: time step, string stop, the strings' damping (``dynamics.string_damping``,
        the value the modes use), the links' damping and mass, the rest-length range. The
        node checks every wrench against its own ``limits.*`` (changeable at run time, the
        swinging load added), so the twin's own wrench bound is off. For the joint, also
        ``link2`` (``joint.link2_*``)."""
        values = self.values
        options = {'timestep': 1.0 / values['sim.rate'], 'max_length': values['sim.max_length'],
                   'tendon_damping': values[STRING_DAMPING_PARAMETER.name],
                   'joint_damping': values['sim.joint_damping'],
                   'link_mass': values['sim.link_mass'],
                   'rest_length_range': self.rest_length_range,
                   'max_force': math.inf, 'max_moment': math.inf}
        if self.chain is None:
            options['link2'] = link2_inertia_from_values(values)
        return options


def sim_node_settings(values: Mapping[str, Any], generation: int = 0) -> SimNodeSettings:
    """Validate a whole parameter set of ``sim_node`` and build its settings; ValueError names
    the bad field. ``generation`` is accepted for symmetry with the other nodes' builders."""
    spine = by_name(SIM_PARAMETERS)['sim.spine'].check(values['sim.spine'])
    n = by_name(CHAIN_PARAMETERS)['chain.n_joints'].check(values['chain.n_joints']) \
        if spine else 1
    checked = {spec.name: spec.check(values[spec.name]) for spec in sim_node_parameters(spine, n)}
    if spine:
        for name in ('frames.base', 'frames.tool'):
            if not checked[name].strip():
                raise ValueError(f'{name} must not be empty')
        chain = JointChain.from_dict(chain_document(checked))
        for joint in chain.joints:  # each link as the twin builds it: sim.link_mass at its origin
            check_dynamics(joint, checked['sim.link_mass'], np.zeros(3),
                           checked[STRING_DAMPING_PARAMETER.name],
                           ('sim.link_mass', 'link com', STRING_DAMPING_PARAMETER.name))
        base, child = checked['frames.base'], checked['frames.tool']
        imu = checked['frames.imu'] or spine_link_frame(base, n)
        model = None
        longest = max(6 * n, sum(m.n_strings for m in chain.joints))
    else:
        for name in ('frames.link1', 'frames.link2'):
            if not checked[name].strip():
                raise ValueError(f'{name} must not be empty')
        model, chain = joint_from_values(checked), None
        inertia = link2_inertia_from_values(checked)
        check_dynamics(model, inertia.mass, inertia.com, checked[STRING_DAMPING_PARAMETER.name],
                       DYNAMICS_PARAMETER_NAMES)
        base, child = checked['frames.link1'], checked['frames.link2']
        imu = checked['frames.imu'] or child
        longest = max(6, model.n_strings)
    if checked['limits.max_array_length'] < longest:
        raise ValueError(f'limits.max_array_length = {checked["limits.max_array_length"]} is '
                         f'below the longest input of this model ({longest} values)')
    if checked['limits.rest_length_range']:
        try:
            SimulationOptions(rest_length_range=tuple(checked['limits.rest_length_range']))
        except ValueError as exc:
            raise ValueError(f'limits.{exc}') from None
    return SimNodeSettings(model=model, chain=chain, base_frame=base, child_frame=child,
                           imu_frame=imu, values=checked)

