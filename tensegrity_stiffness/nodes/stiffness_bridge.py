"""``stiffness_bridge``'s behaviour without ROS (:mod:`tensegrity_stiffness.ros.stiffness_bridge`
runs it): the controllers' forms of the stiffness (:data:`BRIDGE_PRESETS`), its parameter table
(:data:`BRIDGE_PARAMETERS`) and its settings (:func:`bridge_settings`). No ROS import.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from tensegrity_stiffness.mechanics.controller_stiffness import Conditioner
from tensegrity_stiffness.nodes.parameter_specs import ParameterSpec, by_name
from tensegrity_stiffness.nodes.shared_parameters import COMMON_PARAMETERS

#: What ``target.kind`` selects: publish ``~/output_stiffness``, or set a controller's parameters.
BRIDGE_TARGET_KINDS = ('topic', 'parameters')
#: ``output.max_rate`` of parameter targets when left at -1 (Hz): a controller re-reads its
#: parameters each cycle, but every set is a service call and may destabilise it if abrupt.
PARAMETER_TARGET_RATE = 50.0
#: The bridge's tick (Hz) when no rate limit sets it: retries, and the low-pass settling after the
#: last input.
BRIDGE_IDLE_TICK_RATE = 100.0
#: ``target.first_contact_timeout`` default (s). A controller that starts after the bridge
#: discovers the bridge's endpoints up to ~2 s after the bridge saw its service ready
#: (``service_is_ready()`` reflects only the bridge's side): meanwhile a request is held, and a
#: response is dropped when the controller's response writer has not matched the bridge's reader
#: within its 100 ms (rmw_fastrtps) -- that call's answer never comes (issue 37, item 7;
#: docs/performance.md). Until the first answer a call is sent again after this, doubled with
#: each resend, instead of waiting ``target.timeout``.
FIRST_CONTACT_TIMEOUT = 0.25


@dataclass(frozen=True)
class BridgePreset:
    """A controller's form of the stiffness: ``kind`` (:data:`BRIDGE_TARGET_KINDS`); a topic
    target's ``layout``; a parameter target's ``parameters`` (six double parameters, the diagonal
    in the order [x y z rx ry rz], or one double array of those six); ``source``: where that form
    is defined (docs/controllers.md cites the file and version)."""

    kind: str
    layout: str = ''
    parameters: tuple[str, ...] = ()
    source: str = ''


BRIDGE_PRESETS: dict[str, BridgePreset] = {
    'crisp': BridgePreset('topic', 'diagonal_6',
                          source='crisp_controllers target_stiffness topic, 6 values'),
    'crisp_full': BridgePreset('topic', 'row_major_36',
                               source='crisp_controllers target_stiffness topic, 36 values '
                                      'row-major'),
    'column_major_36': BridgePreset('topic', 'column_major_36',
                                    source='Franka stacks: 36 values column-major'),
    'cartesian_controllers': BridgePreset(
        'parameters', parameters=('stiffness.trans_x', 'stiffness.trans_y', 'stiffness.trans_z',
                                  'stiffness.rot_x', 'stiffness.rot_y', 'stiffness.rot_z'),
        source='fzi cartesian_compliance_controller (ros2 branch, f53f798)'),
    'admittance': BridgePreset('parameters', parameters=('admittance.stiffness',),
                               source='ros2_controllers admittance_controller 6.9.0 (94e74de)'),
    'crisp_parameters': BridgePreset(
        'parameters', parameters=('task.k_pos_x', 'task.k_pos_y', 'task.k_pos_z',
                                  'task.k_rot_x', 'task.k_rot_y', 'task.k_rot_z'),
        source='crisp_controllers 0.1.0 cartesian_impedance_controller (809354897a)'),
}

_IDENTITY_POSE = [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
_COMMON_BY_NAME = by_name(COMMON_PARAMETERS)

BRIDGE_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec('preset', 'string', 'crisp',
                  'controller form: fills target.kind, target.layout, target.parameters',
                  read_only=True, choices=tuple(BRIDGE_PRESETS)),
    ParameterSpec('input.frame', 'string', 'tensegrity_link1',
                  'frame ~/input_stiffness is expressed in (rows a wrench about its origin, '
                  'columns a twist of it)'),
    ParameterSpec('output.frame', 'string', '',
                  "the controller's frame (its name, for diagnostics; its pose: output.pose)"),
    ParameterSpec('output.pose', 'double_array', _IDENTITY_POSE,
                  "pose [x y z qx qy qz qw] of the controller's frame in input.frame (m)"),
    ParameterSpec('output.min_eigenvalue', 'double', 1e-3,
                  'eigenvalue floor of the positive definite projection', range=(0.0, 1e12)),
    ParameterSpec('output.scale', 'double', 1.0, 'factor applied after the projection',
                  range=(1e-12, 1e12)),
    ParameterSpec('output.translational_clamp', 'double_array', None,
                  '[min, max] of the translational block eigenvalues, N/m (empty: no clamp)'),
    ParameterSpec('output.rotational_clamp', 'double_array', None,
                  '[min, max] of the rotational block eigenvalues, N m/rad (empty: no clamp)'),
    ParameterSpec('output.time_constant', 'double', 0.0,
                  'first-order low-pass time constant, s (0: off)', range=(0.0, 1000.0)),
    ParameterSpec('output.max_rate', 'double', -1.0,
                  f'highest output rate, Hz (0: one per input; -1: the target kind\'s: one per '
                  f'input for topics, {PARAMETER_TARGET_RATE:g} Hz for parameters)',
                  range=(-1.0, 10_000.0)),
    ParameterSpec('target.kind', 'string', '', "topic | parameters (empty: the preset's)",
                  read_only=True, choices=('', *BRIDGE_TARGET_KINDS)),
    ParameterSpec('target.layout', 'string', '',
                  "layout of ~/output_stiffness (empty: the preset's)",
                  choices=('', 'row_major_36', 'column_major_36', 'diagonal_6')),
    ParameterSpec('target.node', 'string', '',
                  'full name of the controller node whose parameters are set (parameters '
                  'targets)', read_only=True),
    ParameterSpec('target.parameters', 'string_array', None,
                  "six double parameters [x y z rx ry rz] or one double array (empty: the "
                  "preset's)"),
    ParameterSpec('target.deadband', 'double', 0.01,
                  'parameters are set only when a value moved by more than this (relative)',
                  range=(0.0, 1.0)),
    ParameterSpec('target.timeout', 'double', 1.0,
                  'seconds a set_parameters call may take before it counts as lost (and is '
                  'sent again)',
                  range=(0.01, 60.0)),
    ParameterSpec('target.first_contact_timeout', 'double', FIRST_CONTACT_TIMEOUT,
                  'until the controller answers (at first, or after it was unreachable): '
                  'seconds before a set_parameters call is sent again, doubled with each '
                  'resend up to target.timeout (0: target.timeout)',
                  range=(0.0, 60.0)),
    _COMMON_BY_NAME['qos.depth'],
    _COMMON_BY_NAME['qos.input_reliability'],
    _COMMON_BY_NAME['diagnostics.period'],
    _COMMON_BY_NAME['realtime.fast_lane'],
)


@dataclass(frozen=True)
class BridgeSettings:
    """Everything ``stiffness_bridge`` needs, swapped as a whole: built by
    :func:`bridge_settings`. ``conditioner``: a
    :class:`~tensegrity_stiffness.mechanics.controller_stiffness.Conditioner`; ``max_rate``
    resolved (0:
    one output per input)."""

    preset: str
    kind: str
    layout: str
    parameter_names: tuple[str, ...]
    target_node: str
    conditioner: Any
    time_constant: float
    max_rate: float
    deadband: float
    timeout: float
    first_contact_timeout: float
    input_frame: str
    output_frame: str
    generation: int = 0
    values: Mapping[str, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def tick_period(self) -> float:
        """Seconds between the bridge's ticks (rate-limited outputs, retries, settling)."""
        return 1.0 / (self.max_rate if self.max_rate > 0.0 else BRIDGE_IDLE_TICK_RATE)

    def call_timeout(self, answered: bool, resends: int) -> float:
        """Seconds a ``set_parameters`` call may wait for its answer: ``timeout`` once the
        controller ``answered`` (since it was last unreachable); before, the first-contact
        timeout doubled ``resends`` times (calls given up on since), at most ``timeout``."""
        if answered or self.first_contact_timeout <= 0.0:
            return self.timeout
        return min(self.timeout, self.first_contact_timeout * 2.0 ** min(resends, 30))


def _clamp_bounds(name: str, value: list[float]) -> tuple[float, float] | None:
    if not value:
        return None
    if len(value) != 2 or not 0.0 <= value[0] <= value[1]:
        raise ValueError(f'{name} must be empty or [min, max] with 0 <= min <= max, got {value}')
    return value[0], value[1]


def bridge_settings(values: Mapping[str, Any], generation: int = 0) -> BridgeSettings:
    """Validate a whole parameter set of ``stiffness_bridge`` and build its settings; ValueError
    names the bad field."""
    checked = {spec.name: spec.check(values[spec.name]) for spec in BRIDGE_PARAMETERS}
    preset = BRIDGE_PRESETS[checked['preset']]
    kind = checked['target.kind'] or preset.kind
    layout = checked['target.layout'] or preset.layout
    names = tuple(checked['target.parameters']) or preset.parameters
    node = checked['target.node'].strip()
    if kind == 'topic' and not layout:
        raise ValueError(f'target.layout must be set: preset {checked["preset"]!r} has none')
    if kind == 'parameters':
        if len(names) not in (1, 6) or not all(n.strip() for n in names):
            raise ValueError('target.parameters must name six double parameters or one double '
                             f'array, got {list(names)}')
        if not node:
            raise ValueError('target.node must name the controller node of a parameters target')
    try:
        conditioner = Conditioner(
            pose=checked['output.pose'], min_eigenvalue=checked['output.min_eigenvalue'],
            scale=checked['output.scale'],
            translational=_clamp_bounds('output.translational_clamp',
                                        checked['output.translational_clamp']),
            rotational=_clamp_bounds('output.rotational_clamp',
                                     checked['output.rotational_clamp']))
    except ValueError as exc:
        message = str(exc)
        raise ValueError(message if message.startswith('output.') else f'output.{message}'
                         ) from None
    rate = checked['output.max_rate']
    if rate < 0.0:
        rate = PARAMETER_TARGET_RATE if kind == 'parameters' else 0.0
    return BridgeSettings(
        preset=checked['preset'], kind=kind, layout=layout,
        parameter_names=names if kind == 'parameters' else (), target_node=node,
        conditioner=conditioner, time_constant=checked['output.time_constant'], max_rate=rate,
        deadband=checked['target.deadband'], timeout=checked['target.timeout'],
        first_contact_timeout=checked['target.first_contact_timeout'],
        input_frame=checked['input.frame'], output_frame=checked['output.frame'],
        generation=generation, values=checked)

