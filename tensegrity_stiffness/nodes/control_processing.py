"""The old home of ``stiffness_controller``'s ROS-free behaviour, kept as a face that re-exports it
(public names and behaviour unchanged): :mod:`.stiffness_controller` is its home.
"""

from tensegrity_stiffness.nodes.layouts import REST_LENGTHS_LABEL
from tensegrity_stiffness.nodes.stiffness_controller import (
    CONTROL_PARAMETERS,
    CONTROLLER_PARAMETERS,
    DEFAULT_RANGE,
    PRETENSION_RANGE,
    ControllerSettings,
    controller_settings,
    default_tension_limits,
    start_command,
    stiffness_target,
)

__all__ = [
    'CONTROLLER_PARAMETERS',
    'CONTROL_PARAMETERS',
    'DEFAULT_RANGE',
    'PRETENSION_RANGE',
    'REST_LENGTHS_LABEL',
    'ControllerSettings',
    'controller_settings',
    'default_tension_limits',
    'start_command',
    'stiffness_target',
]
