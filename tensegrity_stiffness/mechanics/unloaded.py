"""The one rule for a config's ``initial_screw`` (the joint's unloaded equilibrium), applied by
every reader of a config: :meth:`JointModel.from_dict` (and so ``from_yaml``, ``JointChain``, the
nodes' settings, the twin and the command line).

* **Missing**: the unloaded equilibrium is solved (:func:`unloaded_equilibrium`) from the
  documented starts (:func:`unloaded_starts`): link 2 at the identity rotation and turned over
  by pi about each of :data:`TURN_AXES` of {1}, each placed at the mean of the string vectors
  ``p1_a - R p2_b`` (so no string has zero length). Every start is solved with
  :func:`~tensegrity_stiffness.mechanics.equilibrium.solve_equilibrium`; of the stable
  equilibria found, the one of least elastic energy wins, and among equal energies (relative
  :data:`ENERGY_TIE`) the one whose link 2 lies highest along +z of {1} (the joint's axis,
  within :data:`HEIGHT_TIE`), then the one of the earliest start. None found: ValueError
  asking for ``initial_screw``.
* **Given but not an equilibrium** (``|F| > INITIAL_SCREW_TOLERANCE`` or not admissible): it is
  kept as the start of equilibrium solves and an :class:`InitialScrewWarning` names the residual
  and the equilibrium a solve from it reaches (the command line prints it on stderr, the nodes
  log it).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.mechanics.equilibrium import EquilibriumResult, solve_equilibrium

if TYPE_CHECKING:  # types only: joint reads its config through this module (no import circle)
    from tensegrity_stiffness.mechanics.joint import JointModel

FloatArray = NDArray[np.float64]

#: A given ``initial_screw`` is an unloaded equilibrium when ``|F|`` (N and N m together) is at
#: most this.
INITIAL_SCREW_TOLERANCE = 1e-9
_S = math.sqrt(0.5)
#: Axes of {1} about which the documented starts turn link 2 over (by pi, after the identity).
TURN_AXES: tuple[tuple[float, float, float], ...] = (
    (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0),
    (_S, -_S, 0.0), (_S, _S, 0.0), (_S, 0.0, -_S), (_S, 0.0, _S), (0.0, _S, -_S), (0.0, _S, _S))
#: Relative energy difference below which two equilibria count as equally low.
ENERGY_TIE = 1e-9
#: Height difference (m) below which two equilibria count as equally high.
HEIGHT_TIE = 1e-9
#: The turn of a start, just short of pi (log_se3 of a turn by exactly pi picks a branch).
_TURN = math.pi * (1.0 - 1e-9)


class InitialScrewWarning(UserWarning):
    """A config's ``initial_screw`` is not an unloaded equilibrium (the message names the
    residual |F|)."""


def _rotation(axis: ArrayLike, angle: float) -> FloatArray:
    """Rotation matrix by ``angle`` about the unit ``axis`` (Rodrigues)."""
    xi = np.zeros(6)
    xi[:3] = angle * np.asarray(axis, dtype=np.float64)
    return exp_se3(xi)[:3, :3]


def unloaded_starts(model: JointModel) -> FloatArray:
    """The documented starts (k, 6) of the unloaded solve (module docstring): the identity and
    a turn by pi about each of :data:`TURN_AXES`, each translated to the mean of the string
    vectors ``p1_a - R p2_b``."""
    p1 = model.link1_string_nodes
    p2 = model.link2_nodes[model.connections[:, 1]]
    starts = []
    for R in [np.eye(3)] + [_rotation(axis, _TURN) for axis in TURN_AXES]:
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = np.mean(p1 - p2 @ R.T, axis=0)
        starts.append(log_se3(T))
    return np.array(starts)


def unloaded_equilibrium(model: JointModel, rest_lengths: ArrayLike | None = None
                         ) -> EquilibriumResult:
    """The unloaded equilibrium of the documented rule (module docstring): the stable one of
    least energy (ties: highest link 2 along +z of {1}) over :func:`unloaded_starts`. When none
    is stable, the result of the first start with ``success=False`` and the reason."""
    found: list[EquilibriumResult] = []
    first: EquilibriumResult | None = None
    for start in unloaded_starts(model):
        result = solve_equilibrium(model, np.zeros(6), rest_lengths, start)
        first = first or result
        if result.success and result.stable:
            found.append(result)
    if not found:
        assert first is not None
        return EquilibriumResult(False, 'no stable unloaded equilibrium from the documented '
                                 f'starts (first start: {first.message})', first.screw,
                                 first.residual, first.iterations, first.energy, False,
                                 first.state)
    least = min(r.energy for r in found)
    ties = [r for r in found if r.energy <= least + ENERGY_TIE * max(abs(least), 1e-300)]
    heights = [exp_se3(r.screw)[2, 3] for r in ties]
    top = max(heights)
    return next(r for r, z in zip(ties, heights, strict=True) if z >= top - HEIGHT_TIE)


@dataclass(frozen=True)
class InitialScrewCheck:
    """Whether a screw is an unloaded equilibrium: ``residual`` |F| (inf when not admissible),
    ``equilibrium`` (the unloaded equilibrium a solve from it reaches, or None) and
    ``message`` (why not; '' when it is one)."""

    residual: float
    equilibrium: EquilibriumResult | None
    message: str

    @property
    def is_equilibrium(self) -> bool:
        """True when the residual is within :data:`INITIAL_SCREW_TOLERANCE`."""
        return self.residual <= INITIAL_SCREW_TOLERANCE


def check_initial_screw(model: JointModel, screw: ArrayLike, label: str = 'joint'
                        ) -> InitialScrewCheck:
    """Check a config's ``<label>.initial_screw``: its residual |F| and, when it is not an
    equilibrium, a message naming the residual and where a solve from it goes."""
    xi = np.asarray(screw, dtype=np.float64)
    try:
        residual = float(np.linalg.norm(model.evaluate(xi).wrench))
    except ValueError as exc:
        return InitialScrewCheck(math.inf, None, f'{label}.initial_screw is not admissible '
                                 f'({exc}); it is not an unloaded equilibrium')
    if residual <= INITIAL_SCREW_TOLERANCE:
        return InitialScrewCheck(residual, None, '')
    result = solve_equilibrium(model, np.zeros(6), initial_screw=xi)
    screw_text = '[' + ', '.join(f'{v:.15g}' for v in result.screw) + ']'
    where = (f'a solve from it reaches {screw_text}'
             + ('' if result.stable else ' (not stable)') if result.success
             else f'a solve from it fails: {result.message}')
    return InitialScrewCheck(residual, result, f'{label}.initial_screw is not an unloaded '
                             f'equilibrium: residual |F| = {residual:.3e} (N, N m) > '
                             f'{INITIAL_SCREW_TOLERANCE:g}; {where}')


def resolve_initial_screw(model: JointModel, given: ArrayLike | None, label: str = 'joint'
                          ) -> FloatArray:
    """The rule (module docstring) for a config's ``<label>.initial_screw``: ``given`` None (or
    empty) -> the solved unloaded equilibrium (ValueError when none is found); given -> itself,
    with an :class:`InitialScrewWarning` when it is not an equilibrium."""
    if given is None or np.size(given) == 0:
        result = unloaded_equilibrium(model)
        if not result.success:
            raise ValueError(f'{label}.initial_screw is missing and {result.message}: give it '
                             '(tensegrity-stiffness new-config / equilibrium --initial-screw)')
        return result.screw.copy()
    xi = np.asarray(given, dtype=np.float64).copy()
    check = check_initial_screw(model, xi, label)
    if not check.is_equilibrium:
        warnings.warn(check.message, InitialScrewWarning, stacklevel=3)
    return xi
