"""A scripted roll of a structure on the ground: rest-length commands that tip it from the face
it rests on over one edge onto the next face (docs/structures.md, "The gait that rolls").

The gait, one step
------------------
1. **Plan** (:func:`plan_roll_step`, with the library's equilibrium on the ground): the
   support face is the structure's three ground contacts (the equilibrium's); the edge to roll
   over is the face's edge whose outward normal in the ground plane is nearest the wanted
   ``direction``; the next face is the face of the nodes' convex hull across that edge. Each
   string is probed: its rest length shortened by ``probe`` (a fraction), the equilibrium on the
   ground with the same contacts
   (:func:`~tensegrity_stiffness.structures.equilibrium.solve_structure_equilibrium`, no roll-over)
   moves the centre of mass towards that edge by some distance; the ``n_strings`` strings that move
   it most are the tipping strings. Their contraction is the smallest on a grid of
   ``CONTRACTION_STEP`` whose equilibrium on the support face has the centre of mass past the edge
   by ``TIP_MARGIN`` of the face's inradius (the structure then has no equilibrium there: it tips),
   at most ``max_contraction``.
2. **Tip** (:class:`RollGait`): command the tipping rest lengths (the motors move at their
   rate limit) until the next face's new node touches the ground.
3. **Recover**: command the nominal rest lengths again and wait until the motors have arrived
   and the structure is at rest on the next face.

The gait is ROS-free and reads only the contact nodes and the motors' state (what a robot has
from its sensors: contact switches or the estimator's poses); :func:`run_roll` drives a
:class:`~.structure_twin.StructureSimulation` with it and records the roll.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial import ConvexHull

from tensegrity_stiffness.geometry.screw import exp_so3
from tensegrity_stiffness.simulation.structure_twin import StructureSimulation
from tensegrity_stiffness.structures.elements import WORLD
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure

__all__ = [
    'CONTRACTION_STEP',
    'PHASES',
    'TIP_MARGIN',
    'RollGait',
    'RollRecord',
    'RollStep',
    'centre_of_mass',
    'face_across',
    'plan_roll_step',
    'rolled_onto',
    'run_roll',
]

FloatArray = NDArray[np.float64]

#: The grid of contractions (fraction of a rest length) searched for the tipping command.
CONTRACTION_STEP = 0.05
#: The centre of mass past the edge by this fraction of the support face's inradius at the
#: planned contraction (a margin for what the static model leaves out: soft contacts, motion).
TIP_MARGIN = 0.2
#: The gait's phases in order.
TIP, RECOVER, DONE = 'tip', 'recover', 'done'
PHASES = (TIP, RECOVER, DONE)
#: At rest on the new face: every body speed (m/s, rad/s) at most this.
REST_SPEED = 1e-2


def centre_of_mass(structure: Structure, poses: ArrayLike) -> FloatArray:
    """(3,) the structure's centre of mass in the world at ``poses``."""
    T = structure.transforms(poses)
    masses = np.array([b.mass for b in structure.bodies])
    coms = np.einsum('nij,nj->ni', T[:, :3, :3], np.array([b.com for b in structure.bodies]))
    return masses @ (coms + T[:, :3, 3]) / masses.sum()


def face_across(structure: Structure, poses: ArrayLike, face: tuple[str, ...],
                edge: tuple[str, str]) -> tuple[str, str, str]:
    """The face of the convex hull of the body nodes at ``poses`` that shares ``edge`` with
    ``face`` (the face the structure lands on when it rolls over that edge), in node order."""
    names = [n for n in structure.node_names if not n.startswith(f'{WORLD}.')]
    x = structure.node_positions(structure.transforms(poses))[:len(names)]
    hull = ConvexHull(x)
    want = {names.index(edge[0]), names.index(edge[1])}
    others = {names.index(n) for n in face} - want
    for simplex in hull.simplices:
        nodes = set(int(i) for i in simplex)
        if want <= nodes and not nodes & others:
            return tuple(sorted((names[i] for i in nodes), key=names.index))  # type: ignore
    raise ValueError(f'no hull face across the edge {edge} of {face}')


def rolled_onto(structure: Structure, poses: ArrayLike, edge: tuple[str, str],
                face: tuple[str, ...]) -> FloatArray:
    """The free bodies at ``poses`` turned rigidly about ``edge`` (two nodes on the ground) so
    that the hull face ``face`` (containing the edge) lies in the ground plane: the rigid roll
    over that edge (the rotation about the edge's axis taking the face's outward normal to
    minus the ground's normal)."""
    T = structure.transforms(poses)
    x = structure.node_positions(T)
    n = structure.ground.normal
    xi, xj = x[structure.node_index(edge[0])], x[structure.node_index(edge[1])]
    xk = x[structure.node_index(next(m for m in face if m not in edge))]
    e = (xj - xi) / np.linalg.norm(xj - xi)
    normal = np.cross(xj - xi, xk - xi)
    normal /= np.linalg.norm(normal)
    if normal @ (x[structure.node_bodies >= 0].mean(axis=0) - xi) > 0.0:
        normal = -normal
    angle = math.atan2(float(e @ np.cross(normal, -n)), float(normal @ -n))
    G = np.eye(4)
    G[:3, :3] = exp_so3(e * angle)
    G[:3, 3] = xi - G[:3, :3] @ xi
    return np.array([P if fixed else G @ P for P, fixed in zip(T, structure.fixed,
                                                                strict=True)])


def _edge_margins(structure: Structure, x: FloatArray, face: list[int],
                  centre: FloatArray) -> FloatArray:
    """Signed distances (3,) of the centre of mass's ground projection past each edge
    ``(face[a], face[a + 1])`` of the support face (positive: outside it)."""
    n = structure.ground.normal
    P = x[face] - np.outer(x[face] @ n, n)
    c = centre - (centre @ n) * n
    out = np.empty(3)
    for a in range(3):
        i, j, k = P[a], P[(a + 1) % 3], P[(a + 2) % 3]
        e = (j - i) / np.linalg.norm(j - i)
        outward = np.cross(e, n)
        if (k - i) @ outward > 0.0:
            outward = -outward
        out[a] = (c - i) @ outward
    return out


@dataclass(frozen=True)
class RollStep:
    """One planned roll (module docstring): the ``start_face`` and ``next_face`` (node names),
    the ``edge`` rolled over, the tipping ``strings``, their ``contraction`` (fraction of the
    rest length), the commands ``tip_rest_lengths`` and ``nominal_rest_lengths`` (n,), the
    centre of mass's planned margin past the edge (m, at the contraction), ``landing_face``
    (where the library's equilibrium ends from the rigid roll onto ``next_face`` with the
    nominal rest lengths, rolling on while a face is not stable: the face the gait should
    leave the structure on), ``landing_poses`` that equilibrium and ``com_step`` (3,) m, the
    centre of mass's move in the ground plane from the start's equilibrium to it."""

    start_face: tuple[str, str, str]
    next_face: tuple[str, str, str]
    edge: tuple[str, str]
    strings: tuple[str, ...]
    contraction: float
    tip_rest_lengths: FloatArray
    nominal_rest_lengths: FloatArray
    margin: float
    landing_face: tuple[str, ...]
    landing_poses: FloatArray
    com_step: FloatArray


def plan_roll_step(structure: Structure, poses: ArrayLike | None = None,
                   direction: ArrayLike = (1.0, 0.0, 0.0), n_strings: int = 3,
                   probe: float = 0.1, max_contraction: float = 0.5) -> RollStep:
    """Plan one roll of ``structure`` (with gravity and a ground) from its equilibrium on the
    ground nearest ``poses`` (default the config's) towards ``direction`` (module docstring).
    ValueError when the structure does not rest on three nodes or no contraction up to
    ``max_contraction`` tips it."""
    if structure.ground is None or structure.gravity is None:
        raise ValueError('a roll needs a structure with gravity and a ground')
    if not (isinstance(n_strings, int) and 1 <= n_strings <= structure.n_strings):
        raise ValueError(f'n_strings must be in 1..{structure.n_strings}, got {n_strings!r}')
    for name, value in (('probe', probe), ('max_contraction', max_contraction)):
        if not (isinstance(value, (int, float)) and 0.0 < value < 0.9):
            raise ValueError(f'{name} must be a fraction in (0, 0.9), got {value!r}')
    rest = structure.rest_lengths.copy()
    base = solve_structure_equilibrium(structure, start=poses)
    if not base.success or len(base.contacts) != 3:
        raise ValueError(f'the structure must rest on three nodes to roll: {base.message}, '
                         f'contacts {sorted(base.contacts)}')
    face = [structure.node_index(n) for n in base.contacts]
    face.sort()
    names = [structure.node_names[i] for i in face]
    x = structure.node_positions(base.poses)
    margins = _edge_margins(structure, x, face, centre_of_mass(structure, base.poses))
    n = structure.ground.normal
    d = finite_direction(direction, n)
    outward = []
    for a in range(3):
        m_plus = _edge_margins(structure, x, face,
                               centre_of_mass(structure, base.poses) + 1e-3 * d)[a]
        outward.append(m_plus - margins[a])
    a = int(np.argmax(outward))
    edge = (names[a], names[(a + 1) % 3])
    inradius = float(-margins.max())

    def margin_at(rest_lengths: FloatArray) -> float | None:
        result = solve_structure_equilibrium(structure, start=base.poses,
                                             rest_lengths=rest_lengths, roll=False)
        if result.state is None:
            return None
        return float(_edge_margins(structure, structure.node_positions(result.poses), face,
                                   centre_of_mass(structure, result.poses))[a])

    gains = np.full(structure.n_strings, -math.inf)
    for j in range(structure.n_strings):
        trial = rest.copy()
        trial[j] *= 1.0 - probe
        m = margin_at(trial)
        if m is not None:
            gains[j] = m - margins[a]
    chosen = np.argsort(-gains)[:n_strings]
    chosen = chosen[gains[chosen] > 0.0]
    if not chosen.size:
        raise ValueError(f'no string moves the centre of mass towards the edge {edge}')
    wanted = TIP_MARGIN * inradius
    for contraction in np.arange(CONTRACTION_STEP, max_contraction + 1e-12, CONTRACTION_STEP):
        tip = rest.copy()
        tip[chosen] *= 1.0 - contraction
        m = margin_at(tip)
        if m is not None and m >= wanted:
            nxt = face_across(structure, base.poses, tuple(names), edge)
            landing = solve_structure_equilibrium(
                structure, start=rolled_onto(structure, base.poses, edge, nxt))
            if not landing.success:
                raise ValueError(f'no equilibrium after the roll over {edge}: '
                                 f'{landing.message}')
            step = (centre_of_mass(structure, landing.poses)
                    - centre_of_mass(structure, base.poses))
            step -= (step @ n) * n
            return RollStep(tuple(names), nxt, edge,  # type: ignore[arg-type]
                            tuple(structure.string_names[j] for j in sorted(chosen)),
                            float(contraction), tip, rest, m,
                            tuple(sorted(landing.contacts, key=structure.node_names.index)),
                            landing.poses, step)
    tipping = [structure.string_names[j] for j in chosen]
    raise ValueError(f'no contraction up to {max_contraction} of {tipping} tips the structure '
                     f'over {edge}')


def finite_direction(direction: ArrayLike, normal: FloatArray) -> FloatArray:
    """``direction`` (3,) in the ground plane, unit; ValueError for one along the normal."""
    d = np.asarray(direction, dtype=np.float64).reshape(-1)
    if d.shape != (3,) or not np.all(np.isfinite(d)):
        raise ValueError(f'direction must be 3 finite values, got {direction!r}')
    d = d - (d @ normal) * normal
    size = float(np.linalg.norm(d))
    if size < 1e-12:
        raise ValueError('direction must not be along the ground normal')
    return d / size


class RollGait:
    """The gait of one :class:`RollStep` (module docstring), driven by the contact nodes:
    :meth:`update` takes the time, the contact nodes and whether the structure is at rest with
    its motors arrived, and returns the rest lengths to command when the phase changes (None
    otherwise). ``timeout`` (s): a phase that lasts longer ends the gait (``failed``)."""

    def __init__(self, step: RollStep, timeout: float = 10.0) -> None:
        self.step = step
        self.timeout = float(timeout)
        self.phase = TIP
        self.failed = False
        self._since: float | None = None
        self._new_node = next(n for n in step.next_face if n not in step.edge)

    def start(self, time: float) -> FloatArray:
        """The first command (the tipping rest lengths) at ``time``."""
        self.phase, self._since, self.failed = TIP, time, False
        return self.step.tip_rest_lengths.copy()

    def update(self, time: float, contacts: list[str], settled: bool) -> FloatArray | None:
        """The next command, if the phase changes now (module docstring)."""
        if self._since is None:
            return self.start(time)
        if self.phase == DONE:
            return None
        if time - self._since > self.timeout:
            self.phase, self.failed = DONE, True
            return None
        if self.phase == TIP and self._new_node in contacts:
            self.phase, self._since = RECOVER, time
            return self.step.nominal_rest_lengths.copy()
        if self.phase == RECOVER and settled:
            self.phase, self._since = DONE, time
        return None


@dataclass
class RollRecord:
    """What :func:`run_roll` recorded, every ``every`` steps: ``times`` (s), ``com`` (m, 3)
    per sample, ``contacts`` (node names per sample), ``phases``; the gaits run."""

    times: list[float] = field(default_factory=list)
    com: list[FloatArray] = field(default_factory=list)
    contacts: list[list[str]] = field(default_factory=list)
    phases: list[str] = field(default_factory=list)
    steps: list[RollStep] = field(default_factory=list)


def run_roll(simulation: StructureSimulation, n_steps: int = 1,
             direction: ArrayLike = (1.0, 0.0, 0.0), max_time: float = 20.0,
             every: int = 10, **plan: object) -> RollRecord:
    """Roll the twin ``n_steps`` faces towards ``direction`` (the first; then on along the
    first step's heading): for each, plan from the twin's poses (:func:`plan_roll_step`,
    keywords ``plan``), run the :class:`RollGait` on the twin's contact nodes until it is
    done; ``max_time`` (s, simulated) bounds the whole. The record of the roll (ValueError
    from the plan; a gait that timed out stops the roll)."""
    sim = simulation
    record = RollRecord()
    end = sim.time + max_time
    heading = direction
    for _ in range(n_steps):
        step = plan_roll_step(sim.structure, sim.poses(), heading, **plan)  # type: ignore
        record.steps.append(step)
        if len(record.steps) == 1:  # keep the heading of the first face step
            heading = step.com_step
        gait = RollGait(step, timeout=max(end - sim.time, 0.0))
        sim.set_rest_lengths(gait.start(sim.time))
        while gait.phase != DONE and sim.time < end:
            sim.step(every)
            contacts = sim.contact_nodes()
            speed = float(np.abs(sim.data.qvel).max())
            command = gait.update(sim.time, contacts, not sim.moving and speed <= REST_SPEED)
            if command is not None:
                sim.set_rest_lengths(command)
            record.times.append(sim.time)
            record.com.append(sim.centre_of_mass())
            record.contacts.append(contacts)
            record.phases.append(gait.phase)
        if gait.phase != DONE or gait.failed:
            break
    return record
