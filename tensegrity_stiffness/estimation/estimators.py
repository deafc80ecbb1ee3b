"""Pose, load and stiffness of a tensegrity joint (or a spine) estimated from what robots
measure, with their uncertainty (no rclpy).

Measurements (:class:`Measurements`, models and Jacobians in
:mod:`~tensegrity_stiffness.estimation.sensor_models`): string tensions (load cells), string
lengths (stretch sensors), a pose (motion capture), the direction of gravity in link 2 (an
accelerometer at rest) and the external wrench (known, e.g. zero, or measured by a force-torque
sensor; ``None`` = unknown). Rest lengths (motor encoders) are known inputs of the model.

Method: weighted nonlinear least squares over the screw ``xi`` (Gauss-Newton with Levenberg-
Marquardt damping, analytic Jacobians), warm-started. Each measurement ``z`` with covariance
``S`` contributes the whitened residual ``L^-1 (h(xi) - z)`` (``S = L L^T``). A known or measured
load ``W_m`` enters as the quasi-static residual ``F(xi) + W_m`` with the load's covariance (at
the truth ``F + W = 0``, Section VI). An unknown load is a free unknown of the equilibrium
``F(xi) + W = 0``, which then carries no information on ``xi``: it is eliminated exactly and
recovered as ``W = -F(xi)`` with covariance ``K C K^T`` (``K = dF/dxi``, eq. 10).

Uncertainty: the screw covariance is the inverse of the weighted normal matrix ``C = (J^T J)^-1``
at the estimate (the Cramer-Rao bound of the linearised problem); the pose covariance follows the
ROS ``PoseWithCovariance`` convention (``[dp; dtheta]`` in {1}, ``p -> p + dp``,
``R -> exp(hat(dtheta)) R``): ``P C P^T`` with ``P`` =
:func:`~tensegrity_stiffness.estimation.sensor_models.pose_jacobian`. ``K_c``'s std is the
first-order propagation of ``C`` through central differences of ``K_c(xi)``.

Observability: the rank and condition number of the whitened Jacobian with the translation
columns scaled by the mean rest length (so that radians and metres weigh alike). A set that
cannot determine the pose (fewer than 6 independent measured degrees of freedom, e.g. 3 tensions
and an unknown load, or gravity alone) gets ``success=False, observable=False`` and a message
naming what is missing; it never gets a number.

Trust (``docs/estimation.md#trust``): every estimate says ``consistent`` (the chi-square test of
its whitened residual at :data:`CONSISTENCY_PROBABILITY`; None without redundancy), its
``redundancy`` and the ``outliers`` left out by name: impossible readings
(:data:`IMPOSSIBLE_STD`) before the fit, then, while the estimate is inconsistent and redundancy
remains, the reading the others contradict (:func:`suspect_reading`). A warm start that loses
track (inconsistent or failed) is restarted from a cold start.

The modules (this one re-exports their public names; ``from tensegrity_stiffness.estimation.
estimators import ...`` keeps working): the readings (:mod:`.measurements`), trust
(:mod:`.trust`), the joint's estimator (:mod:`.joint_estimator`), the spine's
(:mod:`.chain_estimator`) and the damped least-squares step they share with the calibration
(:mod:`.least_squares`).
"""

from __future__ import annotations

from tensegrity_stiffness.estimation.chain_estimator import (
    CHAIN_EQUILIBRIUM_TOLERANCE,
    MAX_RESTORATION_STEPS,
    ChainEstimate,
    estimate_chain_state,
    tip_pose_jacobian,
    tip_stiffness_std,
)
from tensegrity_stiffness.estimation.joint_estimator import (  # noqa: F401 (public here)
    DECREMENT_TOLERANCE,
    MAX_ITERATIONS,
    MIN_LENGTH_SCALE,
    NEAR_SINGULAR_TOLERANCE,
    POSE_AXES,
    RANK_TOLERANCE,
    STIFFNESS_JACOBIAN_REUSE,
    STIFFNESS_STEP,
    JointEstimate,
    cartesian_stiffness_jacobian,
    entry_std,
    estimate_joint_state,
    missing_message,
    stiffness_jacobian_near,
)
from tensegrity_stiffness.estimation.least_squares import (  # noqa: F401 (public here)
    DAMPING_GROWTH,
    INITIAL_DAMPING,
    MAX_DAMPING,
    SINGULAR_NORMAL_MATRIX,
    STALL_TOLERANCE,
)
from tensegrity_stiffness.estimation.measurements import (
    IMPOSSIBLE_STD,
    Measurements,
    PreparedMeasurements,
)
from tensegrity_stiffness.estimation.trust import (  # noqa: F401 (public here)
    AMBIGUITY,
    CONSISTENCY_PROBABILITY,
    MAX_CONTRADICTED,
    consistency_threshold,
    suspect_reading,
    wilson_hilferty,
)

__all__ = [
    'CHAIN_EQUILIBRIUM_TOLERANCE',
    'CONSISTENCY_PROBABILITY',
    'DAMPING_GROWTH',
    'DECREMENT_TOLERANCE',
    'IMPOSSIBLE_STD',
    'INITIAL_DAMPING',
    'MAX_DAMPING',
    'MAX_ITERATIONS',
    'MAX_RESTORATION_STEPS',
    'MIN_LENGTH_SCALE',
    'POSE_AXES',
    'RANK_TOLERANCE',
    'STALL_TOLERANCE',
    'STIFFNESS_JACOBIAN_REUSE',
    'STIFFNESS_STEP',
    'ChainEstimate',
    'JointEstimate',
    'Measurements',
    'PreparedMeasurements',
    'cartesian_stiffness_jacobian',
    'consistency_threshold',
    'entry_std',
    'estimate_chain_state',
    'estimate_joint_state',
    'missing_message',
    'stiffness_jacobian_near',
    'suspect_reading',
    'tip_pose_jacobian',
    'tip_stiffness_std',
    'wilson_hilferty',
]
