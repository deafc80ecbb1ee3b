"""Mass properties of a moving link (a joint's link 2, a spine's links 1..N): its mass, centre
of mass and inertia, the twin's defaults, and its spatial inertia.

* Spatial inertia about the origin of {2}, in {2}: ``G = [[I_c - m hat(c)^2, m hat(c)],
  [-m hat(c), m 1]]`` (``c`` the centre of mass, ``I_c`` the inertia about it), twists
  ``[w; v]``: the kinetic energy of a body twist ``V_b`` is ``1/2 V_b^T G V_b``, and the mass
  matrix of the screw coordinates is ``M(xi) = J_b^T G J_b``
  (:mod:`~tensegrity_stiffness.mechanics.joint_dynamics`).
* The twin's default inertia (:func:`default_inertia_moments`): ``m r^2 / 2`` on each axis, ``r^2``
  the mean squared distance of the link's nodes from its centre of mass.

numpy only.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.screw import hat3
from tensegrity_stiffness.geometry.validation import finite_array
from tensegrity_stiffness.mechanics.chain import JointChain

FloatArray = NDArray[np.float64]

#: Mass (kg) of a link whose config gives none: the twin's ``SimulationOptions.link_mass``.
DEFAULT_LINK_MASS = 0.01
#: Floor of the squared radius of gyration (m^2) in the default inertia (a link whose nodes all
#: sit at its centre of mass still gets a positive inertia).
MIN_GYRATION_SQUARED = 1e-8
#: Relative tolerance of the symmetry check of a 3x3 inertia.
SYMMETRY_TOLERANCE = 1e-9

_EYE3 = np.eye(3)


def default_inertia_moments(nodes: ArrayLike, mass: float, com: ArrayLike = (0.0, 0.0, 0.0)
                            ) -> FloatArray:
    """The twin's default principal moments (3,) kg m^2: ``m r^2 / 2`` on each axis, ``r^2`` the
    mean squared distance of the link's nodes from its centre of mass (at least
    :data:`MIN_GYRATION_SQUARED`). The one home of that default."""
    p = finite_array('nodes', nodes)
    if p.ndim != 2 or p.shape[1] != 3 or p.shape[0] == 0:
        raise ValueError(f'nodes must have shape (n, 3), got {p.shape}')
    c = finite_array('com', com)
    r2 = float(np.mean(np.sum((p - c) ** 2, axis=1)))
    return np.full(3, float(mass) * max(r2, MIN_GYRATION_SQUARED) / 2.0)


@dataclass(frozen=True, eq=False)
class LinkInertia:
    """Mass properties of a moving link: ``mass`` (kg, > 0), ``com`` (3,) the centre of mass in
    the link's frame {2} (m), ``inertia`` the 3x3 inertia about the centre of mass in {2}'s axes
    (kg m^2, symmetric positive definite), or three principal moments, or ``None``: the twin's
    default (:func:`default_inertia_moments` of the link's nodes, resolved by the dynamics that
    know the nodes)."""

    mass: float = DEFAULT_LINK_MASS
    com: Any = (0.0, 0.0, 0.0)
    inertia: Any = None

    def __post_init__(self) -> None:
        m = self.mass
        if isinstance(m, bool) or not isinstance(m, (int, float, np.floating, np.integer)) or \
                not math.isfinite(float(m)) or float(m) <= 0.0:
            raise ValueError(f'mass must be a finite number > 0 (kg), got {m!r}')
        object.__setattr__(self, 'mass', float(m))
        c = finite_array('com', self.com).ravel()
        if c.shape != (3,):
            raise ValueError(f'com must be 3 values (m, in {{2}}), got {c.size}')
        object.__setattr__(self, 'com', c)
        if self.inertia is not None:
            object.__setattr__(self, 'inertia', _inertia_matrix(self.inertia))

    @classmethod
    def from_config(cls, section: Mapping[str, Any]) -> LinkInertia:
        """From a ``joint`` config section: ``link2_mass`` (kg, default
        :data:`DEFAULT_LINK_MASS`), ``link2_com`` ([x y z] in {2}, default the origin),
        ``link2_inertia`` (3 principal moments or 9 values row-major, kg m^2; empty or missing:
        the twin's default). Errors name the key."""
        def get(key: str) -> Any:
            value = section.get(key)
            return None if value is None or (isinstance(value, Sequence) and not isinstance(
                value, str) and len(value) == 0) else value

        kwargs: dict[str, Any] = {}
        for key, field_name in (('link2_mass', 'mass'), ('link2_com', 'com'),
                                ('link2_inertia', 'inertia')):
            value = get(key)
            if value is not None:
                kwargs[field_name] = value
        try:
            return cls(**kwargs)
        except ValueError as exc:
            raise ValueError(f'joint.link2_{exc}') from None

    def inertia_matrix(self, nodes: ArrayLike) -> FloatArray:
        """The 3x3 inertia about the centre of mass; ``nodes`` (the link's node set in {2})
        gives the default when ``inertia`` is None."""
        if self.inertia is not None:
            return self.inertia.copy()
        return np.diag(default_inertia_moments(nodes, self.mass, self.com))

    def spatial_inertia(self, nodes: ArrayLike) -> FloatArray:
        """``G`` (6, 6) about the origin of {2}, in {2}, twists ``[w; v]``."""
        m, c = self.mass, self.com
        hc = hat3(c)
        G = np.empty((6, 6))
        G[:3, :3] = self.inertia_matrix(nodes) - m * hc @ hc
        G[:3, 3:] = m * hc
        G[3:, :3] = -m * hc
        G[3:, 3:] = m * _EYE3
        return G


def _inertia_matrix(value: ArrayLike) -> FloatArray:
    arr = finite_array('inertia', value)
    if arr.size == 3:
        arr = np.diag(arr.ravel())
    elif arr.size == 9:
        arr = arr.reshape(3, 3)
    else:
        raise ValueError(f'inertia must be 3 principal moments or a 3x3 matrix, got '
                         f'{arr.size} values')
    scale = float(np.max(np.abs(arr)))
    if not np.allclose(arr, arr.T, rtol=0.0, atol=SYMMETRY_TOLERANCE * scale):
        raise ValueError('inertia must be symmetric')
    eig = np.linalg.eigvalsh(0.5 * (arr + arr.T))
    if eig[0] <= 0.0:
        raise ValueError(f'inertia must be positive definite, got eigenvalues {eig.tolist()}')
    return 0.5 * (arr + arr.T)


def twin_link_inertias(chain: JointChain, link_mass: float = DEFAULT_LINK_MASS,
                       link_inertia: ArrayLike | None = None) -> list[LinkInertia]:
    """The twin's links of a spine: a link with a mass in the chain config has that mass at its
    ``link_coms`` entry; every other link ``link_mass`` at its origin; inertia ``link_inertia``
    (3 principal moments) or the default of the link's nodes."""
    out = []
    for i in range(chain.n_joints):
        m = float(chain.link_masses[i])
        weighted = m > 0.0
        out.append(LinkInertia(m if weighted else link_mass,
                               chain.link_coms[i] if weighted else np.zeros(3), link_inertia))
    return out


def chain_inertias_from_config(document: Any) -> list[LinkInertia]:
    """Per-link inertias of a spine document: ``chain.link_masses`` / ``chain.link_coms`` (the
    existing keys: a link without a mass gets :data:`DEFAULT_LINK_MASS` at its origin, as the
    twin) and ``chain.link_inertias`` (3 principal moments or 9 values per link, or one set for
    all; empty: the twin's default)."""
    chain = JointChain.from_dict(document)
    section = config.section(document, 'chain')
    return chain_link_inertias(chain, section.get('link_inertias') or [])


def chain_link_inertias(chain: JointChain, link_inertias: ArrayLike) -> list[LinkInertia]:
    """Per-link inertias of ``chain``: its masses and centres of mass (the twin's rule,
    :func:`twin_link_inertias`) with the inertias of ``link_inertias`` (the value of
    ``chain.link_inertias``: 3 or 9 values per link, or one set for all; empty: the twin's
    default); errors name the key."""
    raw = finite_array('chain.link_inertias', link_inertias).ravel()
    n = chain.n_joints
    inertias = twin_link_inertias(chain)
    if raw.size == 0:
        return inertias
    for width in (3, 9):
        if raw.size == width:
            raw = np.tile(raw, n)
            break
    if raw.size not in (3 * n, 9 * n):
        raise ValueError(f'chain.link_inertias must have 3 or 9 values per link ({3 * n} or '
                         f'{9 * n}), or 3 or 9 for all, got {raw.size}')
    width = raw.size // n
    try:
        return [LinkInertia(li.mass, li.com, raw[width * i:width * (i + 1)])
                for i, li in enumerate(inertias)]
    except ValueError as exc:
        raise ValueError(f'chain.link_inertias: {exc}') from None
