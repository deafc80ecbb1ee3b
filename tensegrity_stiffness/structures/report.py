"""Service-shaped reports of a structure: plain dicts of counts, flags, numbers and names (JSON-
and message-ready) for ``tensegrity-stiffness structure check`` and a later ROS service
(docs/structures.md, "Command line").

* :func:`analysis_fields`: the pin-jointed analysis (:mod:`.analysis`) as fields.
* :func:`check_structure`: the equilibrium with the file's gravity and ground
  (:func:`~tensegrity_stiffness.structures.equilibrium.solve_structure_equilibrium`), its
  stability, the tensions, slack and saturated strings, the bar forces, the contact forces and
  the modes there; the body counts and the pin-jointed analysis (structures of bars; fixed
  bodies and world nodes as supports) at the prestressed equilibrium (the one without gravity,
  ground and loads, whose member forces are a self-stress: Connelly's and Pellegrino's tests
  are about it); ``problems`` (why the structure is not sound; empty: sound) and ``notes``.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from tensegrity_stiffness.mechanics.templates import pose_vector
from tensegrity_stiffness.structures.analysis import Analysis, analyse, body_counts
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.modes import structure_modes

#: The smallest stress-matrix eigenvalues reported (the nullity's and the next).
REPORTED_EIGENVALUES = 6


def analysis_fields(analysis: Analysis) -> dict[str, Any]:
    """The analysis as plain fields: ``self_stresses``, ``mechanisms``, ``rigid_motions``,
    ``rank``, and with member forces ``force_densities`` {member: N/m}, the smallest
    ``stress_eigenvalues``, ``stress_nullity``, ``stress_psd``, ``stress_residual`` (N),
    ``strings_pull``, ``prestress_stiffness`` (N/m), ``prestress_stable``, ``super_stable``
    (None with supports), ``conic_at_infinity``."""
    a = analysis
    out: dict[str, Any] = {
        'n_nodes': len(a.framework.node_names), 'n_members': int(a.framework.members.shape[0]),
        'n_supports': int(a.framework.fixed.sum()), 'rank': a.rank,
        'self_stresses': a.self_stresses, 'mechanisms': a.mechanisms,
        'rigid_motions': a.rigid_motions}
    if a.density_vector is None:
        return out
    eig = a.stress_eigenvalues
    out.update(force_densities=a.force_densities,
               stress_eigenvalues=[float(v) for v in eig[:REPORTED_EIGENVALUES]],
               stress_nullity=a.stress_nullity, stress_psd=a.stress_psd,
               stress_residual=a.residual, strings_pull=a.strings_pull,
               prestress_stiffness=[float(v) for v in a.prestress_stiffness],
               prestress_stable=a.prestress_stable, super_stable=a.super_stable,
               conic_at_infinity=a.conic_at_infinity)
    return out


def without_loads(structure: Any) -> Any:
    """``structure`` without its gravity and ground (the same bodies, poses and strings)."""
    document = structure.to_dict()
    section = document['structure']
    section.pop('gravity', None)
    section.pop('ground', None)
    return type(structure).from_dict(document)


def prestressed_poses(structure: Any, eq: Any, loads: Any) -> tuple[Any, Any, str | None]:
    """The structure without gravity, ground and loads and its equilibrium poses (``eq``'s
    own when it has none of them; else solved from ``eq``'s poses), or None with the reason."""
    if structure.gravity is None and structure.ground is None and loads is None:
        return (structure, eq.poses, None) if eq.success else (None, None, eq.message)
    free = without_loads(structure)
    unloaded = solve_structure_equilibrium(free, None, eq.poses if eq.success else None)
    if not unloaded.success:
        return None, None, unloaded.message
    return free, unloaded.poses, None


def _prestress_fields(report: dict[str, Any], structure: Any, eq: Any, loads: Any,
                      notes: list[str]) -> None:
    """``body_counts`` and ``analysis`` at the prestressed equilibrium (module docstring)."""
    report['body_counts'] = report['analysis'] = None
    free, poses, reason = prestressed_poses(structure, eq, loads)
    if free is None:
        notes.append(f'no prestressed equilibrium to analyse: {reason}')
        return
    counts = body_counts(free, poses)
    report['body_counts'] = {'rank': counts.rank, 'self_stresses': counts.self_stresses,
                             'mechanisms': counts.mechanisms,
                             'rigid_motions': counts.rigid_motions, 'spins': counts.spins}
    try:
        report['analysis'] = analysis_fields(analyse(free, poses))
    except ValueError as exc:
        notes.append(f'no pin-jointed analysis: {exc}')
    if free is not structure:
        notes.append('body counts and analysis at the prestressed equilibrium without gravity, '
                     'ground and loads')


def _names(names: list[str], mask: Any) -> list[str]:
    return [names[j] for j in np.flatnonzero(mask)]


def check_structure(structure: Any, loads: Any = None, start: ArrayLike | None = None
                    ) -> dict[str, Any]:
    """The check of ``structure`` (module docstring) under ``loads`` (as the equilibrium's)
    from ``start`` (None: its poses). Keys: ``n_bodies``, ``n_bars``, ``n_strings``,
    ``gravity``, ``ground``, ``equilibrium`` {``success``, ``message``, ``residual``,
    ``iterations``, ``stable``, ``stability_margin``, ``poses`` (N x [x y z qx qy qz qw])},
    ``tensions`` {string: N}, ``slack``, ``saturated`` (names), ``bar_forces`` {bar: N,
    compression positive}, ``contacts`` {node: [fx fy fz]}, ``sliding`` (nodes),
    ``modes`` {``frequencies_hz``, ``zero_modes``, ``counts``, ``stable``} at the equilibrium
    (:func:`~.modes.structure_modes`; None with the reason in ``notes``),
    ``body_counts`` (:func:`~.analysis.body_counts`: any bodies) and ``analysis``
    (:func:`analysis_fields`) at the prestressed equilibrium (None with the reason in
    ``notes``), ``problems``, ``notes``, ``sound``."""
    s = structure
    problems: list[str] = []
    notes: list[str] = []
    eq = solve_structure_equilibrium(s, loads, start)
    report: dict[str, Any] = {
        'n_bodies': s.n_bodies, 'n_bars': len(s.bar_names), 'n_strings': s.n_strings,
        'bodies': list(s.body_names),
        'gravity': None if s.gravity is None else [float(v) for v in s.gravity],
        'ground': s.ground is not None,
        'equilibrium': {'success': eq.success, 'message': eq.message,
                        'residual': eq.residual, 'iterations': eq.iterations,
                        'stable': eq.stable, 'stability_margin': eq.stability_margin,
                        'poses': [pose_vector(T) for T in eq.poses]}}
    if not eq.success:
        problems.append(f'no equilibrium: {eq.message}')
    elif not eq.stable:
        problems.append('the equilibrium is not stable (the stiffness on the tangent space '
                        f'without the gauge is not positive definite; margin '
                        f'{eq.stability_margin:.3g})')
    state = eq.state
    if state is not None:
        report.update(
            tensions=dict(zip(s.string_names, map(float, state.tensions), strict=True)),
            lengths=dict(zip(s.string_names, map(float, state.lengths), strict=True)),
            slack=_names(s.string_names, state.slack),
            saturated=_names(s.string_names, state.saturated),
            bar_forces=dict(zip(s.bar_names, map(float, state.bar_forces), strict=True)))
        if report['slack']:
            notes.append(f"slack strings: {', '.join(report['slack'])}")
        if report['saturated']:
            notes.append(f"strings at their maximum length: {', '.join(report['saturated'])}")
    report['contacts'] = {name: [float(v) for v in f] for name, f in eq.contacts.items()}
    report['sliding'] = list(eq.sliding)
    report['modes'] = None
    if eq.success:
        try:
            modes = structure_modes(s, eq)
        except ValueError as exc:
            notes.append(f'no modes: {exc}')
        else:
            report['modes'] = {'frequencies_hz': [float(v) for v in modes.frequencies],
                               'zero_modes': list(modes.zero_modes), 'counts': modes.counts,
                               'stable': modes.stable}
    _prestress_fields(report, s, eq, loads, notes)
    report['problems'] = problems
    report['notes'] = notes
    report['sound'] = not problems
    return report
