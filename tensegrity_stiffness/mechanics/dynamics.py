"""Dynamics in screw coordinates: mass matrix, equations of motion, linear model and modes.

The joint's link 2 (a spine's links 1..N) is a rigid body moved by its screw coordinates
``xi = [omega; v]`` (``T = exp(hat(xi))``, eq. 2 of Monke & Vikas): the Euler-Lagrange equations
in those coordinates, their linearisation (for LQR / MPC) and the vibration modes. numpy /
scipy only; time integration is the twin's (MuJoCo,
:mod:`~tensegrity_stiffness.simulation.twin`), which the tests use to prove these models.

The modules (this one re-exports their public names; ``from tensegrity_stiffness.mechanics.
dynamics import ...`` keeps working), each with its equations in its docstring: a link's mass
properties and spatial inertia (:mod:`.inertia`), the joint's dynamics and linear model
(:mod:`.joint_dynamics`, with the conventions), the spine's (:mod:`.chain_dynamics`), the modes
and frequency response of a linear model (:mod:`.modes`) and the reports of modes
(:mod:`.mode_reports`); the body Jacobian of screw coordinates and its derivatives are
:mod:`~tensegrity_stiffness.geometry.screw_jacobians`'.
"""

from __future__ import annotations

from tensegrity_stiffness.geometry.screw_jacobians import (
    body_jacobian,
    body_jacobian_rate,
    jacobian_derivatives,
)
from tensegrity_stiffness.mechanics.chain_dynamics import ChainDynamics
from tensegrity_stiffness.mechanics.inertia import (
    DEFAULT_LINK_MASS,
    MIN_GYRATION_SQUARED,
    SYMMETRY_TOLERANCE,
    LinkInertia,
    chain_inertias_from_config,
    chain_link_inertias,
    default_inertia_moments,
    twin_link_inertias,
)
from tensegrity_stiffness.mechanics.joint_dynamics import (
    DEFAULT_STRING_DAMPING,
    DYNAMICS_SECTION_KEYS,
    EQUILIBRIUM_TOLERANCE,
    JointDynamics,
    config_string_damping,
    per_string_damping,
)
from tensegrity_stiffness.mechanics.mode_reports import (
    format_modes,
    modes_from_config,
    modes_report,
)
from tensegrity_stiffness.mechanics.modes import (
    REAL_TOLERANCE,
    SCREW_LABELS,
    ComplexArray,
    JointModes,
    frequency_response,
    state_matrix_modes,
    undamped_modes,
)

__all__ = [
    'DEFAULT_LINK_MASS',
    'DEFAULT_STRING_DAMPING',
    'DYNAMICS_SECTION_KEYS',
    'EQUILIBRIUM_TOLERANCE',
    'MIN_GYRATION_SQUARED',
    'REAL_TOLERANCE',
    'SCREW_LABELS',
    'SYMMETRY_TOLERANCE',
    'ChainDynamics',
    'ComplexArray',
    'JointDynamics',
    'JointModes',
    'LinkInertia',
    'body_jacobian',
    'body_jacobian_rate',
    'chain_inertias_from_config',
    'chain_link_inertias',
    'config_string_damping',
    'default_inertia_moments',
    'format_modes',
    'frequency_response',
    'jacobian_derivatives',
    'modes_from_config',
    'modes_report',
    'per_string_damping',
    'state_matrix_modes',
    'twin_link_inertias',
    'undamped_modes',
]
