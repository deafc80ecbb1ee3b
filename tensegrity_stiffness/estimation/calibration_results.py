"""What a calibration reports: its result (:class:`CalibrationResult`), the residual blocks and
their RMS by kind, the names of the fitted parameters and which of them the data identify
(:class:`Identifiability`, :func:`identifiability`).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.estimation.calibration_model import RANK_TOLERANCE
from tensegrity_stiffness.estimation.calibration_samples import (
    RESIDUAL_KINDS,
    CalibrationData,
    CalibrationNoise,
    measures_force,
)
from tensegrity_stiffness.mechanics.joint import JointModel

FloatArray = NDArray[np.float64]

#: Parameter kinds that :func:`calibrate_joint` can fit (``fit=``), in the order of the vector.
FIT_KINDS = ('stiffness', 'rest_length_offsets')
#: Name of parameter j of each kind (``parameters`` keys).
PARAMETER_NAMES = {'stiffness': 'stiffness[{j}]', 'rest_length_offsets': 'rest_length_offset[{j}]'}
#: Units of each kind (tables).
PARAMETER_UNITS = {'stiffness': 'N/m', 'rest_length_offsets': 'm'}


# ------------------------------------------------------------------------------ results
@dataclass
class CalibrationResult:
    """Outcome of :func:`calibrate_joint`.

    ``parameters`` maps a name (``stiffness[j]`` in N/m, ``rest_length_offset[j]`` in m, in the
    fitted kinds) to its value; unidentifiable ones hold their nominal value (0 for an offset).
    ``std`` the standard deviation of each (NaN where not identifiable), ``covariance`` over
    ``names`` (units as the values), ``identifiable`` per name, ``unidentifiable`` the directions
    the data cannot determine in words, ``singular_values`` of the weighted Jacobian (screws
    eliminated, scaled coordinates), ``residual_rms_before`` / ``residual_rms_after`` per
    measurement kind (its unit, :data:`RESIDUAL_UNITS`; before: nominal parameters with each
    screw fitted), ``outliers`` the sample indices left out, ``near_slack`` the (inlier) samples
    with a string within :data:`SLACK_MARGIN` std of slack at the first plain least-squares
    fit (kept; the strings not clearly slack held on their taut branch), ``screws`` (N, 6) the
    fitted screws,
    ``chi2`` and ``dof`` of the final fit (``chi2 / dof`` near 1 when the noise model is right).
    """

    success: bool
    message: str
    model: JointModel
    names: list[str]
    parameters: dict[str, float]
    std: dict[str, float]
    covariance: FloatArray
    identifiable: dict[str, bool]
    unidentifiable: list[str]
    singular_values: FloatArray
    residual_rms_before: dict[str, float]
    residual_rms_after: dict[str, float]
    outliers: list[int]
    iterations: int
    screws: FloatArray
    chi2: float
    dof: int
    nominal: dict[str, float] = field(default_factory=dict)
    offsets: FloatArray = field(default_factory=lambda: np.zeros(0))
    residuals_before: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    residuals_after: FloatArray = field(default_factory=lambda: np.zeros((0, 0)))
    seconds: float = 0.0
    near_slack: list[int] = field(default_factory=list)

    def residuals(self, kind: str, after: bool = True) -> FloatArray:
        """Residuals (N, m) of one measurement kind (:data:`RESIDUAL_KINDS`, its unit) of every
        sample, NaN where not measured; outliers included (``after``: at the estimate, else at
        nominal)."""
        table = self.residuals_after if after else self.residuals_before
        return table[:, residual_block(kind, self.model.n_strings)]

    def table(self) -> list[dict[str, Any]]:
        """Rows ``name, string, nominal, fitted, std, identifiable`` (units of the name)."""
        rows = []
        for name in self.names:
            j = int(re.search(r'\[(\d+)\]', name).group(1))
            rows.append({'name': name, 'string': self.model.string_names[j],
                         'nominal': self.nominal[name], 'fitted': self.parameters[name],
                         'std': self.std[name], 'identifiable': self.identifiable[name]})
        return rows


def residual_block(kind: str, n: int) -> slice:
    """Columns of one measurement kind in a sample's residual rows (pose 6, wrench 6,
    tensions n, lengths n)."""
    blocks = {'position': slice(0, 3), 'rotation': slice(3, 6), 'force': slice(6, 9),
              'moment': slice(9, 12), 'tension': slice(12, 12 + n), 'length': slice(12 + n, None)}
    if kind not in blocks:
        raise ValueError(f'unknown residual kind {kind!r} (known: {", ".join(RESIDUAL_KINDS)})')
    return blocks[kind]


def rms_by_kind(raw: FloatArray, mask: NDArray[np.bool_], n: int) -> dict[str, float]:
    """The RMS of the raw residuals ``raw`` (N, R) where ``mask`` holds, by residual kind (the
    kinds no sample measures are left out)."""
    out = {}
    for kind in RESIDUAL_KINDS:
        sl = residual_block(kind, n)
        m = mask[:, sl]
        if m.any():
            out[kind] = float(np.sqrt(np.mean(raw[:, sl][m] ** 2)))
    return out


def parameter_names(kinds: Sequence[str], n: int) -> list[str]:
    """The names of the fitted parameters of ``kinds`` for ``n`` strings, kind-major."""
    return [PARAMETER_NAMES[kind].format(j=j) for kind in kinds for j in range(n)]


def fit_columns(kinds: Sequence[str], n: int) -> NDArray[np.int64]:
    """The columns of the fitted ``kinds`` among all parameters (:data:`FIT_KINDS` x n)."""
    return np.concatenate([np.arange(n) + FIT_KINDS.index(kind) * n for kind in kinds])


def checked_fit_kinds(fit: Sequence[str] | str) -> tuple[str, ...]:
    """The kinds a calibration fits (in :data:`FIT_KINDS` order, aliases mapped); ValueError
    naming ``fit`` when one is unknown or none is given."""
    kinds = (fit,) if isinstance(fit, str) else tuple(fit)
    aliases = {'rest_length_offset': 'rest_length_offsets', 'offsets': 'rest_length_offsets'}
    kinds = tuple(aliases.get(k, k) for k in kinds)
    unknown = [k for k in kinds if k not in FIT_KINDS]
    if unknown or not kinds:
        raise ValueError(f'fit must name some of {FIT_KINDS}, got {list(fit)}')
    return tuple(k for k in FIT_KINDS if k in kinds)


@dataclass
class Identifiability:
    """The identifiable subspace of the scaled parameters: ``basis`` (P, q) orthonormal,
    ``null`` (P, P - q) its complement, the singular values, and words for each null
    direction."""

    basis: FloatArray
    null: FloatArray
    singular_values: FloatArray
    descriptions: list[str]
    zero_columns: NDArray[np.int64]


def identifiability(information: FloatArray, names: Sequence[str],
                    describe: Callable[[FloatArray], str] | None = None,
                    held: FloatArray | None = None) -> Identifiability:
    """Split the scaled parameter space into what the information ``S`` (P, P) determines and
    what it does not: parameters no measurement depends on (zero diagonal) first, each on its
    own, then the eigen-directions of the rest whose singular value ``sqrt(lambda)`` is below
    :data:`RANK_TOLERANCE` of the largest or below 1 (std above one scaled unit). ``held``
    (P, h) orthonormal: directions known to be unidentifiable (their information is removed)."""
    P = information.shape[0]
    if held is not None and held.shape[1]:
        project = np.eye(P) - held @ held.T
        information = project @ information @ project
    diag = np.diag(information)
    top = float(diag.max()) if P else 0.0
    zero = np.flatnonzero(diag <= (RANK_TOLERANCE ** 2) * max(top, 1e-300))
    rest = np.setdiff1d(np.arange(P), zero)
    null_vectors = [np.eye(P)[:, j] for j in zero]
    basis = []
    singular = []
    if rest.size:
        lam, V = np.linalg.eigh(information[np.ix_(rest, rest)])
        s = np.sqrt(np.maximum(lam, 0.0))
        cut = max(RANK_TOLERANCE * float(s.max()), 1.0)
        for value, vec in zip(s, V.T, strict=True):
            full = np.zeros(P)
            full[rest] = vec
            (basis if value > cut else null_vectors).append(full)
            singular.append(value)
    describe = describe or (lambda v: _combination_words(v, names))
    return Identifiability(
        np.array(basis).T.reshape(P, len(basis)),
        np.array(null_vectors).T.reshape(P, len(null_vectors)),
        np.sort(np.array(singular))[::-1], [describe(v) for v in null_vectors], zero)


def _combination_words(v: FloatArray, names: Sequence[str], limit: int = 6) -> str:
    order = np.argsort(-np.abs(v))
    big = [j for j in order[:limit] if abs(v[j]) >= 0.1 * abs(v[order[0]])]
    terms = ' '.join(f'{v[j]:+.2f} {names[j]}' for j in big)
    more = ' ...' if np.count_nonzero(np.abs(v) >= 0.1 * abs(v[order[0]])) > len(big) else ''
    return f'the combination {terms}{more} (scaled units)'


def describe_null_direction(v: FloatArray, names: Sequence[str], model: JointModel,
                            data: CalibrationData, kinds: Sequence[str], noise: CalibrationNoise
                            ) -> str:
    """Words for one unidentifiable direction ``v`` of the scaled parameters."""
    n = model.n_strings
    force = measures_force(data, noise)
    nz = np.flatnonzero(np.abs(v) > 1e-9)
    if nz.size == 1:
        name = names[nz[0]]
        j = int(re.search(r'\[(\d+)\]', name).group(1))
        what = (f"{name} (string {model.string_names[j]}): no measurement depends on it")
        if name.startswith('stiffness') or not force:
            if not np.isfinite(data.tensions[:, j]).any() and not data.has_wrench.any():
                what += ' (its tension is not measured and no sample has a known load)'
        return what
    if 'stiffness' in kinds:
        ks = v[:n] if kinds[0] == 'stiffness' else np.zeros(n)
        if np.linalg.norm(ks) > 0.99 * np.linalg.norm(v) and \
                abs(ks.sum()) > 0.99 * math.sqrt(n) * np.linalg.norm(ks):
            reason = ('no sample measures a force' if not force
                      else 'the forces measured do not fix it')
            return (f'the common scale of all stiffnesses: {reason} (a tension or a known '
                    'load); the ratios between them are fitted, the scale is held at nominal')
    return _combination_words(v, names)
