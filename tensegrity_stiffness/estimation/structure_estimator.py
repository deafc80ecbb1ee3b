"""Every body's pose of a structure (:mod:`tensegrity_stiffness.structures`) with covariance,
from what tensegrity robots measure (no rclpy): string lengths (stretch sensors), tensions
(load cells), motor encoders (the rest lengths: a known input of the tension model), one IMU
per body (the direction of gravity in its frame, from the accelerometer at rest; the gyro in
the recursive form), optional marker positions of nodes, and the ground contact when it is known
(the named nodes on the ground).

Unknowns: each free body's pose as the increment ``[dp; dw]`` of the PoseWithCovariance
convention (``p -> p + dp``, ``R -> exp(hat(dw)) R``, both in the world): a node ``x = R q + p``
moves by ``dx = dp - hat(x - p) dw``.

Measurement models (value, Jacobian row(s) in ``[dp; dw]`` of the bodies concerned):

* length ``l_j = |x_B - x_A|``: ``u . (dx_B - dx_A)``, ``u`` the unit vector from A to B, so
  ``[u, (x - p) x u]`` at B, minus that at A (:func:`string_model`);
* tension ``phi_j(l_j, l0_j)`` of the string's law (``mechanics.joint.string_forces``, the
  structure's ``evaluate``): ``dphi/dl`` times the length's row;
* IMU of body ``i``: ``h = R^T g_hat`` (``g_hat`` the unit gravity in the world), Jacobian
  ``R^T hat(g_hat)`` in ``dw`` (3 rows, 2 degrees of freedom: the turn about gravity is not
  seen);
* marker at node ``x``: ``x``, ``[I, -hat(x - p)]``;
* ground contact at node ``x``: ``n . x - height`` = 0, ``n^T [I, -hat(x - p)]``.

Method: weighted Gauss-Newton (whitened residuals ``(h - z) / std``), the rotation columns
scaled by the structure's length scale (so that radians and metres weigh alike, as the joint's
estimator), steps of the truncated SVD (no step along an undetermined direction), clipped to
0.5 rad and half the length scale, halved while the cost rises.

Undetermined directions (the null space of the scaled Jacobian, singular values below
:data:`NULL_TOLERANCE` of the largest) are classified:

* a bar's **spin** about its own axis (its nodes are on the axis: no string, marker or contact
  sees it; only its IMU does, unless the bar is vertical) is a **gauge**: held at the start,
  named in ``gauge`` (``spin of <bar>``), its variance zero;
* a **rigid motion** of the whole structure (all six when nothing holds it; on the ground with
  its contacts: the two translations along the ground and the turn about its normal; IMUs add
  the tilt, never the turn about gravity) is refused by name unless
  ``hold_rigid_motion=True``, which holds it at the start (a gauge, named, variance zero); the
  recursive form (:class:`StructureFilter`) follows it from the contacts' zero velocity;
* anything else (a shape the mix cannot see) is refused, naming the bodies that move.

Trust as the joint's (``docs/estimation.md#trust``): ``redundancy`` (measured degrees of freedom
minus the determined unknowns), ``consistent`` (chi-square at
:data:`~tensegrity_stiffness.estimation.estimators.CONSISTENCY_PROBABILITY`), ``outliers``
(left out by name, while the estimate is inconsistent:
:func:`~tensegrity_stiffness.estimation.estimators.suspect_reading`, at most
:data:`~tensegrity_stiffness.estimation.estimators.MAX_CONTRADICTED`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.estimation.joint_estimator import MAX_ITERATIONS
from tensegrity_stiffness.estimation.least_squares import FitClock
from tensegrity_stiffness.estimation.sensor_models import unit_vector
from tensegrity_stiffness.estimation.trust import (
    CONSISTENCY_PROBABILITY,
    MAX_CONTRADICTED,
    consistency_threshold,
    suspect_reading,
)
from tensegrity_stiffness.geometry.screw import exp_so3, hat3
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.joint import string_forces
from tensegrity_stiffness.structures.structure import Structure, StructureState

__all__ = [
    'DEFAULT_ACCELERATION_STD',
    'DEFAULT_ACCELEROMETER_STD',
    'DEFAULT_CONTACT_STD',
    'DEFAULT_CONTACT_VELOCITY_STD',
    'DEFAULT_DYNAMICS_ACCELERATION_STD',
    'DEFAULT_GYRO_STD',
    'DEFAULT_IMU_STD',
    'DEFAULT_LENGTH_STD',
    'DEFAULT_MARKER_STD',
    'DEFAULT_MAX_SUBSTEP',
    'DEFAULT_PIVOT_ACCELEROMETER_STD',
    'DEFAULT_PREDICTION',
    'DEFAULT_TENSION_STD',
    'DEFAULT_WRENCH_STD',
    'FLIPPED_IMU_ANGLE',
    'GAUGE_TOLERANCE',
    'NULL_TOLERANCE',
    'PREDICTIONS',
    'Reading',
    'StructureEstimate',
    'StructureFilter',
    'StructureFilterUpdate',
    'StructureMeasurements',
    'apply_increment',
    'body_accelerations',
    'contact_nodes',
    'estimate_structure_poses',
    'force_scale',
    'length_scale',
    'measurement_model',
    'readings_of',
    'replace_at_rest',
    'rigid_motion_basis',
    'specific_force_model',
    'spin_basis',
    'string_model',
]

FloatArray = NDArray[np.float64]

#: Default standard deviations: a length sensor (m), a load cell (N), an IMU's gravity direction
#: (rad, per axis of the tangent plane), a marker (m, per axis), the ground contact (m).
DEFAULT_LENGTH_STD = 1e-3
DEFAULT_TENSION_STD = 0.05
DEFAULT_IMU_STD = 5e-3
DEFAULT_MARKER_STD = 1e-3
DEFAULT_CONTACT_STD = 1e-4
#: Default std of a body's wrench balance at rest (N, N m).
DEFAULT_WRENCH_STD = (0.02, 0.002)
#: A direction of the scaled whitened Jacobian is undetermined below this times its largest
#: singular value (far above rounding, far below the weakest determined direction here).
NULL_TOLERANCE = 1e-7
#: A spin or a rigid motion of the whole is a gauge when the readings see it less than this
#: times the best-seen direction (:func:`_gauge`).
GAUGE_TOLERANCE = 1e-4
#: Gauss-Newton stops when the step's predicted chi2 decrease is below this (far below chi2's
#: own spread, sqrt(2 dof)).
DECREMENT_TOLERANCE = 1e-6
#: Gauss-Newton iterations of one estimate (over its refits) that a time budget does not cut
#: short: on test_structure_estimator.py a fit takes 3-8 iterations in 87 % of 470 fits
#: (median 5, about 2 ms each; the rest up to the 30 of MAX_ITERATIONS), so an estimate from
#: the resting or last poses is not cut short on a machine that starves it of CPU.
MIN_FIT_ITERATIONS = 8
#: An IMU whose gravity is more than this (deg) from the estimate's is left out first (a
#: flipped or misplaced IMU: far beyond any noise, so not weighed against the others).
FLIPPED_IMU_ANGLE = 90.0
#: Step limits (rad; fraction of the length scale), as the joint's solver.
MAX_ROTATION_STEP = 0.5
MAX_TRANSLATION_FRACTION = 0.5
_AXES = 'xyz'


@dataclass
class StructureMeasurements:
    """One set of readings of a structure (any of them None: not measured).

    ``lengths`` / ``tensions`` {string: value} (m / N) with ``length_std`` / ``tension_std``;
    ``rest_lengths`` (n,) the motor encoders' rest lengths (None: the configured ones);
    ``imu_gravity`` {body: (3,)} the unit direction of gravity in the body's frame (from an
    accelerometer at rest: ``sensor_models.gravity_from_specific_force``) with ``imu_std``
    (rad); ``markers`` {``body.node``: (3,)} world positions with ``marker_std`` (m);
    ``contacts`` the nodes known to be on the ground (or {node: its measured height above the
    ground}, default 0) with ``contact_std`` (m); ``at_rest``: the robot is still, so every
    free body's wrench balance holds (strings at the encoders' rest lengths, weight, the
    unknown contact forces at ``contacts``) to ``wrench_std`` (N and N m: the model's error)."""

    lengths: Mapping[str, float] | None = None
    tensions: Mapping[str, float] | None = None
    rest_lengths: ArrayLike | None = None
    imu_gravity: Mapping[str, ArrayLike] | None = None
    markers: Mapping[str, ArrayLike] | None = None
    contacts: Sequence[str] | Mapping[str, float] | None = None
    at_rest: bool = False
    length_std: float = DEFAULT_LENGTH_STD
    tension_std: float = DEFAULT_TENSION_STD
    imu_std: float = DEFAULT_IMU_STD
    marker_std: float = DEFAULT_MARKER_STD
    contact_std: float = DEFAULT_CONTACT_STD
    wrench_std: tuple[float, float] = DEFAULT_WRENCH_STD


@dataclass
class StructureEstimate:
    """Outcome of :func:`estimate_structure_poses`.

    ``poses`` (N, 4, 4); ``covariance`` (6N, 6N) of the stacked ``[dp; dw]`` of the bodies
    (PoseWithCovariance convention per body; fixed bodies and gauge directions zero);
    ``body_covariance(i)`` its (6, 6) block; ``state`` the :class:`StructureState` at the
    estimate (tensions, ...); ``chi2``, ``redundancy``, ``consistent`` (None without
    redundancy), ``outliers`` / ``outlier_reasons`` (names ``length[s]``, ``tension[s]``,
    ``imu[body]``, ``marker[body.node]``, ``contact[body.node]``); ``gauge`` the undetermined
    directions held at the start, by name; ``rank`` of the scaled Jacobian and its
    ``condition_number``; ``iterations``. When ``success`` is False the numbers are NaN and
    ``message`` names what the readings cannot determine."""

    success: bool
    message: str
    poses: FloatArray
    covariance: FloatArray
    state: StructureState | None
    chi2: float
    redundancy: int
    consistent: bool | None
    gauge: tuple[str, ...]
    rank: int
    condition_number: float
    iterations: int
    inputs: str = ''
    outliers: tuple[str, ...] = ()
    outlier_reasons: tuple[str, ...] = ()
    undetermined: tuple[str, ...] = field(default=())

    def body_covariance(self, i: int) -> FloatArray:
        """The (6, 6) covariance of body ``i``'s pose (PoseWithCovariance convention)."""
        return self.covariance[6 * i:6 * i + 6, 6 * i:6 * i + 6]


# ---------------------------------------------------------------------------------- models
def _node_rows(structure: Structure, T: FloatArray, node: int) -> tuple[int, FloatArray]:
    """Body index of ``node`` (-1: the world) and ``[I, -hat(x - p)]`` (3, 6) of its motion."""
    b = int(structure.node_bodies[node])
    if b < 0:
        return b, np.zeros((3, 6))
    x = T[b, :3, :3] @ structure.node_points[node] + T[b, :3, 3]
    return b, np.hstack([np.eye(3), -hat3(x - T[b, :3, 3])])


def string_model(structure: Structure, T: FloatArray, rest: FloatArray | None = None
                 ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """Lengths (n,), tensions (n,) and their Jacobians (n, 6N) in the bodies' ``[dp; dw]``
    (module docstring) at the (N, 4, 4) transforms ``T`` with ``rest`` (n,) (None: the
    configured rest lengths); the tensions by the strings' law (``Structure.evaluate``'s)."""
    rest = structure.rest_lengths if rest is None else rest
    xa, xb, lengths = structure.string_geometry(T)
    u = (xb - xa) / lengths[:, None]
    phi, dphi, _, _ = string_forces(lengths, rest, structure.k, structure.max_stretch,
                                    structure.force_law)
    n_b = structure.n_bodies
    L = np.zeros((structure.n_strings, 6 * n_b + 6))  # the world last, dropped
    ends = np.where(structure.string_bodies < 0, n_b, structure.string_bodies)
    p = np.concatenate([T[:, :3, 3], np.zeros((1, 3))])
    rows = np.arange(structure.n_strings)[:, None]
    for side, x, sign in ((0, xa, -1.0), (1, xb, 1.0)):  # (string, column) unique per side
        body = ends[:, side]
        arm = np.cross(x - p[body], u)
        cols = 6 * body[:, None] + np.arange(6)[None, :]
        L[rows, cols] += sign * np.hstack([u, arm])
    L = L[:, :6 * n_b]
    return lengths, phi, L, dphi[:, None] * L


def spin_basis(structure: Structure, T: FloatArray) -> tuple[list[str], FloatArray]:
    """The free bars' spins about their own axes (names ``spin of <bar>``, (6N, k) unit
    ``dw`` along each axis)."""
    n = 6 * structure.n_bodies
    names, cols = [], []
    for i in structure.bar_indices:
        if structure.fixed[i]:
            continue
        v = np.zeros(n)
        v[6 * i + 3:6 * i + 6] = T[i, :3, 2]
        names.append(f'spin of {structure.body_names[i]}')
        cols.append(v)
    return names, np.array(cols).T.reshape(n, len(cols))


def rigid_motion_basis(structure: Structure, T: FloatArray) -> tuple[list[str], FloatArray]:
    """The six rigid motions of all free bodies together (names ``translation along x`` ...
    ``turn about z``; (6N, 6)), turns about the free bodies' mean origin."""
    free = np.flatnonzero(~structure.fixed)
    c = T[free, :3, 3].mean(axis=0)
    n = 6 * structure.n_bodies
    B = np.zeros((n, 6))
    names = [f'translation along {a}' for a in _AXES] + [f'turn about {a}' for a in _AXES]
    for i in free:
        B[6 * i:6 * i + 3, :3] = np.eye(3)
        B[6 * i:6 * i + 3, 3:] = -hat3(T[i, :3, 3] - c)
        B[6 * i + 3:6 * i + 6, 3:] = np.eye(3)
    return names, B


# ---------------------------------------------------------------------------------- readings
@dataclass
class Reading:
    """One named reading: ``kind`` (``length``, ``tension``, ``imu``, ``marker``,
    ``contact``), the string, body or node ``index``, its ``value``, ``std`` and measured
    degrees of freedom ``dof``."""

    name: str
    kind: str
    index: int
    value: FloatArray
    std: float | FloatArray
    dof: int


def _positive(name: str, value: float) -> float:
    v = float(value)
    if not (math.isfinite(v) and v > 0.0):
        raise ValueError(f'{name} must be finite and > 0, got {value!r}')
    return v


def readings_of(structure: Structure, m: StructureMeasurements) -> list[Reading]:
    """The measurements as named readings, checked (ValueError naming the field)."""
    out: list[Reading] = []
    strings = {name: j for j, name in enumerate(structure.string_names)}
    for kind, values, std in (('length', m.lengths, m.length_std),
                              ('tension', m.tensions, m.tension_std)):
        if values is None:
            continue
        s = _positive(f'{kind}_std', std)
        for key, v in values.items():
            if key not in strings:
                raise ValueError(f'{kind}s: no string {key!r} (strings: {structure.string_names})')
            x = finite_array(f'{kind}s[{key}]', v).reshape(-1)
            if x.shape != (1,) or (kind == 'length' and x[0] <= 0.0):
                raise ValueError(f'{kind}s[{key}] must be one {"positive " * (kind == "length")}'
                                 f'number, got {v!r}')
            out.append(Reading(f'{kind}[{key}]', kind, strings[key], x, s, 1))
    if m.imu_gravity is not None:
        s = _positive('imu_std', m.imu_std)
        if structure.gravity is None or not np.any(structure.gravity):
            raise ValueError('imu_gravity needs the structure\'s gravity')
        for key, v in m.imu_gravity.items():
            i = structure.body_index(key)
            out.append(Reading(f'imu[{key}]', 'imu', i, unit_vector(v, f'imu_gravity[{key}]'),
                                s, 2))
    if m.markers is not None:
        s = _positive('marker_std', m.marker_std)
        for key, v in m.markers.items():
            node = structure.node_index(key)
            x = finite_array(f'markers[{key}]', v).reshape(-1)
            if x.shape != (3,):
                raise ValueError(f'markers[{key}] must be 3 values [x, y, z]')
            out.append(Reading(f'marker[{key}]', 'marker', node, x, s, 3))
    if m.contacts is not None:
        if structure.ground is None:
            raise ValueError('contacts need the structure\'s ground')
        s = _positive('contact_std', m.contact_std)
        heights = (m.contacts if isinstance(m.contacts, Mapping)
                   else dict.fromkeys(m.contacts, 0.0))
        for key, v in heights.items():
            x = finite_array(f'contacts[{key}]', v).reshape(-1)
            if x.shape != (1,):
                raise ValueError(f'contacts[{key}] must be one height (m), got {v!r}')
            out.append(Reading(f'contact[{key}]', 'contact', structure.node_index(key), x, s, 1))
    if m.at_rest:
        f_std = _positive('wrench_std[0]', m.wrench_std[0])
        m_std = _positive('wrench_std[1]', m.wrench_std[1])
        std = np.array([f_std] * 3 + [m_std] * 3)
        for i, body in enumerate(structure.bodies):
            if not body.fixed:
                out.append(Reading(f'equilibrium[{body.name}]', 'equilibrium', i, np.zeros(6),
                                   std, 5 if body.kind == 'bar' else 6))
    return out


def contact_nodes(readings: Sequence[Reading]) -> list[int]:
    """The nodes whose contact forces are unknowns: the contacts' when a wrench balance is
    among the readings, else none."""
    if not any(r.kind == 'equilibrium' for r in readings):
        return []
    return [r.index for r in readings if r.kind == 'contact']


def _equilibrium(structure: Structure, T: FloatArray, rest: FloatArray, nodes: Sequence[int],
                 forces: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Every body's wrench balance (N, 6) (strings, weight, contact ``forces`` (c, 3) at
    ``nodes``) and its Jacobian (6N, 6N + 3c) in ``[dp; dw]`` and the forces: the strings' and
    weights' ``-K D`` (``D`` the map to spatial twists, ``dv = dp + hat(p) dw``), a contact's
    ``[I; hat(x)]`` in its force and ``[0; -hat(lambda) [I, -hat(x - p)]]`` in its body's pose."""
    n = structure.n_bodies
    state = structure.evaluate_transforms(T, rest)
    Wg, Kg = structure.gravity_wrenches(T)
    W = state.wrenches + Wg
    D = np.zeros((6 * n, 6 * n))
    for i in range(n):
        D[6 * i:6 * i + 6, 6 * i:6 * i + 6] = np.eye(6)
        D[6 * i:6 * i + 3, 6 * i + 3:6 * i + 6] = hat3(T[i, :3, 3])
    J = np.zeros((6 * n, 6 * n + 3 * len(nodes)))
    J[:, :6 * n] = -(state.stiffness + Kg) @ D
    for c, node in enumerate(nodes):
        b, rows = _node_rows(structure, T, node)
        x = T[b, :3, :3] @ structure.node_points[node] + T[b, :3, 3]
        lam = forces[c]
        W[b, :3] += lam
        W[b, 3:] += np.cross(x, lam)
        J[6 * b:6 * b + 3, 6 * n + 3 * c:6 * n + 3 * c + 3] = np.eye(3)
        J[6 * b + 3:6 * b + 6, 6 * n + 3 * c:6 * n + 3 * c + 3] = hat3(x)
        J[6 * b + 3:6 * b + 6, 6 * b:6 * b + 6] += -hat3(lam) @ rows
    return W, J


_SIZES = {'length': 1, 'tension': 1, 'contact': 1, 'imu': 3, 'marker': 3, 'equilibrium': 6}


def measurement_model(structure: Structure, T: FloatArray, readings: Sequence[Reading],
                      rest: FloatArray, forces: FloatArray | None = None
                      ) -> tuple[FloatArray, FloatArray, FloatArray, list[int]]:
    """Predictions ``h`` (m,), Jacobian ``H`` (m, 6N + 3c) in the ``[dp; dw]`` of the bodies
    and the contact forces (c, 3) ``forces`` at :func:`contact_nodes` (a wrench balance's
    unknowns), the rows' stds (m,) and the first row of each reading, at transforms ``T``
    (module docstring). The strings' readings in one vectorised pass."""
    nodes = contact_nodes(readings)
    forces = np.zeros((len(nodes), 3)) if forces is None else forces.reshape(-1, 3)
    n6 = 6 * structure.n_bodies
    width = n6 + 3 * len(nodes)
    sizes = np.array([_SIZES[r.kind] for r in readings], dtype=np.intp)
    starts_arr = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.intp)
    m = int(sizes.sum())
    h = np.zeros(m)
    H = np.zeros((m, width))
    std = np.zeros(m)
    g_hat = (None if structure.gravity is None or not np.any(structure.gravity)
             else structure.gravity / np.linalg.norm(structure.gravity))
    string_kinds = [(q, r) for q, r in enumerate(readings) if r.kind in ('length', 'tension')]
    if string_kinds:
        lengths, phi, dl, dphi = string_model(structure, T, rest)
        for kind, value, jac in (('length', lengths, dl), ('tension', phi, dphi)):
            pick = [(starts_arr[q], r.index, r.std) for q, r in string_kinds if r.kind == kind]
            if pick:
                rows, js, sd = (np.array(x) for x in zip(*pick, strict=True))
                h[rows] = value[js]
                H[rows, :n6] = jac[js]
                std[rows] = sd
    balance = None
    for q, r in enumerate(readings):
        a = starts_arr[q]
        if r.kind in ('length', 'tension'):
            continue
        rows = slice(a, a + sizes[q])
        std[rows] = r.std
        if r.kind == 'imu':
            R = T[r.index, :3, :3]
            H[rows, 6 * r.index + 3:6 * r.index + 6] = R.T @ hat3(g_hat)
            h[rows] = R.T @ g_hat
        elif r.kind == 'equilibrium':
            if balance is None:
                balance = _equilibrium(structure, T, rest, nodes, forces)
            h[rows] = balance[0][r.index]
            H[rows] = balance[1][6 * r.index:6 * r.index + 6]
        else:
            b, block = _node_rows(structure, T, r.index)
            x = (structure.node_points[r.index] if b < 0
                 else T[b, :3, :3] @ structure.node_points[r.index] + T[b, :3, 3])
            if r.kind == 'marker':
                h[rows] = x
                if b >= 0:
                    H[rows, 6 * b:6 * b + 6] = block
            else:
                ground = structure.ground
                h[rows] = ground.normal @ x - ground.height
                if b >= 0:
                    H[rows, 6 * b:6 * b + 6] = ground.normal[None] @ block
    return h, H, std, starts_arr.tolist()


def apply_increment(T: FloatArray, dx: FloatArray) -> FloatArray:
    """The transforms ``T`` (N, 4, 4) moved by the stacked ``[dp; dw]`` (6N,): ``p + dp``,
    ``exp(hat(dw)) R``."""
    out = T.copy()
    d = dx.reshape(-1, 6)
    out[:, :3, 3] += d[:, :3]
    out[:, :3, :3] = exp_so3(d[:, 3:]) @ T[:, :3, :3]  # one batched Rodrigues
    return out


# ---------------------------------------------------------------------------------- estimator
def length_scale(structure: Structure) -> float:
    """The structure's length scale (m): the mean rest length (radians and metres weighed
    alike by it)."""
    return float(max(np.mean(structure.rest_lengths), 1e-6))


def force_scale(structure: Structure, n_contacts: int) -> float:
    """The contact forces' unit (N): the weight per contact (1 N without gravity)."""
    if structure.gravity is None or n_contacts == 0:
        return 1.0
    weight = sum(b.mass for b in structure.bodies if not b.fixed) * np.linalg.norm(
        structure.gravity)
    return float(max(weight / n_contacts, 1e-6))


def _describe(structure: Structure, v: FloatArray, rigid_names: list[str], rigid: FloatArray,
              cols: NDArray[np.intp]) -> str:
    """A direction ``v`` of the scaled free unknowns in words: the rigid motions it is made of
    (``rigid`` their scaled columns), else the bodies that move."""
    coef, *_ = np.linalg.lstsq(rigid, v, rcond=None)
    rest = v - rigid @ coef
    if np.linalg.norm(rest) < 1e-6 * max(float(np.linalg.norm(v)), 1e-300):
        big = np.abs(coef) > 0.2 * np.abs(coef).max()
        return ' and '.join(n for n, b in zip(rigid_names, big, strict=True) if b) + \
            ' of the whole structure'
    moving = np.linalg.norm(v.reshape(-1, 6), axis=1)
    bodies = cols[::6] // 6
    names = [structure.body_names[bodies[i]] for i in np.flatnonzero(moving > 0.2 * moving.max())]
    return 'a relative motion of ' + ', '.join(names)


@dataclass
class _Fit:
    T: FloatArray
    forces: FloatArray  # (c, 3) the contact forces of a wrench balance
    r: FloatArray
    J: FloatArray  # whitened, scaled columns of the unknowns, the gauge projected out
    C: FloatArray  # covariance of the scaled unknowns (pseudo-inverse)
    rank: int
    condition: float
    null: FloatArray  # (n_unknowns, d) undetermined directions besides the gauge (scaled)
    gauge: FloatArray  # (n_pose_unknowns, g) the gauge directions (scaled, orthonormal)
    iterations: int

    @property
    def chi2(self) -> float:
        return float(self.r @ self.r)


def _gauge(structure: Structure, T: FloatArray, J: FloatArray, cols: NDArray[np.intp],
           pose_scale: FloatArray) -> FloatArray:
    """The gauge (npose, g) at ``T``: the directions among the bars' spins and the rigid motions
    of the whole that the readings see less than :data:`GAUGE_TOLERANCE` of the best-seen
    direction, the contact forces eliminated (a turn of the whole turns them too). Tested on
    this span with a tolerance of its own because a residual's imbalance gives them a spurious,
    second-order weight (1e-6 of the largest on the twin's data)."""
    npose = cols.size
    _, spins = spin_basis(structure, T)
    _, rigid = rigid_motion_basis(structure, T)
    G = np.hstack([spins[cols], rigid[cols]]) / pose_scale[:, None]
    Q, _ = np.linalg.qr(G)
    Jp = J[:, :npose]
    if J.shape[1] > npose:
        Ul, sl, _ = np.linalg.svd(J[:, npose:], full_matrices=False)
        Ul = Ul[:, sl > NULL_TOLERANCE * sl[0]]
        Jp = Jp - Ul @ (Ul.T @ Jp)
    _, sm, Vm = np.linalg.svd(Jp @ Q, full_matrices=True)
    s0 = float(np.linalg.norm(J, 2))
    sm = np.concatenate([sm, np.zeros(Q.shape[1] - sm.size)])
    return Q @ Vm[sm < GAUGE_TOLERANCE * s0].T


def _fit(structure: Structure, readings: Sequence[Reading], rest: FloatArray, T0: FloatArray,
         cols: NDArray[np.intp], scale: FloatArray, max_iterations: int,
         clock: FitClock | None = None) -> _Fit:
    """Gauss-Newton from ``T0`` over the free pose columns ``cols`` and the contact forces
    (module docstring); ``scale`` (len(cols) + 3c) the unknowns' units; no step along the
    gauge (:func:`_gauge`); a step only while the estimate's ``clock`` allows it (it says
    when it refused)."""
    z = np.concatenate([r.value for r in readings])
    lc = float(scale[0])
    n6 = 6 * structure.n_bodies
    nf = 3 * len(contact_nodes(readings))
    sel = np.concatenate([cols, n6 + np.arange(nf)])
    npose = cols.size

    def whitened(T: FloatArray, lam: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        h, H, std, _ = measurement_model(structure, T, readings, rest, lam)
        J = (H[:, sel] * scale[None, :]) / std[:, None]
        Z = _gauge(structure, T, J, cols, scale[:npose])
        J[:, :npose] -= (J[:, :npose] @ Z) @ Z.T
        return (h - z) / std, J, Z

    T, lam = T0, np.zeros(nf)
    r, J, Z = whitened(T, lam)
    cost = float(r @ r)
    iterations = 0
    for iteration in range(1, max_iterations + 1):
        if clock is not None and not clock.next_iteration():
            break
        iterations = iteration
        U, s, Vt = np.linalg.svd(J, full_matrices=False)
        keep = s > NULL_TOLERANCE * s[0]
        step = -(Vt[keep].T @ ((U[:, keep].T @ r) / s[keep])) * scale
        predicted = float(np.sum((U[:, keep].T @ r) ** 2))
        dx = np.zeros(n6)
        dx[cols] = step[:npose]
        d = dx.reshape(-1, 6)
        limit = max(np.abs(d[:, 3:]).max() / MAX_ROTATION_STEP,
                    np.abs(d[:, :3]).max() / (MAX_TRANSLATION_FRACTION * lc), 1.0)
        dx /= limit
        dlam = step[npose:] / limit
        for _ in range(30):
            T_new, lam_new = apply_increment(T, dx), lam + dlam
            r_new, J_new, Z_new = whitened(T_new, lam_new)
            new_cost = float(r_new @ r_new)
            if new_cost <= cost or not np.isfinite(cost):
                break
            dx *= 0.5
            dlam *= 0.5
        else:
            break
        T, lam, r, J, Z, cost = T_new, lam_new, r_new, J_new, Z_new, new_cost
        if predicted < DECREMENT_TOLERANCE:
            break
    U, s, Vt = np.linalg.svd(J, full_matrices=True)
    keep = s > NULL_TOLERANCE * s[0]
    rank = int(keep.sum())
    C = (Vt[:rank].T / s[:rank] ** 2) @ Vt[:rank]
    null = Vt[rank:].T
    if Z.shape[1]:  # the gauge is not an undetermined direction to report
        Zf = np.vstack([Z, np.zeros((nf, Z.shape[1]))])
        null = null - Zf @ (Zf.T @ null)
        U_n, s_n, _ = np.linalg.svd(null, full_matrices=False)
        null = U_n[:, s_n > 0.5]
    return _Fit(T, lam.reshape(-1, 3), r, J, C, rank, float(s[0] / s[rank - 1]), null, Z,
                iterations)


def _classify(structure: Structure, fit: _Fit, cols: NDArray[np.intp], scale: FloatArray,
              hold_rigid_motion: bool) -> tuple[list[str], list[str]]:
    """(gauge names, undetermined descriptions) of the fit (module docstring)."""
    pose_scale = scale[:cols.size]
    spin_names, spins = spin_basis(structure, fit.T)
    rigid_names, rigid = rigid_motion_basis(structure, fit.T)
    spins_s, rigid_s = spins[cols] / pose_scale[:, None], rigid[cols] / pose_scale[:, None]
    Z = fit.gauge
    gauge: list[str] = []
    undetermined: list[str] = []
    if Z.shape[1]:
        G = np.hstack([spins_s, rigid_s])
        coef = np.linalg.lstsq(G, Z, rcond=None)[0]
        ns = spins_s.shape[1]
        spin_part = spins_s @ coef[:ns]
        # a spin is held when it is in the gauge
        for k, v in enumerate(spins_s.T):
            if np.linalg.norm(v - Z @ (Z.T @ v)) < 1e-6 * np.linalg.norm(v):
                gauge.append(spin_names[k])
        rigid_coef = np.linalg.norm(coef[ns:], axis=1)
        rigid_in = np.linalg.norm(Z - spin_part) > 1e-6
        seen = [n for n, c in zip(rigid_names, rigid_coef, strict=True)
                if rigid_in and c > 1e-3 * max(rigid_coef.max(), 1e-300)]
        if seen and hold_rigid_motion:
            gauge += [f'{n} of the whole structure' for n in seen]
        elif seen:
            undetermined.append(', '.join(seen) + ' of the whole structure')
    null = fit.null[:cols.size]
    if null.shape[1]:
        U_n, s_n, _ = np.linalg.svd(null, full_matrices=False)
        undetermined += [_describe(structure, v, rigid_names, rigid_s, cols)
                         for v in U_n[:, s_n > 0.1].T]
    return gauge, undetermined


def estimate_structure_poses(structure: Structure, measurements: StructureMeasurements,
                             start: ArrayLike | None = None, hold_rigid_motion: bool = False,
                             consistency_probability: float = CONSISTENCY_PROBABILITY,
                             max_iterations: int = MAX_ITERATIONS,
                             time_budget: float | None = None) -> StructureEstimate:
    """Every body's pose with covariance from ``measurements`` (module docstring), Gauss-Newton
    from ``start`` ((N, 4, 4) or (N, 7); None: the structure's poses). ``hold_rigid_motion``:
    hold an undetermined rigid motion of the whole at the start (named in ``gauge``) instead of
    refusing it. ``time_budget`` (s; None: no bound): one deadline for the estimate, checked
    between iterations once its fits have taken :data:`MIN_FIT_ITERATIONS`; an estimate that
    hits it fails with ``time budget exhausted after <k> iterations (...)``."""
    T0 = structure.transforms(start)
    clock = FitClock(DECREMENT_TOLERANCE, max_iterations, time_budget, MIN_FIT_ITERATIONS)
    rest = structure.validate_rest_lengths(measurements.rest_lengths)
    readings = readings_of(structure, measurements)
    inputs = _inputs(readings)
    n6 = 6 * structure.n_bodies
    cols = np.flatnonzero(np.repeat(~structure.fixed, 6))
    lc = length_scale(structure)
    pose_scale = np.tile([lc, lc, lc, 1.0, 1.0, 1.0], cols.size // 6)  # [dp; dw] = scale y
    dropped: list[tuple[str, str]] = []
    while True:
        if not readings:
            return _failed('no readings', structure, inputs, dropped)
        n_forces = len(contact_nodes(readings))
        scale = np.concatenate([pose_scale, np.full(3 * n_forces, force_scale(structure,
                                                                              n_forces))])
        fit = _fit(structure, readings, rest, T0, cols, scale, max_iterations, clock)
        if clock.exhausted:
            return _failed(clock.message(inputs), structure, inputs, dropped)
        gauge, undetermined = _classify(structure, fit, cols, scale, hold_rigid_motion)
        if undetermined:
            msg = (f'{inputs} cannot determine ' + '; '.join(dict.fromkeys(undetermined))
                   + (' (add markers, or hold_rigid_motion=True to hold it at the start)'
                      if any('whole structure' in u for u in undetermined) else ''))
            return _failed(msg, structure, inputs, dropped, undetermined)
        measured = sum(r.dof for r in readings)
        redundancy = measured - fit.rank
        threshold = consistency_threshold(redundancy, consistency_probability)
        if (fit.chi2 > threshold and redundancy > 0 and len(dropped) < MAX_CONTRADICTED):
            h, _, _, starts = measurement_model(structure, fit.T, readings, rest, fit.forces)
            flipped = [(r, math.degrees(math.acos(float(np.clip(h[a:a + 3] @ r.value, -1, 1)))))
                       for r, a in zip(readings, starts, strict=True) if r.kind == 'imu']
            flipped = [(r, angle) for r, angle in flipped if angle > FLIPPED_IMU_ANGLE]
            if flipped and redundancy >= 2:
                r, angle = max(flipped, key=lambda item: item[1])
                dropped.append((r.name, f'flipped or misplaced: {angle:.0f} deg from the '
                                        'direction of gravity the other readings give'))
                readings = [q for q in readings if q.name != r.name]
                continue
            ends = starts[1:] + [fit.r.size]
            named = [(r.name, np.arange(a, b), r.dof)  # the statics are the model: kept
                     for r, a, b in zip(readings, starts, ends, strict=True)
                     if r.kind != 'equilibrium']
            suspect = suspect_reading(fit.r, fit.J, fit.C, named, redundancy)
            if suspect is not None:
                dropped.append(suspect)
                readings = [r for r in readings if r.name != suspect[0]]
                continue
        break
    cov = np.zeros((n6, n6))
    p = cols.size
    cov[np.ix_(cols, cols)] = pose_scale[:, None] * fit.C[:p, :p] * pose_scale[None, :]
    consistent = None if redundancy <= 0 else bool(fit.chi2 <= threshold)
    return StructureEstimate(
        True, 'ok', fit.T, cov, structure.evaluate_transforms(fit.T, rest), fit.chi2,
        redundancy, consistent, tuple(gauge), fit.rank, fit.condition, fit.iterations, inputs,
        tuple(n for n, _ in dropped), tuple(w for _, w in dropped))


def _inputs(readings: Sequence[Reading]) -> str:
    counts: dict[str, int] = {}
    for r in readings:
        counts[r.kind] = counts.get(r.kind, 0) + 1
    return ', '.join(f'{v} {k}{"s" if v > 1 else ""}' for k, v in counts.items()) or 'nothing'


def _failed(message: str, structure: Structure, inputs: str, dropped: list[tuple[str, str]],
            undetermined: Sequence[str] = ()) -> StructureEstimate:
    n = structure.n_bodies
    return StructureEstimate(False, message, np.full((n, 4, 4), np.nan),
                             np.full((6 * n, 6 * n), np.nan), None, math.nan, 0, None, (), 0,
                             math.nan, 0, inputs, tuple(d for d, _ in dropped),
                             tuple(w for _, w in dropped), tuple(undetermined))


# ---------------------------------------------------------------------------------- recursive
#: Default process noise of :class:`StructureFilter`'s constant-velocity prediction: white
#: accelerations (m/s^2, rad/s^2) of each body's origin and turn, std per axis per sqrt(s) (a
#: rolling robot's).
DEFAULT_ACCELERATION_STD = (2.0, 20.0)
#: The same for the prediction on the dynamics (what they leave out: impacts, the contacts'
#: slide, the encoders held over a step), (linear, angular across a bar, about its axis): the
#: dynamics' one-step errors at the rolling twins' true states (RMS over 0.01 s: 1.3 m/s^2,
#: 16 rad/s^2 across a bar, 46 about its axis; constant velocity's 2.6, 25, 46) set the angular
#: ratio, 1 : 3; the levels are the smallest of a grid (0.5 .. 2 m/s^2, 4 .. 10 rad/s^2) whose
#: NEES stays below the band's top on both twins, gating at most 3 % as many readings as there
#: are accelerometer readings (4 seeds; at 0.7 m/s^2 the 3-bar's NEES is 2.2, at 4 rad/s^2
#: 3.3 % gated). White noise at the errors' own RMS is inconsistent (NEES 3.5 .. 6, the 3-bar's
#: track lost): they come in bursts (impacts, slides).
DEFAULT_DYNAMICS_ACCELERATION_STD = (1.0, 5.0, 15.0)
#: Default std of a gyro (rad/s) and of a contact node's velocity (m/s: it sticks).
DEFAULT_GYRO_STD = 0.01
DEFAULT_CONTACT_VELOCITY_STD = 2e-3
#: Default std of an accelerometer's specific force (m/s^2 per axis): its noise and the
#: dynamics' model error (:func:`specific_force_model`).
DEFAULT_ACCELEROMETER_STD = 0.1
#: Default std (m/s^2) of the dynamics' specific force on a body turning about its contact node:
#: the contact's own error (a soft contact that gives, a node that slides: median 0.03, 10 % of
#: the readings above 0.45 m/s^2 on the rolling twin, up to 14 at an impact; 3e-3 at rest).
DEFAULT_PIVOT_ACCELEROMETER_STD = 3.0
#: :class:`StructureFilter`'s predictions: the structure's dynamics
#: (:meth:`StructureFilter.drift`) or constant velocity.
PREDICTIONS = ('dynamics', 'constant_velocity')
DEFAULT_PREDICTION = 'dynamics'
#: The dynamics' longest sub-step (s) of :class:`StructureFilter`'s linearly implicit step.
DEFAULT_MAX_SUBSTEP = 0.01


def body_accelerations(structure: Structure, T: FloatArray, V: FloatArray, rest: FloatArray,
                       bodies: Sequence[int], pivots: Mapping[int, int] | None = None,
                       angular: bool = True) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The accelerations ``[a_i; alpha_i]`` (k, 6) (the origin's, the angular one; world) of
    ``bodies`` (free, each with its centre of mass at its origin) by their dynamics at the
    transforms ``T`` with ``rest``, ``V`` (N, 6) the bodies' ``[v; w]``:

    * off the ground, Newton-Euler about the centre of mass: ``m a_i = F_i + F_d,i + m g``,
      ``I_i alpha_i + w x I_i w = M_i + M_d,i`` (``I_i = R I R^T``), ``[F_i; M_i]`` the strings'
      wrench (``Structure.evaluate``'s, moment taken about ``p_i``) and ``[F_d,i; M_d,i]`` their
      damping (the generalised force ``-L^T c (L V)``, ``c`` N s/m as MuJoCo's tendon damping,
      ``L = dl/d[dp; dw]`` of :func:`string_model`);
    * on one sticking node ``pivots[i]`` (``x_c``, ``r = p - x_c``), Euler's law about it (the
      contact force has no moment there): ``I_c alpha + w x I_c w = M_c`` with ``I_c`` the
      inertia about ``x_c`` and ``M_c`` the strings', their damping's and the weight's moment
      about it, and ``a_i = alpha x r + w x (w x r)``.

    Returns the accelerations and their Jacobians (6k, 6N) in the poses' ``[dp; dw]`` (through
    the strings' stiffness ``-K D``, ``D`` the map to ``K``'s spatial twists, and the body's own
    turn) and in ``V`` (the damping, the gyroscopic and centripetal terms); the damping's change
    with the pose (second order) is left out but for its turn with the body. ``angular=False``:
    ``alpha`` and its rows zero off the ground (the accelerometers' model needs only ``a``)."""
    pivots = {} if pivots is None else pivots
    state = structure.evaluate_transforms(T, rest)
    n6 = 6 * structure.n_bodies
    idx = np.asarray(bodies, dtype=np.intp)
    k = idx.size
    rows6 = (6 * idx[:, None] + np.arange(6)[None, :]).ravel()
    Kb = state.stiffness[rows6]  # (6k, 6N) the bodies' wrench rows, spatial twists
    dW = np.empty((6 * k, structure.n_bodies, 6))  # d[F; M0]/d[dp; dw] (about the origin)
    Kn = Kb.reshape(6 * k, structure.n_bodies, 6)
    dW[..., :3] = -Kn[..., :3]  # D: dv = dp + hat(p) dw
    dW[..., 3:] = -(np.einsum('rnj,njk->rnk', Kn[..., :3], hat3(T[:, :3, 3])) + Kn[..., 3:])
    dW = dW.reshape(6 * k, n6)
    Wd = np.zeros((k, 6))  # the damping's [force; moment about p]
    dWd = np.zeros((6 * k, n6))
    if np.any(structure.damping > 0.0):
        L = string_model(structure, T, rest)[2]
        cl = structure.damping[:, None] * L
        Lb = L[:, rows6]  # (n, 6k)
        Wd = -(Lb.T @ (cl @ V.reshape(-1))).reshape(k, 6)
        dWd = -Lb.T @ cl
    g = np.zeros(3) if structure.gravity is None else np.asarray(structure.gravity, float)
    acc = np.empty((k, 6))
    J_pose = np.empty((6 * k, n6))
    J_vel = np.empty((6 * k, n6))
    for q, i in enumerate(idx):
        W, dWq = state.wrenches[i], dW[6 * q:6 * q + 6]
        rows = slice(6 * q, 6 * q + 6)
        if i not in pivots and not angular:  # Newton's law alone
            m = structure.bodies[i].mass
            acc[q, :3] = (W[:3] + Wd[q, :3]) / m + g
            J_pose[6 * q:6 * q + 3] = dWq[:3] / m
            J_vel[6 * q:6 * q + 3] = dWd[6 * q:6 * q + 3] / m
            acc[q, 3:] = J_pose[6 * q + 3:6 * q + 6] = J_vel[6 * q + 3:6 * q + 6] = 0.0
        elif i not in pivots:
            acc[q], J_pose[rows], J_vel[rows] = _free_acceleration(
                structure, T, V, i, W, dWq, Wd[q], dWd[rows], g)
        else:
            acc[q], J_pose[rows], J_vel[rows] = _pivot_acceleration(
                structure, T, V, i, pivots[i], W, dWq, Wd[q], dWd[rows], g)
    return acc, J_pose, J_vel


def specific_force_model(structure: Structure, T: FloatArray, V: FloatArray, rest: FloatArray,
                         bodies: Sequence[int], pivots: Mapping[int, int] | None = None
                         ) -> tuple[FloatArray, FloatArray, FloatArray]:
    """The accelerometers at the origins of ``bodies`` (free, each with its centre of mass at its
    origin) while the structure moves: the specific force ``f_i = R_i^T (a_i - g)`` of the
    body's dynamics (:func:`body_accelerations`: off the ground Newton's law, so ``f_i = R_i^T
    (F_i + F_d,i) / m_i``; on one sticking node ``pivots[i]`` Euler's law about it) at the
    transforms ``T`` with ``rest``, ``V`` (N, 6) the bodies' ``[v; w]``.

    Returns ``f`` (k, 3) and its Jacobians (3k, 6N) in the poses' ``[dp; dw]`` (those of
    ``a_i`` and the body's own turn of ``R_i^T``) and in ``V``."""
    acc, J_pose, J_vel = body_accelerations(structure, T, V, rest, bodies, pivots,
                                            angular=False)
    g = np.zeros(3) if structure.gravity is None else np.asarray(structure.gravity, float)
    k = len(acc)
    f = np.empty((k, 3))
    H_pose = np.empty((3 * k, J_pose.shape[1]))
    H_vel = np.empty((3 * k, J_pose.shape[1]))
    for q, i in enumerate(bodies):
        R = T[i, :3, :3]
        a = acc[q, :3]
        f[q] = R.T @ (a - g)
        H_pose[3 * q:3 * q + 3] = R.T @ J_pose[6 * q:6 * q + 3]
        H_pose[3 * q:3 * q + 3, 6 * i + 3:6 * i + 6] += R.T @ hat3(a - g)
        H_vel[3 * q:3 * q + 3] = R.T @ J_vel[6 * q:6 * q + 3]
    return f, H_pose, H_vel


def _free_acceleration(structure: Structure, T: FloatArray, V: FloatArray, i: int,
                       W: FloatArray, dW: FloatArray, Wd: FloatArray, dWd: FloatArray,
                       g: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Body ``i``'s ``[a; alpha]`` off the ground (Newton-Euler about its centre of mass, its
    origin) and their Jacobians (6, 6N) in the poses and the velocities
    (:func:`body_accelerations`): the strings' wrench ``W`` = [F; M0] about the world origin
    with ``dW``, the damping's ``Wd`` = [F_d; M_d] about the body's origin with ``dWd`` in
    ``V``."""
    body = structure.bodies[i]
    m = body.mass
    R, p = T[i, :3, :3], T[i, :3, 3]
    w = V[i, 3:]
    F = W[:3]
    Ig = R @ body.inertia @ R.T
    Iw = Ig @ w
    h_p, h_w, h_F, h_Iw = hat3(np.array([p, w, F, Iw]))  # one call
    M = W[3:] - h_p @ F + Wd[3:]  # about p
    alpha = np.linalg.solve(Ig, M - h_w @ Iw)
    h_Ia, h_alpha = hat3(np.array([Ig @ alpha, alpha]))
    own_p, own_w = slice(6 * i, 6 * i + 3), slice(6 * i + 3, 6 * i + 6)
    dM = dW[3:] - h_p @ dW[:3]
    dM[:, own_p] += h_F
    # N = M - w x Ig w, less dIg alpha: the own turn (dIg = hat(dw) Ig - Ig hat(dw))
    dM[:, own_w] += h_w @ h_Iw - h_w @ Ig @ h_w + h_Ia - Ig @ h_alpha
    # the damping's moment turned with the body (its change with the pose is otherwise left
    # out): kept normal to a bar's axis, whose tiny axial inertia would amplify it
    dM[:, own_w] -= hat3(Wd[3:])
    dMv = dWd[3:].copy()
    dMv[:, own_w] += h_Iw - h_w @ Ig  # the gyroscopic term
    n6 = dM.shape[1]
    dalpha = np.linalg.solve(Ig, np.hstack([dM, dMv]))  # one solve for both
    acc = np.concatenate([(F + Wd[:3]) / m + g, alpha])
    J_pose = np.vstack([dW[:3] / m, dalpha[:, :n6]])
    J_vel = np.vstack([dWd[:3] / m, dalpha[:, n6:]])
    return acc, J_pose, J_vel

def _pivot_acceleration(structure: Structure, T: FloatArray, V: FloatArray, i: int, node: int,
                        W: FloatArray, dW: FloatArray, Wd: FloatArray, dWd: FloatArray,
                        g: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Body ``i``'s ``[a; alpha]`` turning about its sticking ``node`` and their Jacobians
    (6, 6N) in the poses and the velocities (:func:`body_accelerations`): the
    strings' wrench ``W`` = [F; M0] about the world origin with ``dW``, the damping's ``Wd`` =
    [F_d; M_d] about the body's origin with ``dWd`` in ``V``."""
    body = structure.bodies[i]
    m = body.mass
    R, p = T[i, :3, :3], T[i, :3, 3]
    w = V[i, 3:]
    xc = R @ structure.node_points[node] + p
    r = p - xc
    F, Fd = W[:3], Wd[:3]
    h_r, h_w, h_xc, h_F, h_Fd, h_mg = hat3(np.array([r, w, xc, F, Fd, m * g]))  # one call
    Ic = R @ body.inertia @ R.T + m * (float(r @ r) * np.eye(3) - np.outer(r, r))
    Mc = W[3:] - h_xc @ F + Wd[3:] + h_r @ (Fd + m * g)
    Iw = Ic @ w
    alpha = np.linalg.solve(Ic, Mc - h_w @ Iw)
    wr = h_w @ r
    a = -h_r @ alpha + h_w @ wr
    h_Iw, h_Ia, h_alpha, h_wr = hat3(np.array([Iw, Ic @ alpha, alpha, wr]))
    # d x_c = dp + hat(r) dw, d r = -hat(r) dw, d I_c = hat(dw) I_c - I_c hat(dw) (own pose)
    dMc = dW[3:] - h_xc @ dW[:3]
    dMc[:, 6 * i:6 * i + 3] += h_F
    dMc[:, 6 * i + 3:6 * i + 6] += (h_F + h_Fd + h_mg) @ h_r
    # the damping's wrench turned with the body (:func:`_free_acceleration`)
    dMc[:, 6 * i + 3:6 * i + 6] -= hat3(Wd[3:]) + h_r @ h_Fd
    # N = M_c - w x I_c w, less dI_c alpha: the body's own turn
    dMc[:, 6 * i + 3:6 * i + 6] += h_w @ h_Iw - h_w @ Ic @ h_w + h_Ia - Ic @ h_alpha
    # velocities: the damping's wrench and w (gyroscopic and centripetal terms)
    dMv = dWd[3:] + h_r @ dWd[:3]
    dMv[:, 6 * i + 3:6 * i + 6] += h_Iw - h_w @ Ic
    n6 = dMc.shape[1]
    dalpha = np.linalg.solve(Ic, np.hstack([dMc, dMv]))  # one solve for both
    J_pose = np.empty((6, n6))
    J_vel = np.empty((6, n6))
    J_pose[:3] = -h_r @ dalpha[:, :n6]
    J_pose[:3, 6 * i + 3:6 * i + 6] -= (h_alpha + h_w @ h_w) @ h_r
    J_vel[:3] = -h_r @ dalpha[:, n6:]
    J_vel[:3, 6 * i + 3:6 * i + 6] -= h_wr + h_w @ h_r
    J_pose[3:] = dalpha[:, :n6]
    J_vel[3:] = dalpha[:, n6:]
    return np.concatenate([a, alpha]), J_pose, J_vel


#: Readings as the filter's update takes them: names, residuals ``z - h``, Jacobians in the
#: state, stds and degrees of freedom, one entry per reading.
ReadingRows = tuple[list[str], list[FloatArray], list[FloatArray], list[FloatArray], list[int]]


@dataclass
class StructureFilterUpdate:
    """One :meth:`StructureFilter.update`: ``poses`` (N, 4, 4), ``velocities`` (N, 6)
    ``[v; w]`` (the origin's velocity and the angular velocity in the world), ``covariance``
    (6N, 6N) of the poses (PoseWithCovariance per body), ``nis`` and ``dof`` of the readings
    kept, ``consistent`` (the NIS's chi-square test), ``outliers`` the readings gated out by
    name with ``outlier_reasons``."""

    poses: FloatArray
    velocities: FloatArray
    covariance: FloatArray
    nis: float
    dof: int
    consistent: bool | None
    outliers: tuple[str, ...]
    outlier_reasons: tuple[str, ...]


class StructureFilter:
    """The recursive form: an extended Kalman filter on every free body's pose and velocity.
    Prediction (``prediction``): ``'dynamics'`` (default), the structure's dynamics
    (:meth:`drift`: Newton-Euler off the ground with the strings' forces at the held rest
    lengths, their damping and gravity; Euler about a body's one sticking contact node;
    constant velocity on a body with more nodes down) by linearly implicit trapezoidal steps
    (:meth:`implicit_step`) of at most ``max_substep``, plus white accelerations
    (``acceleration_std`` = (linear, angular[, a bar's about its own axis]), default
    :data:`DEFAULT_DYNAMICS_ACCELERATION_STD`) for what they leave out; or
    ``'constant_velocity'`` with white accelerations (default :data:`DEFAULT_ACCELERATION_STD`).
    Updated by
    the static estimator's measurement models (:func:`measurement_model`) plus each IMU's gyro
    (``R^T w``, Jacobian ``R^T`` in ``w`` and ``R^T hat(w)`` in ``dw``) and the contacts' zero
    velocity (a sticking node: ``v + w x (x - p) = 0``), which carries the position along the
    ground and the turn about it through a roll. Each reading is gated by its own NIS
    (:func:`~tensegrity_stiffness.estimation.estimators.consistency_threshold` of its degrees
    of freedom) and a gated one is named in ``outliers`` at once (a broken length sensor, a
    flipped IMU: in the first update that has it). An accelerometer is the dynamics'
    (:func:`specific_force_model`): Newton's law with the strings' forces and damping at the
    state on a body off the ground (to ``accelerometer_std``), Euler's law about its contact
    node on a body touching the ground at one node (to ``pivot_accelerometer_std``); on a body
    with more nodes down only its gravity direction ``imu_gravity`` is used, when given, its
    std the caller's (a roll's accelerations, ~0.5 m/s^2 / g, belong in ``imu_std``). The
    structure's string damping is the robot's (a twin's: ``StructureTwinOptions.
    string_damping``).

    ``poses`` the start ((N, 4, 4) or (N, 7)); ``pose_std`` (m, rad) its std per axis."""

    def __init__(self, structure: Structure, poses: ArrayLike, pose_std: tuple[float, float]
                 = (0.01, 0.05), acceleration_std: tuple[float, ...] | None = None,
                 gyro_std: float = DEFAULT_GYRO_STD,
                 contact_velocity_std: float = DEFAULT_CONTACT_VELOCITY_STD,
                 gate_probability: float = CONSISTENCY_PROBABILITY,
                 accelerometer_std: float = DEFAULT_ACCELEROMETER_STD,
                 pivot_accelerometer_std: float = DEFAULT_PIVOT_ACCELEROMETER_STD,
                 prediction: str = DEFAULT_PREDICTION,
                 max_substep: float = DEFAULT_MAX_SUBSTEP) -> None:
        if prediction not in PREDICTIONS:
            raise ValueError(f'prediction must be one of {PREDICTIONS}, got {prediction!r}')
        self.prediction = prediction
        self.max_substep = _positive('max_substep', max_substep)
        #: The rest lengths (n,) and contact nodes the prediction holds (the last update's;
        #: None before it: constant velocity).
        self.held_rest_lengths: FloatArray | None = None
        self.held_contacts: tuple[int, ...] = ()
        self.structure = structure
        self.T = structure.transforms(poses)
        n = structure.n_bodies
        self.V = np.zeros((n, 6))
        self.cols = np.flatnonzero(np.repeat(~structure.fixed, 6))
        f = self.cols.size
        p_std = np.tile([pose_std[0]] * 3 + [pose_std[1]] * 3, f // 6)
        v_std = np.tile([0.1] * 3 + [1.0] * 3, f // 6)
        self.P = np.diag(np.concatenate([p_std, v_std]) ** 2)
        if acceleration_std is None:
            acceleration_std = (DEFAULT_DYNAMICS_ACCELERATION_STD if prediction == 'dynamics'
                                else DEFAULT_ACCELERATION_STD)
        if len(acceleration_std) not in (2, 3):
            raise ValueError('acceleration_std must be (linear, angular[, about a bar\'s axis])')
        self.q = np.tile([acceleration_std[0]] * 3 + [acceleration_std[1]] * 3, f // 6) ** 2
        #: a bar's angular acceleration about its own axis: its density less the others'
        self.q_axial = (acceleration_std[-1] ** 2 - acceleration_std[1] ** 2
                        if len(acceleration_std) == 3 else 0.0)
        free = np.flatnonzero(~structure.fixed)
        self.free_bars = np.flatnonzero(np.isin(free, structure.bar_indices))  # among the free
        self.gyro_std = _positive('gyro_std', gyro_std)
        self.contact_velocity_std = _positive('contact_velocity_std', contact_velocity_std)
        self.accelerometer_std = _positive('accelerometer_std', accelerometer_std)
        self.pivot_accelerometer_std = _positive('pivot_accelerometer_std',
                                                 pivot_accelerometer_std)
        self.gate_probability = gate_probability

    def predict(self, dt: float, rest_lengths: ArrayLike | None = None,
                contacts: Sequence[str | int] | None = None) -> None:
        """Move the state ``dt`` (s) and grow the covariance: by the structure's dynamics
        (``prediction='dynamics'``, :meth:`drift`) with ``rest_lengths`` and the sticking
        ``contacts`` (node names or indices) held over ``dt`` (None: the last update's; before
        any, constant velocity), or at constant velocity (``prediction='constant_velocity'``)."""
        dt = _positive('dt', dt)
        s = self.structure
        rest = self.held_rest_lengths if rest_lengths is None else s.validate_rest_lengths(
            rest_lengths)
        nodes = self.held_contacts if contacts is None else tuple(
            s.node_index(c) if isinstance(c, str) else int(c) for c in contacts)
        if self.prediction == 'dynamics' and rest is not None:
            steps = max(1, math.ceil(dt / self.max_substep - 1e-9))
            for _ in range(steps):
                self._implicit_step(dt / steps, rest, nodes)
            return
        self._constant_velocity_step(dt)

    def dynamic_bodies(self, contacts: Sequence[int] = ()) -> tuple[list[int], dict[int, int]]:
        """The free bodies whose accelerations the dynamics give (:func:`body_accelerations`:
        mass, the centre of mass at the origin, at most one node among the ``contacts``) and
        {body: its contact node} (its pivot); the others move at constant velocity."""
        s = self.structure
        nodes: dict[int, list[int]] = {}
        for c in contacts:
            if s.node_bodies[c] >= 0:
                nodes.setdefault(int(s.node_bodies[c]), []).append(int(c))
        bodies = [i for i in range(s.n_bodies) if _modelled(s, i) and len(nodes.get(i, ())) <= 1]
        return bodies, {i: nodes[i][0] for i in bodies if i in nodes}

    def drift(self, T: FloatArray, V: FloatArray, rest: FloatArray,
              contacts: Sequence[int] = ()) -> tuple[FloatArray, FloatArray]:
        """The state's rate ``x' = [V; acc(x)]`` (2f,) in the free columns (``V`` the poses' rate
        in ``[dp; dw]``, ``acc`` the bodies' ``[a; alpha]`` of :func:`body_accelerations`, zero
        on the bodies :meth:`dynamic_bodies` leaves out) and its Jacobian ``A`` (2f, 2f) in the
        error state ``[dp; dw; dV]``: ``[[Omega, I], [dacc/dpose, dacc/dV]]``, ``Omega`` the blocks
        ``hat(w_i)`` of the turn (``d dw/dt = dw_V + w x dw``: the world-frame increment turns
        with the body)."""
        f = self.cols.size
        n6 = 6 * self.structure.n_bodies
        rate = np.zeros(2 * f)
        A = np.zeros((2 * f, 2 * f))
        rate[:f] = V.reshape(-1)[self.cols]
        A[np.arange(f), f + np.arange(f)] = 1.0
        free = self.cols[::6] // 6
        for q, i in enumerate(free):
            A[6 * q + 3:6 * q + 6, 6 * q + 3:6 * q + 6] = hat3(V[i, 3:])
        bodies, pivots = self.dynamic_bodies(contacts)
        if bodies:
            acc, J_pose, J_vel = body_accelerations(self.structure, T, V, rest, bodies, pivots)
            full = np.zeros(n6)
            rows = (6 * np.asarray(bodies)[:, None] + np.arange(6)).ravel()
            full[rows] = acc.ravel()
            rate[f:] = full[self.cols]
            at = f + np.searchsorted(self.cols, rows)
            A[np.ix_(at, np.arange(f))] = J_pose[:, self.cols]
            A[np.ix_(at, f + np.arange(f))] = J_vel[:, self.cols]
        return rate, A

    def implicit_step(self, h: float, rest: FloatArray, contacts: Sequence[int] = ()
                      ) -> tuple[FloatArray, FloatArray]:
        """One linearly implicit trapezoidal (Rosenbrock, ``gamma = 1/2``) step of :meth:`drift`
        over ``h`` from the state, as the joint's filter (``estimation/joint_filter.py``): the
        increment ``dx = (I - h/2 A)^-1 h x'`` (2f,) of ``[dp; dw; dV]`` and ``Phi = (I - h/2
        A)^-1 (I + h/2 A)`` (2f, 2f), its Jacobian but for ``A``'s own change (second order in
        ``h``); A-stable against the string modes (up to 27 Hz), second order in ``h``."""
        rate, A = self.drift(self.T, self.V, rest, contacts)
        n = rate.size
        E = -0.5 * h * A
        E[np.arange(n), np.arange(n)] += 1.0
        rhs = np.empty((n, n + 1))
        rhs[:, 0] = h * rate
        rhs[:, 1:] = 0.5 * h * A
        rhs[np.arange(n), 1 + np.arange(n)] += 1.0
        sol = np.linalg.solve(E, rhs)  # one factorisation for the step and Phi
        return sol[:, 0], sol[:, 1:]

    def _implicit_step(self, h: float, rest: FloatArray, contacts: Sequence[int]) -> None:
        """The state moved by :meth:`implicit_step`, the covariance ``Phi P Phi^T + Q`` (``Q``
        the white accelerations': what the dynamics leave out, contacts and impacts)."""
        dx, Phi = self.implicit_step(h, rest, contacts)
        f = self.cols.size
        full = np.zeros(6 * self.structure.n_bodies)
        full[self.cols] = dx[:f]
        self.T = apply_increment(self.T, full)
        self.V.reshape(-1)[self.cols] += dx[f:]
        P = Phi @ self.P @ Phi.T
        self.P = self._add_process_noise(0.5 * (P + P.T), h)

    def _add_process_noise(self, P: FloatArray, dt: float) -> FloatArray:
        """``P + Q``: the white accelerations' discretised noise over ``dt`` (``q`` per axis;
        a bar's turn about its own axis ``a`` its own density: ``q_axial a a^T`` more), by
        diagonals and the bars' (3, 3) blocks."""
        f = self.cols.size
        i = np.arange(f)
        P[i, i] += self.q * dt ** 3 / 3.0
        P[i, f + i] += self.q * dt ** 2 / 2.0
        P[f + i, i] += self.q * dt ** 2 / 2.0
        P[f + i, f + i] += self.q * dt
        if self.q_axial and self.free_bars.size:
            bars = self.free_bars
            axes = self.T[self.cols[6 * bars] // 6, :3, 2]
            blocks = self.q_axial * np.einsum('ki,kj->kij', axes, axes)  # (k, 3, 3)
            rows = (6 * bars + 3)[:, None] + np.arange(3)
            r, c = rows[:, :, None], rows[:, None, :]
            for (dr, dc), scale in (((0, 0), dt ** 3 / 3.0), ((0, f), dt ** 2 / 2.0),
                                    ((f, 0), dt ** 2 / 2.0), ((f, f), dt)):
                P[r + dr, c + dc] += scale * blocks
        return P

    def _constant_velocity_step(self, dt: float) -> None:
        """Move the state ``dt`` at constant velocity, the covariance by blocks."""
        step = self.V * dt
        step[self.structure.fixed] = 0.0
        self.T = apply_increment(self.T, step.ravel())
        # F P F^T + Q with F = [[I, dt I], [0, I]] and the white accelerations' Q, by blocks
        f = self.cols.size
        P = 0.5 * (self.P + self.P.T)  # symmetric (the update's rounding removed)
        B = P[:f, f:] + dt * P[f:, f:]
        P[:f, :f] += dt * (P[:f, f:] + P[f:, :f]) + dt * dt * P[f:, f:]
        P[:f, f:] = B
        P[f:, :f] = B.T
        self.P = self._add_process_noise(P, dt)

    def _rows(self, measurements: StructureMeasurements,
              gyros: Mapping[str, ArrayLike] | None,
              accelerometers: Mapping[str, ArrayLike] | None = None) -> ReadingRows:
        """(names, residuals z - h, Jacobians in the state, stds, dofs) of every reading."""
        s = self.structure
        f = self.cols.size
        readings = readings_of(s, replace_at_rest(measurements))
        rest = s.validate_rest_lengths(measurements.rest_lengths)
        # held by the next prediction
        self.held_rest_lengths = rest
        self.held_contacts = tuple(r.index for r in readings if r.kind == 'contact')
        accel, pivots = self._accelerometers(self.held_contacts, accelerometers)
        if accel:  # an accelerometer modelled by the dynamics replaces its gravity direction
            modelled = {f'imu[{s.body_names[i]}]' for i in accel}
            readings = [r for r in readings if r.name not in modelled]
        names, res, jac, stds, dofs = [], [], [], [], []
        if readings:
            h, H, std, starts = measurement_model(s, self.T, readings, rest)
            z = np.concatenate([r.value for r in readings])
            J_all = np.zeros((h.size, 2 * f))
            J_all[:, :f] = H[:, self.cols]
            names = [r.name for r in readings]
            res = np.split(z - h, starts[1:])
            jac = np.split(J_all, starts[1:])
            stds = np.split(std, starts[1:])
            dofs = [r.dof for r in readings]
            if self.held_contacts:
                self._extend_rows((names, res, jac, stds, dofs),
                                  self._contact_velocity_rows(list(self.held_contacts)))
        if gyros:
            self._extend_rows((names, res, jac, stds, dofs), self._gyro_rows(gyros))
        if accel:
            bodies = list(accel)
            h_a, H_p, H_v = specific_force_model(s, self.T, self.V, rest, bodies, pivots)
            for q, i in enumerate(bodies):
                J = np.zeros((3, 2 * f))
                J[:, :f] = H_p[3 * q:3 * q + 3, self.cols]
                J[:, f:] = H_v[3 * q:3 * q + 3, self.cols]
                names.append(f'accelerometer[{s.body_names[i]}]')
                res.append(accel[i] - h_a[q])
                jac.append(J)
                stds.append(np.full(3, self.pivot_accelerometer_std if i in pivots
                                    else self.accelerometer_std))
                dofs.append(3)
        return names, res, jac, stds, dofs

    @staticmethod
    def _extend_rows(rows: ReadingRows, more: ReadingRows) -> None:
        """Append the readings ``more`` (names, residuals, Jacobians, stds, dofs) to ``rows``."""
        for kept, added in zip(rows, more, strict=True):
            kept.extend(added)

    def _contact_velocity_rows(self, contacts: list[int]) -> ReadingRows:
        """The contact nodes' zero velocity (a sticking node: ``v + w x (x - p) = 0``), all in
        one pass: (names, residuals, Jacobians, stds, dofs)."""
        s = self.structure
        f = self.cols.size
        nodes = np.array(contacts)
        b = s.node_bodies[nodes]
        arm = np.einsum('cij,cj->ci', self.T[b, :3, :3], s.node_points[nodes])
        w = self.V[b, 3:]
        h_arm, h_w = hat3(arm), hat3(w)
        k = np.searchsorted(self.cols, 6 * b)
        J = np.zeros((nodes.size, 3, 2 * f))
        c = np.arange(nodes.size)[:, None, None]
        i3 = np.arange(3)[None, :, None]
        J[c, i3, (f + k)[:, None, None] + np.arange(3)] = np.eye(3)
        J[c, i3, (f + k + 3)[:, None, None] + np.arange(3)] = -h_arm
        J[c, i3, (k + 3)[:, None, None] + np.arange(3)] = -h_w @ h_arm
        v = -(self.V[b, :3] + np.einsum('cij,cj->ci', h_w, arm))
        names = [f'contact_velocity[{s.node_names[n]}]' for n in contacts]
        res = list(v)
        jac = list(J)
        stds = [np.full(3, self.contact_velocity_std)] * nodes.size
        dofs = [3] * nodes.size
        return names, res, jac, stds, dofs

    def _gyro_rows(self, gyros: Mapping[str, ArrayLike]) -> ReadingRows:
        """Each gyro (``R^T w``), all in one pass: (names, residuals, Jacobians, stds, dofs)."""
        s = self.structure
        f = self.cols.size
        keys = list(gyros)
        idx = np.array([s.body_index(key) for key in keys])
        g = np.empty((idx.size, 3))
        for q, key in enumerate(keys):
            g[q] = finite_array(f'gyros[{key}]', gyros[key]).reshape(-1) \
                if np.size(gyros[key]) == 3 else _bad_gyro(key)
        R = self.T[idx, :3, :3]
        Rt = np.transpose(R, (0, 2, 1))
        w = self.V[idx, 3:]
        k = np.searchsorted(self.cols, 6 * idx)
        J = np.zeros((idx.size, 3, 2 * f))
        c = np.arange(idx.size)[:, None, None]
        i3 = np.arange(3)[None, :, None]
        J[c, i3, (f + k + 3)[:, None, None] + np.arange(3)] = Rt
        J[c, i3, (k + 3)[:, None, None] + np.arange(3)] = Rt @ hat3(w)
        names = [f'gyro[{key}]' for key in keys]
        res = list(g - np.einsum('kij,kj->ki', Rt, w))
        jac = list(J)
        stds = [np.full(3, self.gyro_std)] * idx.size
        dofs = [3] * idx.size
        return names, res, jac, stds, dofs

    def _accelerometers(self, contacts: Sequence[int],
                        accelerometers: Mapping[str, ArrayLike] | None
                        ) -> tuple[dict[int, FloatArray], dict[int, int]]:
        """{body index: specific force (3,)} of the accelerometers the dynamics model (on the
        bodies of :meth:`dynamic_bodies` with the ``contacts``) and {body: its contact node}
        (its pivot); checked (ValueError naming the body)."""
        s = self.structure
        bodies, pivots = self.dynamic_bodies(contacts)
        modelled = set(bodies)
        out: dict[int, FloatArray] = {}
        for key, value in (accelerometers or {}).items():
            i = s.body_index(key)
            a = finite_array(f'accelerometers[{key}]', value).reshape(-1)
            if a.shape != (3,):
                raise ValueError(f'accelerometers[{key}] must be 3 values (m/s^2)')
            if i in modelled:
                out[i] = a
        return out, {b: c for b, c in pivots.items() if b in out}

    def update(self, measurements: StructureMeasurements,
               gyros: Mapping[str, ArrayLike] | None = None,
               accelerometers: Mapping[str, ArrayLike] | None = None) -> StructureFilterUpdate:
        """Correct the state with one set of readings (``at_rest`` is ignored: the robot
        moves), the IMUs' ``gyros`` {body: (3,) rad/s in its frame} and their
        ``accelerometers`` {body: (3,) specific force, m/s^2 in its frame}: modelled by the
        dynamics (:func:`specific_force_model`) on a body with at most one node among the
        contacts, in place of its ``imu_gravity``; on a body with more (its contact forces
        unknown) its ``imu_gravity`` is used, when given."""
        names, res, jac, stds, dofs = self._rows(measurements, gyros, accelerometers)
        nis, dof, gated = math.nan, 0, []
        if names:
            sizes = [r.size for r in res]
            H_all = np.vstack(jac) / np.concatenate(stds)[:, None]
            r_all = np.concatenate(res) / np.concatenate(stds)
            HP = H_all @ self.P
            S_all = HP @ H_all.T + np.eye(r_all.size)
            bounds = np.concatenate([[0], np.cumsum(sizes)])
            keep = np.zeros(r_all.size, dtype=bool)
            sizes_arr = np.array(sizes)
            values = np.empty(len(names))
            for size in (1, 3, 6):
                which = np.flatnonzero(sizes_arr == size)
                if not which.size:
                    continue
                if size == 1:  # a scalar reading's NIS: r^2 / S_kk
                    rows = bounds[which]
                    values[which] = r_all[rows] ** 2 / S_all[rows, rows]
                    continue
                idx = bounds[which][:, None] + np.arange(size)[None, :]
                blocks = S_all[idx[:, :, None], idx[:, None, :]]
                rr = r_all[idx]
                values[which] = np.einsum('ki,ki->k', rr,
                                          np.linalg.solve(blocks, rr[..., None])[..., 0])
            thresholds = {d: consistency_threshold(d, self.gate_probability)
                          for d in set(dofs)}
            for k in range(len(names)):
                if values[k] > thresholds[dofs[k]]:
                    gated.append((names[k], f'gated: NIS {values[k]:.4g} over {dofs[k]} dof'))
                else:
                    keep[bounds[k]:bounds[k + 1]] = True
                    dof += dofs[k]
            if keep.any():
                H, r, S = H_all[keep], r_all[keep], S_all[np.ix_(keep, keep)]
                solved = np.linalg.solve(S, np.column_stack([HP[keep], r]))  # one solve
                K = solved[:, :-1].T
                dx = K @ r
                nis = float(r @ solved[:, -1])
                I_KH = np.eye(self.P.shape[0]) - K @ H
                self.P = I_KH @ self.P @ I_KH.T + K @ K.T
                f = self.cols.size
                full = np.zeros(6 * self.structure.n_bodies)
                full[self.cols] = dx[:f]
                self.T = apply_increment(self.T, full)
                self.V.reshape(-1)[self.cols] += dx[f:]
        consistent = None if dof == 0 else bool(nis <= consistency_threshold(
            dof, self.gate_probability))
        return StructureFilterUpdate(self.T.copy(), self.V.copy(), self.pose_covariance(), nis,
                                     dof, consistent, tuple(n for n, _ in gated),
                                     tuple(w for _, w in gated))

    def pose_covariance(self) -> FloatArray:
        """(6N, 6N) the poses' covariance (PoseWithCovariance per body; fixed bodies zero)."""
        n6 = 6 * self.structure.n_bodies
        C = np.zeros((n6, n6))
        f = self.cols.size
        C[np.ix_(self.cols, self.cols)] = self.P[:f, :f]
        return C


def _modelled(structure: Structure, i: int) -> bool:
    """Whether :func:`body_accelerations` models body ``i`` (free, with mass, its centre of mass
    at its origin)."""
    body = structure.bodies[i]
    return bool(not structure.fixed[i] and body.mass > 0.0
                and not np.any(np.asarray(body.com, dtype=float)))


def _bad_gyro(key: str) -> FloatArray:
    raise ValueError(f'gyros[{key}] must be 3 values (rad/s)')


def replace_at_rest(measurements: StructureMeasurements) -> StructureMeasurements:
    """The readings without the statics (a moving robot's)."""
    return dataclasses.replace(measurements, at_rest=False)
