"""A recursive estimator of a moving joint: an extended Kalman filter on the joint's dynamics
(no rclpy; docs/estimation.md#the-filter-jointfilter).

State ``x = [xi (6); V (6); W (6)]``: the screw ``xi`` of link 2 (the library's screw,
``T = exp(hat(xi))``), link 2's body twist ``V = [w; v]`` in {2} (``hat(V) = T^-1 dT/dt``) and,
with ``load='unknown'``, the external wrench ``W`` (``[f; m]`` on link 2 in {1} about its
origin, constant in {1}) as a random walk. The error of ``xi`` is additive in screw
coordinates (the static estimator's covariance, so the two compare directly).

Prediction: the equations of motion of
:class:`~tensegrity_stiffness.mechanics.joint_dynamics.JointDynamics` in their Newton-Euler form in
{2} (that module's docstring: ``G dV/dt - ad_V^T G V = J_b^-T Q``), :func:`body_dynamics`:

    dxi/dt = J_b(xi)^-1 V,
    G dV/dt = ad_V^T G V + Ad_T^T Pi (F(xi) + W) - A^T C A V,

``G`` link 2's spatial inertia, ``F`` the strings' wrench (eq. 9) at the rest lengths in force
during ``dt``, ``A = dl/dV = L J_b^-1`` the strings' length rates per body twist and ``C`` the
string damping (``J_b^T`` maps these to ``JointDynamics.acceleration``; held to it in
``test/estimation/test_joint_filter.py``). The body form needs no derivative of ``J_b`` (the
screw form's ``Jdot_b xi_dot`` costs a 12x12 matrix exponential). Integration: one
linearly implicit trapezoidal (Rosenbrock, ``gamma = 1/2``) step per at most
:data:`MAX_SUBSTEP` s, ``dx = (I - h/2 A)^-1 h f(x)``: A-stable (the joint's modes are stiff
against a 1 kHz step only at their damping), second order with the exact Jacobian; the
covariance is propagated with ``Phi = (I - h/2 A)^-1 (I + h/2 A)`` and the discretised white
noise of :class:`ProcessNoise`.

Updates (one stacked update per step, whitened): tensions, lengths and a pose (the models of
:mod:`~tensegrity_stiffness.estimation.sensor_models`, Jacobians in ``xi``), an accelerometer's
specific force modelled with the link's acceleration
(:func:`~tensegrity_stiffness.estimation.sensor_models.predicted_specific_force`, chained
through ``dV/dt`` of the dynamics), a gravity direction (``-f / |f|`` of that specific force),
a gyro (link 2's angular velocity) and, with an unknown load, a measured wrench.

Trust: ``consistent`` is the normalised innovation squared (NIS) test of each update at
``consistency_probability``; while it fails, the reading whose innovation a broken sensor
explains best (the drop of NIS when it is left out, as
:func:`~tensegrity_stiffness.estimation.estimators.suspect_reading` does for residuals) is left
out, at most :data:`~tensegrity_stiffness.estimation.estimators.MAX_CONTRADICTED`, and only when
the rest then passes. :data:`LOST_TRACK_STEPS` inconsistent updates in a row (or a gap longer than
:data:`MAX_PREDICTION`) restart the filter from
:func:`~tensegrity_stiffness.estimation.estimators.estimate_joint_state`.

EKF, not UKF: every model here has an analytic Jacobian (the compiled kernel gives the strings'
in one call), so one linearisation per update replaces the 2n + 1 = 37 sigma-point evaluations
of the dynamics and the sensors that a UKF would make; at the joint's small motions per step
(micrometres, milliradians) the linearisation error is far below the sensors' noise.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.joint_estimator import (
    JointEstimate,
    entry_std,
    estimate_joint_state,
    missing_message,
    stiffness_jacobian_near,
)
from tensegrity_stiffness.estimation.measurements import Measurements, PreparedMeasurements
from tensegrity_stiffness.estimation.trust import (
    CONSISTENCY_PROBABILITY,
    MAX_CONTRADICTED,
    consistency_threshold,
    wilson_hilferty,
)
from tensegrity_stiffness.geometry.screw import (
    BLOCK_SWAP,
    ScrewKinematics,
    check_in_chart,
    single_screw,
)
from tensegrity_stiffness.geometry.validation import finite_array, optional_vector
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.inertia import LinkInertia
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.joint_dynamics import JointDynamics

__all__ = [
    'DEFAULT_CHAIN_PROCESS_NOISE',
    'DEFAULT_GRAVITY',
    'DEFAULT_PROCESS_NOISE',
    'INITIAL_ANGULAR_VELOCITY_STD',
    'INITIAL_LINEAR_VELOCITY_STD',
    'KNOWN_LOAD_STD',
    'LOAD_MODES',
    'LOST_TRACK_STEPS',
    'MAX_PREDICTION',
    'MAX_SUBSTEP',
    'BodyDynamics',
    'FilterTrack',
    'JointFilter',
    'ProcessNoise',
    'UpdateResult',
    'body_dynamics',
    'checked_prediction_time',
    'innovation_outliers',
    'kalman_update',
    'resolved_load',
    'validated_filter_options',
]

FloatArray = NDArray[np.float64]

#: The longest integration step (s); a longer ``dt`` is split into equal steps of at most this.
MAX_SUBSTEP = 1e-3
#: A gap between two steps longer than this (s) restarts the filter from the static estimator
#: (the prediction would carry too little).
MAX_PREDICTION = 0.5
#: Consecutive updates whose NIS fails its test with every reading kept (a reading already
#: known broken excepted) that mean the filter has lost track: it restarts from the static
#: estimator. A single broken sensor fails one update (then it is held out); sound readings
#: fail three in a row with the chance ``consistency_probability ** 3``.
LOST_TRACK_STEPS = 3
#: Gravity (m/s^2) in {1} that the accelerometer senses, default: the twin's
#: (``simulation.twin.DEFAULT_JOINT_GRAVITY``; the joint itself carries no weight).
DEFAULT_GRAVITY = (0.0, -9.81, 0.0)
#: Std of the twist at a (re)start from the static estimator, which assumes rest: rad/s, m/s.
INITIAL_ANGULAR_VELOCITY_STD = 1.0
INITIAL_LINEAR_VELOCITY_STD = 0.05
#: Std (N, N m) of a known load handed to the static estimator at a (re)start.
KNOWN_LOAD_STD = 1e-6
#: The load modes: the external wrench a state (random walk) or given at every step.
LOAD_MODES = ('unknown', 'known')

_EYE3 = np.eye(3)


@dataclass(frozen=True)
class ProcessNoise:
    """White-noise densities of what the model leaves out (one sigma per sqrt(s)), the
    accelerations' following the commanded rest lengths.

    ``angular_acceleration`` (rad/s^2 sqrt(s)) and ``linear_acceleration`` (m/s^2 sqrt(s)):
    unmodelled accelerations of link 2 (in {2}) while the rest lengths change at the RMS rate
    ``rest_rate`` (m/s); ``force_rate`` (N/s sqrt(s)) and ``moment_rate`` (N m/s sqrt(s)): the
    random walk of an unknown load (constant). Over a step ``dt`` a density ``q`` adds a
    variance ``q^2 dt``.

    The accelerations' variance densities follow the input the filter predicts with (the rest
    lengths ``r`` in force over the step, ``r_prev`` those of the step before,
    :meth:`motion_scale`)::

        q_a(t)^2 = q_a^2 (hold_fraction + (rdot / rest_rate)^2),
        rdot = |r - r_prev| / (sqrt(n) dt)    (the RMS rate of the n strings over the step),

    the model's error growing with how fast the strings are driven (measured on the twin,
    docs/estimation.md#process-noise): while the rest lengths hold, only ``hold_fraction`` of
    it is left. ``rest_rate = 0`` turns the rule off (constant densities ``q_a``, the filters'
    behaviour before issue 37's steps); before the filter has seen two sets of rest lengths
    the factor is 1."""

    angular_acceleration: float = 6.0
    linear_acceleration: float = 0.015
    force_rate: float = 0.5
    moment_rate: float = 0.01
    rest_rate: float = 0.019
    hold_fraction: float = 0.0

    def __post_init__(self) -> None:
        for name in ('angular_acceleration', 'linear_acceleration', 'force_rate',
                     'moment_rate', 'rest_rate', 'hold_fraction'):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or \
                    not math.isfinite(value) or value < 0.0:
                raise ValueError(f'process_noise.{name} must be a finite number >= 0, got '
                                 f'{value!r}')

    def twist_density(self) -> FloatArray:
        """(6,) variances per second of the body twist ``[w; v]`` at the factor 1 of
        :meth:`motion_scale`."""
        return np.array([self.angular_acceleration ** 2] * 3 +
                        [self.linear_acceleration ** 2] * 3)

    def load_density(self) -> FloatArray:
        """(6,) variances per second of the load ``[f; m]``."""
        return np.array([self.force_rate ** 2] * 3 + [self.moment_rate ** 2] * 3)

    def motion_scale(self, previous_rest: FloatArray | None, rest: FloatArray,
                     dt: float) -> float:
        """The factor of :meth:`twist_density` over a prediction of ``dt`` s (> 0) with the
        rest lengths ``rest`` (m, every string of the joint or the spine) after
        ``previous_rest`` (the class docstring's rule; 1 with ``rest_rate = 0`` or no
        ``previous_rest``)."""
        if self.rest_rate == 0.0 or previous_rest is None:
            return 1.0
        d = rest - previous_rest
        rate2 = float(d @ d) / (d.size * dt * dt)
        return self.hold_fraction + rate2 / (self.rest_rate * self.rest_rate)


#: The joint filter's defaults (the one home of their values: :class:`ProcessNoise`'s fields).
DEFAULT_PROCESS_NOISE = ProcessNoise()
#: The spine filter's defaults
#: (:class:`~tensegrity_stiffness.estimation.chain_filter.ChainFilter`): its prediction leaves out
#: the velocity-product terms and each joint's acceleration carries the others' motion, so its
#: accelerations are 8x the joint's (tuned on the twin's moving spine,
#: docs/estimation.md#spines-chainfilter).
DEFAULT_CHAIN_PROCESS_NOISE = ProcessNoise(angular_acceleration=48.0, linear_acceleration=0.12)


def _hat(a: FloatArray) -> FloatArray:
    """``hat(a)`` (3, 3) of one 3-vector from plain floats (the filter's per-step path)."""
    x, y, z = a.tolist()
    return np.array([[0.0, -z, y], [z, 0.0, -x], [-y, x, 0.0]])


def _hat_pair(p: FloatArray) -> FloatArray:
    """``C(p) = [[hat(p_m), hat(p_f)], [hat(p_f), 0]]`` (6, 6) for a wrench ``p = [m; f]``:
    ``ad_V^T p = C(p) V`` for every twist ``V = [w; v]``."""
    a, b, c, d, e, f = p.tolist()
    return np.array([[0.0, -c, b, 0.0, -f, e], [c, 0.0, -a, f, 0.0, -d],
                     [-b, a, 0.0, -e, d, 0.0], [0.0, -f, e, 0.0, 0.0, 0.0],
                     [f, 0.0, -d, 0.0, 0.0, 0.0], [-e, d, 0.0, 0.0, 0.0, 0.0]])


@dataclass(slots=True)
class BodyDynamics:
    """The equations of motion in {2} at one state (:func:`body_dynamics`).

    ``screw_rate`` (6,) ``dxi/dt = J_b^-1 V``; ``twist_rate`` (6,) ``dV/dt``; ``body_inverse``
    (6, 6) ``J_b^-1``; Jacobians of ``dV/dt``: ``d_screw`` (6, 6) (the string damping's change
    with the pose left out: it is ``c |V|`` per rad), ``d_twist`` (6, 6), ``d_load`` (6, 6);
    ``prediction`` the strings'
    :class:`~tensegrity_stiffness.estimation.sensor_models.StringPrediction` it was computed from;
    ``packed`` the compiled kernel's buffer the arrays are views of (``tsk_filter_body_dynamics``'
    layout), None from the numpy path."""

    screw_rate: FloatArray
    twist_rate: FloatArray
    body_inverse: FloatArray
    d_screw: FloatArray
    d_twist: FloatArray
    d_load: FloatArray
    prediction: sm.StringPrediction
    packed: FloatArray | None = None

    def packed_buffer(self) -> FloatArray:
        """The fields in ``tsk_filter_body_dynamics``' layout (156,): ``packed`` or a copy."""
        if self.packed is not None:
            return self.packed
        return np.concatenate([self.screw_rate, self.twist_rate, self.body_inverse.ravel(),
                               self.d_screw.ravel(), self.d_twist.ravel(),
                               self.d_load.ravel()])


def body_dynamics(dynamics: JointDynamics, prediction: sm.StringPrediction, twist: FloatArray,
                  load: FloatArray, inertia_inverse: FloatArray | None = None) -> BodyDynamics:
    """:class:`BodyDynamics` of ``dynamics`` at the strings' ``prediction`` (the screw's
    :func:`~tensegrity_stiffness.estimation.sensor_models.string_predictions_unchecked`, with
    the rest lengths in force), link 2's body twist ``twist`` ``[w; v]`` (6,) and the load
    ``load`` ``[f; m]`` (6,) in {1} (module docstring). ``inertia_inverse``: ``G^-1`` when the
    caller keeps it."""
    kin, state = prediction.kinematics, prediction.state
    T, Jl = kin.T, kin.J
    R = T[:3, :3]
    Ad = np.empty((6, 6))  # Ad_T for twists [w; v]
    Ad[:3, :3] = R
    Ad[:3, 3:] = 0.0
    Ad[3:, 3:] = R
    Ad[3:, :3] = _hat(T[:3, 3]) @ R
    # J_l^-1 = [[G^-1, 0], [-G^-1 Q G^-1, G^-1]]; J_b^-1 = J_l^-1 Ad_T (J_l = Ad_T J_b); G^-1
    # by LAPACK (5x faster here than the closed form on plain floats)
    Gi = np.linalg.inv(kin.G)
    Jl_inv = np.empty((6, 6))
    Jl_inv[:3, :3] = Gi
    Jl_inv[:3, 3:] = 0.0
    Jl_inv[3:, 3:] = Gi
    Jl_inv[3:, :3] = -Gi @ kin.Q @ Gi
    Jb_inv = Jl_inv @ Ad
    G = dynamics.spatial_inertia
    Ginv = np.linalg.inv(G) if inertia_inverse is None else inertia_inverse
    spatial = (state.wrench + load)[BLOCK_SWAP]  # [m; f] in {1}
    AdT = Ad.T
    GV = G @ twist
    # ad_V^T = [[-hat(w), -hat(v)], [0, -hat(w)]]: -C(V) with its lower blocks replaced
    adT = _hat_pair(twist)
    np.negative(adT, out=adT)
    adT[3:, :3] = 0.0
    adT[3:, 3:] = adT[:3, :3]
    coriolis = _hat_pair(GV)  # ad_V^T G V = C(G V) V
    total = coriolis @ twist + AdT @ spatial
    d_twist = adT @ G + coriolis
    if dynamics.damped:
        A = prediction.length_jacobian @ Jb_inv  # dl/dV
        D = (A.T * dynamics.string_damping) @ A
        total -= D @ twist
        d_twist -= D
    stacked = np.empty((6, 19))  # one product with G^-1 for the rate and its Jacobians
    stacked[:, 0] = total
    stacked[:, 1:7] = AdT @ (state.stiffness[BLOCK_SWAP] + _hat_pair(spatial) @ Jl)
    stacked[:, 7:13] = d_twist
    stacked[:, 13:] = AdT[:, BLOCK_SWAP]
    out = Ginv @ stacked
    return BodyDynamics(Jb_inv @ twist, out[:, 0], Jb_inv, out[:, 1:7], out[:, 7:13],
                        out[:, 13:], prediction)


def body_dynamics_kernel(library: Any, dynamics: JointDynamics,
                         prediction: sm.StringPrediction, twist: FloatArray, load: FloatArray,
                         inertia_inverse: FloatArray,
                         constants: tuple[int, int, int] | None = None) -> BodyDynamics:
    """:func:`body_dynamics` in the compiled kernel (``tsk_filter_body_dynamics`` of
    ``library``, :func:`~tensegrity_stiffness.mechanics.kernel.library`): the same equations,
    equal to rounding (``test/kernel/test_filter_kernel.py``); the arrays are views of one
    buffer (``packed``). ``constants``: the addresses of ``G``, ``inertia_inverse`` and the
    string damping when the caller keeps them alive (a filter, for its life)."""
    kin, state = prediction.kinematics, prediction.state
    # every array bound to a name until the call returns (kernel.address)
    T = np.ascontiguousarray(kin.T)
    J = np.ascontiguousarray(kin.J)
    L = np.ascontiguousarray(prediction.length_jacobian)
    F = np.ascontiguousarray(state.wrench)
    K = np.ascontiguousarray(state.stiffness)
    V = np.ascontiguousarray(twist)
    W = np.ascontiguousarray(load)
    address = kernel.address
    if constants is None:
        G = np.ascontiguousarray(dynamics.spatial_inertia)
        Gi = np.ascontiguousarray(inertia_inverse)
        c = np.ascontiguousarray(dynamics.string_damping, dtype=np.float64)
        constants = (address(G), address(Gi), address(c))
    out = np.empty(kernel.FILTER_BODY_SIZE)
    kernel.check(library.filter_body_dynamics(
        L.shape[0], int(dynamics.damped), address(T), address(J), address(L), address(F),
        address(K), address(V), address(W), *constants, address(out), out.size),
        'tsk_filter_body_dynamics')
    return BodyDynamics(out[:6], out[6:12], out[12:48].reshape(6, 6),
                        out[48:84].reshape(6, 6), out[84:120].reshape(6, 6),
                        out[120:].reshape(6, 6), prediction, out)


class FilterTrack:
    """The track a recursive filter keeps (``_x``, ``_P``): the properties
    :class:`JointFilter` and :class:`~tensegrity_stiffness.estimation.chain_filter.ChainFilter`
    share."""

    _x: FloatArray | None
    _P: FloatArray | None

    @property
    def initialized(self) -> bool:
        """Whether the filter has a state (after ``reset`` with one, or a first step)."""
        return self._x is not None

    @property
    def state(self) -> FloatArray | None:
        """A copy of the state (its parts: the filter's class docstring)."""
        return None if self._x is None else self._x.copy()

    @property
    def covariance(self) -> FloatArray | None:
        """A copy of the state's covariance."""
        return None if self._P is None else self._P.copy()


def validated_filter_options(load: str, process_noise: ProcessNoise | None,
                             default_noise: ProcessNoise, consistency_probability: float
                             ) -> ProcessNoise:
    """A filter's ``load`` mode (one of :data:`LOAD_MODES`), ``process_noise`` (None:
    ``default_noise``) and ``consistency_probability`` checked (ValueError naming the field);
    returns the process noise in force."""
    if load not in LOAD_MODES:
        raise ValueError(f'load must be one of {LOAD_MODES}, got {load!r}')
    if process_noise is None:
        process_noise = default_noise
    if not isinstance(process_noise, ProcessNoise):
        raise ValueError(f'process_noise must be a ProcessNoise, got '
                         f'{type(process_noise).__name__}')
    consistency_threshold(1, consistency_probability)  # checks the probability
    return process_noise


def checked_restart_budget(restart_time_budget: float | None) -> float | None:
    """A filter's ``restart_time_budget`` (s; None: no bound) checked: finite and >= 0
    (ValueError naming it)."""
    if restart_time_budget is None:
        return None
    value = float(restart_time_budget)
    if not (math.isfinite(value) and value >= 0.0):
        raise ValueError(f'restart_time_budget must be None or a finite number of seconds >= 0, '
                         f'got {restart_time_budget}')
    return value


def checked_prediction_time(t: float, last: float | None) -> float:
    """``t`` (s) as a float, ValueError unless finite and not earlier than ``last``."""
    t = float(t)
    if not math.isfinite(t) or (last is not None and t < last):
        raise ValueError(f't = {t} must be finite and not earlier than the last step '
                         f'({last})')
    return t


def resolved_load(mode: str, known_load: ArrayLike | None, measured: FloatArray | None,
                  measured_hint: str) -> FloatArray:
    """The load (6,) a step predicts with: zero with ``mode='unknown'`` (ValueError if
    ``known_load`` is given; ``measured_hint`` says where a measured load goes), else
    ``known_load``, by default the ``measured`` load, else zero."""
    if mode == 'unknown':
        if known_load is not None:
            raise ValueError("known_load is given but the filter's load is 'unknown' "
                             f'({measured_hint})')
        return np.zeros(6)
    if known_load is None:
        return measured.copy() if measured is not None else np.zeros(6)
    W = finite_array('known_load', known_load)
    if W.shape != (6,):
        raise ValueError(f'known_load must have shape (6,), got {W.shape}')
    return W


class JointFilter(FilterTrack):
    """Extended Kalman filter of one joint's pose, twist and load (module docstring).

    ``model``: a :class:`~tensegrity_stiffness.mechanics.joint.JointModel` (with ``inertia``,
    link 2's :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia`, and
    ``string_damping`` N s/m) or a
    :class:`~tensegrity_stiffness.mechanics.joint_dynamics.JointDynamics`;
    ``process_noise`` a :class:`ProcessNoise` (default :data:`DEFAULT_PROCESS_NOISE`); ``load``
    ``'unknown'`` (a state) or ``'known'`` (given to :meth:`step`); ``gravity`` (3,) m/s^2 in {1}
    for the accelerometer; ``consistency_probability`` of the NIS test; ``stiffness_std`` whether
    estimates carry the std of ``K_c``; ``reject_outliers`` whether contradicted readings are left
    out; ``use_kernel`` the prediction's and the update's linear algebra in the compiled kernel
    when it is loaded (``tsk_filter_*``; the numpy lines here are the reference, equal to
    rounding); ``restart_time_budget`` (s, None: no bound) the time budget of a (re)start's
    static estimate (``estimate_joint_state``'s ``time_budget``: its first iterations are never
    cut short; past it the start fails by name and the next reading tries again).

    The :class:`~tensegrity_stiffness.estimation.estimators.JointEstimate` of a step: ``chi2``
    is the update's NIS and ``dof`` = ``redundancy`` its degrees of freedom (every reading
    checks itself against the prediction), ``condition_number`` NaN (not computed),
    ``iterations`` 1; ``external_wrench`` the load state (or the known load, with a zero
    covariance); ``twist`` and ``twist_covariance`` link 2's ``[dp/dt; w]`` in {1}.
    """

    def __init__(self, model: JointModel | JointDynamics, inertia: LinkInertia | None = None,
                 process_noise: ProcessNoise | None = None, load: str = 'unknown', *,
                 string_damping: ArrayLike = 0.0, gravity: ArrayLike = DEFAULT_GRAVITY,
                 consistency_probability: float = CONSISTENCY_PROBABILITY,
                 stiffness_std: bool = True, reject_outliers: bool = True,
                 use_kernel: bool = True, restart_time_budget: float | None = None) -> None:
        if isinstance(model, JointDynamics):
            if inertia is not None:
                raise ValueError('inertia: give it to the JointDynamics, not to the filter')
            self.dynamics = model
        elif isinstance(model, JointModel):
            self.dynamics = JointDynamics(model, inertia, string_damping)
        else:
            raise ValueError(f'model must be a JointModel or a JointDynamics, got '
                             f'{type(model).__name__}')
        process_noise = validated_filter_options(load, process_noise, DEFAULT_PROCESS_NOISE,
                                                 consistency_probability)
        g = finite_array('gravity', gravity)
        if g.shape != (3,):
            raise ValueError(f'gravity must have 3 values (m/s^2 in {{1}}), got {g.size}')
        self.model = self.dynamics.model
        self.load = load
        self.process_noise = process_noise
        self.gravity = g
        self.consistency_probability = consistency_probability
        self.stiffness_std = stiffness_std
        self.reject_outliers = reject_outliers
        self.restart_time_budget = checked_restart_budget(restart_time_budget)
        self.size = 18 if load == 'unknown' else 12
        self._inertia_inverse = np.linalg.inv(self.dynamics.spatial_inertia)
        self._identity = np.eye(self.size)
        # the accelerations' densities at the factor 1 and those of the current prediction
        # (ProcessNoise.motion_scale; written in place: the kernel keeps their address)
        self._twist_q0 = process_noise.twist_density()
        self._twist_q = self._twist_q0.copy()
        self._load_q = process_noise.load_density()
        self._kernel = kernel.library() if use_kernel else None
        self.use_kernel = self._kernel is not None
        self._damping = np.ascontiguousarray(self.dynamics.string_damping, dtype=np.float64)
        if self._kernel is not None:
            self._propagate_size = self._kernel.filter_propagate_size(self.size)
            # arrays the filter keeps for its life: their addresses taken once
            self._spatial_inertia = np.ascontiguousarray(self.dynamics.spatial_inertia)
            self._constants = tuple(kernel.address(a) for a in (
                self._spatial_inertia, self._inertia_inverse, self._damping))
            self._densities = (kernel.address(self._twist_q), kernel.address(self._load_q))
        self.reset()

    # ------------------------------------------------------------------ state
    # (initialized, state: ``[xi; V; W]`` (18,), ``[xi; V]`` (12,) with a known load, and
    # covariance: FilterTrack's)
    def reset(self, screw: ArrayLike | None = None, estimate: JointEstimate | None = None,
              covariance: ArrayLike | None = None, twist: ArrayLike | None = None,
              load: ArrayLike | None = None) -> None:
        """Forget the track. With ``estimate`` (a :class:`JointEstimate`, e.g. the static
        estimator's): start from its screw, twist, load and their covariances; with ``screw``
        (6,): start there with ``twist`` (6,, the estimates' ``[dp/dt; w]`` in {1}, default
        rest), ``load`` (6,, an unknown load's start, default zero) and ``covariance``
        (``size`` x ``size`` of the state, default: the restart stds on the twist, 1e-3 rad /
        1e-5 m on the screw and 1 N / 0.01 N m on a load); without either: the next
        :meth:`step` starts from the static estimator."""
        self._t: float | None = None
        self._last_rest: FloatArray | None = None
        self._inconsistent = 0
        self._patterns: dict[tuple, tuple[list, int]] = {}
        self._suspected: set[str] = set()
        self._cache: tuple[Any, ...] | None = None
        self._x: FloatArray | None = None
        self._P: FloatArray | None = None
        if screw is not None and estimate is not None:
            raise ValueError('reset takes a screw or an estimate, not both')
        if estimate is not None:
            self._start_from(estimate)
        elif screw is not None:
            xi = single_screw(screw)
            x = np.zeros(self.size)
            x[:6] = xi
            if twist is not None:
                tw = optional_vector('twist', twist)
                R = ScrewKinematics(xi).R
                x[6:9], x[9:12] = R.T @ tw[3:], R.T @ tw[:3]
            if load is not None:
                if self.size != 18:
                    raise ValueError("load: a filter with load='known' has no load state")
                x[12:] = optional_vector('load', load)
            if covariance is None:
                P = np.diag(np.r_[[1e-6] * 3, [1e-10] * 3, self._initial_twist_variance(),
                                  [1.0] * 3 * (self.size == 18), [1e-4] * 3 * (self.size == 18)])
            else:
                P = finite_array('covariance', covariance)
                if P.shape != (self.size, self.size):
                    raise ValueError(f'covariance must have shape ({self.size}, {self.size}), '
                                     f'got {P.shape}')
            self._x, self._P = x, 0.5 * (P + P.T)

    def set_state(self, state: ArrayLike, covariance: ArrayLike) -> None:
        """Set the state ``[xi; V; W]`` (``size``,: screw, body twist ``[w; v]`` in {2},
        load) and its covariance (``size`` x ``size``) directly, keeping the time."""
        x = finite_array('state', state)
        P = finite_array('covariance', covariance)
        if x.shape != (self.size,) or P.shape != (self.size, self.size):
            raise ValueError(f'state must have shape ({self.size},) and covariance '
                             f'({self.size}, {self.size}), got {x.shape} and {P.shape}')
        check_in_chart(x[:6], 'state')
        self._x, self._P = x.copy(), 0.5 * (P + P.T)
        self._cache = None

    @staticmethod
    def _initial_twist_variance() -> FloatArray:
        return np.array([INITIAL_ANGULAR_VELOCITY_STD ** 2] * 3 +
                        [INITIAL_LINEAR_VELOCITY_STD ** 2] * 3)

    def _start_from(self, est: JointEstimate) -> None:
        if not isinstance(est, JointEstimate) or not est.success:
            raise ValueError('estimate must be a successful JointEstimate')
        x = np.zeros(self.size)
        P = np.zeros((self.size, self.size))
        x[:6] = est.screw
        P[:6, :6] = est.screw_covariance
        kin = ScrewKinematics(est.screw)
        R = kin.R
        twist = np.asarray(est.twist, dtype=np.float64)
        if np.any(twist) or np.any(est.twist_covariance):
            # [dp/dt; w_s] in {1} -> body [w; v] = [R^T w_s; R^T dp/dt] (first order)
            x[6:9], x[9:12] = R.T @ twist[3:], R.T @ twist[:3]
            rot = np.zeros((6, 6))
            rot[:3, 3:] = R.T
            rot[3:, :3] = R.T
            P[6:12, 6:12] = rot @ est.twist_covariance @ rot.T
        else:
            P[6:12, 6:12] = np.diag(self._initial_twist_variance())
        if self.size == 18:
            x[12:] = est.external_wrench
            P[12:, 12:] = est.wrench_covariance
            # the static estimate's load is -F(xi): correlated with the screw through K
            K = est.state.stiffness if est.state is not None else np.zeros((6, 6))
            P[12:, :6] = -K @ est.screw_covariance
            P[:6, 12:] = P[12:, :6].T
        self._x, self._P = x, 0.5 * (P + P.T)

    # ------------------------------------------------------------------ one step
    def step(self, t: float, measurements: Measurements | PreparedMeasurements,
             rest_lengths: ArrayLike | None = None, known_load: ArrayLike | None = None
             ) -> JointEstimate:
        """Predict to time ``t`` (s, not earlier than the last step) with ``rest_lengths`` (the
        encoders' values in force since the last step; default the model's) and update with
        ``measurements``. ``known_load`` (6,) ``[f; m]`` in {1} with ``load='known'`` (default:
        the measurements' ``external_wrench``, else zero). Returns the :class:`JointEstimate`
        at ``t`` (with ``twist`` and ``twist_covariance``); bad input raises ValueError naming
        the field, an unobservable set returns ``success=False`` naming what is missing."""
        model = self.model
        n = model.n_strings
        t = float(t)
        if not math.isfinite(t):
            raise ValueError(f't must be finite, got {t}')
        if self._t is not None and t < self._t:
            raise ValueError(f't = {t} is earlier than the last step ({self._t})')
        prep = (measurements if isinstance(measurements, PreparedMeasurements)
                else Measurements.prepared(measurements, n))
        if prep.n_strings != n:
            raise ValueError(f'measurements were prepared for {prep.n_strings} strings, the '
                             f'model has {n}')
        rest = model.validate_rest_lengths(rest_lengths, batched=False)
        load = self._load(prep, known_load)
        names = model.string_names
        dropped = prep.impossible(model, rest)
        if dropped:
            prep = prep.without([name for name, _ in dropped], names)
        dof = self._measured_dof(prep)
        restarted = False
        if self._x is not None and self._t is not None and t - self._t > MAX_PREDICTION:
            self.reset()
            restarted = True
        if dof < 6:
            if self._x is not None and self._t is not None:
                self._predict(t - self._t, rest, load)
                self._t = t
            message = missing_message(prep, names, dof, [], [])
            return self._failed(message, prep, dropped)
        if self._x is None:
            start = self._static_start(prep, rest, load, None)
            if not start.success:
                return start
            self._t = t
            self._last_rest = rest.copy()
            return self._estimate(prep, rest, load, start.chi2, start.dof, dropped,
                                  start.consistent, restarted, start.outliers,
                                  start.outlier_reasons)
        self._predict(t - self._t, rest, load)
        self._t = t
        nis, nis_dof, consistent, suspects = self._update(prep, rest, load)
        if self._inconsistent >= LOST_TRACK_STEPS:
            start = self._static_start(prep, rest, load, self._x[:6].copy())
            if start.success:
                return self._estimate(prep, rest, load, start.chi2, start.dof, dropped,
                                      start.consistent, True, start.outliers,
                                      start.outlier_reasons)
        return self._estimate(prep, rest, load, nis, nis_dof, dropped + suspects, consistent,
                              restarted)

    def predict(self, t: float, rest_lengths: ArrayLike | None = None,
                known_load: ArrayLike | None = None) -> None:
        """Only the prediction to time ``t`` (s) with ``rest_lengths`` in force (and
        ``known_load`` with ``load='known'``, default zero); ValueError before the filter has a
        state or when ``t`` is earlier than its time."""
        if self._x is None:
            raise ValueError('the filter has no state: reset it with a screw or an estimate, or '
                             'step it with readings')
        t = checked_prediction_time(t, self._t)
        rest = self.model.validate_rest_lengths(rest_lengths, batched=False)
        load = self._load(Measurements().prepared(self.model.n_strings), known_load)
        if self._t is not None:
            self._predict(t - self._t, rest, load)
        self._t = t

    def measurement_model(self, measurements: Measurements, rest_lengths: ArrayLike | None = None,
                          known_load: ArrayLike | None = None
                          ) -> tuple[FloatArray, FloatArray, list[str]]:
        """At the current state: the whitened residual ``h(x) - z`` of ``measurements``, its
        Jacobian in the state (rows, ``size``) and the reading of each row (the names of
        ``outliers``), as the update uses them."""
        if self._x is None:
            raise ValueError('the filter has no state')
        prep = Measurements.prepared(measurements, self.model.n_strings)
        rest = self.model.validate_rest_lengths(rest_lengths, batched=False)
        load = self._load(prep, known_load)
        dyn = self._linearize(self._x[:6], self._x[6:12], self._current_load(load), rest)
        r, H, readings = self._rows(prep, dyn)
        labels = [''] * r.size
        for name, rows, _ in readings:
            for k in rows.tolist():
                labels[k] = name
        return r, H, labels

    def _load(self, prep: PreparedMeasurements, known_load: ArrayLike | None) -> FloatArray:
        return resolved_load(self.load, known_load, prep.wrench,
                             'a measured load goes into measurements.external_wrench')

    def _measured_dof(self, prep: PreparedMeasurements) -> int:
        """Degrees of freedom the readings give the pose (the static estimator's count, an
        accelerometer's specific force counting as a gravity direction, a known load 6)."""
        dof = prep.dof  # a measured load's 6 included
        if self.load == 'known' and prep.wrench is None:
            dof += 6
        if prep.specific_force is not None and prep.gravity is None:
            dof += sm.GRAVITY_DOF
        return dof

    # ------------------------------------------------------------------ prediction
    def _linearize(self, xi: FloatArray, twist: FloatArray, load: FloatArray,
                   rest: FloatArray) -> BodyDynamics:
        pred = sm.string_predictions_unchecked(self.model, xi, rest)
        if self._kernel is not None:
            return body_dynamics_kernel(self._kernel, self.dynamics, pred, twist, load,
                                        self._inertia_inverse, self._constants)
        return body_dynamics(self.dynamics, pred, twist, load, self._inertia_inverse)

    def _current_load(self, load: FloatArray) -> FloatArray:
        return self._x[12:] if self.size == 18 else load

    def _predict(self, dt: float, rest: FloatArray, load: FloatArray) -> None:
        if dt <= 0.0:
            return
        # the accelerations' densities of this prediction (ProcessNoise.motion_scale)
        np.multiply(self._twist_q0,
                    self.process_noise.motion_scale(self._last_rest, rest, dt),
                    out=self._twist_q)
        self._last_rest = rest.copy()
        steps = max(1, math.ceil(dt / MAX_SUBSTEP - 1e-9))
        h = dt / steps
        for _ in range(steps):
            self._substep(h, rest, load)

    def _substep(self, h: float, rest: FloatArray, load: FloatArray) -> None:
        x, P = self._x, self._P
        cache = self._cache
        # (the cached arrays have the shapes of these: == then all(), array_equal's test)
        if cache is not None and cache[0] is x and bool((cache[1] == rest).all()) and \
                (self.size == 18 or bool((cache[2] == load).all())):
            # the last update's linearisation (at its prior) carried to its posterior to first
            # order: f(x + dx) = f(x) + A dx, one evaluation of the strings per step
            dyn, dx = cache[3], cache[4]
        else:
            dyn, dx = self._linearize(x[:6], x[6:12], self._current_load(load), rest), None
        if self._kernel is not None:
            self._substep_kernel(h, dyn, dx)
            return
        A = np.zeros((12, 12))
        f = np.empty(12)
        A[:6, 6:] = dyn.body_inverse
        A[6:, :6] = dyn.d_screw
        A[6:, 6:] = dyn.d_twist
        f[:6] = dyn.screw_rate
        f[6:] = dyn.twist_rate
        if dx is not None:
            f += A @ dx[:12]
            if self.size == 18:
                f[6:] += dyn.d_load @ dx[12:]
        rhs = np.empty((12, 13 + (6 if self.size == 18 else 0)))
        rhs[:, 0] = f * h
        half = 0.5 * h
        rhs[:, 1:13] = half * A
        rhs[np.arange(12), np.arange(1, 13)] += 1.0
        if self.size == 18:
            rhs[:6, 13:] = 0.0
            rhs[6:, 13:] = h * dyn.d_load
        E = -half * A
        E[np.arange(12), np.arange(12)] += 1.0
        sol = np.linalg.solve(E, rhs)
        Phi = self._identity.copy()
        Phi[:12, :12] = sol[:, 1:13]
        if self.size == 18:
            Phi[:12, 12:] = sol[:, 13:]
        xn = x.copy()
        xn[:12] += sol[:, 0]
        check_in_chart(xn[:6], 'screw')
        # discretised white noise: the twist's density through J_b^-1 into the screw
        Q = np.zeros((self.size, self.size))
        q = self._twist_q
        Bq = dyn.body_inverse * q
        Q[:6, :6] = Bq @ dyn.body_inverse.T * (h ** 3 / 3.0)
        Q[:6, 6:12] = Bq * (h * h / 2.0)
        Q[6:12, :6] = Q[:6, 6:12].T
        Q[6:12, 6:12] = np.diag(q * h)
        if self.size == 18:
            Q[12:, 12:] = np.diag(self._load_q * h)
        Pn = Phi @ P @ Phi.T + Q
        self._x, self._P = xn, 0.5 * (Pn + Pn.T)

    def _substep_kernel(self, h: float, dyn: BodyDynamics, dx: FloatArray | None) -> None:
        """:meth:`_substep`'s step and covariance propagation in the kernel
        (``tsk_filter_propagate``)."""
        size = self.size
        buf = np.empty(self._propagate_size)
        buf[:size] = self._x
        buf[size:size + size * size] = self._P.ravel()
        packed = dyn.packed_buffer()
        dxc = None if dx is None else np.ascontiguousarray(dx)
        address = kernel.address
        kernel.check(self._kernel.filter_propagate(
            size, h, address(packed), None if dxc is None else address(dxc),
            *self._densities, address(buf), buf.size),
            'tsk_filter_propagate')
        xn = buf[:size]
        check_in_chart(xn[:6], 'screw')
        self._x, self._P = xn, buf[size:size + size * size].reshape(size, size)

    # ------------------------------------------------------------------ update
    def _readings(self, prep: PreparedMeasurements
                  ) -> tuple[list[tuple[str, NDArray[np.intp], int]], int]:
        """The readings of a sensor pattern (name, rows, dof) in row order and the row count
        (kept per pattern: a tracker's pattern rarely changes)."""
        key = (prep.tension_index.tobytes(), prep.length_index.tobytes(), prep.pose is not None,
               prep.specific_force is not None, prep.gravity is not None,
               prep.angular_velocity is not None, prep.wrench is not None and self.size == 18)
        known = self._patterns.get(key)
        if known is not None:
            return known
        names = self.model.string_names
        out: list[tuple[str, NDArray[np.intp], int]] = []
        row = 0
        for label, index in (('tension', prep.tension_index), ('length', prep.length_index)):
            for i in index.tolist():
                out.append((f'{label}[{names[i]}]', np.array([row]), 1))
                row += 1
        for name, present, rows, dof in (('pose', key[2], 6, 6), ('imu', key[3], 3, 3),
                                         ('gravity', key[4], 3, sm.GRAVITY_DOF),
                                         ('gyro', key[5], 3, 3), ('wrench', key[6], 6, 6)):
            if present:
                out.append((name, np.arange(row, row + rows), dof))
                row += rows
        if len(self._patterns) >= 16:
            self._patterns.pop(next(iter(self._patterns)))
        self._patterns[key] = (out, row)
        return out, row

    def _rows(self, prep: PreparedMeasurements, dyn: BodyDynamics
              ) -> tuple[FloatArray, FloatArray, list[tuple[str, NDArray[np.intp], int]]]:
        """(whitened residual h(x) - z, its Jacobian in the state, the readings (name, rows,
        dof)) at the state the linearisation ``dyn`` was made at (rows in the order of
        :meth:`_readings`)."""
        size = self.size
        pred = dyn.prediction
        kin = pred.kinematics
        x = self._x
        readings, count = self._readings(prep)
        r = np.empty(count)
        H = np.zeros((count, size))
        row = 0
        for index, values, weight, h, dh in (
                (prep.tension_index, prep.tensions, prep.tension_weight, pred.tensions,
                 pred.tension_jacobian),
                (prep.length_index, prep.lengths, prep.length_weight, pred.lengths,
                 pred.length_jacobian)):
            k = index.size
            if k:
                r[row:row + k] = (h[index] - values) * weight
                H[row:row + k, :6] = dh[index] * weight[:, None]
                row += k
        if prep.pose is not None:
            res, jac = sm.pose_residual_unchecked(kin.T, prep.pose, sm.pose_jacobian(x[:6], kin))
            r[row:row + 6] = prep.pose_whitener @ res
            H[row:row + 6, :6] = prep.pose_whitener @ jac
            row += 6
        motion = (prep.gravity is not None or prep.specific_force is not None or
                  prep.angular_velocity is not None)
        if motion and self._kernel is not None and \
                self._motion_rows_kernel(prep, dyn, r, H, row):
            row += 3 * ((prep.gravity is not None) + (prep.specific_force is not None) +
                        (prep.angular_velocity is not None))
            motion = False
        if motion and (prep.gravity is not None or prep.specific_force is not None):
            sf = sm.predicted_specific_force(kin, x[6:12], dyn.twist_rate, self.gravity)
            df = np.empty((3, size))
            # df/d(dv/dt) = I: the dynamics' rows of dv/dt chained in
            df[:, :6] = sf.screw + dyn.d_screw[3:]
            df[:, 6:12] = sf.twist + dyn.d_twist[3:]
            if size == 18:
                df[:, 12:] = dyn.d_load[3:]
            if prep.specific_force is not None:
                w = prep.specific_force_weight
                r[row:row + 3] = (sf.value - prep.specific_force) * w
                H[row:row + 3] = df * w[:, None]
                row += 3
            if prep.gravity is not None:
                u, du = sm.gravity_direction_jacobian(sf.value)
                w = prep.gravity_weight
                r[row:row + 3] = (u - prep.gravity) * w
                H[row:row + 3] = (du @ df) * w[:, None]
                row += 3
        if motion and prep.angular_velocity is not None:
            w = prep.angular_velocity_weight
            value, dw = sm.predicted_angular_velocity(x[6:12])
            r[row:row + 3] = (value - prep.angular_velocity) * w
            H[row:row + 3, 6:12] = dw * w[:, None]
            row += 3
        if prep.wrench is not None and size == 18:
            r[row:row + 6] = prep.wrench_whitener @ (x[12:] - prep.wrench)
            H[row:row + 6, 12:] = prep.wrench_whitener
        return r, H, readings

    def _motion_rows_kernel(self, prep: PreparedMeasurements, dyn: BodyDynamics,
                            r: FloatArray, H: FloatArray, row: int) -> bool:
        """:meth:`_rows`' accelerometer, gravity and gyro rows in the kernel
        (``tsk_filter_motion_rows``) into ``r`` and ``H`` from ``row``; False (nothing
        written) where the numpy lines decide (a specific force below
        ``sensor_models.MIN_GRAVITY_NORM`` with a gravity reading: their error)."""
        kin = dyn.prediction.kinematics
        buf = np.empty(kernel.FILTER_MOTION_INPUT)
        buf[:16] = kin.T.ravel()
        buf[16:52] = kin.J.ravel()
        buf[52:58] = self._x[6:12]
        buf[58:61] = self.gravity
        readings = 0
        if prep.specific_force is not None:
            buf[61:64] = prep.specific_force
            buf[64:67] = prep.specific_force_weight
            readings |= kernel.FILTER_SPECIFIC_FORCE
        if prep.gravity is not None:
            buf[67:70] = prep.gravity
            buf[70:73] = prep.gravity_weight
            readings |= kernel.FILTER_GRAVITY
        if prep.angular_velocity is not None:
            buf[73:76] = prep.angular_velocity
            buf[76:79] = prep.angular_velocity_weight
            readings |= kernel.FILTER_GYRO
        packed = dyn.packed_buffer()
        address = kernel.address
        status = self._kernel.filter_motion_rows(
            self.size, readings, sm.MIN_GRAVITY_NORM, address(buf), address(packed),
            address(r) + 8 * row, address(H) + 8 * row * self.size)
        if status == kernel.ERROR_ARGUMENT:
            return False
        if status < 0:
            kernel.check(status, 'tsk_filter_motion_rows')
        return True

    def _update(self, prep: PreparedMeasurements, rest: FloatArray, load: FloatArray
                ) -> tuple[float, int, bool | None, list[tuple[str, str]]]:
        """One stacked update; (NIS, its dof, consistent, readings left out (name, why))."""
        x, P = self._x, self._P
        dyn = self._linearize(x[:6], x[6:12], self._current_load(load), rest)
        r, H, readings = self._rows(prep, dyn)
        out = kalman_update(P, r, H, readings, self._suspected, self.consistency_probability,
                            self.reject_outliers, self.use_kernel)
        self._suspected = {name for name, _ in out.left_out}
        if out.raw_consistent is not None:
            self._inconsistent = 0 if out.raw_consistent else self._inconsistent + 1
        xn = x + out.correction
        check_in_chart(xn[:6], 'screw')
        self._x, self._P = xn, out.covariance
        self._cache = (xn, rest.copy(), load.copy(), dyn, out.correction)
        return out.nis, out.dof, out.consistent, out.left_out

    # ------------------------------------------------------------------ (re)starts
    def _static_start(self, prep: PreparedMeasurements, rest: FloatArray, load: FloatArray,
                      warm: FloatArray | None) -> JointEstimate:
        """The static estimator on these readings (a specific force as a gravity direction,
        a known load as a measured one); on success the filter starts from its estimate."""
        static = self._static_readings(prep, load)
        est = estimate_joint_state(self.model, static, rest, warm,
                                   stiffness_std=False,
                                   consistency_probability=self.consistency_probability,
                                   reject_outliers=self.reject_outliers,
                                   time_budget=self.restart_time_budget)
        if est.success:
            self._start_from(est)
            self._inconsistent = 0
            self._cache = None
        return est

    def _static_readings(self, prep: PreparedMeasurements, load: FloatArray
                         ) -> PreparedMeasurements:
        out = copy.copy(prep)
        if prep.gravity is None and prep.specific_force is not None:
            f = prep.specific_force
            norm = float(np.linalg.norm(f))
            if norm > sm.MIN_GRAVITY_NORM:
                out.gravity = -f / norm
                out.gravity_base = sm.unit_vector(self.gravity, 'gravity')
                out.gravity_weight = prep.specific_force_weight * norm
        if self.load == 'known':
            out.wrench = load.copy()
            out.wrench_covariance = np.eye(6) * KNOWN_LOAD_STD ** 2
            out.wrench_whitener = np.eye(6) / KNOWN_LOAD_STD
        out.recount()
        return out

    # ------------------------------------------------------------------ output
    def _failed(self, message: str, prep: PreparedMeasurements,
                dropped: list[tuple[str, str]]) -> JointEstimate:
        nan6, nan66 = np.full(6, np.nan), np.full((6, 6), np.nan)
        return JointEstimate(False, message, nan6, np.full((4, 4), np.nan), nan66, nan66.copy(),
                             nan6.copy(), nan66.copy(), None, nan66.copy(), math.nan,
                             prep.dof - 6, False, 0, math.inf, 0,
                             prep.describe(self.model.string_names), np.empty(0), None,
                             prep.dof - 6, tuple(n for n, _ in dropped),
                             tuple(f'{n}: {w}' for n, w in dropped), False,
                             nan6.copy(), nan66.copy())

    def _estimate(self, prep: PreparedMeasurements, rest: FloatArray, load: FloatArray,
                  nis: float, dof: int, dropped: list[tuple[str, str]],
                  consistent: bool | None, restarted: bool,
                  outliers: tuple[str, ...] = (), reasons: tuple[str, ...] = ()
                  ) -> JointEstimate:
        x, P = self._x, self._P
        xi = x[:6]
        cache = self._cache
        if cache is not None and cache[0] is x:
            # the strings at the estimate (one kernel call; the update linearised at its prior)
            pred = sm.string_predictions_unchecked(self.model, xi, rest)
            state, kin = pred.state, pred.kinematics
        else:
            dyn = self._linearize(xi, x[6:12], self._current_load(load), rest)
            self._cache = (x, rest.copy(), load.copy(), dyn, np.zeros(self.size))
            state, kin = dyn.prediction.state, dyn.prediction.kinematics
        C = P[:6, :6].copy()
        Pj = sm.pose_jacobian(xi, kin)
        if self._kernel is not None:
            pose_cov, twist, twist_cov = self._output_kernel(P, x, state.transform, Pj)
        else:
            pose_cov, twist, twist_cov = self._output_numpy(P, x, state.transform, Pj, C)
        if self.size == 18:
            W, W_cov = x[12:].copy(), P[12:, 12:].copy()
        else:
            W, W_cov = load.copy(), np.zeros((6, 6))
        Kc_std = (entry_std(stiffness_jacobian_near(self.model, xi, rest), C)
                  if self.stiffness_std else np.full((6, 6), np.nan))
        names = tuple(n for n, _ in dropped) + tuple(outliers)
        why = tuple(f'{n}: {w}' for n, w in dropped) + tuple(reasons)
        return JointEstimate(True, 'ok', xi.copy(), state.transform.copy(), pose_cov, C, W,
                             W_cov, state, Kc_std, float(nis), int(dof), True, 6, math.nan, 1,
                             prep.describe(self.model.string_names), np.empty(0), consistent,
                             int(dof), names, why, restarted, twist, twist_cov)

    def _output_kernel(self, P: FloatArray, x: FloatArray, T: FloatArray, Pj: FloatArray
                       ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """:meth:`_output_numpy` in the kernel (``tsk_filter_output``)."""
        out = np.empty(kernel.FILTER_OUTPUT_SIZE)
        Pc, xc, Tc = np.ascontiguousarray(P), np.ascontiguousarray(x), np.ascontiguousarray(T)
        address = kernel.address
        kernel.check(self._kernel.filter_output(self.size, address(Pc), address(xc),
                                                address(Tc), address(Pj), address(out),
                                                out.size), 'tsk_filter_output')
        return out[:36].reshape(6, 6), out[36:42], out[42:].reshape(6, 6)

    @staticmethod
    def _output_numpy(P: FloatArray, x: FloatArray, T: FloatArray, Pj: FloatArray,
                      C: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The pose covariance, the twist ``[dp/dt; w]`` in {1} and its covariance (both
        symmetrised) of the state ``x`` with covariance ``P`` (``C`` its screw block), ``T``
        and the pose Jacobian ``Pj`` at its screw."""
        pose_cov = Pj @ C @ Pj.T
        # twist [dp/dt; w_s] = [R v; R w]; first order in the screw through R (dtheta = G dxi)
        R = T[:3, :3]
        w_s, v_s = R @ x[6:9], R @ x[9:12]
        Jt = np.zeros((6, 12))
        Jt[:3, 9:12] = R
        Jt[3:, 6:9] = R
        Jt[:3, :6] = -_hat(v_s) @ Pj[3:]
        Jt[3:, :6] = -_hat(w_s) @ Pj[3:]
        twist_cov = Jt @ P[:12, :12] @ Jt.T
        return (0.5 * (pose_cov + pose_cov.T), np.concatenate([v_s, w_s]),
                0.5 * (twist_cov + twist_cov.T))


@dataclass(slots=True)
class UpdateResult:
    """The outcome of :func:`kalman_update`: the state ``correction`` and the updated
    ``covariance``; ``nis`` and its ``dof`` over the readings kept; ``consistent`` the NIS test
    of those (None without readings), ``raw_consistent`` that of every reading but those still
    held out (what a lost track is judged by); ``left_out`` (name, why) of the readings left
    out."""

    correction: FloatArray
    covariance: FloatArray
    nis: float
    dof: int
    consistent: bool | None
    raw_consistent: bool | None
    left_out: list[tuple[str, str]]


def kalman_update(P: FloatArray, r: FloatArray, H: FloatArray,
                  readings: list[tuple[str, NDArray[np.intp], int]], suspected: set[str],
                  probability: float, reject_outliers: bool = True,
                  use_kernel: bool = False) -> UpdateResult:
    """One stacked EKF update with the trust rules (module docstring) for the whitened
    residual ``r = h(x) - z`` (rows,), its Jacobian ``H`` (rows, size) and the state covariance
    ``P``; ``readings`` (name, rows, dof) name the rows, ``suspected`` the readings left out at
    the last update: each stays out while its own innovation fails its test (the prediction's
    uncertainty grows without it: a broken sensor would otherwise be absorbed by a load's random
    walk after a few steps). Then the NIS test at ``probability``; while it fails the reading a
    broken sensor explains best is left out (:func:`innovation_outliers`), kept out only when
    the rest then passes. ``use_kernel``: the update with every reading kept in the compiled
    kernel (``tsk_filter_update``, when it is loaded) while no reading is held out; the search
    for a contradicted one stays here."""
    size = P.shape[0]
    if not r.size:
        return UpdateResult(np.zeros(size), P, 0.0, 0, None, None, [])
    library = kernel.library() if use_kernel else None
    if library is not None and not (suspected and reject_outliers):
        fast = _kalman_update_kernel(library, P, r, H, readings, probability, reject_outliers)
        if fast is not None:
            return fast
    nu = -r
    HP = H @ P
    S = HP @ H.T
    S[np.diag_indices_from(S)] += 1.0
    left: list[tuple[str, str]] = []
    if suspected and reject_outliers:
        keep = np.ones(r.size, dtype=bool)
        for name, rows, rdof in readings:
            if name not in suspected:
                continue
            stat = float(nu[rows] @ np.linalg.solve(S[np.ix_(rows, rows)], nu[rows]))
            if stat > consistency_threshold(rdof, probability):
                keep[rows] = False
                left.append((name, f'still contradicted by the prediction: its normalized '
                                   f'innovation is {stat:.4g} on {rdof} degrees of freedom'))
        if left:
            readings = [c for c in readings if keep[c[1][0]]]
            HP, nu = HP[keep], nu[keep]
            S = S[np.ix_(keep, keep)]
            offset = np.cumsum(np.r_[0, [c[1].size for c in readings]])
            readings = [(c[0], np.arange(offset[i], offset[i + 1]), c[2])
                        for i, c in enumerate(readings)]
    if not readings:
        return UpdateResult(np.zeros(size), P, 0.0, 0, None, None, left)
    dof = sum(d for _, _, d in readings)
    sol = np.linalg.solve(S, np.column_stack([nu, HP]))
    nis = float(nu @ sol[:, 0])
    raw = nis <= consistency_threshold(dof, probability)
    consistent: bool | None = raw
    if not raw and reject_outliers:
        nis_kept, dof_kept, keep, snooped = innovation_outliers(S, nu, readings, nis, dof,
                                                                probability)
        if snooped:
            nis, dof, consistent = nis_kept, dof_kept, True
            left += snooped
            HP, nu = HP[keep], nu[keep]
            S = S[np.ix_(keep, keep)]
            sol = np.linalg.solve(S, np.column_stack([nu, HP]))
    dx = HP.T @ sol[:, 0]
    Pn = P - HP.T @ sol[:, 1:]
    return UpdateResult(dx, 0.5 * (Pn + Pn.T), nis, dof, consistent, raw, left)


def _kalman_update_kernel(library: Any, P: FloatArray, r: FloatArray, H: FloatArray,
                          readings: list[tuple[str, NDArray[np.intp], int]], probability: float,
                          reject_outliers: bool) -> UpdateResult | None:
    """:func:`kalman_update` with every reading kept, in the kernel; None when its NIS test
    fails and readings are to be searched (or S is singular: the numpy path then decides)."""
    size, rows = P.shape[0], r.size
    buf = np.empty(library.filter_update_size(size, rows))
    end = size * size
    buf[:end] = P.ravel()
    buf[end:end + rows] = r
    buf[end + rows:end + rows + rows * size] = H.ravel()
    status = library.filter_update(size, rows, kernel.address(buf), buf.size)
    if status == kernel.ERROR_SINGULAR_SYSTEM:
        return None
    kernel.check(status, 'tsk_filter_update')
    start = end + rows + rows * size
    nis = float(buf[start])
    dof = sum(d for _, _, d in readings)
    raw = nis <= consistency_threshold(dof, probability)
    if not raw and reject_outliers:
        return None
    return UpdateResult(buf[start + 1:start + 1 + size],
                        buf[start + 1 + size:].reshape(size, size), nis, dof, raw, raw, [])


def innovation_outliers(S: FloatArray, nu: FloatArray,
                        readings: list[tuple[str, NDArray[np.intp], int]], nis: float,
                        dof: int, probability: float
                        ) -> tuple[float, int, NDArray[np.bool_], list[tuple[str, str]]]:
    """Leave out the reading whose innovation a broken sensor explains best, at most
    :data:`~tensegrity_stiffness.estimation.estimators.MAX_CONTRADICTED`, while the NIS test at
    ``probability`` fails: for a reading's rows ``g`` the statistic
    ``(S^-1 nu)_g^T ((S^-1)_gg)^-1 (S^-1 nu)_g`` is the drop of NIS when they are left out
    (chi-square with their dof for a sound reading: Baarda's test in innovation form), compared
    across readings by their Wilson-Hilferty z. Kept out only when the rest then passes; returns
    (NIS, dof, rows kept, (name, why)) of the rest (every row kept and none named otherwise)."""
    keep = np.ones(nu.size, dtype=bool)
    left: list[tuple[str, str]] = []
    current = list(readings)
    for _ in range(MAX_CONTRADICTED):
        idx = np.flatnonzero(keep)
        Si = np.linalg.inv(S[np.ix_(idx, idx)])
        y = Si @ nu[idx]
        where = {int(k): i for i, k in enumerate(idx.tolist())}
        scored = []
        for name, rows, rdof in current:
            if rdof >= dof:
                continue
            local = [where[int(k)] for k in rows.tolist()]
            yg = y[local]
            stat = float(yg @ np.linalg.solve(Si[np.ix_(local, local)], yg))
            scored.append((wilson_hilferty(max(stat, 1e-300), rdof), stat, name, rows, rdof))
        if not scored:
            break
        scored.sort(key=lambda item: item[0], reverse=True)
        z, stat, name, rows, rdof = scored[0]
        keep[rows] = False
        nis -= stat
        dof -= rdof
        current = [c for c in current if c[0] != name]
        left.append((name, f'contradicted by the prediction and the others: leaving it out '
                           f'lowers the NIS by {stat:.4g} (normalized z = {z:.3g})'))
        if nis <= consistency_threshold(dof, probability):
            return nis, dof, keep, left
    return nis, dof, np.ones(nu.size, dtype=bool), []

