"""The health of a joint configuration, as a node reports it in ``/diagnostics``: slack and
saturated strings, the margin to the chart limit ``|omega| = 2 pi``, the stability margin of
K_c and the conditioning of K."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from tensegrity_stiffness.geometry.screw import CHART_LIMIT
from tensegrity_stiffness.mechanics.equilibrium import STABILITY_TOLERANCE, stability_margin
from tensegrity_stiffness.mechanics.joint import JointState

#: A configuration closer than this to the chart limit (rad) is reported.
CHART_WARNING_MARGIN = 0.1


@dataclass(frozen=True)
class StringHealth:
    """The shape of every node's health record: ``slack`` / ``saturated`` string names and the
    ``stability_margin``; stable above
    :data:`~tensegrity_stiffness.mechanics.equilibrium.STABILITY_TOLERANCE`. A subclass adds its
    own figures (:meth:`extra_problems`, :meth:`extra_values`) and whether the problems name the
    strings (``NAMES_IN_PROBLEMS``)."""

    slack: list[str]
    saturated: list[str]
    stability_margin: float

    #: Whether a problem lists the strings' names after their count.
    NAMES_IN_PROBLEMS = False

    @property
    def stable(self) -> bool:
        return self.stability_margin > STABILITY_TOLERANCE

    @property
    def problems(self) -> list[str]:
        """What a WARN level names (empty: all strings taut, stable, and no problem of the
        subclass)."""
        problems = []
        for kind, names in (('slack', self.slack), ('saturated', self.saturated)):
            if names:
                problems.append(f'{len(names)} {kind}' + (': ' + ' '.join(names)
                                                         if self.NAMES_IN_PROBLEMS else ''))
        if not self.stable:
            problems.append('not stable')
        return problems + self.extra_problems()

    def extra_problems(self) -> list[str]:
        """The subclass's own problems (none here)."""
        return []

    def values(self) -> list[tuple[str, Any]]:
        """``(key, value)`` pairs for a diagnostic status: the strings, then the subclass's."""
        return [('slack strings', self.slack or 'none'),
                ('saturated strings', self.saturated or 'none'), *self.extra_values()]

    def extra_values(self) -> list[tuple[str, Any]]:
        """The subclass's own ``(key, value)`` pairs."""
        return []


@dataclass(frozen=True)
class JointHealth(StringHealth):
    """:class:`StringHealth` of a joint with ``chart_margin`` = 2 pi - |omega| (rad),
    ``stability_margin`` (:func:`equilibrium.stability_margin`) and ``condition_number`` of
    K."""

    chart_margin: float = math.inf
    condition_number: float = math.nan

    def extra_problems(self) -> list[str]:
        return (['near the chart limit |omega| = 2 pi']
                if self.chart_margin < CHART_WARNING_MARGIN else [])

    def extra_values(self) -> list[tuple[str, Any]]:
        return [
            ('chart margin 2pi - |omega| [rad]', self.chart_margin),
            ('stability margin (min eig of scaled sym K_c)', self.stability_margin),
            ('condition number of K', self.condition_number),
        ]


def joint_health(state: JointState, string_names: list[str]) -> JointHealth:
    """The health of one evaluated configuration (``state`` of a single screw)."""
    names = np.array(string_names if len(string_names) == state.tensions.shape[0]
                     else [str(i) for i in range(state.tensions.shape[0])])
    theta = float(np.linalg.norm(state.screw[:3]))
    return JointHealth(
        slack=names[state.slack].tolist(), saturated=names[state.saturated].tolist(),
        chart_margin=CHART_LIMIT - theta,
        stability_margin=stability_margin(state.cartesian_stiffness),
        condition_number=float(np.linalg.cond(state.stiffness)))
