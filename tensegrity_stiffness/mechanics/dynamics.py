"""Dynamics in screw coordinates: mass matrix, equations of motion, linear model and modes.

The joint's link 2 (a spine's links 1..N) is a rigid body moved by its screw coordinates
``xi = [omega; v]`` (``T = exp(hat(xi))``, eq. 2 of Monke & Vikas); this module gives the
Euler-Lagrange equations in those coordinates, their linearisation (for LQR / MPC) and the
vibration modes. numpy / scipy only; time integration is the twin's (MuJoCo,
:mod:`~tensegrity_stiffness.simulation.twin`), which the tests use to prove these models.

Conventions (every twist here is in the ``[omega; v]`` order of the screws, every wrench in the
matching ``[m; f]`` order, unless it says ``[f; m]`` / ``[v; w]`` as the rest of the package)
------------------------------------------------------------------------------------------
* Body twist of link 2, in {2}: ``hat(V_b) = T^-1 dT/dt``, ``V_b = J_b(xi) xi_dot`` with
  ``J_b(xi) = J_r(xi) = J_l(-xi)`` (the SE(3) right Jacobian, from the closed-form left Jacobian
  of :class:`~tensegrity_stiffness.geometry.screw.ScrewKinematics`: exact at every angle, including
  ``|omega| -> 0`` (series branch) and near ``pi``).
* Spatial inertia about the origin of {2}, in {2}: ``G = [[I_c - m hat(c)^2, m hat(c)],
  [-m hat(c), m 1]]`` (``c`` the centre of mass, ``I_c`` the inertia about it).
* Mass matrix ``M(xi) = J_b^T G J_b``: the kinetic energy is ``1/2 xi_dot^T M xi_dot``.
* Equations of motion (Newton-Euler in {2}, mapped by ``J_b^T``, equivalent to Euler-Lagrange
  with the Christoffel symbols of ``M``)::

      M xi_ddot + J_b^T (G Jdot_b xi_dot - ad_{V_b}^T G V_b) = Q,
      Q = J_l^T Pi (F + W) - L^T C L xi_dot,

  ``F`` the strings' wrench (eq. 9, ``[f; m]`` in {1} about its origin), ``W`` the external
  wrench (the same convention, constant in {1}), ``Pi`` the swap of the 3-blocks, ``J_l`` the
  left Jacobian (``Pi J_l xi_dot`` is the spatial twist ``[v; w]`` in {1}, so ``J_l^T Pi F`` is
  the generalized force: its power is ``F . delta_dot``; this is why ``F`` is *not* a generalized
  force itself, and why ``dU/dxi = -J_l^T Pi F`` in docs/errata.md). ``L = dl/dxi`` (n, 6),
  ``L_j = -w_j^T Pi J_l`` with ``w_j = [u_j; p1_j x u_j]`` the unit wrench of string j
  (``u_j = s_j / l_j``), and ``C = diag(c_j)`` the string damping: a force ``-c_j dl_j/dt`` along
  every string, slack or taut, as MuJoCo's tendon damping. ``Jdot_b xi_dot`` comes from the
  second derivative of ``exp`` along ``xi + t xi_dot`` (the (1, 3) block of the exponential of
  a block-bidiagonal 12x12 matrix, exact to rounding at every angle).
* Linear model at a state with zero velocity, state ``[dxi; dxi_dot]``, inputs
  ``[d l0 (n); dW (6)]``: ``A = [[0, 1], [M^-1 dQ/dxi, -M^-1 L^T C L]]``,
  ``B = [[0, 0], [M^-1 J_l^T Pi dF/dl0, M^-1 J_l^T Pi]]``. At an equilibrium (``F + W = 0``)
  ``dQ/dxi = J_l^T Pi K`` with ``K`` the closed-form screw stiffness (eq. 10); elsewhere the
  derivatives of ``J_l`` and ``M`` add terms, computed from the mixed second derivatives of
  ``exp`` (21 block exponentials: about 1 ms, against about 40 us at an equilibrium).
* Modes: the eigenvalues ``lambda`` of ``A``, one per conjugate pair: undamped natural frequency
  ``|lambda| / 2 pi`` (Hz), damping ratio ``-Re lambda / |lambda|``; an overdamped pair of real
  eigenvalues ``l1, l2`` gives ``sqrt(l1 l2) / 2 pi`` and ``-(l1 + l2) / (2 sqrt(l1 l2))``.
* Spines: link i's body twist ``V_i = Ad_{X_i^-1} V_{i-1} + J_b(xi_i) xi_dot_i`` with
  ``X_i = O_{i-1} T_i`` (:mod:`~tensegrity_stiffness.mechanics.chain`); ``M = sum_i Jc_i^T G_i
  Jc_i`` over
  the links' body Jacobians ``Jc_i`` (6, 6N); the generalized force of joint i is
  ``J_l(xi_i)^T Pi r_i`` with ``r_i`` the chain's equilibrium residual (strings, tip wrench and
  link weights above joint i), so that ``dQ/dxi = diag(J_l^T Pi) dr/dxi`` at an equilibrium with
  the chain's closed-form residual Jacobian.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray
from scipy.linalg.lapack import dgeev

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.components import SCREW_NAMES
from tensegrity_stiffness.geometry.screw import (
    BLOCK_SWAP,
    ScrewKinematics,
    check_in_chart,
    hat3,
    single_screw,
    small_adjoint,
)
from tensegrity_stiffness.geometry.screw_jacobians import (  # noqa: F401 (body_jacobian: public here)
    body_jacobian,
    body_jacobian_rate,
    jacobian_derivatives,
)
from tensegrity_stiffness.geometry.transforms import (
    adjoint,
    adjoint_screw_order,
    inverse_transform,
)
from tensegrity_stiffness.geometry.validation import finite_array, optional_vector
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.plausibility import check_dynamics

FloatArray = NDArray[np.float64]
ComplexArray = NDArray[np.complex128]

#: Mass (kg) of a link whose config gives none: the twin's ``SimulationOptions.link_mass``.
DEFAULT_LINK_MASS = 0.01
#: Damping of every string along its length (N s/m) where a config gives none: the one value
#: of the config's ``dynamics.string_damping``, the nodes' parameter of that name and the
#: twin's tendon damping (``SimulationOptions.tendon_damping``), so that the modes predict the
#: ringing the twin shows. It settles the default joint (10 g links) in about 0.3 s, near
#: critical damping of its stiffest and softest modes.
DEFAULT_STRING_DAMPING = 0.5
#: Every key a config's ``dynamics`` section may hold: ``string_damping`` (read here) and the
#: nodes' ``enabled`` switch. Any other key is a mistake (``string_dampin: 0`` would leave the
#: damping at its default): refused with the nearest name.
DYNAMICS_SECTION_KEYS = ('enabled', 'string_damping')
#: Floor of the squared radius of gyration (m^2) in the default inertia (a link whose nodes all
#: sit at its centre of mass still gets a positive inertia).
MIN_GYRATION_SQUARED = 1e-8
#: Relative tolerance of the symmetry check of a 3x3 inertia.
SYMMETRY_TOLERANCE = 1e-9
#: A state counts as an equilibrium when ``|F + W|`` (N, N m) is at most this times the largest
#: string tension (plus 1e-300): the linear model then skips the derivatives of ``J`` and ``M``.
EQUILIBRIUM_TOLERANCE = 1e-9
#: An eigenvalue is real when ``|Im| <= REAL_TOLERANCE |lambda|``.
REAL_TOLERANCE = 1e-9
#: Labels of the screw coordinates and of the modes' frequencies (for messages and reports).
SCREW_LABELS = SCREW_NAMES

_EYE3 = np.eye(3)


# ---------------------------------------------------------------------------- inertia
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


def _config_damping(document: Any) -> Any:
    """``dynamics.string_damping`` of a config document (N s/m), :data:`DEFAULT_STRING_DAMPING`
    when absent; a key of ``dynamics`` outside :data:`DYNAMICS_SECTION_KEYS` is refused
    (ValueError) with the nearest name."""
    section = config.section(document, 'dynamics', required=False)
    config.check_keys(section, DYNAMICS_SECTION_KEYS, 'dynamics')
    value = section.get('string_damping')
    if value is None or (isinstance(value, Sequence) and not isinstance(value, str) and
                         len(value) == 0):
        return DEFAULT_STRING_DAMPING
    return value


# ---------------------------------------------------------------------------- modes
@dataclass(frozen=True, eq=False)
class JointModes:
    """Vibration modes of a linear model, ascending in frequency (``m`` = 6 for a joint, 6N for
    a spine).

    ``frequencies`` (m,) Hz: undamped natural frequencies; ``damping_ratios`` (m,);
    ``eigenvalues`` (m,) complex (1/s; the one with ``Im >= 0`` of each pair); ``shapes``
    (m, m) complex: row k the screw-coordinate part of mode k (unit norm, largest component
    real); ``twists`` (m, m): the same as spatial twists ``[dv; dw]`` in {1} (per joint in
    {1}_i for a spine), real part after that normalisation; ``stable``: every eigenvalue has
    ``Re < 0`` (damped), or, without damping, every squared frequency is positive;
    ``screw``: the state (6,) or (N, 6)."""

    frequencies: FloatArray
    damping_ratios: FloatArray
    eigenvalues: ComplexArray
    shapes: ComplexArray
    twists: FloatArray
    stable: bool
    screw: FloatArray

    @property
    def overdamped(self) -> NDArray[np.bool_]:
        """(m,) True for a mode of a pair of real eigenvalues (overdamped, or unstable with
        real growth): it does not oscillate, and its ``frequencies`` entry is
        ``sqrt(l1 l2) / 2 pi`` of the pair, not a frequency of vibration (issue #42)."""
        return np.asarray(self.eigenvalues).imag == 0.0


def _dgeev(A: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
    """LAPACK's ``dgeev`` of a real square ``A`` (through ``scipy.linalg.lapack``, the routine
    ``np.linalg.eig`` calls, without numpy's per-call wrapping, which costs as much as the
    decomposition at 6x6): the real and imaginary parts of the eigenvalues and the right
    eigenvectors in LAPACK's real storage (a complex pair, ``Im > 0`` first, as its real and
    imaginary parts in two columns). LinAlgError as numpy's for a matrix that is not finite or
    does not converge."""
    if not np.isfinite(A).all():
        raise np.linalg.LinAlgError('Array must not contain infs or NaNs')
    wr, wi, _, vr, info = dgeev(A, compute_vl=0)
    if info != 0:
        raise np.linalg.LinAlgError('Eigenvalues did not converge')
    return wr, wi, vr


def _eigenvectors(vr: FloatArray, wi: FloatArray, columns: NDArray[np.intp]) -> ComplexArray:
    """Columns ``columns`` of the complex eigenvector matrix ``np.linalg.eig`` returns, from
    :func:`_dgeev`'s real storage."""
    out = vr[:, columns].astype(complex)
    first, second = wi[columns] > 0.0, wi[columns] < 0.0
    if first.any():
        out[:, first] += 1j * vr[:, columns[first] + 1]
    if second.any():
        out[:, second] = vr[:, columns[second] - 1] - 1j * vr[:, columns[second]]
    return out


def _eig(A: FloatArray) -> tuple[NDArray[Any], NDArray[Any]]:
    """``np.linalg.eig(A)`` of a real square ``A`` from :func:`_dgeev`: the eigenvalues (real
    when every one is) and the right eigenvectors as columns (unit norm)."""
    wr, wi, vr = _dgeev(A)
    if not wi.any():
        return wr, vr
    return wr + 1j * wi, _eigenvectors(vr, wi, np.arange(wr.size))


def _modes(A: FloatArray, twist_map: FloatArray, screw: FloatArray, damped: bool) -> JointModes:
    n = A.shape[0] // 2
    wr, wi, vr = _dgeev(A)
    lam = wr + 1j * wi
    scale = np.abs(lam)
    real = np.abs(wi) <= REAL_TOLERANCE * np.maximum(scale, 1e-300)
    upper = np.flatnonzero(~real & (wi > 0.0))
    w = scale[upper]
    zeta = -wr[upper] / w
    chosen = lam[upper]
    # The first of each complex pair: its eigenvector is columns j + i (j + 1).
    shapes = (vr[:n, upper] + 1j * vr[:n, upper + 1]).T
    if upper.size < n:
        # Real eigenvalues: overdamped (or unstable) pairs, by ascending |lambda|.
        reals = np.flatnonzero(real)
        order = reals[np.argsort(scale[reals])]
        a, b = order[0::2], order[1::2]
        l1, l2 = wr[a], wr[b]
        wo = np.sqrt(np.abs(l1 * l2))
        with np.errstate(divide='ignore', invalid='ignore'):
            zr = np.where(wo > 0.0, -(l1 + l2) / (2.0 * wo), np.inf)
        w, zeta = np.r_[w, wo], np.r_[zeta, zr]
        chosen = np.r_[chosen, l1.astype(complex)]
        shapes = np.vstack([shapes, _eigenvectors(vr, wi, a)[:n].T])
    order = np.argsort(w, kind='stable')[:n]
    w, zeta, chosen, shapes = w[order], zeta[order], chosen[order], shapes[order]
    # Unit norm, largest component real and positive (one scaling of each row).
    size = np.abs(shapes)
    rows = np.arange(order.size)
    largest = size.argmax(axis=1)
    scaling = size[rows, largest] / (shapes[rows, largest] *
                                     np.sqrt(np.einsum('ij,ij->i', size, size)))
    shapes = shapes * scaling[:, None]
    if damped:
        # No eigenvalue grows beyond rounding, none is zero: a mode the strings' damping does
        # not reach (a ring joint's spin about its axis, whose strings keep their lengths to
        # first order) rings on, Re = 0 to rounding, and is not an instability.
        stable = bool(np.all(wr <= REAL_TOLERANCE * scale) and np.all(scale > 0.0))
    else:
        # Undamped: stable when every eigenvalue is +-i w with w > 0 (a constant wrench is not
        # conservative on SE(3), so a loaded joint can also flutter: Re > 0 in a complex pair).
        stable = bool(np.all(np.abs(wr) <= REAL_TOLERANCE * scale) and np.all(scale > 0.0))
    return JointModes(w / (2.0 * math.pi), zeta, chosen, shapes, (twist_map @ shapes.T).real.T,
                      stable, screw)


def state_matrix_modes(A: FloatArray, twist_map: FloatArray, state: FloatArray,
                       damped: bool) -> JointModes:
    """The modes of a linear model's state matrix ``A`` (2m, 2m) = ``[[0, I], [., .]]`` by
    the method of :meth:`JointDynamics.modes` (one per conjugate pair, ascending; an overdamped
    pair of real eigenvalues as one mode), ``twist_map`` (6k, m) taking the coordinates to
    twists, ``state`` stored as :attr:`JointModes.screw`: public for the structures' modes
    (:mod:`tensegrity_stiffness.structures.modes`)."""
    return _modes(A, twist_map, state, damped)


def _undamped_modes(A21: FloatArray, twist_map: FloatArray, screw: FloatArray) -> JointModes:
    """Modes without damping from the half-size problem: ``A`` has the eigenvalues
    ``+-sqrt(mu)`` with ``mu`` those of ``A21`` (same shapes), so a 6x6 (6N x 6N) eigenproblem
    replaces the 12x12 one. (Kept lean: this is the node's per-input path.)"""
    mu, vec = _eig(A21)
    lam = 1j * np.sqrt(-mu + 0j)  # the root with Im >= 0: i w for mu = -w^2
    w = np.abs(lam)
    order = np.argsort(w)
    lam, w = lam[order], w[order]
    shapes = vec.T[order]  # unit norm from LAPACK
    rows = np.arange(order.size)
    big = shapes[rows, np.abs(shapes).argmax(axis=1)]
    if np.isrealobj(mu):
        shapes = (shapes * np.sign(big)[:, None]).astype(complex)
        stable = bool(mu.max() < 0.0)
    else:
        shapes = shapes * (np.abs(big) / big)[:, None]
        stable = bool((np.abs(mu.imag) <= REAL_TOLERANCE * np.abs(mu)).all() and
                      mu.real.max() < 0.0)
    # + 0.0: a ratio of a conservative mode is 0, not -0 (-lam.real of Re lambda = 0).
    return JointModes(w / (2.0 * math.pi), -lam.real / w + 0.0, lam, shapes,
                      (twist_map @ shapes.T).real.T, stable, screw)


# ---------------------------------------------------------------------------- the joint
def _string_damping(value: ArrayLike, n: int, name: str = 'string_damping') -> FloatArray:
    c = finite_array(name, value)
    if c.ndim == 0:
        c = np.full(n, float(c))
    if c.shape != (n,):
        raise ValueError(f'{name} must be a scalar or {n} values (N s/m), got shape {c.shape}')
    if np.any(c < 0.0):
        raise ValueError(f'{name} must be >= 0 (N s/m), got {c.tolist()}')
    return c


class JointDynamics:
    """Euler-Lagrange dynamics of a joint's link 2 in screw coordinates (module docstring).

    ``model``: the :class:`~tensegrity_stiffness.mechanics.joint.JointModel`; ``inertia``: link 2's
    :class:`LinkInertia` (default: the twin's, ``LinkInertia()`` with the default inertia of
    ``model.link2_nodes``); ``string_damping``: N s/m, a scalar or one per string. The joint has
    no weights (the library's joint has none; the twin compensates gravity on its link 2).
    """

    def __init__(self, model: JointModel, inertia: LinkInertia | None = None,
                 string_damping: ArrayLike = 0.0) -> None:
        if not isinstance(model, JointModel):
            raise ValueError(f'model must be a JointModel, got {type(model).__name__}')
        if inertia is None:
            inertia = LinkInertia()
        if not isinstance(inertia, LinkInertia):
            raise ValueError(f'inertia must be a LinkInertia, got {type(inertia).__name__}')
        self.model = model
        self.inertia = inertia
        self._string_damping = _string_damping(string_damping, model.n_strings)
        self._string_damping.flags.writeable = False
        check_dynamics(model, inertia.mass, inertia.com, self._string_damping)
        self._damped = bool(np.any(self._string_damping > 0.0))
        self.spatial_inertia = inertia.spatial_inertia(model.link2_nodes)
        self._p1 = model.link1_nodes[model.connections[:, 0]]
        # Permuted link-1 nodes for p1 x u without np.cross (a hot path of modes).
        self._p1_yzx = np.ascontiguousarray(self._p1[:, [1, 2, 0]])
        self._p1_zxy = np.ascontiguousarray(self._p1[:, [2, 0, 1]])
        self._yzx = np.array([1, 2, 0])
        self._zxy = np.array([2, 0, 1])
        # The compiled linear model (tsk_joint_linear_model), None on the numpy path.
        self._kernel = model.compiled_kernel

    @classmethod
    def from_config(cls, document: Any, string_damping: ArrayLike | None = None
                    ) -> JointDynamics:
        """From a joint config document (``config/default_joint.yaml``): the ``joint``
        section's model and :meth:`LinkInertia.from_config`; ``string_damping`` (N s/m) default:
        ``dynamics.string_damping`` (scalar or one per string), else
        :data:`DEFAULT_STRING_DAMPING`."""
        section = config.section(document, 'joint')
        damping = _config_damping(document)  # the section's keys checked even when given
        if string_damping is None:
            string_damping = damping
        return cls(JointModel.from_dict(section), LinkInertia.from_config(section),
                   string_damping)

    @property
    def string_damping(self) -> FloatArray:
        """(n,) N s/m per string (read-only)."""
        return self._string_damping

    @property
    def damped(self) -> bool:
        """Whether any string has damping."""
        return self._damped

    # -- kinematics
    def _kinematics(self, xi: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(T, J_l, J_b) at ``xi``."""
        kin = ScrewKinematics(xi)
        Jb = adjoint_screw_order(inverse_transform(kin.T)) @ kin.J
        return kin.T, kin.J, Jb

    def mass_matrix(self, xi: ArrayLike) -> FloatArray:
        """``M(xi) = J_b^T G J_b`` (6, 6), symmetric positive definite: the kinetic energy of
        link 2 is ``1/2 xi_dot^T M xi_dot``."""
        Jb = ScrewKinematics(-single_screw(xi, 'xi')).J
        M = Jb.T @ self.spatial_inertia @ Jb
        return 0.5 * (M + M.T)

    def string_length_jacobian(self, xi: ArrayLike) -> FloatArray:
        """``L = dl/dxi`` (n, 6): ``L_j = -w_j^T Pi J_l``, ``w_j`` string j's unit wrench."""
        x = single_screw(xi, 'xi')
        state = self.model.evaluate(x)
        return self._length_jacobian(state.string_vectors, state.lengths,
                                     ScrewKinematics(x).J)

    def _unit_wrenches(self, s: FloatArray, lengths: FloatArray) -> FloatArray:
        """(n, 6) ``[p1_j x u_j, u_j]`` (``[m; f]``): each string's wrench per newton."""
        u = s / lengths[:, None]
        out = np.empty((u.shape[0], 6))
        out[:, :3] = self._p1_yzx * u[:, self._zxy] - self._p1_zxy * u[:, self._yzx]
        out[:, 3:] = u
        return out

    def _length_jacobian(self, s: FloatArray, lengths: FloatArray, Jl: FloatArray) -> FloatArray:
        return -self._unit_wrenches(s, lengths) @ Jl

    def _rest(self, rest_lengths: ArrayLike | None) -> FloatArray:
        return self.model.validate_rest_lengths(rest_lengths, batched=False)

    def coriolis(self, xi: ArrayLike, xi_dot: ArrayLike) -> FloatArray:
        """``J_b^T (G Jdot_b xi_dot - ad_{V_b}^T G V_b)`` (6,): the velocity-product terms of the
        Euler-Lagrange equations (``= dM/dt xi_dot - 1/2 d(xi_dot^T M xi_dot)/dxi``)."""
        x, r = single_screw(xi, 'xi'), optional_vector('xi_dot', xi_dot)
        Jb = ScrewKinematics(-x).J
        return self._coriolis(x, r, Jb)

    def _coriolis(self, x: FloatArray, r: FloatArray, Jb: FloatArray) -> FloatArray:
        if not np.any(r):
            return np.zeros(6)
        G = self.spatial_inertia
        V = Jb @ r
        a = body_jacobian_rate(x, r)
        return Jb.T @ (G @ a - small_adjoint(V).T @ (G @ V))

    def generalized_force(self, xi: ArrayLike, xi_dot: ArrayLike | None = None,
                          rest_lengths: ArrayLike | None = None,
                          external_wrench: ArrayLike | None = None) -> FloatArray:
        """``Q = J_l^T Pi (F + W) - L^T C L xi_dot`` (6,)."""
        x = single_screw(xi, 'xi')
        r = optional_vector('xi_dot', xi_dot)
        W = optional_vector('external_wrench', external_wrench)
        state = self.model.evaluate(x, self._rest(rest_lengths))
        Jl = ScrewKinematics(x).J
        return self._force(state, Jl, W, r)

    def _force(self, state: Any, Jl: FloatArray, W: FloatArray, r: FloatArray) -> FloatArray:
        Q = Jl.T @ (state.wrench + W)[BLOCK_SWAP]
        if self.damped and np.any(r):
            L = self._length_jacobian(state.string_vectors, state.lengths, Jl)
            Q -= L.T @ (self.string_damping * (L @ r))
        return Q

    def acceleration(self, xi: ArrayLike, xi_dot: ArrayLike,
                     rest_lengths: ArrayLike | None = None,
                     external_wrench: ArrayLike | None = None) -> FloatArray:
        """``xi_ddot`` (6,) from ``M xi_ddot + coriolis = Q`` (module docstring); the external
        wrench ``W`` on link 2 in {1} about its origin ``[f; m]``, constant in {1}."""
        x, r = single_screw(xi, 'xi'), optional_vector('xi_dot', xi_dot)
        W = optional_vector('external_wrench', external_wrench)
        state = self.model.evaluate(x, self._rest(rest_lengths))
        _, Jl, Jb = self._kinematics(x)
        M = Jb.T @ self.spatial_inertia @ Jb
        rhs = self._force(state, Jl, W, r) - self._coriolis(x, r, Jb)
        return np.linalg.solve(M, rhs)

    def _rest_derivative(self, state: Any, rest: FloatArray,
                         unit: FloatArray | None = None) -> FloatArray:
        """``Pi dF/dl0`` (6, n) ``[m; f]``: ``dt_j/dl0_j`` times the unit wrench of string j."""
        model = self.model
        slack, sat = state.slack, state.saturated
        taut = ~(slack | sat)
        if model.force_law == 'hooke':
            dt = np.where(taut, -model.k, 0.0)
        else:  # 'paper': k (l - l0) / l, constant k s / (l0 + s) past lmax (stretch s kept)
            lmax = rest + model.max_stretch
            with np.errstate(invalid='ignore'):  # inf / inf for strings without a limit
                dt = np.where(taut, -model.k / state.lengths,
                              np.where(sat, -model.k * model.max_stretch / lmax ** 2, 0.0))
        if unit is None:
            unit = self._unit_wrenches(state.string_vectors, state.lengths)
        return (unit * dt[:, None]).T

    def linearize(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None,
                  external_wrench: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        """``(A, B)`` of the linear model at ``xi`` with zero velocity: state ``[dxi; dxi_dot]``
        (12), inputs ``[d l0 (n); dW (6)]`` (module docstring). Exact at any ``xi``; at an
        equilibrium (:data:`EQUILIBRIUM_TOLERANCE`) without the derivatives of ``J`` and ``M``
        (they multiply ``F + W = 0``)."""
        x = single_screw(xi, 'xi')
        W = optional_vector('external_wrench', external_wrench)
        rest = self._rest(rest_lengths)
        blocks = self._blocks(x, rest, W, inputs=True)
        n = self.model.n_strings
        A = np.zeros((12, 12))
        A[:6, 6:] = np.eye(6)
        A[6:, :6] = blocks[0]
        A[6:, 6:] = blocks[1]
        B = np.zeros((12, n + 6))
        B[6:] = blocks[2]
        return A, B

    def _blocks(self, x: FloatArray, rest: FloatArray, W: FloatArray, inputs: bool
                ) -> tuple[FloatArray, FloatArray, FloatArray | None, FloatArray]:
        """``M^-1 dQ/dxi``, ``-M^-1 L^T C L``, ``M^-1 [dQ/dl0, dQ/dW]`` (or None) and ``J_l``:
        one linear solve for all of them; at an equilibrium in the compiled kernel when it is
        loaded (:meth:`_blocks_in_kernel`), else (and off equilibrium) here in numpy, the
        reference."""
        if self._kernel is not None:
            blocks = self._blocks_in_kernel(x, rest, W)
            if blocks is not None:
                return blocks[0], blocks[1], blocks[2] if inputs else None, blocks[3]
        state = self.model.evaluate(x, rest)
        Jl = ScrewKinematics(x).J
        Jb = ScrewKinematics(-x).J
        G = self.spatial_inertia
        M = Jb.T @ G @ Jb
        net = state.wrench + W
        JlT_Pi = Jl.T[:, BLOCK_SWAP]
        n = self.model.n_strings
        damped = self.damped
        unit = self._unit_wrenches(state.string_vectors, state.lengths) \
            if damped or inputs else None
        parts = [JlT_Pi @ state.stiffness]
        tol = EQUILIBRIUM_TOLERANCE * max(float(state.tensions.max(initial=0.0)), 1e-300)
        if float(abs(net).max()) > tol:
            dJl, dJb = jacobian_derivatives(x)
            acc = np.linalg.solve(M, JlT_Pi @ net)
            extra = np.empty((6, 6))
            for i in range(6):
                dM = dJb[i].T @ G @ Jb + Jb.T @ G @ dJb[i]
                extra[:, i] = dJl[i].T @ net[BLOCK_SWAP] - dM @ acc
            parts[0] = parts[0] + extra
        if damped:
            L = -unit @ Jl
            parts.append(-(L.T * self.string_damping) @ L)
        if inputs:
            parts.append(Jl.T @ self._rest_derivative(state, rest, unit))
            parts.append(JlT_Pi)
        solved = np.linalg.solve(M, parts[0] if len(parts) == 1 else
                                 np.concatenate(parts, axis=1))
        dxi = solved[:, :6]
        ddot = solved[:, 6:12] if damped else np.zeros((6, 6))
        k = 12 if damped else 6
        return dxi, ddot, (solved[:, k:k + n + 6] if inputs else None), Jl

    def _blocks_in_kernel(self, x: FloatArray, rest: FloatArray, W: FloatArray
                          ) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray] | None:
        """:meth:`_blocks` (with the inputs' block) in one call of ``tsk_joint_linear_model``
        (validated ``x``, ``rest``, ``W``): views into its buffer, or ``None`` off an equilibrium
        (the derivatives of ``J`` and ``M`` are numpy's) or when a string has zero length (the
        numpy path then raises the error that names it)."""
        kn = self._kernel
        # One buffer: the packed evaluation (inputs xi, rest lengths), then the linear model's
        # (input W); besides it C reads the inertia and the damping, bound to names here (they
        # outlive the call).
        buf = np.empty(kn.size + kn.linear_size)
        lin = kn.size
        buf[:kn.rest] = x
        buf[kn.rest:kn.transform] = rest
        buf[lin:lin + 6] = W
        start = kernel.address(buf)
        inertia = np.ascontiguousarray(self.spatial_inertia, dtype=np.float64)
        damping = np.ascontiguousarray(self._string_damping) if self._damped else None
        status = kn.linear_model(kn.model, kernel.address(inertia),
                                 None if damping is None else kernel.address(damping),
                                 EQUILIBRIUM_TOLERANCE, start, kn.size, start + 8 * lin,
                                 kn.linear_size)
        if status != kernel.OK:
            if status == kernel.ERROR_ZERO_LENGTH:
                return None
            kernel.check(status, 'tsk_joint_linear_model')
        if buf[lin + kn.linear_flag] == 0.0:
            return None
        solved = buf[lin + kn.linear_solved:lin + kn.linear_flag].reshape(6, kn.linear_width)
        Jl = buf[lin + kn.linear_jacobian:lin + kn.linear_mass].reshape(6, 6)
        return solved[:, :6], solved[:, 6:12], solved[:, 12:], Jl

    def modes(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None,
              external_wrench: ArrayLike | None = None) -> JointModes:
        """The 6 modes of :meth:`linearize` at ``xi`` (an equilibrium of ``rest_lengths`` and
        ``external_wrench``): see :class:`JointModes`; twists ``Pi J_l shape`` in {1}."""
        x = single_screw(xi, 'xi')
        W = optional_vector('external_wrench', external_wrench)
        A21, A22, _, Jl = self._blocks(x, self._rest(rest_lengths), W, inputs=False)
        if not self.damped:
            return _undamped_modes(A21, Jl[BLOCK_SWAP], x)
        A = np.zeros((12, 12))
        A[:6, 6:] = np.eye(6)
        A[6:, :6] = A21
        A[6:, 6:] = A22
        return _modes(A, Jl[BLOCK_SWAP], x, self.damped)

    def modes_at_pose(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None
                      ) -> tuple[JointModes, FloatArray]:
        """The modes of the joint held at ``xi`` by the load that balances it there,
        ``W = -F(xi)`` (every pose is the equilibrium of that load): what a node streaming
        measured poses can publish at the cost of an equilibrium (no derivatives of ``J`` and
        ``M``). Returns the modes and that wrench (6,) ``[f; m]`` in {1}."""
        x = single_screw(xi, 'xi')
        rest = self._rest(rest_lengths)
        W = -self.model.evaluate(x, rest).wrench
        return self.modes(x, rest, W), W

    def frequency_response(self, xi: ArrayLike, frequencies_hz: ArrayLike,
                           rest_lengths: ArrayLike | None = None,
                           external_wrench: ArrayLike | None = None) -> ComplexArray:
        """(F, 6, 6) complex compliance from a wrench ``dW`` ([f; m], {1}) to the spatial
        displacement twist ``[dv; dw]`` of link 2 in {1} at each frequency (Hz); at 0 Hz the
        inverse of ``K_c`` at an equilibrium."""
        x = single_screw(xi, 'xi')
        A, B = self.linearize(x, rest_lengths, external_wrench)
        Jl = ScrewKinematics(x).J
        C = np.zeros((6, 12))
        C[:, :6] = Jl[BLOCK_SWAP]
        return _frequency_response(A, B[:, -6:], C, frequencies_hz)


def _frequency_response(A: FloatArray, B: FloatArray, C: FloatArray, frequencies_hz: ArrayLike
                        ) -> ComplexArray:
    f = finite_array('frequencies_hz', frequencies_hz).ravel()
    if np.any(f < 0.0):
        raise ValueError('frequencies_hz must be >= 0')
    n = A.shape[0]
    out = np.empty((f.size,) + (C.shape[0], B.shape[1]), dtype=complex)
    for k, fk in enumerate(f):
        out[k] = C @ np.linalg.solve(2j * math.pi * fk * np.eye(n) - A, B)
    return out


# ---------------------------------------------------------------------------- spines
class ChainDynamics:
    """Dynamics of a spine (:class:`~tensegrity_stiffness.mechanics.chain.JointChain`) in its
    joints'
    screw coordinates (6N, joint-major).

    ``inertias``: one :class:`LinkInertia` per moving link (default: the twin's,
    :func:`twin_link_inertias`); ``string_damping``: N s/m, a scalar, one value per joint, or
    one array per joint. Weights are the chain's (``link_masses`` at ``link_coms`` under
    ``chain.gravity``), as in its statics and in the twin.
    """

    def __init__(self, chain: JointChain, inertias: Sequence[LinkInertia] | None = None,
                 string_damping: Any = 0.0) -> None:
        if not isinstance(chain, JointChain):
            raise ValueError(f'chain must be a JointChain, got {type(chain).__name__}')
        n = chain.n_joints
        if inertias is None:
            inertias = twin_link_inertias(chain)
        inertias = list(inertias)
        if len(inertias) != n or not all(isinstance(i, LinkInertia) for i in inertias):
            raise ValueError(f'inertias must be {n} LinkInertia (one per link)')
        self.chain = chain
        self.inertias = inertias
        if np.ndim(string_damping) == 0:
            per_joint = [string_damping] * n
        elif isinstance(string_damping, (Sequence, np.ndarray)):
            per_joint = list(string_damping)
        else:
            raise ValueError('string_damping must be a scalar or one entry per joint')
        if len(per_joint) != n:
            raise ValueError(f'string_damping must be a scalar, {n} values or {n} arrays')
        self.string_damping = [_string_damping(c, m.n_strings, f'string_damping[{i}]')
                               for i, (c, m) in enumerate(zip(per_joint, chain.joints,
                                                              strict=True))]
        self.joint_dynamics = [JointDynamics(m, li, c) for m, li, c in
                               zip(chain.joints, inertias, self.string_damping, strict=True)]
        self.spatial_inertias = np.array([jd.spatial_inertia for jd in self.joint_dynamics])

    @classmethod
    def from_config(cls, document: Any, string_damping: Any = None) -> ChainDynamics:
        """From a spine config document (``config/default_spine.yaml``): the chain,
        :func:`chain_inertias_from_config`, ``string_damping`` default ``dynamics.string_damping``
        (a scalar), else :data:`DEFAULT_STRING_DAMPING`."""
        damping = _config_damping(document)  # the section's keys checked even when given
        if string_damping is None:
            string_damping = damping
        return cls(JointChain.from_dict(document), chain_inertias_from_config(document),
                   string_damping)

    @property
    def n_joints(self) -> int:
        """N."""
        return self.chain.n_joints

    @property
    def damped(self) -> bool:
        """Whether any string has damping."""
        return any(jd.damped for jd in self.joint_dynamics)

    def _screws(self, screws: ArrayLike, name: str = 'screws') -> FloatArray:
        x = finite_array(name, screws)
        n = self.n_joints
        if x.shape == (6 * n,):
            x = x.reshape(n, 6)
        if x.shape != (n, 6):
            raise ValueError(f'{name} must have shape ({n}, 6), got {x.shape}')
        if name == 'screws':
            check_in_chart(x, name)
        return x

    def _frames(self, xi: FloatArray) -> tuple[list[ScrewKinematics], FloatArray]:
        """Per-joint kinematics and the relative transforms ``X_i = O_{i-1} T_i``."""
        kins = [ScrewKinematics(x) for x in xi]
        X = np.empty((self.n_joints, 4, 4))
        for i, kin in enumerate(kins):
            X[i] = kin.T if i == 0 else self.chain.link_offsets[i - 1] @ kin.T
        return kins, X

    def body_jacobians(self, screws: ArrayLike) -> FloatArray:
        """(N, 6, 6N): link i's body twist ``[w; v]`` in {2}_i per screw rate (joint-major)."""
        xi = self._screws(screws)
        kins, X = self._frames(xi)
        return self._body_jacobians(kins, X)

    def _body_jacobians(self, kins: list[ScrewKinematics], X: FloatArray) -> FloatArray:
        n = self.n_joints
        out = np.zeros((n, 6, 6 * n))
        for i, kin in enumerate(kins):
            Jb = adjoint_screw_order(inverse_transform(kin.T)) @ kin.J
            if i:
                out[i] = adjoint_screw_order(inverse_transform(X[i])) @ out[i - 1]
            out[i, :, 6 * i:6 * i + 6] = Jb
        return out

    def mass_matrix(self, screws: ArrayLike) -> FloatArray:
        """``M = sum_i Jc_i^T G_i Jc_i`` (6N, 6N), symmetric positive definite."""
        Jc = self.body_jacobians(screws)
        M = np.einsum('iak,iab,ibl->kl', Jc, self.spatial_inertias, Jc)
        return 0.5 * (M + M.T)

    def body_velocities(self, screws: ArrayLike, rates: ArrayLike, accelerations: ArrayLike
                        | None = None) -> tuple[FloatArray, FloatArray]:
        """Each link's body twist ``V_i`` and its rate ``V_dot_i`` ((N, 6) each, ``[w; v]`` in
        {2}_i) for screw rates and accelerations (N, 6) (recursion of the module docstring)."""
        xi = self._screws(screws)
        r = self._screws(rates, 'rates')
        a = np.zeros_like(r) if accelerations is None else self._screws(accelerations,
                                                                        'accelerations')
        kins, X = self._frames(xi)
        return self._velocities(xi, r, a, kins, X)

    def _velocities(self, xi: FloatArray, r: FloatArray, a: FloatArray,
                    kins: list[ScrewKinematics], X: FloatArray) -> tuple[FloatArray, FloatArray]:
        n = self.n_joints
        V = np.zeros((n, 6))
        Vd = np.zeros((n, 6))
        for i, kin in enumerate(kins):
            Jb = adjoint_screw_order(inverse_transform(kin.T)) @ kin.J
            rel = Jb @ r[i]
            Ad = adjoint_screw_order(inverse_transform(X[i]))
            prev_V = V[i - 1] if i else np.zeros(6)
            prev_A = Vd[i - 1] if i else np.zeros(6)
            V[i] = Ad @ prev_V + rel
            rate = body_jacobian_rate(xi[i], r[i]) if np.any(r[i]) else np.zeros(6)
            Vd[i] = Ad @ prev_A + small_adjoint(V[i]) @ rel + Jb @ a[i] + rate
        return V, Vd

    def generalized_force(self, screws: ArrayLike, rates: ArrayLike | None = None,
                          rest_lengths: Any = None, tip_wrench: ArrayLike | None = None
                          ) -> FloatArray:
        """``Q`` (6N,): ``J_l(xi_i)^T Pi r_i`` (strings, tip wrench, weights) minus the string
        damping ``L_i^T C_i L_i xi_dot_i`` of each joint."""
        xi = self._screws(screws)
        r = np.zeros_like(xi) if rates is None else self._screws(rates, 'rates')
        return self._force(xi, r, rest_lengths, optional_vector('tip_wrench', tip_wrench))

    def _force(self, xi: FloatArray, r: FloatArray, rest_lengths: Any, W: FloatArray
               ) -> FloatArray:
        res = self.chain.residuals(xi, W, None, rest_lengths)
        rest = _chain_rest(self.chain, rest_lengths)
        Q = np.empty(6 * self.n_joints)
        for i, jd in enumerate(self.joint_dynamics):
            Jl = ScrewKinematics(xi[i]).J
            q = Jl.T @ res[i][BLOCK_SWAP]
            if jd.damped and np.any(r[i]):
                state = jd.model.evaluate(xi[i], rest[i])
                L = jd._length_jacobian(state.string_vectors, state.lengths, Jl)
                q -= L.T @ (jd.string_damping * (L @ r[i]))
            Q[6 * i:6 * i + 6] = q
        return Q

    def acceleration(self, screws: ArrayLike, rates: ArrayLike, rest_lengths: Any = None,
                     tip_wrench: ArrayLike | None = None) -> FloatArray:
        """Screw accelerations (N, 6) from ``M xi_ddot + b(xi, xi_dot) = Q`` (``b`` by the
        recursive Newton-Euler pass with ``xi_ddot = 0``)."""
        xi = self._screws(screws)
        r = self._screws(rates, 'rates')
        W = optional_vector('tip_wrench', tip_wrench)
        kins, X = self._frames(xi)
        Jc = self._body_jacobians(kins, X)
        G = self.spatial_inertias
        M = np.einsum('iak,iab,ibl->kl', Jc, G, Jc)
        V, Vd = self._velocities(xi, r, np.zeros_like(r), kins, X)
        bias = np.zeros(6 * self.n_joints)
        for i in range(self.n_joints):
            bias += Jc[i].T @ (G[i] @ Vd[i] - small_adjoint(V[i]).T @ (G[i] @ V[i]))
        Q = self._force(xi, r, rest_lengths, W)
        return np.linalg.solve(M, Q - bias).reshape(self.n_joints, 6)

    def linearize(self, screws: ArrayLike, rest_lengths: Any = None,
                  tip_wrench: ArrayLike | None = None) -> tuple[FloatArray, FloatArray]:
        """``(A, B)`` at an equilibrium with zero velocity: state ``[dxi; dxi_dot]`` (12N),
        inputs ``[d l0 (every joint's strings, joint-major); dW (6, tip wrench)]``. ValueError
        if ``screws`` is not an equilibrium of the load (:data:`EQUILIBRIUM_TOLERANCE` relative
        to the largest tension): off equilibrium the derivatives of the links' Jacobians would
        enter, which this model does not have for spines."""
        xi = self._screws(screws)
        W = optional_vector('tip_wrench', tip_wrench)
        chain = self.chain
        n = self.n_joints
        rest = _chain_rest(chain, rest_lengths)
        res = chain.residuals(xi, W, None, rest_lengths)
        states = [jd.model.evaluate(xi[i], rest[i]) for i, jd in enumerate(self.joint_dynamics)]
        top = max(float(np.max(s.tensions, initial=0.0)) for s in states)
        if np.max(np.abs(res)) > EQUILIBRIUM_TOLERANCE * max(top, 1e-300):
            raise ValueError(f'screws: not an equilibrium of this load (largest residual '
                             f'{np.max(np.abs(res)):.3g}); solve_chain_equilibrium first')
        dr = chain.residual_jacobian(xi, W, None, rest_lengths)
        M = self.mass_matrix(xi)
        Minv = np.linalg.inv(M)
        JT = np.zeros((6 * n, 6 * n))
        Ad = _chain_adjoints(chain, xi)
        counts = [jd.model.n_strings for jd in self.joint_dynamics]
        starts = np.concatenate([[0], np.cumsum(counts)]).astype(int)
        m = int(starts[-1])
        dQdl = np.zeros((6 * n, m))
        dQdW = np.zeros((6 * n, 6))
        D = np.zeros((6 * n, 6 * n))
        for i, jd in enumerate(self.joint_dynamics):
            Jl = ScrewKinematics(xi[i]).J
            blk = slice(6 * i, 6 * i + 6)
            JT[blk, blk] = Jl.T[:, BLOCK_SWAP]
            dQdl[blk, starts[i]:starts[i + 1]] = Jl.T @ jd._rest_derivative(states[i], rest[i])
            dQdW[blk] = JT[blk, blk] @ Ad[i].T
            if jd.damped:
                L = jd._length_jacobian(states[i].string_vectors, states[i].lengths, Jl)
                D[blk, blk] = (L.T * jd.string_damping) @ L
        A = np.zeros((12 * n, 12 * n))
        A[:6 * n, 6 * n:] = np.eye(6 * n)
        A[6 * n:, :6 * n] = Minv @ JT @ dr
        A[6 * n:, 6 * n:] = -Minv @ D
        B = np.zeros((12 * n, m + 6))
        B[6 * n:, :m] = Minv @ dQdl
        B[6 * n:, m:] = Minv @ dQdW
        return A, B

    def modes(self, screws: ArrayLike, rest_lengths: Any = None,
              tip_wrench: ArrayLike | None = None) -> JointModes:
        """The 6N modes at an equilibrium (:class:`JointModes`; twists per joint in {1}_i)."""
        xi = self._screws(screws)
        A, _ = self.linearize(xi, rest_lengths, tip_wrench)
        twist = scipy.linalg.block_diag(*[ScrewKinematics(x).J[BLOCK_SWAP] for x in xi])
        if not self.damped:
            m = 6 * self.n_joints
            return _undamped_modes(A[m:, :m], twist, xi)
        return _modes(A, twist, xi, True)

    def tip_frequency_response(self, screws: ArrayLike, frequencies_hz: ArrayLike,
                               rest_lengths: Any = None, tip_wrench: ArrayLike | None = None
                               ) -> ComplexArray:
        """(F, 6, 6) complex: the tip's dynamic compliance, from a tip wrench ``dW`` ([f; m],
        base, about its origin) to the tool frame's spatial displacement twist ``[dv; dw]`` in
        the base, at each frequency (Hz). At 0 Hz it is the inverse of ``chain.tip_stiffness``."""
        xi = self._screws(screws)
        A, B = self.linearize(xi, rest_lengths, tip_wrench)
        n = self.n_joints
        C = np.zeros((6, 12 * n))
        C[:, :6 * n] = self.chain.jacobian(xi)
        return _frequency_response(A, B[:, -6:], C, frequencies_hz)


def _chain_rest(chain: JointChain, rest_lengths: Any) -> list[FloatArray]:
    n = chain.n_joints
    if rest_lengths is None:
        return [m.rest_lengths for m in chain.joints]
    if len(rest_lengths) != n:
        raise ValueError(f'rest_lengths must hold one entry per joint ({n}), got '
                         f'{len(rest_lengths)}')
    return [m.rest_lengths if r is None else m.validate_rest_lengths(r, batched=False)
            for m, r in zip(chain.joints, rest_lengths, strict=True)]


def _chain_adjoints(chain: JointChain, xi: FloatArray) -> FloatArray:
    """``Ad_{P_i}`` (N, 6, 6) of the joints' frames {1}_i in the base (twists [v; w])."""
    state = chain.evaluate(xi)
    return adjoint(state.joint_frames)


# ---------------------------------------------------------------------------- reports
def modes_report(modes: JointModes, inertias: Sequence[LinkInertia] | None = None,
                 string_damping: Any = None) -> dict[str, Any]:
    """Plain data of :class:`JointModes` (for ``--json`` and tables): frequencies (Hz), damping
    ratios, the shapes (real parts, screw coordinates) and twists, ``stable``, the state and the
    inertia parameters it was computed with."""
    out: dict[str, Any] = {
        'stable': modes.stable,
        'screw': np.asarray(modes.screw).tolist(),
        'modes': [{'index': k + 1, 'frequency_hz': float(modes.frequencies[k]),
                   'damping_ratio': float(modes.damping_ratios[k]),
                   'eigenvalue': [float(modes.eigenvalues[k].real),
                                  float(modes.eigenvalues[k].imag)],
                   'shape': modes.shapes[k].real.tolist(),
                   'twist': modes.twists[k].tolist()}
                  for k in range(len(modes.frequencies))],
    }
    if inertias is not None:
        out['inertias'] = [{'mass': li.mass, 'com': li.com.tolist(),
                            'inertia': None if li.inertia is None else li.inertia.tolist()}
                           for li in inertias]
    if string_damping is not None:
        out['string_damping'] = np.asarray(string_damping, dtype=float).tolist()
    return out


def format_modes(modes: JointModes) -> str:
    """A text table of the modes (frequency, damping ratio, dominant twist component)."""
    names = ('dv_x', 'dv_y', 'dv_z', 'dw_x', 'dw_y', 'dw_z')
    # Rounded first, + 0.0: a ratio of rounding noise (-1e-17) prints 0.0000, not -0.0000.
    ratios = np.round(modes.damping_ratios, 4) + 0.0
    lines = ['mode  frequency (Hz)  damping ratio  dominant twist component',
             *(f'{k + 1:4d}  {modes.frequencies[k]:14.4f}  {ratios[k]:13.4f}  '
               f'{_dominant(modes.twists[k], names)}' for k in range(len(modes.frequencies))),
             f'stable: {"yes" if modes.stable else "NO"}']
    return '\n'.join(lines)


def _dominant(twist: FloatArray, names: Sequence[str]) -> str:
    k = int(np.argmax(np.abs(twist)))
    prefix = '' if twist.size == 6 else f'joint {k // 6 + 1} '
    return prefix + names[k % 6]


def modes_from_config(config_path: Any = None, spine: bool = False,
                      string_damping: ArrayLike | None = None
                      ) -> tuple[JointDynamics | ChainDynamics, JointModes, dict[str, Any]]:
    """The dynamics of a config file's joint (``spine``: spine), its modes at the unloaded
    equilibrium and their :func:`modes_report`: what ``tensegrity-stiffness modes`` prints and
    draws. Default config: the packaged one; ``string_damping`` (N s/m) default: the config's
    ``dynamics.string_damping`` or 0. ValueError names a bad field."""
    from pathlib import Path

    from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG
    from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium

    name = DEFAULT_SPINE_CONFIG if spine else config.DEFAULT_JOINT_CONFIG
    path = Path(config_path) if config_path else config.packaged_config_path(name)
    document = config.load_yaml(path)
    if spine:
        from tensegrity_stiffness.mechanics.chain import solve_chain_equilibrium

        cd = ChainDynamics.from_config(document, string_damping)
        # The spine's rest pose carries its links' weights (chain.link_masses, chain.gravity):
        # the equilibrium under no tip load, started from each joint's unloaded screw.
        res = solve_chain_equilibrium(cd.chain, np.zeros(6),
                                      initial_screws=cd.chain.unloaded_screws())
        if not res.success:
            raise ValueError(f'config {path}: no equilibrium of the spine under its links\' '
                             f'weights ({res.message})')
        modes = cd.modes(res.screws)
        return cd, modes, modes_report(modes, cd.inertias, None)
    jd = JointDynamics.from_config(document, string_damping)
    res = solve_equilibrium(jd.model, np.zeros(6))
    if not res.success:
        raise ValueError(f'config {path}: no unloaded equilibrium ({res.message})')
    modes = jd.modes(res.screw)
    return jd, modes, modes_report(modes, [jd.inertia], jd.string_damping)
