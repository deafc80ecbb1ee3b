"""Form-finding of bar-and-string structures (docs/structures.md, "Form-finding").

* **Force density method** (Schek 1974, "The force density method for form finding and
  computation of general networks", Comput. Methods Appl. Mech. Eng. 3): with force densities
  ``q`` the nodal equilibrium is linear, ``Omega X = 0`` on the free nodes (``Omega`` the stress
  matrix of :mod:`.analysis`). With supports: ``Omega_ff X_f = -Omega_fs X_s``, one solution.
  Without (a free-standing tensegrity): the positions lie in the null space of ``Omega``, which
  must hold a 3D configuration (nullity >= 4: ones and three coordinates), known only up to an
  affine map. The **gauge**: with a ``start``, its columns projected onto that null space (the
  configuration nearest the start in least squares, centroid kept); without, the null space's
  orthonormal basis orthogonal to the ones (centroid at the origin, unit-norm coordinate
  columns). For a symmetric start the projection keeps the symmetry: the regular p-prism comes
  out at the twist ``90 - 180/p`` from a start at any twist.
* **Kinematic form-finding** (Pellegrino 1986; Tibert & Pellegrino 2003, "Review of form-finding
  methods for tensegrity structures", Int. J. Space Struct. 18, Section 2.2, the non-linear
  optimisation): the chosen bars lengthened, kept equal, to their maximum with every string's
  length fixed (and the other bars'), by SLSQP from a start; the rigid motion fixed by the
  linear gauge ``sum (x_i - x0_i) = 0``, ``sum x0_i x x_i = 0`` (no translation, no
  infinitesimal rotation from the start) when nothing is fixed. At the maximum the framework
  has a self-stress (the constraints' multipliers): for unit strings the p-prism's bar is
  ``sqrt(1 + 1/sin(pi/p))`` (p = 3: 1.4679, Tibert & Pellegrino's triangular prism).
* **Rest-length design for a target shape**: at the given poses, string tensions ``t`` with
  every free body's wrench balance ``G t = -W`` (:func:`~.analysis.string_wrench_matrix`;
  ``W`` the weights when a fixed body or a world node carries them, zero for a free
  structure: its self-stress), bodies of any kind, closest to the middle of the tension band
  with every string inside ``[t_min, t_max]``: a QP solved by the library's active-set iteration
  (:func:`~tensegrity_stiffness.mechanics.active_set.active_set`) from a feasible start (a linear
  programme that maximises the smallest margin to the band). For bars this is the nodal
  equilibrium with the bars' forces eliminated (a bar's balance makes them axial). The rest
  lengths follow from the strings' force law
  (:func:`~tensegrity_stiffness.mechanics.design.rest_from_tensions`). Where the structure
  has the joint's form (one fixed body at the origin, one free body: :func:`joint_model_of`),
  :func:`design_joint_stiffness` runs the joint's design with its stiffness objective.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.optimize import linprog, minimize

from tensegrity_stiffness.mechanics.active_set import active_set, kkt_system
from tensegrity_stiffness.mechanics.design import BOUND_MARGIN, rest_from_tensions
from tensegrity_stiffness.structures.analysis import (
    EIGENVALUE_RTOL,
    Framework,
    analyse_framework,
    equilibrium_matrix,
    free_coordinates,
    stress_matrix,
    string_wrench_matrix,
)

FloatArray = NDArray[np.float64]

#: SLSQP's tolerance and iteration limit of the kinematic form-finding.
KINEMATIC_TOLERANCE = 1e-12
KINEMATIC_MAX_ITERATIONS = 500
#: Constraint violation (relative to the lengths) above which a kinematic search failed.
KINEMATIC_FEASIBILITY = 1e-8
#: Residual ``|A t - f|`` (relative to the largest force) above which a design failed.
DESIGN_RESIDUAL_RTOL = 1e-9


@dataclass
class FormFindingResult:
    """``positions`` (n, 3) of ``framework``'s nodes (``framework`` carries them, with forces
    where the method gives them); ``success`` and ``message``; method-specific numbers in
    ``info`` (force density: ``nullity``, ``residual``; kinematic: ``bar_length``,
    ``iterations``, ``violation``)."""

    framework: Framework
    success: bool
    message: str
    info: dict[str, Any] = field(default_factory=dict)

    @property
    def positions(self) -> FloatArray:
        """(n, 3) the node positions found."""
        return self.framework.positions


def force_density_form(framework: Framework, densities: ArrayLike,
                       start: ArrayLike | None = None,
                       eigenvalue_rtol: float = EIGENVALUE_RTOL) -> FormFindingResult:
    """Node positions of ``framework``'s topology at force ``densities`` (b,) (module
    docstring): supports (``framework.fixed``) stay at ``framework.positions``; free frameworks
    take the affine gauge of ``start`` (n, 3) (None: the null-space basis). ValueError when
    the densities admit no configuration (``Omega_ff`` singular with supports, nullity < 4
    without). The result's framework carries the member forces ``q l``."""
    fw = framework
    q = np.asarray(densities, dtype=np.float64).reshape(-1)
    b, n = fw.members.shape[0], fw.positions.shape[0]
    if q.shape != (b,) or not np.all(np.isfinite(q)):
        raise ValueError(f'densities must be {b} finite force densities (one per member)')
    Omega = stress_matrix(n, fw.members, q)
    free = ~fw.fixed
    if fw.fixed.any():
        Off = Omega[np.ix_(free, free)]
        eig = np.linalg.eigvalsh(Off)
        if np.min(np.abs(eig)) <= eigenvalue_rtol * np.max(np.abs(eig)):
            raise ValueError('force densities: Omega on the free nodes is singular (a free node '
                             'or group of nodes is not held by the densities)')
        X = fw.positions.copy()
        X[free] = np.linalg.solve(Off, -Omega[np.ix_(free, fw.fixed)] @ X[fw.fixed])
        nullity = 0
    else:
        eig, V = np.linalg.eigh(Omega)
        zero = eigenvalue_rtol * max(float(np.max(np.abs(eig))), 1e-300)
        null = V[:, np.abs(eig) <= zero]
        nullity = null.shape[1]
        if nullity < 4:
            smallest = ', '.join(f'{v:.3g}' for v in np.sort(np.abs(eig))[:4])
            raise ValueError(f'force densities: the stress matrix has nullity {nullity} < 4, so '
                             'no 3D configuration is in equilibrium with them (its smallest '
                             f'|eigenvalues| {smallest}; densities rounded? give them exactly, '
                             'e.g. 3**0.5)')
        ones = np.ones((n, 1)) / np.sqrt(n)
        basis = null - ones @ (ones.T @ null)
        U, s, _ = np.linalg.svd(basis, full_matrices=False)
        basis = U[:, s > 1e-8]  # the null space orthogonal to the ones
        if start is None:
            if basis.shape[1] != 3:
                raise ValueError(f'force densities: nullity {nullity} admits configurations of '
                                 f'{basis.shape[1]} dimensions; give a start to choose one')
            X = basis.copy()
        else:
            X0 = np.asarray(start, dtype=np.float64)
            if X0.shape != (n, 3) or not np.all(np.isfinite(X0)):
                raise ValueError(f'start must be finite with shape ({n}, 3), got {X0.shape}')
            c = X0.mean(axis=0)
            X = c + basis @ (basis.T @ (X0 - c))
            if np.linalg.matrix_rank(X - X.mean(axis=0), tol=1e-9 * np.abs(X0 - c).max()) < 3:
                raise ValueError('force densities: the start projects onto a flat configuration; '
                                 'give a start closer to the expected shape')
    out = fw.with_positions(X)
    out = out.with_forces(q * out.lengths)
    residual = float(np.abs((Omega @ X)[free]).max())
    return FormFindingResult(out, True, f'force density method: nullity {nullity}',
                             {'nullity': nullity, 'residual': residual})


def rigid_gauge(start: FloatArray) -> FloatArray:
    """(6, 3n) ``G`` of the linear gauge ``G x = G x0``: no translation of the centroid,
    ``sum x0_i x x_i = 0`` (no infinitesimal rotation) from the (n, 3) ``start``."""
    n = start.shape[0]
    G = np.zeros((6, 3 * n))
    for c in range(3):
        G[c, c::3] = 1.0
    for k, a in enumerate(start):
        G[3:, 3 * k:3 * k + 3] = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]],
                                           [-a[1], a[0], 0.0]])
    return G


def bar_members(framework: Framework, names: Sequence[str] | None) -> NDArray[np.intp]:
    """Member indices of the bars ``names`` (None: every bar); ValueError naming a missing
    one."""
    bars = np.flatnonzero(framework.is_bar)
    known = [framework.member_names[k] for k in bars]
    if names is None:
        chosen = list(bars)
    else:
        chosen = []
        for name in names:
            if name not in known:
                raise ValueError(f'lengthen: no bar {name!r} (bars: {", ".join(known)})')
            chosen.append(bars[known.index(name)])
    if not chosen:
        raise ValueError('lengthen: no bar to lengthen')
    return np.asarray(chosen, dtype=np.intp)


def kinematic_form(framework: Framework, lengthen: Sequence[str] | None = None,
                   string_lengths: ArrayLike | None = None,
                   tolerance: float = KINEMATIC_TOLERANCE,
                   max_iterations: int = KINEMATIC_MAX_ITERATIONS) -> FormFindingResult:
    """Kinematic form-finding (module docstring) from ``framework.positions``: the bars named
    in ``lengthen`` (None: every bar) lengthened together to their largest common length with
    the strings at ``string_lengths`` (b_strings,) (None: their lengths at the start) and the
    other bars at their start lengths. The result carries the self-stress found there (scaled
    to a largest string tension of 1), when there is one."""
    fw = framework
    lengths0 = fw.lengths
    chosen = bar_members(fw, lengthen)
    strings = np.flatnonzero(~fw.is_bar)
    target = lengths0.copy()
    if string_lengths is not None:
        L = np.asarray(string_lengths, dtype=np.float64).reshape(-1)
        if L.shape != (strings.size,) or np.any(~np.isfinite(L)) or np.any(L <= 0.0):
            raise ValueError(f'string_lengths must be {strings.size} positive lengths')
        target[strings] = L
    # Members between two supports keep their lengths by themselves: no constraint.
    between_supports = np.flatnonzero(fw.fixed[fw.members].all(axis=1))
    held = np.setdiff1d(np.arange(fw.members.shape[0]), np.union1d(chosen, between_supports))
    lead, others = chosen[0], chosen[1:]
    rows = free_coordinates(fw.fixed)
    X0 = fw.positions
    i, j = fw.members.T

    def positions(x: FloatArray) -> FloatArray:
        X = X0.copy().reshape(-1)
        X[rows] = x
        return X.reshape(-1, 3)

    def squared(x: FloatArray) -> FloatArray:
        X = positions(x)
        d = X[i] - X[j]
        return np.sum(d * d, axis=1)

    def squared_jacobian(x: FloatArray) -> FloatArray:
        X = positions(x)
        return 2.0 * (equilibrium_matrix(X, fw.members) * np.sqrt(squared(x))).T[:, rows]

    def equalities(x: FloatArray) -> FloatArray:
        s = squared(x)
        return np.concatenate([s[held] - target[held] ** 2, s[others] - s[lead]])

    def equalities_jacobian(x: FloatArray) -> FloatArray:
        J = squared_jacobian(x)
        return np.vstack([J[held], J[others] - J[lead]])

    constraints = [{'type': 'eq', 'fun': equalities, 'jac': equalities_jacobian}]
    if not fw.fixed.any():  # the gauge: no translation, no rotation from the start
        G = rigid_gauge(X0)
        g0 = G @ X0.reshape(-1)
        constraints.append({'type': 'eq', 'fun': lambda x: G @ x - g0, 'jac': lambda x: G})
    scale = float(lengths0[lead] ** 2)
    res = minimize(lambda x: -squared(x)[lead] / scale, X0.reshape(-1)[rows],
                   jac=lambda x: -squared_jacobian(x)[lead] / scale, method='SLSQP',
                   constraints=constraints,
                   options={'ftol': tolerance, 'maxiter': max_iterations})
    X = positions(res.x)
    out = fw.with_positions(X)
    violation = float(np.abs(out.lengths[held] - target[held]).max() / target.max())
    spread = float(np.ptp(out.lengths[chosen]) / target.max()) if chosen.size > 1 else 0.0
    ok = bool(res.success) and max(violation, spread) <= KINEMATIC_FEASIBILITY
    analysis = analyse_framework(out)
    if analysis.self_stresses >= 1:
        t = analysis.self_stress_basis[:, 0]
        if t[strings].sum() < 0.0:
            t = -t
        out = out.with_forces(t / np.abs(t[strings]).max())
    info = {'bar_length': float(out.lengths[lead]), 'iterations': int(res.nit),
            'violation': max(violation, spread), 'self_stresses': analysis.self_stresses}
    message = (f'kinematic form-finding: bars {float(out.lengths[lead]):.9g} m '
               f'({res.message})')
    return FormFindingResult(out, ok, message, info)


@dataclass
class ShapeDesign:
    """A rest-length design at a target shape: ``rest_lengths`` (n_strings,), ``tensions``
    (n_strings,), ``bar_forces`` (n_bars,) compression positive, ``residual`` ``|A t - f|`` (N),
    ``success`` and ``message``."""

    rest_lengths: FloatArray
    tensions: FloatArray
    bar_forces: FloatArray
    residual: float
    success: bool
    message: str


def tension_caps(structure: Any, lengths: FloatArray) -> FloatArray:
    """(n,) the largest tension each string can hold at ``lengths`` with a positive rest
    length and below its maximum length (``lmax - l0`` kept, as the joint's design keeps it):
    ``hooke`` ``min(k l, k m)``, ``paper`` ``min(k, k m / l)``, less
    :data:`~tensegrity_stiffness.mechanics.design.BOUND_MARGIN` of it."""
    k, m = structure.k, structure.max_stretch
    if structure.force_law == 'hooke':
        cap = np.minimum(k * lengths, k * m)
    else:
        cap = np.minimum(k, k * m / lengths)
    return (1.0 - BOUND_MARGIN) * cap


def design_rest_lengths_for_shape(structure: Any, poses: ArrayLike | None = None,
                                  t_min: float = 1.0, t_max: float = 100.0) -> ShapeDesign:
    """Rest lengths that hold ``structure`` at ``poses`` (None: its start) with every string
    tension in ``[t_min, t_max]`` (N) and below its cap (:func:`tension_caps`), the tensions
    closest to ``(t_min + t_max) / 2`` (module docstring): each free body's wrench balance
    ``G_i t = -W_i`` (:func:`~.analysis.string_wrench_matrix`; ``W`` the weights when a
    fixed body or a world node carries them, zero otherwise), bodies of any kind.
    ``success`` False with the reason when no such tensions exist; a ground's contacts are
    not designed (a structure on the ground gets its prestress alone)."""
    if not (0.0 < t_min < t_max and np.isfinite(t_max)):
        raise ValueError(f'tension band must have 0 < t_min < t_max < inf, got [{t_min}, '
                         f'{t_max}]')
    s = structure
    T = s.transforms(poses)
    free = np.flatnonzero(~s.fixed)
    rows = (6 * free[:, None] + np.arange(6)).reshape(-1)
    A = string_wrench_matrix(s, T)[rows]
    supported = bool(s.fixed.any() or s.world_nodes)
    f = -s.gravity_wrenches(T)[0].reshape(-1)[rows] if supported else np.zeros(rows.size)
    n = s.n_strings
    lengths = s.evaluate(T).lengths
    lo, hi = np.full(n, float(t_min)), np.minimum(float(t_max), tension_caps(s, lengths))
    if np.any(hi <= lo):
        j = int(np.argmin(hi - lo))
        nan = np.full(n, np.nan)
        return ShapeDesign(nan, nan, np.full(len(s.bar_names), np.nan), np.nan, False,
                           f'string {s.string_names[j]} cannot carry t_min = {t_min:g} N '
                           f'(at most {hi[j]:.6g} N: a positive rest length and its maximum '
                           'length)')
    # Feasible start: maximise the smallest margin m of the tensions inside the band.
    c = np.zeros(n + 1)
    c[-1] = -1.0
    G = np.zeros((2 * n, n + 1))
    G[np.arange(n), np.arange(n)] = -1.0
    G[n + np.arange(n), np.arange(n)] = 1.0
    G[:, -1] = 1.0
    lp = linprog(c, A_ub=G, b_ub=np.concatenate([-lo, hi]),
                 A_eq=np.hstack([A, np.zeros((A.shape[0], 1))]), b_eq=f,
                 bounds=list(zip(lo, hi, strict=True)) + [(None, None)], method='highs')
    if lp.status != 0 or lp.x[-1] < 0.0:
        nan = np.full(n, np.nan)
        return ShapeDesign(nan, nan, np.full(len(s.bar_names), np.nan), np.nan, False,
                           f'no string tensions hold this shape inside [{t_min:g}, '
                           f'{t_max:g}] N (the bodies\' balance leaves '
                           f'{n - np.linalg.matrix_rank(A)} self-stresses)')
    P = np.eye(n)
    ref = np.full(n, 0.5 * (t_min + t_max))

    def face(t: FloatArray, free_set: Any, nu: FloatArray) -> tuple[FloatArray, FloatArray]:
        K, rhs = kkt_system(P, ref, A, f, t, free_set)
        sol = np.linalg.lstsq(K, rhs, rcond=None)[0]
        nf = int(np.sum(free_set))
        return sol[:nf], sol[nf:]

    qp = active_set(P, ref, A, lo, hi, lp.x[:n], face)
    t = qp.t
    residual = float(np.linalg.norm(A @ t - f))
    rest = rest_from_tensions(s, lengths, t)
    state = s.evaluate(T, rest_lengths=rest) if np.all(rest > 0.0) else None
    ok = (qp.converged and state is not None
          and residual <= DESIGN_RESIDUAL_RTOL * max(1.0, float(np.abs(t).max())))
    bar_forces = state.bar_forces if state is not None else np.full(len(s.bar_names), np.nan)
    message = (f'tensions {t.min():.6g}..{t.max():.6g} N in the band [{t_min:g}, {t_max:g}] N'
               if ok else 'the design did not converge or needs a rest length <= 0 (stiffen '
               'the strings or lower the band)')
    return ShapeDesign(rest, t, bar_forces, residual, ok, message)


def joint_model_of(structure: Any) -> tuple[Any, FloatArray]:
    """A structure of two bodies, one fixed at the world origin (identity pose) and one free,
    joined only by strings, as the joint
    (:class:`~tensegrity_stiffness.mechanics.joint.JointModel`: link 1 the fixed body, link 2 the
    free one) and the screw of the free body's pose: the structure's form where the joint's
    stiffness design applies (ValueError naming what does not fit)."""
    from tensegrity_stiffness.geometry.screw import log_se3
    from tensegrity_stiffness.mechanics.joint import JointModel

    s = structure
    if s.n_bodies != 2 or int(s.fixed.sum()) != 1 or s.world_nodes:
        raise ValueError('the joint design applies to two bodies, one fixed and one free, '
                         'without world nodes')
    base, free = (0, 1) if s.fixed[0] else (1, 0)
    if not np.allclose(s.bodies[base].pose, np.eye(4), rtol=0.0, atol=1e-12):
        raise ValueError(f"the joint design needs the fixed body '{s.body_names[base]}' at the "
                         'world origin (identity pose)')
    nodes1, nodes2 = s.bodies[base].node_names, s.bodies[free].node_names
    connections = []
    for name, (a, b) in zip(s.string_names, s.string_bodies, strict=True):
        if {int(a), int(b)} != {base, free}:
            raise ValueError(f'strings: {name} does not join the fixed body to the free one')
    for spec, (a, _) in zip(s.strings, s.string_bodies, strict=True):
        start, end = spec.start.split('.', 1)[1], spec.end.split('.', 1)[1]
        if int(a) != base:
            start, end = end, start
        connections.append((nodes1.index(start), nodes2.index(end)))
    model = JointModel(s.bodies[base].node_array, connections, s.k, s.rest_lengths,
                       link2_nodes=s.bodies[free].node_array, max_lengths=s.max_lengths,
                       force_law=s.force_law, node_names=nodes1, link2_node_names=nodes2,
                       string_names=s.string_names)
    return model, log_se3(s.bodies[free].pose)


def design_joint_stiffness(structure: Any, target_stiffness: ArrayLike, t_min: float = 1.0,
                           t_max: float = 100.0) -> Any:
    """The joint's stiffness design
    (:func:`~tensegrity_stiffness.mechanics.design.design_rest_lengths`: rest lengths holding the
    pose with tensions in the band and ``K_c`` closest to ``target_stiffness``) for a structure of
    the joint's form (:func:`joint_model_of`), under the free body's weight when the structure has
    gravity. Returns the joint design's
    :class:`~tensegrity_stiffness.mechanics.design.DesignResult` (rest lengths in the structure's
    string order)."""
    from tensegrity_stiffness.mechanics.design import design_rest_lengths

    model, screw = joint_model_of(structure)
    free = int(np.flatnonzero(~structure.fixed)[0])
    weight = structure.gravity_wrenches(structure.start_poses())[0][free]
    return design_rest_lengths(model, screw, weight, t_min, t_max, target_stiffness)
