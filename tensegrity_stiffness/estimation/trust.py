"""Trust in an estimate (docs/estimation.md#trust): the chi-square consistency test
(:func:`consistency_threshold` at :data:`CONSISTENCY_PROBABILITY`) and the reading the others
contradict (:func:`suspect_reading`, normalised by :func:`wilson_hilferty`; at most
:data:`MAX_CONTRADICTED` left out, none when two are within :data:`AMBIGUITY`).
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
from numpy.typing import NDArray
from scipy.special import chdtri

FloatArray = NDArray[np.float64]

#: Probability of the consistency test (the one home of its default, read by the nodes'
#: ``estimation.consistency_probability``): an estimate is inconsistent when its chi2 exceeds
#: the ``1 - p`` quantile of chi-square(redundancy), which a set of sound readings does once in
#: ``1 / p`` estimates.
CONSISTENCY_PROBABILITY = 1e-3
#: Two suspects whose normalized residuals (Wilson-Hilferty z) are within this fraction of each
#: other cannot be told apart (with a redundancy of 1 every reading's is the same): none is left
#: out.
AMBIGUITY = 0.02
#: The most readings one estimate leaves out as contradicted. Left out only when the rest then
#: passes the chi-square test: a set that stays inconsistent after as many (the joint moving,
#: so that the static model fits no subset; a wrong model) keeps every reading and is reported
#: inconsistent, instead of a fit to whichever readings happened to agree.
MAX_CONTRADICTED = 2


def consistency_threshold(redundancy: int, probability: float = CONSISTENCY_PROBABILITY
                          ) -> float:
    """The chi2 above which an estimate with ``redundancy`` degrees of freedom is inconsistent
    (the ``1 - probability`` quantile of chi-square(redundancy)); inf without redundancy."""
    if redundancy <= 0:
        return math.inf
    if not 0.0 < probability < 1.0:
        raise ValueError(f'consistency_probability must be in (0, 1), got {probability}')
    return chi2_quantile(redundancy, probability)


@functools.lru_cache(maxsize=256)
def chi2_quantile(dof: int, probability: float) -> float:
    """The upper ``probability`` quantile of chi-square(dof) (a tracker asks for a few)."""
    return float(chdtri(dof, probability))


def wilson_hilferty(value: float, dof: int) -> float:
    """The standard normal quantile of a chi-square(dof) ``value`` (Wilson-Hilferty): readings
    of different degrees of freedom compared on one scale."""
    a = 2.0 / (9.0 * dof)
    return ((value / dof) ** (1.0 / 3.0) - (1.0 - a)) / math.sqrt(a)


def suspect_reading(r: FloatArray, J: FloatArray, C: FloatArray,
                    readings: Sequence[tuple[str, NDArray[np.intp], int]], redundancy: int
                    ) -> tuple[str, str] | None:
    """The reading the others contradict most, as robust estimators find it (Baarda's data
    snooping): for each reading's rows ``g`` of the whitened residual ``r`` (Jacobian ``J``,
    covariance ``C = (J^T J)^-1`` of the unknowns), ``r_g^T S_gg^+ r_g`` with
    ``S = I - J C J^T`` the residual's covariance, which is the drop of chi2 when the reading
    is left out (chi-square with its degrees of freedom for a sound reading). Returns (name, why)
    of the largest (Wilson-Hilferty z) among the readings that can be left out (no more degrees
    of freedom than ``redundancy``, checked by the others), or None when there is none or the
    two largest cannot be told apart (:data:`AMBIGUITY`)."""
    S = np.eye(r.size) - J @ C @ J.T
    scored: list[tuple[float, float, str]] = []
    for name, rows, dof in readings:
        if dof > redundancy:
            continue
        w, V = np.linalg.eigh(S[np.ix_(rows, rows)])
        checked = w > 1e-6
        if not checked.any():
            continue
        proj = V[:, checked].T @ r[rows]
        statistic = float(np.sum(proj * proj / w[checked]))
        k = min(dof, int(checked.sum()))
        scored.append((wilson_hilferty(statistic, k), statistic, name))
    if not scored:
        return None
    scored.sort(reverse=True)
    z, statistic, name = scored[0]
    if len(scored) > 1 and scored[1][0] >= z - AMBIGUITY * abs(z):
        return None
    return name, (f'contradicted by the others: leaving it out lowers chi2 by '
                  f'{statistic:.4g} (normalized residual z = {z:.3g})')
