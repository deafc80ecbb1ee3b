"""The health of a joint configuration, as a node reports it in ``/diagnostics``: slack and
saturated strings, the margin to the chart limit ``|omega| = 2 pi``, the stability margin of
K_c and the conditioning of K."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from tensegrity_stiffness.geometry.screw import CHART_LIMIT
from tensegrity_stiffness.mechanics.equilibrium import STABILITY_TOLERANCE, stability_margin
from tensegrity_stiffness.mechanics.joint import JointState

#: A configuration closer than this to the chart limit (rad) is reported.
CHART_WARNING_MARGIN = 0.1


@dataclass(frozen=True)
class JointHealth:
    """``slack`` / ``saturated`` string names, ``chart_margin`` = 2 pi - |omega| (rad),
    ``stability_margin`` (:func:`equilibrium.stability_margin`), ``condition_number`` of K."""

    slack: list[str]
    saturated: list[str]
    chart_margin: float
    stability_margin: float
    condition_number: float

    @property
    def stable(self) -> bool:
        return self.stability_margin > STABILITY_TOLERANCE

    @property
    def problems(self) -> list[str]:
        """What a WARN level names (empty: all strings taut, stable, inside the chart)."""
        problems = []
        if self.slack:
            problems.append(f'{len(self.slack)} slack')
        if self.saturated:
            problems.append(f'{len(self.saturated)} saturated')
        if not self.stable:
            problems.append('not stable')
        if self.chart_margin < CHART_WARNING_MARGIN:
            problems.append('near the chart limit |omega| = 2 pi')
        return problems

    def values(self) -> list[tuple[str, Any]]:
        """``(key, value)`` pairs for a diagnostic status."""
        return [
            ('slack strings', self.slack or 'none'),
            ('saturated strings', self.saturated or 'none'),
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
