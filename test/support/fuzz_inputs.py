"""Malformed, hostile and valid inputs for ``stiffness_node``, and the library's answer to each.

Pure and seeded: no node, no clock, no I/O; one seed gives one sequence of inputs. Shared by
``test/ros/test_robustness.py`` (a shortened fuzz) and ``bench/fuzz_node.py`` (the full one); the
ROS
side (publishing, matching, counting) is :class:`ros_harness.NodeFuzzer`.

* :class:`InputFuzzer` draws :class:`Case` objects: one input for ``~/screw``, ``~/pose``,
  ``~/rest_lengths`` or one of the three services, with a label (``kind``) and ``must_reject``
  (True when the input is built to be invalid: the node must publish nothing for it or answer
  ``success: false``). Hostile values: wrong lengths (0, 5, 7, 10, 11, 13 and 10**6 values), NaN,
  +-inf, denormals, +-1e308, zero / non-unit / NaN quaternions, frames, data offsets, negative,
  zero, tiny and huge rest lengths, screws at and beyond ``|omega| = 2 pi``, planar requests on
  every singular curve (i-v, neutral point) and on and outside every workspace boundary,
  equilibrium requests with huge wrenches, all strings slack, far or overflowing starts.
* :class:`TopicOracle` predicts the node's outputs for the topic inputs (None: nothing must be
  published) from the library, with the node's state (rest lengths, last screw) mirrored.
* :func:`check_forward`, :func:`check_inverse`, :func:`check_equilibrium` judge a service answer
  against the library (None: correct; else the reason it is wrong).

Messages are built by :func:`to_message` from a case's plain payload, when it is sent.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from tensegrity_stiffness.geometry.screw import CHART_LIMIT, exp_se3, log_se3
from tensegrity_stiffness.mechanics.equilibrium import RESIDUAL_TOLERANCE, is_stable
from tensegrity_stiffness.mechanics.interpretation import interpretation_vector
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.planar import PlanarMechanism
from tensegrity_stiffness.mechanics.plausibility import (
    check_rest_lengths,
    check_screw,
    check_wrench,
)
from tensegrity_stiffness.nodes import parameters
from tensegrity_stiffness.ros import conversions

CONFIG = Path(__file__).resolve().parents[2] / 'config' / 'default_joint.yaml'
#: The node's default limits (``limits.max_array_length``, frame of link 1).
_DEFAULTS = parameters.defaults(parameters.STIFFNESS_NODE_PARAMETERS)
MAX_ARRAY_LENGTH = _DEFAULTS['limits.max_array_length']
LINK1_FRAME = _DEFAULTS['frames.link1']
#: Element count of the oversized arrays (8 MB of float64).
OVERSIZED = 10**6
DENORMALS = (5e-324, -5e-324, 1e-310, -2.5e-320, 2.2250738585072014e-308 / 2)
HUGE = (1e308, -1e308, 1.7976931348623157e308)
NONFINITE = (math.nan, math.inf, -math.inf)
#: Floats no input field should be able to trip over.
HOSTILE_FLOATS = (*NONFINITE, *HUGE, *DENORMALS, 0.0, -0.0, 1e154, 1e-300)

TOPICS = ('screw', 'pose', 'rest_lengths')
SERVICES = ('forward', 'inverse', 'equilibrium')


@dataclass(frozen=True, eq=False)
class Case:
    """One input. ``target``: a topic of :data:`TOPICS` or a service of :data:`SERVICES`;
    ``kind``: what is hostile about it (``'valid'`` for the anchors); ``must_reject``: built to be
    invalid; ``payload``: plain values (see :func:`to_message`)."""

    target: str
    kind: str
    payload: dict[str, Any] = field(repr=False)
    must_reject: bool = False


def planar_from_config(path: Path = CONFIG) -> PlanarMechanism:
    """The planar mechanism of a node parameter file (the table's defaults where a key is left
    out), as the node builds it."""
    return parameters.planar_from_values(
        parameters.values_from_config(path, parameters.STIFFNESS_NODE_PARAMETERS))


# ---------------------------------------------------------------------------- messages
def to_message(case: Case) -> Any:
    """The ROS message (topic) or request (service) of a case."""
    p = case.payload
    if case.target in ('screw', 'rest_lengths'):
        import array

        from std_msgs.msg import Float64MultiArray

        msg = Float64MultiArray()
        msg.data = array.array('d', np.ascontiguousarray(p['data'], dtype=np.float64).tobytes())
        msg.layout.data_offset = int(p.get('data_offset', 0))
        return msg
    if case.target == 'pose':
        from geometry_msgs.msg import PoseStamped

        msg = PoseStamped()
        msg.header.frame_id = p['frame_id']
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = p['position']
        o = msg.pose.orientation
        o.x, o.y, o.z, o.w = p['orientation']
        return msg
    if case.target == 'forward':
        from tensegrity_stiffness.srv import PlanarForwardKinematics

        return PlanarForwardKinematics.Request(actuator_length=p['L3'], actuator_angle=p['theta1'])
    if case.target == 'inverse':
        from tensegrity_stiffness.srv import PlanarInverseKinematics

        return PlanarInverseKinematics.Request(x=p['x'], y=p['y'])
    if case.target == 'equilibrium':
        import array

        from tensegrity_stiffness.srv import SolveEquilibrium

        req = SolveEquilibrium.Request()
        f, t = req.external_wrench.force, req.external_wrench.torque
        f.x, f.y, f.z, t.x, t.y, t.z = (float(v) for v in p['wrench'])
        req.rest_lengths = array.array('d', np.asarray(p['rest_lengths'], np.float64).tobytes())
        req.initial_screw = array.array('d',
                                        np.asarray(p['initial_screw'], np.float64).tobytes())
        return req
    raise ValueError(f'unknown target {case.target!r}')


# ---------------------------------------------------------------------------- generators
def _bisect(f: Any, a: float, b: float, iterations: int = 200) -> float:
    fa = f(a)
    for _ in range(iterations):
        m = 0.5 * (a + b)
        fm = f(m)
        if fm == 0.0 or m in (a, b):
            return m
        if (fm < 0.0) == (fa < 0.0):
            a, fa = m, fm
        else:
            b = m
    return 0.5 * (a + b)


class InputFuzzer:
    """Seeded source of :class:`Case` objects for one joint model and planar mechanism.

    ``oversized_every``: every that many array-bearing hostile cases, one carries 10**6 values
    (0: never); they cost the middleware 8 MB each, so the full fuzz uses them sparingly.
    """

    SCREW_NOISE = np.array([0.05, 0.05, 0.05, 0.002, 0.002, 0.002])

    def __init__(self, model: JointModel, planar: PlanarMechanism, seed: int = 0,
                 oversized_every: int = 0) -> None:
        self.model = model
        self.planar = planar
        self.rng = np.random.default_rng(seed)
        self.oversized_every = oversized_every
        self._array_cases = 0
        self._singular = self._singular_actuator_points()
        self._boundary = self._cartesian_boundary_points()

    # -------------------------------------------------------------- basic draws
    def _choice(self, options: Any) -> Any:
        return options[int(self.rng.integers(len(options)))]

    def _oversized_now(self) -> bool:
        self._array_cases += 1
        return self.oversized_every > 0 and self._array_cases % self.oversized_every == 0

    def valid_screw(self) -> np.ndarray:
        """A screw near the unloaded equilibrium: every string has a length, K is finite."""
        return self.model.initial_screw + self.rng.normal(scale=self.SCREW_NOISE)

    def valid_rest_lengths(self) -> np.ndarray:
        return self.model.rest_lengths * self.rng.uniform(0.97, 1.03, self.model.n_strings)

    def _unit(self, n: int = 3) -> np.ndarray:
        v = self.rng.normal(size=n)
        return v / np.linalg.norm(v)

    def _omega_at_least(self, norm: float) -> np.ndarray:
        """A rotation vector in a random direction with |omega| >= norm after rounding."""
        w = norm * self._unit()
        while np.linalg.norm(w) < norm:
            w *= 1.0 + 2.0**-52
        return w

    def _wrong_length(self, right: int, oversized: bool) -> int:
        if oversized:
            return OVERSIZED
        return int(self._choice([n for n in (0, 1, 5, 7, 10, 11, 13, 2 * right) if n != right]))

    # -------------------------------------------------------------- topics
    def valid_screw_case(self) -> Case:
        return Case('screw', 'valid', {'data': self.valid_screw()})

    def screw_case(self) -> Case:
        """A hostile screw (most invalid; denormal and near-chart ones valid)."""
        xi = self.valid_screw()
        kind = self._choice([
            'length', 'length', 'nan', 'inf', 'huge', 'denormal', 'omega=2pi', 'omega>2pi',
            'omega>>2pi', 'omega overflow', 'omega just below 2pi', 'zero screw',
            'offset past end', 'offset', 'offset leaves 9'])
        must_reject = True
        offset = 0
        if kind == 'length':
            n = self._wrong_length(6, self._oversized_now())
            data = self.rng.normal(size=n) if n != OVERSIZED else np.zeros(n)
            kind = f'{n} values'
        elif kind in ('nan', 'inf', 'huge'):
            data = xi.copy()
            pool = {'nan': (math.nan,), 'inf': (math.inf, -math.inf), 'huge': HUGE}[kind]
            for i in self.rng.choice(6, size=int(self.rng.integers(1, 4)), replace=False):
                data[i] = self._choice(pool)
            must_reject = kind != 'huge'  # 1e308 in v: the oracle decides (overflow)
        elif kind == 'denormal':
            data = xi.copy()
            for i in self.rng.choice(6, size=int(self.rng.integers(1, 4)), replace=False):
                data[i] = self._choice(DENORMALS)
            must_reject = False
        elif kind.startswith('omega'):
            norm = {'omega=2pi': CHART_LIMIT, 'omega>2pi': np.nextafter(CHART_LIMIT, 7.0),
                    'omega>>2pi': float(self.rng.uniform(7.0, 1e3)),
                    'omega overflow': 1e200,
                    'omega just below 2pi': CHART_LIMIT - float(self.rng.uniform(1e-9, 1e-3))
                    }[kind]
            data = np.r_[norm * self._unit(), xi[3:]]
            if kind == 'omega=2pi':  # exactly 2 pi along an axis (no rounding in the norm)
                data[:3] = CHART_LIMIT * np.eye(3)[int(self.rng.integers(3))]
            elif kind == 'omega>2pi':  # the first floats beyond 2 pi, after rounding
                data[:3] = self._omega_at_least(norm)
            must_reject = kind != 'omega just below 2pi'
        elif kind == 'zero screw':
            data = np.zeros(6)  # link 2 on link 1: every string has zero length
        elif kind == 'offset past end':
            data, offset = xi, int(self.rng.integers(7, 2**32))
        elif kind == 'offset':  # 6 values after a valid data_offset
            lead = int(self.rng.integers(1, 4))
            data, offset = np.r_[self.rng.normal(size=lead), xi], lead
            must_reject = False
        else:  # 'offset leaves 9': an offset within the data, but 9 values follow it
            data, offset = np.r_[xi, xi], 3
        return Case('screw', kind, {'data': np.asarray(data, dtype=np.float64),
                                    'data_offset': offset}, must_reject)

    def valid_pose_case(self, kind: str = 'valid') -> Case:
        T = exp_se3(self.valid_screw())
        pose = conversions.transform_to_pose(T)
        p, o = pose.position, pose.orientation
        return Case('pose', kind, {'position': (p.x, p.y, p.z),
                                   'orientation': (o.x, o.y, o.z, o.w),
                                   'frame_id': self._choice([LINK1_FRAME, ''])})

    def pose_case(self) -> Case:
        """A hostile pose (most invalid; near-unit, denormal and half-turn ones valid)."""
        base = self.valid_pose_case().payload
        pos, quat = np.array(base['position']), np.array(base['orientation'])
        frame = base['frame_id']
        kind = self._choice([
            'zero quaternion', 'tiny quaternion', 'non-unit quaternion', 'nan quaternion',
            'inf quaternion', 'huge quaternion', 'near-unit quaternion', 'denormal quaternion',
            'nan position', 'inf position', 'huge position', 'denormal position',
            'wrong frame', 'half turn'])
        must_reject = True
        if kind == 'zero quaternion':
            quat = np.zeros(4)
        elif kind == 'tiny quaternion':
            quat = quat * 1e-200
        elif kind == 'non-unit quaternion':
            quat = quat * self._choice([2.0, 0.5, 1.0 + 2e-3, 1.0 - 2e-3, 1e3])
        elif kind in ('nan quaternion', 'inf quaternion', 'huge quaternion'):
            quat[int(self.rng.integers(4))] = {'nan quaternion': math.nan,
                                                'inf quaternion': math.inf,
                                                'huge quaternion': 1e308}[kind]
        elif kind == 'near-unit quaternion':  # within the tolerance: renormalised, valid
            quat = quat * (1.0 + float(self.rng.uniform(-9e-4, 9e-4)))
            must_reject = False
        elif kind == 'denormal quaternion':
            quat[int(self.rng.integers(4))] = self._choice(DENORMALS)
            must_reject = False  # the oracle decides (a component replaced by ~0)
        elif kind in ('nan position', 'inf position'):
            pos[int(self.rng.integers(3))] = math.nan if kind == 'nan position' else -math.inf
        elif kind == 'huge position':
            pos[int(self.rng.integers(3))] = self._choice(HUGE)
            must_reject = False  # the oracle decides (overflow)
        elif kind == 'denormal position':
            pos[int(self.rng.integers(3))] = self._choice(DENORMALS)
            must_reject = False
        elif kind == 'wrong frame':
            frame = self._choice(['map', 'tensegrity_link2', ' ', LINK1_FRAME + '_'])
        else:  # half turn: omega = pi u, the log map has two branches
            u = self._unit()
            T = exp_se3(np.r_[math.pi * u, 0.01 * self._unit()])
            pose = conversions.transform_to_pose(T)
            pos = np.array([pose.position.x, pose.position.y, pose.position.z])
            o = pose.orientation
            quat = np.array([o.x, o.y, o.z, o.w])
            must_reject = False
        return Case('pose', kind, {'position': tuple(pos), 'orientation': tuple(quat),
                                   'frame_id': frame}, must_reject)

    def valid_rest_case(self) -> Case:
        return Case('rest_lengths', 'valid', {'data': self.valid_rest_lengths()})

    def rest_case(self) -> Case:
        """Hostile rest lengths (most invalid, tiny positive ones too: below the joint's range;
        huge positive ones valid unless they leave no room for the maximum stretch)."""
        n = self.model.n_strings
        rest = self.valid_rest_lengths()
        kind = self._choice(['length', 'length', 'negative', 'zero', 'nan', 'inf',
                             'denormal', 'huge', 'offset past end'])
        must_reject = True
        offset = 0
        if kind == 'length':
            m = self._wrong_length(n, self._oversized_now())
            data = np.full(m, 0.03) if m != OVERSIZED else np.zeros(m)
            kind = f'{m} values'
        elif kind in ('negative', 'zero', 'nan', 'inf'):
            data = rest.copy()
            value = {'negative': -0.03, 'zero': self._choice([0.0, -0.0]), 'nan': math.nan,
                     'inf': self._choice([math.inf, -math.inf])}[kind]
            idx = self.rng.choice(n, size=int(self.rng.integers(1, n + 1)), replace=False)
            data[idx] = value
        elif kind == 'denormal':  # > 0 and finite, but below the joint's range (#42)
            data = np.full(n, self._choice([5e-324, 1e-310, 1e-300]))
        elif kind == 'huge':  # finite: valid, every string slack (K = 0)
            data = np.full(n, self._choice([1e308, 1.0, 1e6]))
            must_reject = False
        else:
            data, offset = rest, n + 1
        return Case('rest_lengths', kind, {'data': np.asarray(data, dtype=np.float64),
                                           'data_offset': offset}, must_reject)

    def topic_cases(self, n: int, pose_share: float = 0.15,
                    rest_share: float = 0.15) -> Iterator[Case]:
        """``n`` topic inputs: every other one a valid screw (the anchor whose answer is known
        by value); the others hostile ones on ``~/screw``, ``~/pose`` (share ``pose_share``, a
        quarter of them valid) or ``~/rest_lengths`` (share ``rest_share``, each followed by
        valid rest lengths so that later answers stay distinct)."""
        i = 0
        while i < n:
            if i % 2:
                yield self.valid_screw_case()
                i += 1
                continue
            u = self.rng.uniform()
            if u < pose_share:
                yield self.valid_pose_case() if self.rng.uniform() < 0.25 else self.pose_case()
                i += 1
            elif u < pose_share + rest_share:
                yield self.rest_case()
                yield self.valid_rest_case()
                i += 2
            else:
                yield self.screw_case()
                i += 1

    def screw_cases(self, n: int) -> Iterator[Case]:
        """``n`` screws, hostile and valid alternating."""
        for i in range(n):
            yield self.screw_case() if i % 2 == 0 else self.valid_screw_case()

    # -------------------------------------------------------------- planar
    def _singular_actuator_points(self) -> list[tuple[str, float, float]]:
        """(name, L3, theta1) on each singular curve of the planar mechanism."""
        pl = self.planar
        out: list[tuple[str, float, float]] = []
        lo, hi = pl.theta1_min, pl.theta1_max
        for L3 in np.linspace(0.05, pl.L3_max, 12):
            out += [('i', 0.0, float(self.rng.uniform(lo, hi))), ('ii', float(L3), 0.0),
                    ('ii', float(L3), math.pi)]
            grid = np.linspace(lo - 0.5, hi + 0.5, 400)
            for name in ('iii', 'iv'):
                r = pl.singularity_residuals(np.full_like(grid, L3), grid)[name]
                for k in np.flatnonzero(np.sign(r[:-1]) * np.sign(r[1:]) < 0):
                    def f(t: float, name: str = name, L3: float = float(L3)) -> float:
                        return float(pl.singularity_residuals(L3, t)[name])
                    out.append((name, float(L3), _bisect(f, grid[k], grid[k + 1])))
        cx, cy, r = pl.fold_circle_actuator()
        for phi in np.linspace(0.0, 2 * math.pi, 24, endpoint=False):
            x, y = cx + r * math.cos(phi), cy + r * math.sin(phi)
            out.append(('v', math.hypot(x, y), math.atan2(y, x)))
        nx, ny = pl.neutral_point
        out.append(('neutral', math.hypot(nx, ny), math.atan2(ny, nx)))
        return out

    def _cartesian_boundary_points(self) -> list[tuple[str, float, float]]:
        """(name, x, y) on the fold circle and the image of the actuator-range boundary."""
        pl = self.planar
        out: list[tuple[str, float, float]] = []
        cx, cy, r = pl.fold_circle_cartesian()
        out.append(('fold centre', cx, cy))
        for phi in np.linspace(0.0, 2 * math.pi, 16, endpoint=False):
            out.append(('fold circle', cx + r * math.cos(phi), cy + r * math.sin(phi)))
        for t in np.linspace(pl.theta1_min, pl.theta1_max, 16):
            fk = pl.forward(pl.L3_max, float(t))
            out.append(('L3_max edge', fk.x, fk.y))
        for L3 in np.linspace(pl.L3_min, pl.L3_max, 16):
            for t in (pl.theta1_min, pl.theta1_max):
                fk = pl.forward(float(L3), t)
                if math.isfinite(fk.x):
                    out.append(('theta1 edge', fk.x, fk.y))
        nx, ny = pl.neutral_point
        out.append(('neutral point', nx, ny))
        return out

    def _nudge(self, value: float) -> float:
        """The value, or just beside it (one ulp, 1e-12, 1e-9, 1e-6 relative, either side)."""
        how = self._choice(['same', 'ulp', '1e-12', '1e-9', '1e-6'])
        if how == 'same':
            return value
        if how == 'ulp':
            return float(np.nextafter(value, self._choice([-math.inf, math.inf])))
        step = float(how) * max(1.0, abs(value))
        return value + self._choice([-step, step])

    def forward_case(self) -> Case:
        pl = self.planar
        kind = self._choice(['valid', 'valid', 'singular', 'singular', 'boundary', 'hostile'])
        must_reject = False
        if kind == 'valid':
            L3 = float(self.rng.uniform(pl.L3_min, pl.L3_max))
            t1 = float(self.rng.uniform(pl.theta1_min, pl.theta1_max))
        elif kind == 'singular':
            name, L3, t1 = self._choice(self._singular)
            L3, t1 = abs(self._nudge(L3)), self._nudge(t1)
            kind = f'singular {name}'
        elif kind == 'boundary':
            L3 = self._nudge(self._choice([pl.L3_min, pl.L3_max, float(self.rng.uniform(0, 2))]))
            t1 = self._nudge(self._choice([pl.theta1_min, pl.theta1_max, 2 * math.pi,
                                           -2 * math.pi, float(self.rng.uniform(0, 3))]))
        else:
            L3 = self._choice([*HOSTILE_FLOATS, float(self.rng.uniform(0, 2)), -1.0])
            t1 = self._choice([*HOSTILE_FLOATS, float(self.rng.uniform(0, 3)), 1e6])
            must_reject = not (math.isfinite(L3) and math.isfinite(t1)) or L3 < 0.0
        return Case('forward', kind, {'L3': float(L3), 'theta1': float(t1)}, must_reject)

    def inverse_case(self) -> Case:
        pl = self.planar
        kind = self._choice(['valid', 'valid', 'boundary', 'boundary', 'far', 'hostile'])
        must_reject = False
        if kind == 'valid':
            fk = pl.forward(float(self.rng.uniform(0.05, pl.L3_max)),
                            float(self.rng.uniform(0.05, pl.theta1_max - 0.05)))
            x, y = fk.x, fk.y
        elif kind == 'boundary':
            name, x, y = self._choice(self._boundary)
            x, y = self._nudge(x), self._nudge(y)
            kind = name
        elif kind == 'far':
            x, y = (float(v) for v in self.rng.normal(scale=50.0, size=2))
        else:
            x = self._choice([*HOSTILE_FLOATS, float(self.rng.normal())])
            y = self._choice([*HOSTILE_FLOATS, float(self.rng.normal())])
            must_reject = not (math.isfinite(x) and math.isfinite(y))
        return Case('inverse', kind, {'x': float(x), 'y': float(y)}, must_reject)

    # -------------------------------------------------------------- equilibrium
    def equilibrium_case(self, hard_share: float = 0.1) -> Case:
        """A request for ``~/solve_equilibrium``: easy (must succeed), hard (a wrench beyond
        reach, all strings slack, far or overflowing starts, denormals: may fail, must not be
        wrong), or invalid (must be refused). ``hard_share``: share of the hard ones that use
        up the solve's time budget (huge wrenches)."""
        m = self.model
        W = np.r_[self.rng.normal(scale=0.05, size=3), self.rng.normal(scale=1e-3, size=3)]
        rest: np.ndarray = np.empty(0)
        x0: np.ndarray = m.initial_screw.copy()
        easy, must_reject = False, False
        u = self.rng.uniform()
        if u < hard_share:
            kind = self._choice(['wrench 50 N', 'wrench 500 N', 'wrench 1e6', 'wrench 1e308',
                                 'torque 1 N m'])
            W = {'wrench 50 N': np.r_[50.0, 0, 0, 0, 0, 0],
                 'wrench 500 N': np.r_[0, 500.0, 0, 0, 0, 0],
                 'wrench 1e6': np.full(6, 1e6),
                 'wrench 1e308': np.r_[1e308, -1e308, 0, 0, 0, 0],
                 'torque 1 N m': np.r_[0, 0, 0, 1.0, 0, 0]}[kind]
            x0 = self._choice([x0, np.empty(0)])
        else:
            kind = self._choice([
                'easy', 'easy', 'easy', 'all slack', 'far start', 'overflowing start',
                'denormal wrench', 'denormal rest', 'huge rest', 'nan wrench', 'inf wrench',
                'rest length', 'rest negative', 'rest zero', 'rest nan', 'start length',
                'start nan', 'start beyond chart', 'start overflow'])
            if kind == 'easy':
                easy = True
                rest = self._choice([np.empty(0), self.valid_rest_lengths()])
            elif kind == 'all slack':
                rest = np.full(m.n_strings, 1.0)
                W = self._choice([np.zeros(6), W])
            elif kind == 'far start':
                x0 = np.r_[float(self.rng.uniform(5.5, CHART_LIMIT - 1e-9)) * self._unit(),
                           self.rng.normal(scale=0.02, size=3)]
            elif kind == 'overflowing start':  # string lengths overflow: F evaluates to 0
                x0 = np.r_[x0[:3], self._choice([1e200, 1e308, -1e160]) * self._unit()]
            elif kind == 'denormal wrench':
                W = np.array([self._choice(DENORMALS) for _ in range(6)])
            elif kind == 'denormal rest':
                rest = np.full(m.n_strings, self._choice([5e-324, 1e-300]))
            elif kind == 'huge rest':
                rest = np.full(m.n_strings, self._choice([1e308, 1e6]))
            else:
                must_reject = True
                if kind in ('nan wrench', 'inf wrench'):
                    W[int(self.rng.integers(6))] = math.nan if kind == 'nan wrench' else \
                        self._choice([math.inf, -math.inf])
                elif kind == 'rest length':
                    k = self._wrong_length(m.n_strings, self._oversized_now())
                    rest = np.full(k, 0.03) if k else np.full(5, 0.03)
                    kind = f'rest {len(rest)} values'
                elif kind in ('rest negative', 'rest zero', 'rest nan'):
                    rest = self.valid_rest_lengths()
                    rest[int(self.rng.integers(m.n_strings))] = {
                        'rest negative': -0.01, 'rest zero': 0.0, 'rest nan': math.nan}[kind]
                elif kind == 'start length':
                    k = self._wrong_length(6, self._oversized_now())
                    x0 = np.zeros(k if k else 5)
                    kind = f'start {len(x0)} values'
                elif kind == 'start nan':
                    x0[int(self.rng.integers(6))] = self._choice(NONFINITE)
                elif kind == 'start beyond chart':
                    x0 = np.r_[self._omega_at_least(self._choice([CHART_LIMIT, 7.0, 1e3])),
                               x0[3:]]
                    if self.rng.uniform() < 0.3:
                        x0[:3] = CHART_LIMIT * np.eye(3)[int(self.rng.integers(3))]
                else:  # omega of 1e308: its norm overflows
                    x0 = np.r_[1e308 * self._unit(), x0[3:]]
        return Case('equilibrium', kind, {'wrench': W, 'rest_lengths': rest,
                                          'initial_screw': x0, 'easy': easy}, must_reject)

    def service_cases(self, n: int, shares: tuple[float, float, float] = (0.4, 0.3, 0.3),
                      hard_share: float = 0.1) -> Iterator[Case]:
        """``n`` service requests: forward, inverse, equilibrium in the given shares."""
        for _ in range(n):
            u = self.rng.uniform()
            if u < shares[0]:
                yield self.forward_case()
            elif u < shares[0] + shares[1]:
                yield self.inverse_case()
            else:
                yield self.equilibrium_case(hard_share)


# ---------------------------------------------------------------------------- oracles
@dataclass(frozen=True, eq=False)
class Output:
    """What the node publishes for one input: K (36,) row-major and the wrench (6,)."""

    stiffness: np.ndarray
    wrench: np.ndarray


class TopicOracle:
    """The node's answer to each topic input, predicted with the library.

    Mirrors the node's state: the joint model with the current rest lengths and the last screw
    answered (the log-map branch of a pose and the re-publish after new rest lengths depend on
    it). Each method returns the :class:`Output` the node must publish, or None (nothing), and
    updates the state as the node does.
    """

    def __init__(self, model: JointModel, max_array_length: int = MAX_ARRAY_LENGTH,
                 link1_frame: str = LINK1_FRAME) -> None:
        self.model = model
        self.max_array_length = max_array_length
        self.link1_frame = link1_frame
        self.last_screw: np.ndarray | None = None

    def evaluate(self, xi: np.ndarray) -> Output | None:
        """The outputs at ``xi`` under the current model, or None where the node rejects."""
        try:
            with np.errstate(all='ignore'):
                state = self.model.evaluate(xi)
                interpretation = interpretation_vector(state.stiffness)
                finite = all(np.isfinite(a).all() for a in (
                    state.wrench, state.stiffness, state.cartesian_stiffness, state.tensions,
                    state.transform, interpretation))
        except ValueError:
            return None
        if not finite:
            return None
        self.last_screw = np.asarray(xi, dtype=np.float64)
        return Output(state.stiffness.ravel().copy(), state.wrench.copy())

    def screw(self, msg: Any) -> Output | None:
        try:
            xi = conversions.multiarray_to_array(msg, expected_length=6,
                                               max_length=self.max_array_length)
        except ValueError:
            return None
        with np.errstate(all='ignore'):
            if np.linalg.norm(xi[:3]) >= CHART_LIMIT:
                return None
        return self.evaluate(xi)

    def pose(self, msg: Any) -> Output | None:
        frame = msg.header.frame_id
        if frame and frame != self.link1_frame:
            return None
        try:
            T = conversions.pose_message_to_transform(msg.pose)
            reference = self.last_screw if self.last_screw is not None else \
                self.model.initial_screw
            with np.errstate(all='ignore'):
                xi = log_se3(T, reference=reference)
        except ValueError:
            return None
        return self.evaluate(xi)

    def rest_lengths(self, msg: Any) -> Output | None:
        try:
            rest = conversions.multiarray_to_array(msg, expected_length=self.model.n_strings,
                                                 max_length=self.max_array_length)
            self.model = self.model.with_rest_lengths(check_rest_lengths(self.model, rest))
        except ValueError:
            return None
        return None if self.last_screw is None else self.evaluate(self.last_screw)

    def predict(self, case: Case, msg: Any) -> Output | None:
        with np.errstate(all='ignore'):  # overflow is part of the game
            return {'screw': self.screw, 'pose': self.pose,
                    'rest_lengths': self.rest_lengths}[case.target](msg)


def _same(a: Any, b: Any) -> bool:
    """Equal floats (NaN equal to NaN) or equal sequences of them."""
    a, b = np.asarray(a, dtype=np.float64), np.asarray(b, dtype=np.float64)
    return a.shape == b.shape and bool(np.all((a == b) | (np.isnan(a) & np.isnan(b))))


def expected_forward(planar: PlanarMechanism, L3: float, theta1: float) -> dict[str, Any]:
    """The node's ``~/planar_forward_kinematics`` answer, from the library: ``success``, a
    message prefix, and the fields of a success."""
    try:
        fk = planar.forward(L3, theta1)
    except ValueError:
        return {'success': False, 'prefix': 'invalid request'}
    if not fk.actuator_in_range:
        return {'success': False, 'prefix': 'actuator (L3 ='}
    values = (fk.x, fk.y, fk.theta2, fk.stiffness, fk.energy, fk.jacobian_determinant)
    if not all(math.isfinite(v) for v in values) or not np.isfinite(fk.jacobian).all():
        return {'success': False, 'prefix': 'no isolated equilibrium'}
    return {'success': True, 'prefix': 'ok', 'x': fk.x, 'y': fk.y, 'platform_angle': fk.theta2,
            'stiffness': fk.stiffness, 'energy': fk.energy, 'stable': bool(fk.stable),
            'in_range': bool(fk.theta2_in_range),
            'jacobian': np.asarray(fk.jacobian).ravel(),
            'jacobian_determinant': fk.jacobian_determinant,
            'singularities': list(fk.singularities)}


def check_forward(planar: PlanarMechanism, case: Case, response: Any) -> str | None:
    """None if the node's forward-kinematics answer equals the library's, else why not."""
    exp = expected_forward(planar, case.payload['L3'], case.payload['theta1'])
    if bool(response.success) != exp['success']:
        return f'success {response.success}, library {exp["success"]} ({response.message})'
    if not response.message.startswith(exp['prefix']):
        return f'message {response.message!r}, expected {exp["prefix"]!r}...'
    if case.must_reject and response.success:
        return 'accepted an invalid request'
    if not exp['success']:
        return None
    for key in ('x', 'y', 'platform_angle', 'stiffness', 'energy', 'jacobian',
                'jacobian_determinant'):
        if not _same(getattr(response, key), exp[key]):
            return f'{key} {getattr(response, key)} != library {exp[key]}'
    if (bool(response.stable), bool(response.in_range)) != (exp['stable'], exp['in_range']):
        return 'stable / in_range differ from the library'
    if list(response.singularities) != exp['singularities']:
        return f'singularities {list(response.singularities)} != {exp["singularities"]}'
    return None


def check_inverse(planar: PlanarMechanism, case: Case, response: Any) -> str | None:
    """None if the node's inverse-kinematics answer equals the library's, else why not."""
    try:
        sols = planar.inverse(case.payload['x'], case.payload['y'])
    except ValueError:
        if response.success or not response.message.startswith('invalid request'):
            return f'library refuses the request, node answered {response.message!r}'
        return None
    if case.must_reject:
        return 'the library accepted a request built to be invalid (generator error)'
    if bool(response.success) != (len(sols) > 0):
        return f'success {response.success}, library has {len(sols)} solution(s)'
    fields = {'actuator_length': [s.L3 for s in sols], 'actuator_angle': [s.theta1 for s in sols],
              'platform_angle': [s.theta2 for s in sols],
              'stiffness': [s.stiffness for s in sols]}
    for key, values in fields.items():
        if not _same(list(getattr(response, key)), values):
            return f'{key} {list(getattr(response, key))} != library {values}'
    if list(response.stable) != [bool(s.stable) for s in sols]:
        return 'stable flags differ from the library'
    return None


def equilibrium_refusal(model: JointModel, case: Case,
                        max_array_length: int = MAX_ARRAY_LENGTH) -> str | None:
    """Why the node's validation refuses an equilibrium request (None: it accepts it)."""
    p = case.payload
    W = np.asarray(p['wrench'], dtype=np.float64)
    rest = np.asarray(p['rest_lengths'], dtype=np.float64)
    x0 = np.asarray(p['initial_screw'], dtype=np.float64)
    if rest.size > max_array_length or x0.size > max_array_length:
        return 'too many elements'
    if not np.isfinite(W).all():
        return 'wrench contains NaN or inf'
    if rest.size:
        try:
            model.validate_rest_lengths(rest, batched=False)
        except ValueError as exc:
            return str(exc)
    if x0.size:
        with np.errstate(all='ignore'):
            if x0.shape != (6,) or not np.isfinite(x0).all() or \
                    np.linalg.norm(x0[:3]) >= CHART_LIMIT:
                return 'initial_screw must have 6 finite values with |omega| < 2 pi'
    return None


def plausibility_refusal(model: JointModel, case: Case) -> str | None:
    """Why the node's ranges (issue #42, :mod:`tensegrity_stiffness.mechanics.plausibility`)
    refuse an equilibrium request its validation accepts (None: within them)."""
    p = case.payload
    try:
        rest = np.asarray(p['rest_lengths'], dtype=np.float64)
        if rest.size:
            check_rest_lengths(model, rest)
        check_wrench(model, np.asarray(p['wrench'], dtype=np.float64),
                     rest_lengths=rest if rest.size else None)
        x0 = np.asarray(p['initial_screw'], dtype=np.float64)
        if x0.size:
            check_screw(model, x0, 'initial_screw')
    except ValueError as exc:
        return str(exc)
    return None


def check_equilibrium(model: JointModel, case: Case, response: Any) -> str | None:
    """None if the node's equilibrium answer is right, else why not.

    ``model``: the node's model at the time (its current rest lengths). An invalid request must
    be refused (``invalid request: ...``); a valid one may fail (budget, no equilibrium within
    reach) unless it is an easy one; a success must be an equilibrium: finite, |F + W| within
    the solver's tolerance at the returned screw, and K, K_c, tensions, pose, energy, stability
    equal to the library's there.
    """
    p = case.payload
    refusal = equilibrium_refusal(model, case)
    if case.must_reject != (refusal is not None):
        return f'generator error: must_reject {case.must_reject}, validation says {refusal!r}'
    if case.must_reject:
        if response.success or not response.message.startswith('invalid request'):
            return f'an invalid request was not refused: {response.message!r}'
        return None
    if not response.success:
        out_of_range = 'range of this joint' in response.message
        if out_of_range and plausibility_refusal(model, case) is not None:
            return None  # outside the joint's ranges: refused by name
        if response.message.startswith(('invalid request', 'internal error')):
            return f'a valid request was refused: {response.message!r}'
        if p['easy']:
            return f'an easy request failed: {response.message!r}'
        return None
    rest = np.asarray(p['rest_lengths'], dtype=np.float64)
    rest = model.rest_lengths if rest.size == 0 else rest
    W = np.asarray(p['wrench'], dtype=np.float64)
    screw = np.asarray(response.screw, dtype=np.float64)
    if not np.isfinite(screw).all() or np.linalg.norm(screw[:3]) >= CHART_LIMIT:
        return f'success with screw {screw.tolist()}'
    with np.errstate(all='ignore'):
        state = model.evaluate(screw, rest)
    arrays = {'stiffness': state.stiffness.ravel(),
              'cartesian_stiffness': state.cartesian_stiffness.ravel(),
              'tensions': state.tensions}
    if not all(np.isfinite(a).all() for a in (*arrays.values(), state.wrench, state.transform)):
        return 'success at a screw where the state is not finite'
    residual = float(np.linalg.norm(state.wrench + W))
    if not residual <= 10.0 * RESIDUAL_TOLERANCE:
        return f'success with |F + W| = {residual:.3e}'
    if np.all(state.slack):
        return 'success with every string slack'
    for key, value in arrays.items():
        if not np.allclose(np.asarray(getattr(response, key)), value, rtol=1e-9, atol=1e-9):
            return f'{key} differs from the library at the returned screw'
    if not np.allclose(conversions.msg_to_wrench(response.string_wrench), state.wrench,
                       rtol=1e-9, atol=1e-9):
        return 'string_wrench differs from the library'
    if not np.allclose(conversions.pose_message_to_transform(response.pose), exp_se3(screw),
                       atol=1e-9):
        return 'pose is not exp(screw)'
    if bool(response.stable) != is_stable(state.cartesian_stiffness):
        return 'stable flag differs from the library'
    energy = float(model.energy(screw, rest))
    if not math.isclose(response.energy, energy, rel_tol=1e-9, abs_tol=1e-12):
        return f'energy {response.energy} != library {energy}'
    return None
