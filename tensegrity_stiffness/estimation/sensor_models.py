"""Measurement models of a tensegrity joint's sensors, with analytic Jacobians (no rclpy).

What a robot measures, predicted from the screw ``xi = [omega; v]`` (``T = exp(hat(xi))`` maps
{2} into {1}, :mod:`~tensegrity_stiffness.geometry.screw`) through
:meth:`JointModel.evaluate <tensegrity_stiffness.mechanics.joint.JointModel.evaluate>`, and the
derivative of each prediction with respect to the screw through the closed-form ``dT/dxi`` of
:mod:`~tensegrity_stiffness.geometry.screw` (eqs. 12-18: ``dT/dxi`` applied to a point is
``[-hat(q), I] J(xi)`` with ``J`` the SE(3) left Jacobian ``[[G, 0], [Q, G]]``;
:func:`~tensegrity_stiffness.geometry.screw.dexp_se3` is the same closed form as a (4, 4, 6)
array). Shared by the estimator and the calibration.

Models (string j joins link-1 node ``p1_j`` to link-2 node ``p2_j``; ``q_j = T p2_j``,
``s_j = p1_j - q_j``, ``l_j = |s_j|``, ``u_j = s_j / l_j``, eq. 7):

* string lengths ``l_j`` (stretch sensors, motor encoders on the string):
  ``dl_j/dxi = -[(q_j x u_j)^T, u_j^T] J``;
* string tensions ``phi_j(l_j)`` (inline load cells, eq. 8): ``dphi_j/dxi = phi_j'(l_j) dl_j/dxi``;
* a pose (motion capture) in ROS's ``PoseWithCovariance`` convention: the covariance is that of
  ``[dp; dtheta]`` with ``p -> p + dp``, ``R -> exp(hat(dtheta)) R``, both in {1}, ordered
  ``[x y z rx ry rz]``. :func:`pose_error` is ``[p - p_ref; log(R R_ref^T)]`` and
  ``d[dp; dtheta]/dxi = [[D, G], [G, 0]]`` (:func:`pose_jacobian`; ``D = dt/domega``, eqs. 15-17);
* gravity seen by an accelerometer at rest on link 2: the unit direction ``g_2 = R^T g_1`` in
  {2} of the known direction ``g_1`` in {1}; ``dg_2/dxi = [R^T hat(g_1) G, 0]``. It carries two
  degrees of freedom (its component along ``g_2`` is fixed by the unit length), which is what
  :data:`GRAVITY_DOF` says;
* quasi-static equilibrium with an external wrench ``W`` (on link 2, in {1} about its origin):
  ``e = F(xi) + W`` with ``de/d[xi; W] = [K, I]`` (Section VI, eq. 10);
* for calibration, the derivatives of tensions and of the string wrench with respect to each
  string's stiffness ``k_j`` and rest length ``l0_j`` (the maximum stretch ``lmax - l0`` kept, as
  :meth:`JointModel.evaluate` does with overridden rest lengths).

Every Jacobian is held to central differences in ``test/estimation/test_sensor_models.py``.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import (
    ScrewKinematics,
    hat3,
    left_jacobian_so3_inverse,
    log_so3,
    single_screw,
)
from tensegrity_stiffness.geometry.transforms import rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array_of_shape
from tensegrity_stiffness.mechanics.joint import JointModel, JointState

FloatArray = NDArray[np.float64]

#: Degrees of freedom of one gravity-direction measurement (a unit vector: two angles).
GRAVITY_DOF = 2
#: A gravity direction (or its reference) shorter than this cannot be normalised.
MIN_GRAVITY_NORM = 1e-9
_EYE3 = np.eye(3)


def unit_vector(value: ArrayLike, name: str) -> FloatArray:
    """``value`` (3,) scaled to unit length; ValueError naming ``name`` when it is not three
    finite numbers or (nearly) zero."""
    x, y, z = finite_array_of_shape(name, value, (3,)).tolist()
    norm = math.sqrt(x * x + y * y + z * z)
    if norm < MIN_GRAVITY_NORM:
        raise ValueError(f'{name} must not be zero')
    return np.array([x / norm, y / norm, z / norm])


# ---------------------------------------------------------------------------------- strings
@dataclass(slots=True)
class StringPrediction:
    """Predicted string measurements at one screw, from one :meth:`JointModel.evaluate`.

    ``state`` the :class:`JointState` (wrench, K, K_c, slack ...); ``lengths`` (n,) m and
    ``length_jacobian`` (n, 6) = dl/dxi; ``tensions`` (n,) N and ``tension_jacobian`` (n, 6) =
    dphi/dxi; ``tension_slope`` (n,) = dphi/dl (N/m; 0 for slack or saturated strings);
    ``kinematics`` the :class:`ScrewKinematics` of the screw (T, J, G, Q).
    """

    state: JointState
    lengths: FloatArray
    length_jacobian: FloatArray
    tensions: FloatArray
    tension_jacobian: FloatArray
    tension_slope: FloatArray
    kinematics: ScrewKinematics


def link2_points_jacobian(points: ArrayLike, kinematics: ScrewKinematics) -> FloatArray:
    """``dq/dxi`` (m, 3, 6) of points ``q = T p`` given in {1} (``points`` (m, 3), already
    transformed): ``[-hat(q), I] J`` (the closed-form dT/dxi applied to ``p``, eqs. 12-18)."""
    q = np.asarray(points, dtype=np.float64)
    J = kinematics.J
    # [-hat(q), I] @ [[G, 0], [Q, G]] = [Q - hat(q) G, G]
    out = np.empty(q.shape[:-1] + (3, 6))
    out[..., :3] = kinematics.Q - hat3(q) @ kinematics.G
    out[..., 3:] = J[3:, 3:]
    return out


def string_predictions(model: JointModel, xi: ArrayLike,
                       rest_lengths: ArrayLike | None = None) -> StringPrediction:
    """Lengths and tensions of every string at screw ``xi`` with their Jacobians (one
    evaluation). ``dl_j/dxi = -[(q_j x u_j)^T, u_j^T] J`` (``u_j^T ds_j/dxi`` with
    ``ds_j/dxi = -dq_j/dxi``), ``dphi_j/dxi = phi_j'(l_j) dl_j/dxi`` (eq. 8)."""
    return string_predictions_unchecked(
        model, single_screw(xi, in_chart=False),
        model.validate_rest_lengths(rest_lengths, batched=False))


_UNIT_ROWS: weakref.WeakKeyDictionary[JointModel, FloatArray] = weakref.WeakKeyDictionary()


def _unit_rows(model: JointModel) -> FloatArray:
    """``[hat(p1_j)^T, I]`` (n, 3, 6) per string of ``model`` (cached per model): ``u_j^T``
    times it is ``[(p1_j x u_j)^T, u_j^T]``."""
    rows = _UNIT_ROWS.get(model)
    if rows is None:
        p1 = model.link1_string_nodes
        rows = np.zeros((p1.shape[0], 3, 6))
        rows[:, :, :3] = np.swapaxes(hat3(p1), 1, 2)
        rows[:, :, 3:] = np.eye(3)
        _UNIT_ROWS[model] = rows
    return rows


class KernelKinematics(ScrewKinematics):
    """:class:`ScrewKinematics` of one screw computed by the compiled kernel, with the pose
    Jacobian it computed there (:func:`pose_jacobian` returns a copy of it)."""

    __slots__ = ('pose_jacobian',)


def string_predictions_unchecked(model: JointModel, xi: FloatArray, rest: FloatArray
                                 ) -> StringPrediction:
    """:func:`string_predictions` for a validated screw (6,) and rest lengths (n,) (the
    estimator's per-iteration path). With the compiled kernel everything comes from one call
    (``tsk_joint_measure_packed``, the twin of the numpy lines below, held to them in
    ``test/estimation/test_sensor_models.py``), kinematics and pose Jacobian included
    (:class:`KernelKinematics`)."""
    measured = model.measure_in_kernel(xi, rest)
    if measured is not None:
        return _kernel_prediction(model, xi, *measured)
    state = model.evaluate(xi, rest)
    kin = ScrewKinematics(xi)
    lengths = state.lengths
    u = state.string_vectors / lengths[:, None]
    # [q x u, u] = u^T [hat(p1)^T, I] (q x u = (p1 - s) x u = p1 x u): one batched product with
    # the per-string constant blocks, then -(...) J.
    length_jacobian = (u[:, None, :] @ _unit_rows(model))[:, 0, :] @ kin.J
    np.negative(length_jacobian, out=length_jacobian)
    slope = model.string_forces(lengths, rest)[1]
    if np.ndim(slope) == 0 or slope.shape != lengths.shape:
        slope = np.broadcast_to(slope, lengths.shape).astype(np.float64)
    return StringPrediction(state, lengths, length_jacobian, state.tensions,
                            slope[:, None] * length_jacobian, slope, kin)


def _kernel_prediction(model: JointModel, xi: FloatArray, state: JointState,
                       measured: FloatArray) -> StringPrediction:
    """The :class:`StringPrediction` of the kernel's measurement buffer (views into it)."""
    kn = model.compiled_kernel
    n = kn.n
    wx, wy, wz = xi[:3].tolist()
    kin = KernelKinematics.from_matrices(math.sqrt(wx * wx + wy * wy + wz * wz),
                                         state.transform, measured[:36].reshape(6, 6))
    kin.pose_jacobian = measured[kn.measure_pose:kn.measure_lengths].reshape(6, 6)
    return StringPrediction(state, state.lengths,
                            measured[kn.measure_lengths:kn.measure_tensions].reshape(n, 6),
                            state.tensions,
                            measured[kn.measure_tensions:kn.measure_slope].reshape(n, 6),
                            measured[kn.measure_slope:kn.measure_size], kin)


def predicted_lengths(model: JointModel, xi: ArrayLike, rest_lengths: ArrayLike | None = None
                      ) -> tuple[FloatArray, FloatArray]:
    """String lengths (n,) m at ``xi`` and their Jacobian dl/dxi (n, 6)."""
    pred = string_predictions(model, xi, rest_lengths)
    return pred.lengths, pred.length_jacobian


def predicted_tensions(model: JointModel, xi: ArrayLike, rest_lengths: ArrayLike | None = None
                       ) -> tuple[FloatArray, FloatArray]:
    """String tensions (n,) N at ``xi`` and their Jacobian dphi/dxi (n, 6)."""
    pred = string_predictions(model, xi, rest_lengths)
    return pred.tensions, pred.tension_jacobian


@dataclass(slots=True)
class StringParameterJacobians:
    """Derivatives with respect to each string's stiffness ``k_j`` and rest length ``l0_j`` at a
    fixed screw (every one is diagonal in the strings for the tensions).

    ``tension_stiffness`` (n,) = dphi_j/dk_j (= phi_j / k_j, every region of eq. 8);
    ``tension_rest_length`` (n,) = dphi_j/dl0_j (Hooke: ``-k`` taut, 0 slack or saturated; paper
    law: ``-k / l`` taut, ``-phi / lmax`` saturated, 0 slack), with ``lmax - l0`` kept;
    ``wrench_stiffness`` (6, n) = dF/dk_j and ``wrench_rest_length`` (6, n) = dF/dl0_j: column j
    is ``[u_j; p1_j x u_j]`` (the unit wrench of string j, eq. 9) times the tension's derivative.
    """

    tension_stiffness: FloatArray
    tension_rest_length: FloatArray
    wrench_stiffness: FloatArray
    wrench_rest_length: FloatArray


def string_parameter_jacobians(model: JointModel, xi: ArrayLike,
                               rest_lengths: ArrayLike | None = None
                               ) -> StringParameterJacobians:
    """:class:`StringParameterJacobians` at screw ``xi`` with rest lengths ``rest_lengths``."""
    xi = single_screw(xi, in_chart=False)
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    state = model.evaluate(xi, rest)
    lengths, phi = state.lengths, state.tensions
    taut = ~(state.slack | state.saturated)
    d_k = phi / model.k
    if model.force_law == 'hooke':
        d_rest = np.where(taut, -model.k, 0.0)
    else:
        lmax = rest + model.max_stretch
        d_rest = np.where(taut, -model.k / lengths,
                          np.where(state.saturated, -phi / lmax, 0.0))
    u = state.string_vectors / lengths[:, None]
    unit_wrench = np.concatenate([u, np.cross(model.link1_string_nodes, u)], axis=1).T  # (6, n)
    return StringParameterJacobians(d_k, d_rest, unit_wrench * d_k, unit_wrench * d_rest)


# ---------------------------------------------------------------------------------- pose
def pose_error(transform: ArrayLike, reference: ArrayLike) -> FloatArray:
    """``[p - p_ref; log(R R_ref^T)]`` (6,): the ``[dp; dtheta]`` of the PoseWithCovariance
    convention that takes ``reference`` to ``transform`` (``p = p_ref + dp``,
    ``R = exp(hat(dtheta)) R_ref``). Both (4, 4) or ``[x y z qx qy qz qw]``."""
    T = rigid_transform(transform, 'transform')
    T_ref = rigid_transform(reference, 'reference')
    return np.concatenate([T[:3, 3] - T_ref[:3, 3], log_so3(T[:3, :3] @ T_ref[:3, :3].T)])


def pose_jacobian(xi: ArrayLike, kinematics: ScrewKinematics | None = None) -> FloatArray:
    """``d[dp; dtheta]/dxi = [[D, G], [G, 0]]`` (6, 6): the change of the pose of {2} in {1}, in
    the PoseWithCovariance convention, per change of screw coordinates (``D = dt/domega``,
    eqs. 15-17; ``G`` the SO(3) left Jacobian, eq. 4)."""
    kin = ScrewKinematics(single_screw(xi, in_chart=False)) if kinematics is None else kinematics
    if type(kin) is KernelKinematics:  # the kernel's twin of the lines below
        return kin.pose_jacobian.copy()
    tx, ty, tz = kin.t.tolist()
    out = np.zeros((6, 6))
    # D = Q - hat(t) G (ScrewKinematics.D, written out for the estimator's per-estimate path)
    out[:3, :3] = kin.Q - np.array([[0.0, -tz, ty], [tz, 0.0, -tx], [-ty, tx, 0.0]]) @ kin.G
    out[:3, 3:] = kin.G
    out[3:, :3] = kin.G
    return out


def pose_covariance(xi: ArrayLike, screw_covariance: ArrayLike) -> FloatArray:
    """Covariance (6, 6) of the pose ``[dp; dtheta]`` (PoseWithCovariance convention) for a
    screw covariance (6, 6): ``P C P^T`` with ``P`` = :func:`pose_jacobian` (first order)."""
    P = pose_jacobian(xi)
    C = finite_array_of_shape('screw_covariance', screw_covariance, (6, 6))
    out = P @ C @ P.T
    return 0.5 * (out + out.T)


def pose_residual(xi: ArrayLike, measured: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """Residual ``r = [p(xi) - p_m; log(R(xi) R_m^T)]`` (6,) between the pose ``T(xi)`` and a
    measured pose (4, 4) or ``[x y z qx qy qz qw]``, and ``dr/dxi`` (6, 6).

    With the measurement ``p_m = p + dp``, ``R_m = exp(hat(dtheta)) R`` the residual at the true
    screw is ``-[dp; dtheta]`` to first order, so its covariance is the measurement's.
    ``dr/dxi = [[I, 0], [0, Jl^-1(E)]] [[D, G], [G, 0]]`` with ``E = log(R R_m^T)`` and ``Jl``
    the SO(3) left Jacobian (``exp(hat(d)) exp(hat(E)) = exp(hat(E + Jl^-1(E) d))``).
    """
    xi = single_screw(xi, in_chart=False)
    kin = ScrewKinematics(xi)
    r, J = pose_residual_unchecked(kin.T, rigid_transform(measured, 'measured pose'),
                                   pose_jacobian(xi, kin))
    return r, J


def pose_residual_unchecked(transform: FloatArray, measured: FloatArray,
                            jacobian: FloatArray | None = None
                            ) -> tuple[FloatArray, FloatArray | None]:
    """:func:`pose_residual` between (4, 4) transforms already checked (the estimators'
    per-iteration path) and, given ``jacobian`` = ``d[dp; dtheta]/dx`` (6, k) of ``transform``
    (modified in place), ``dr/dx``; without it the residual alone (Jacobian None)."""
    E = log_so3(transform[:3, :3] @ measured[:3, :3].T)
    r = np.concatenate([transform[:3, 3] - measured[:3, 3], E])
    if jacobian is not None:
        jacobian[3:] = left_jacobian_so3_inverse(E) @ jacobian[3:]
    return r, jacobian


# ---------------------------------------------------------------------------------- gravity
def predicted_gravity(xi: ArrayLike, gravity_base: ArrayLike,
                      kinematics: ScrewKinematics | None = None
                      ) -> tuple[FloatArray, FloatArray]:
    """Gravity direction in link 2's frame ``g_2 = R^T g_1`` (3,) (unit; ``g_1`` =
    ``gravity_base`` normalised, in {1}) and ``dg_2/dxi = [R^T hat(g_1) G, 0]`` (3, 6)
    (``R -> exp(hat(G domega)) R``, eq. 4)."""
    g1 = unit_vector(gravity_base, 'gravity_base')
    kin = ScrewKinematics(single_screw(xi, in_chart=False)) if kinematics is None else kinematics
    return gravity_prediction_unchecked(kin, g1)


def gravity_prediction_unchecked(kinematics: ScrewKinematics, gravity_base: FloatArray
                                 ) -> tuple[FloatArray, FloatArray]:
    """:func:`predicted_gravity` for the kinematics of a screw and a unit ``gravity_base`` (3,)
    already checked (the estimator's per-iteration path)."""
    Rt = kinematics.R.T
    gx, gy, gz = gravity_base.tolist()
    J = np.zeros((3, 6))
    J[:, :3] = Rt @ np.array([[0.0, -gz, gy], [gz, 0.0, -gx], [-gy, gx, 0.0]]) @ kinematics.G
    return Rt @ gravity_base, J


# ---------------------------------------------------------------------------------- statics
def equilibrium_residual(model: JointModel, xi: ArrayLike, external_wrench: ArrayLike,
                         rest_lengths: ArrayLike | None = None
                         ) -> tuple[FloatArray, FloatArray]:
    """Quasi-static residual ``e = F(xi) + W`` (6,) [N; N m] (Section VI) and its Jacobian with
    respect to ``[xi; W]``, ``[K, I]`` (6, 12) (K = dF/dxi, eq. 10)."""
    xi = single_screw(xi, in_chart=False)
    W = finite_array_of_shape('external_wrench', external_wrench, (6,))
    state = model.evaluate(xi, model.validate_rest_lengths(rest_lengths, batched=False))
    J = np.zeros((6, 12))
    J[:, :6] = state.stiffness
    J[:, 6:] = np.eye(6)
    return state.wrench + W, J


def gravity_from_specific_force(specific_force: ArrayLike) -> FloatArray:
    """The unit direction of gravity (3,) in the accelerometer's frame from its specific force
    at rest (``a - g`` = ``-g``: it points up), ``-a / |a|``; ValueError when it is not three
    finite numbers or zero."""
    return -unit_vector(specific_force, 'specific_force')


# ---------------------------------------------------------------------------------- motion
@dataclass(slots=True)
class SpecificForcePrediction:
    """An accelerometer at the origin of link 2 on a moving link, in {2}: ``value`` (3,) m/s^2
    the specific force ``f = dv/dt + w x v - R^T g`` (the acceleration of {2}'s origin minus
    gravity, both in {2}); its Jacobians ``screw`` (3, 6) = df/dxi (through ``R`` alone),
    ``twist`` (3, 6) = df/dV and ``twist_rate`` (3, 6) = df/d(dV/dt), for the body twist
    ``V = [w; v]`` of link 2 in {2} and its rate."""

    value: FloatArray
    screw: FloatArray
    twist: FloatArray
    twist_rate: FloatArray


def predicted_specific_force(kinematics: ScrewKinematics, twist: FloatArray,
                             twist_rate: FloatArray, gravity: FloatArray
                             ) -> SpecificForcePrediction:
    """:class:`SpecificForcePrediction` at the kinematics of a screw, link 2's body twist
    ``twist`` (6,) ``[w; v]`` in {2}, its rate ``twist_rate`` (6,) and ``gravity`` (3,) m/s^2 in
    {1} (e.g. (0, -9.81, 0)). The point acceleration of {2}'s origin is ``R (dv/dt + w x v)``
    (``dp/dt = R v``), hence ``f = dv/dt + w x v - R^T g``; ``d(w x v)/d[w; v] =
    [-hat(v), hat(w)]``, ``d(R^T g)/dxi`` as :func:`gravity_prediction_unchecked` (linear in
    ``g``), ``df/d(dV/dt) = [0, I]``."""
    wx, wy, wz, vx, vy, vz = twist.tolist()
    g2, dg = gravity_prediction_unchecked(kinematics, gravity)
    value = twist_rate[3:] + np.array([wy * vz - wz * vy, wz * vx - wx * vz,
                                       wx * vy - wy * vx]) - g2
    d_twist = np.array([[0.0, vz, -vy, 0.0, -wz, wy], [-vz, 0.0, vx, wz, 0.0, -wx],
                        [vy, -vx, 0.0, -wy, wx, 0.0]])  # [-hat(v), hat(w)]
    d_rate = np.zeros((3, 6))
    d_rate[:, 3:] = _EYE3
    np.negative(dg, out=dg)
    return SpecificForcePrediction(value, dg, d_twist, d_rate)


def predicted_angular_velocity(twist: FloatArray) -> tuple[FloatArray, FloatArray]:
    """A gyro on link 2: its angular velocity ``w`` (3,) rad/s in {2} from the body twist
    ``[w; v]`` (6,) and ``dw/dV = [I, 0]`` (3, 6)."""
    J = np.zeros((3, 6))
    J[:, :3] = np.eye(3)
    return np.array(twist[:3], dtype=np.float64), J


def gravity_direction_jacobian(specific_force: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The direction of gravity an accelerometer reports, ``u = -f / |f|`` (3,) (at rest
    :func:`gravity_from_specific_force`; on a moving link the model of a ``gravity`` reading
    taken from its specific force ``f``), and ``du/df = -(I - n n^T) / |f|`` (3, 3) with
    ``n = f / |f|``; ValueError when ``f`` is (nearly) zero."""
    fx, fy, fz = specific_force.tolist()
    norm = math.sqrt(fx * fx + fy * fy + fz * fz)
    if norm < MIN_GRAVITY_NORM:
        raise ValueError('specific force must not be zero')
    n = specific_force / norm
    return -n, -(np.eye(3) - np.outer(n, n)) / norm
