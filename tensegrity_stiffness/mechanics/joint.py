"""Six-DOF tensegrity joint: string forces, wrench and analytical stiffness (Monke & Vikas).

Model (eqs. 6-11, with the corrections of ``docs/errata.md``)
---------------------------------------------------------
Two rigid links carry nodes ``p1`` (in {1}) and ``p2`` (in {2}). String j joins link-1 node
``a_j`` to link-2 node ``b_j``; with ``T = exp(hat(xi))`` (maps {2} into {1}):

* ``s_j = p1_{a_j} - T p2_{b_j}`` (eq. 7), ``l_j = |s_j|``, unit vector ``u_j = s_j / l_j``.
* tension ``phi_j`` (N): 0 when ``l <= l0`` (slack); ``k (l - l0)`` when taut;
  ``k (lmax - l0)`` when ``l >= lmax`` (saturated) -- Hooke's law, the default.
  With ``force_law='paper'`` (the authors' published code, which is what eq. 11 differentiates)
  the tension is ``k (l - l0) / l`` when taut and ``k (lmax - l0) / lmax`` when saturated.
* force on link 2: ``f_j = phi_j u_j``; wrench on link 2 in {1} about the origin of {1},
  ``F = sum_j [f_j; p1_{a_j} x f_j]`` (eq. 9, summed once).
* ``K = dF/dxi`` (eq. 10), rows ``[fx fy fz mx my mz]``, columns ``[wx wy wz vx vy vz]``.
  ``df/ds = (phi' - phi/l) u u^T + (phi/l) I`` for every region (Hooke taut:
  ``k (1 - l0/l) I + k l0/l^3 s s^T``; saturated: ``(phi/l)(I - u u^T)``; slack: 0).
* ``K_c = -dF/d(delta)``, ``delta = [dv; dw]`` a spatial twist in {1} applied as
  ``T -> exp(hat(delta)) T``; rows ``[f; m]``, columns ``[linear; angular]`` (ROS order). At an
  unloaded equilibrium ``K_c`` is symmetric and it is positive definite exactly when the
  equilibrium is stable. ``K = -K_c P J(xi)`` with ``P`` the swap of the two 3-blocks and ``J`` the
  SE(3) left Jacobian in [omega; v] order.

Implementation: with ``A_j = df/ds`` and ``q_j = T p2_{b_j}``, ``ds_j/dxi = [hat(q_j) G - Q, -G]``
(``G``, ``Q`` from :class:`~tensegrity_stiffness.geometry.screw.ScrewKinematics`), so that both
matrices
follow from two 6x3 sums ``H_D = sum [I; hat(p1_j)] A_j`` and ``H_G = sum [I; hat(p1_j)] A_j
hat(q_j)``: ``K = [H_G G - H_D Q, -H_D G]`` and ``K_c = [H_D, -H_G]``. Two implementations of
exactly this computation: the compiled kernel (:mod:`~tensegrity_stiffness.mechanics.kernel`, used
when it
is built) and :meth:`JointModel._evaluate_numpy`, written step by step in numpy for one screw or
a batch (the fallback and the reference the tests hold the kernel to, 1e-13).
"""

from __future__ import annotations

import copy
import functools
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.errors import BadRestLengthsError
from tensegrity_stiffness.geometry.screw import (
    CHART_LIMIT,
    ScrewKinematics,
    as_screws,
    exp_se3,
    hat3,
)
from tensegrity_stiffness.geometry.validation import finite_array, per_string
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.unloaded import resolve_initial_screw

FloatArray = NDArray[np.float64]

FORCE_LAWS = ('hooke', 'paper')
#: The most strings a joint may have: the joints of the tensegrity literature have 6 to a few
#: dozen; past this a config is a mistake (and an evaluation's time and memory grow with it).
MAX_STRINGS = 1000
#: The keys of a config's ``joint`` section that :meth:`JointModel.from_dict` reads.
JOINT_KEYS = ('node_names', 'link1_nodes', 'link2_nodes', 'link2_node_names', 'string_names',
              'string_link1_nodes', 'string_link2_nodes', 'stiffness', 'rest_lengths',
              'max_lengths', 'force_law', 'initial_screw')
#: Every key a ``joint`` section may hold: :data:`JOINT_KEYS`, link 2's inertia (read by
#: :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia`) and the encoders' offsets (read
#: by the nodes and the calibration). Any other key is a mistake (a typo would otherwise leave
#: a value out and compute another joint's stiffness): refused with the nearest name.
JOINT_SECTION_KEYS = JOINT_KEYS + ('link2_mass', 'link2_com', 'link2_inertia',
                                   'rest_length_offsets')
#: Strings shorter than this (m) have no defined direction: evaluation raises ValueError (its
#: home is the kernel's module, whose constants the compiled kernel is built with).
MIN_STRING_LENGTH = kernel.MIN_STRING_LENGTH
#: Screws per chunk of the numpy evaluation of a batch (bounds its temporaries to a few MB).
BATCH_CHUNK = 1024
#: Default central-difference step of :meth:`JointModel.numerical_stiffness` (eq. 21).
NUMERICAL_STEP = 1e-6


def string_forces(lengths: FloatArray, rest: FloatArray, k: FloatArray,
                  max_stretch: FloatArray, force_law: str
                  ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
    """The strings' force law (eq. 8, corrected; module docstring), the one home of it for the
    joint and the structures (:mod:`tensegrity_stiffness.structures`): tension phi (N),
    d phi / d l (N/m), slack and saturated masks of strings of ``lengths`` with rest lengths
    ``rest``, stiffness ``k`` and maximum stretch ``max_stretch`` (inf: none) under
    ``force_law`` (one of :data:`FORCE_LAWS`)."""
    lmax = rest + max_stretch
    slack = lengths <= rest
    saturated = lengths >= lmax
    taut = ~(slack | saturated)
    clipped = np.minimum(np.maximum(lengths, rest), lmax)
    if force_law == 'hooke':
        phi = k * (clipped - rest)
        dphi = k * taut
    else:  # 'paper': tension k (l - l0) / l, constant beyond lmax
        phi = k * (clipped - rest) / clipped
        dphi = (k * rest / (clipped * clipped)) * taut
    return phi, dphi, slack, saturated


@dataclass(slots=True)
class JointState:
    """Everything the joint model computes at one screw (or a batch, leading axis N).

    Shapes for one screw (batched: prefix ``N``): ``screw`` (6,), ``transform`` (4, 4),
    ``string_vectors`` (n, 3) = s_j in {1} (m), ``lengths`` (n,) m, ``tensions`` (n,) N,
    ``slack`` / ``saturated`` (n,) bool, ``wrench`` (6,) [N; N m], ``stiffness`` (6, 6) K,
    ``cartesian_stiffness`` (6, 6) K_c.
    """

    screw: FloatArray
    transform: FloatArray
    string_vectors: FloatArray
    lengths: FloatArray
    tensions: FloatArray
    slack: NDArray[np.bool_]
    saturated: NDArray[np.bool_]
    wrench: FloatArray
    stiffness: FloatArray
    cartesian_stiffness: FloatArray


_EYE3 = np.eye(3)


def _kernel_state(kn: kernel.JointKernel, xi: FloatArray, buf: FloatArray) -> JointState:
    """The :class:`JointState` of a packed buffer the kernel evaluated (views into it)."""
    n = kn.n
    flags = buf[kn.flags:kn.size].view(np.bool_)
    return JointState(xi, buf[kn.transform:kn.strings].reshape(4, 4),
                      buf[kn.strings:kn.lengths].reshape(n, 3), buf[kn.lengths:kn.tensions],
                      buf[kn.tensions:kn.wrench], flags[:n], flags[n:2 * n],
                      buf[kn.wrench:kn.stiffness], buf[kn.stiffness:kn.cartesian].reshape(6, 6),
                      buf[kn.cartesian:kn.flags].reshape(6, 6))


def _packed_input(kn: kernel.JointKernel, xi: FloatArray, rest: FloatArray,
                  extra: int = 0) -> FloatArray:
    """The packed buffer of one screw and its rest lengths (``extra`` more values after it for
    C to write): the inputs are copied into it, nothing else is for C to read."""
    buf = np.empty(kn.size + extra)
    buf[:kn.rest] = xi
    buf[kn.rest:kn.transform] = rest
    return buf


def _zero_length(status: int, function: str) -> bool:
    """For a kernel ``status`` other than ``kernel.OK``: True when a string has zero length
    (the numpy path then raises the error that names it); any other failure raises
    (:func:`kernel.check`)."""
    if status == kernel.ERROR_ZERO_LENGTH:
        return True
    kernel.check(status, function)
    return False


def _check_single_screw(xi: FloatArray) -> None:
    """ValueError naming a non-finite entry of one screw (6,) (a finite sum may overflow: then
    no error); OverflowError for a finite screw whose angle overflows (as the array path)."""
    values = xi.tolist()
    if not math.isfinite(sum(values)):
        as_screws(xi)
    math.sqrt(values[0] ** 2 + values[1] ** 2 + values[2] ** 2)


def _config_value(section: Mapping[str, Any], key: str, default: Any = None) -> Any:
    """``section[key]`` (None counts as missing), else ``default``; without a default a missing
    key is a ValueError naming ``joint.<key>``."""
    if key in section and section[key] is not None:
        return section[key]
    if default is None:
        raise ValueError(f'joint.{key} is missing')
    return default


def _config_points(key: str, value: Any) -> FloatArray:
    """The (k, 3) points of the flat xyz list ``joint.<key>``."""
    arr = finite_array(f'joint.{key}', value).ravel()
    if arr.size == 0 or arr.size % 3:
        raise ValueError(f'joint.{key} must be a flat list of x, y, z triples, '
                         f'got {arr.size} values')
    return arr.reshape(-1, 3)


def _config_nodes(section: Mapping[str, Any]
                  ) -> tuple[FloatArray, list[str], FloatArray | None, list[str]]:
    """Link 1's nodes and names, link 2's (None: the same points) and names of a ``joint``
    config section (names default to the indices, link 2's to link 1's when it has its
    points)."""
    p1 = _config_points('link1_nodes', _config_value(section, 'link1_nodes'))
    names1 = [str(x) for x in _config_value(section, 'node_names', [])] or [
        str(i) for i in range(p1.shape[0])]
    if len(names1) != p1.shape[0]:
        raise ValueError(f'joint.node_names has {len(names1)} names for {p1.shape[0]} nodes')
    _refuse_duplicates('joint.node_names', names1)
    raw2 = _config_value(section, 'link2_nodes', [])
    p2 = _config_points('link2_nodes', raw2) if len(raw2) else None
    names2 = [str(x) for x in _config_value(section, 'link2_node_names', [])]
    if p2 is None:
        names2 = names2 or names1
        n2 = p1.shape[0]
    else:
        names2 = names2 or [str(i) for i in range(p2.shape[0])]
        n2 = p2.shape[0]
    if len(names2) != n2:
        raise ValueError(f'joint.link2_node_names has {len(names2)} names for {n2} nodes')
    if p2 is not None:
        _refuse_duplicates('joint.link2_node_names', names2)
    return p1, names1, p2, names2


def _config_connections(section: Mapping[str, Any], names1: list[str], names2: list[str]
                        ) -> NDArray[np.int_]:
    """The strings' (n, 2) node indices on link 1 and link 2 from ``string_link1_nodes`` and
    ``string_link2_nodes`` (node names): their count judged against :data:`MAX_STRINGS` first,
    then each name looked up once (a hostile file of many strings costs its length, and its
    error names the first few)."""
    ends1 = [str(x) for x in _config_value(section, 'string_link1_nodes')]
    ends2 = [str(x) for x in _config_value(section, 'string_link2_nodes')]
    if len(ends1) != len(ends2) or not ends1:
        raise ValueError('joint.string_link1_nodes and joint.string_link2_nodes must be '
                         f'non-empty and of equal length, got {len(ends1)} and {len(ends2)}')
    if len(ends1) > MAX_STRINGS:
        raise ValueError(f'joint.string_link1_nodes: {len(ends1)} strings, more than the '
                         f'{MAX_STRINGS} a joint may have (MAX_STRINGS)')
    index1 = {name: i for i, name in enumerate(names1)}
    index2 = {name: i for i, name in enumerate(names2)}
    unknown = sorted({a for a in ends1 if a not in index1} | {b for b in ends2 if b not in index2})
    if unknown:
        raise ValueError('joint.string_link1_nodes / string_link2_nodes name unknown nodes '
                         f'{few_names(unknown)}')
    return np.array([[index1[a], index2[b]] for a, b in zip(ends1, ends2, strict=True)])


#: How many names an error lists before it only counts the rest (:func:`few_names`).
NAMES_SHOWN = 5


def few_names(names: Sequence[str]) -> str:
    """``names`` for an error: all of them up to :data:`NAMES_SHOWN`, else the first few and
    the count (a hostile file's error stays a line), each name cut to 40 characters."""
    shown = [repr(name if len(name) <= 40 else name[:37] + '...')
             for name in names[:NAMES_SHOWN]]
    more = f' and {len(names) - NAMES_SHOWN} more ({len(names)} in all)' if (
        len(names) > NAMES_SHOWN) else ''
    return f'[{", ".join(shown)}]{more}'


def _config_per_string(key: str, value: Any, n: int, allow_empty: bool = False
                       ) -> FloatArray | None:
    """``n`` values of ``key`` (one for all is repeated; the constructor checks the values);
    None for an empty one when ``allow_empty``."""
    if allow_empty and np.size(value) == 0:
        return None
    return per_string(f'joint.{key}', value, n, repeat_one=True, finite=False)


def _refuse_duplicates(key: str, names: Sequence[str]) -> None:
    """ValueError naming the names given more than once in ``key``."""
    seen: set[str] = set()
    repeated = sorted({name for name in names if name in seen or seen.add(name)})
    if repeated:
        raise ValueError(f'{key} must be unique, got {few_names(repeated)} more than once')


def _unique(names: list[str]) -> list[str]:
    """``names`` with the second and later copies of a name numbered (``a``, ``a#2``, ...)."""
    seen: dict[str, int] = {}
    out = []
    for name in names:
        seen[name] = seen.get(name, 0) + 1
        out.append(name if seen[name] == 1 else f'{name}#{seen[name]}')
    return out


def _names(node_names: Sequence[str] | None, link2_node_names: Sequence[str] | None,
           string_names: Sequence[str] | None, n1: int, n2: int | None,
           connections: NDArray[np.intp]) -> tuple[list[str], list[str], list[str]]:
    """The node names of link 1 (default the indices), of link 2 (default link 1's when it has
    link 1's points, ``n2`` None, else the indices) and the string names (default
    ``<node>-<node>``, a repeated pair numbered ``<node>-<node>#2`` ...); names given must be
    unique."""
    names1 = list(node_names) if node_names is not None else [str(i) for i in range(n1)]
    names2 = list(link2_node_names) if link2_node_names is not None else (
        names1 if n2 is None else [str(i) for i in range(n2)])
    strings = list(string_names) if string_names is not None else _unique([
        f'{names1[a]}-{names2[b]}' for a, b in connections])
    if len(strings) != len(connections):
        raise ValueError(f'string_names must have {len(connections)} entries, got '
                         f'{len(strings)}')
    for key, names in (('node_names', node_names), ('link2_node_names', link2_node_names),
                       ('string_names', string_names)):
        if names is not None:
            _refuse_duplicates(key, [str(name) for name in names])
    return names1, names2, strings


class JointModel:
    """A six-DOF tensegrity joint: node sets, strings and their elastic law.

    Parameters
    ----------
    link1_nodes : (n1, 3) node coordinates of link 1 in {1}, metres.
    connections : (n, 2) int, string j joins ``link1_nodes[connections[j, 0]]`` to
        ``link2_nodes[connections[j, 1]]``.
    stiffness : (n,) or scalar, N/m, > 0.
    rest_lengths : (n,) m, > 0.
    link2_nodes : (n2, 3) in {2}; ``None`` uses ``link1_nodes`` (the paper's setting).
    max_lengths : (n,) m, > rest length; ``None`` or ``inf`` for no limit. When rest lengths are
        overridden at evaluation, each string keeps its maximum *stretch* ``lmax - l0``.
    force_law : ``'hooke'`` (default) or ``'paper'`` (the authors' code, see module docstring).
    node_names, link2_node_names, string_names : labels (optional).
    initial_screw : (6,) default starting point of equilibrium solves (e.g. the unloaded
        equilibrium); zeros when omitted here (a config reader, :meth:`from_dict`, solves it
        instead: :mod:`~tensegrity_stiffness.mechanics.unloaded`).
    use_kernel : evaluate with the compiled kernel (:mod:`~tensegrity_stiffness.mechanics.kernel`)
    when it
        is available (default); ``False`` keeps the numpy implementation, its reference.
    """

    def __init__(
        self,
        link1_nodes: ArrayLike,
        connections: ArrayLike,
        stiffness: ArrayLike,
        rest_lengths: ArrayLike,
        link2_nodes: ArrayLike | None = None,
        max_lengths: ArrayLike | None = None,
        force_law: str = 'hooke',
        node_names: Sequence[str] | None = None,
        link2_node_names: Sequence[str] | None = None,
        string_names: Sequence[str] | None = None,
        initial_screw: ArrayLike | None = None,
        use_kernel: bool = True,
    ) -> None:
        p1 = finite_array('link1_nodes', link1_nodes)
        if p1.ndim != 2 or p1.shape[1] != 3 or p1.shape[0] == 0:
            raise ValueError(f'link1_nodes must have shape (n1, 3) with n1 >= 1, got {p1.shape}')
        p2 = p1 if link2_nodes is None else finite_array('link2_nodes', link2_nodes)
        if p2.ndim != 2 or p2.shape[1] != 3 or p2.shape[0] == 0:
            raise ValueError(f'link2_nodes must have shape (n2, 3) with n2 >= 1, got {p2.shape}')
        conn = np.asarray(connections)
        if conn.ndim != 2 or conn.shape[1] != 2 or conn.shape[0] == 0:
            raise ValueError(f'connections must have shape (n, 2) with n >= 1, got {conn.shape}')
        if not np.issubdtype(conn.dtype, np.integer):
            raise ValueError(f'connections must be integer node indices, got dtype {conn.dtype}')
        n = conn.shape[0]
        if n > MAX_STRINGS:
            raise ValueError(f'connections: {n} strings, more than the {MAX_STRINGS} a joint may '
                             'have (MAX_STRINGS)')
        if conn[:, 0].min() < 0 or conn[:, 0].max() >= p1.shape[0]:
            raise ValueError(f'connections[:, 0] must index link1_nodes (0..{p1.shape[0] - 1})')
        if conn[:, 1].min() < 0 or conn[:, 1].max() >= p2.shape[0]:
            raise ValueError(f'connections[:, 1] must index link2_nodes (0..{p2.shape[0] - 1})')
        k = np.broadcast_to(finite_array('stiffness', stiffness), (n,)).copy()
        if np.any(k <= 0.0):
            raise ValueError(f'stiffness must be > 0 for every string, got {k}')
        if force_law not in FORCE_LAWS:
            raise ValueError(f'force_law must be one of {FORCE_LAWS}, got {force_law!r}')
        self.link1_nodes = p1
        self.link2_nodes = p2
        self.connections = conn.astype(np.intp)
        self.k = k
        self.force_law = force_law
        self._set_rest_lengths(rest_lengths, max_lengths)
        self.node_names, self.link2_node_names, self.string_names = _names(
            node_names, link2_node_names, string_names, p1.shape[0],
            None if link2_nodes is None else p2.shape[0], self.connections)
        x0 = np.zeros(6) if initial_screw is None else as_screws(initial_screw, 'initial_screw')
        if x0.shape != (6,) or np.linalg.norm(x0[:3]) >= CHART_LIMIT:
            raise ValueError('initial_screw must have 6 values with |omega| < 2 pi')
        self.initial_screw = x0
        # Per-string node coordinates, gathered once.
        self._p1 = p1[self.connections[:, 0]]
        self._p2 = p2[self.connections[:, 1]]

        # Z_j = [I; hat(p1_j)] (n, 6, 3): the wrench of a force f_j at p1_j is Z_j f_j.
        self._Z = np.concatenate([np.broadcast_to(_EYE3, (n, 3, 3)), hat3(self._p1)], axis=1)
        self._kernel = self._joint_kernel() if use_kernel else None

    def _set_rest_lengths(self, rest_lengths: ArrayLike, max_lengths: ArrayLike | None) -> None:
        """``rest_lengths``, ``max_lengths`` (None: no limit) and ``max_stretch``, validated
        (the strings' count is the model's)."""
        n = self.n_strings
        self.rest_lengths = np.ascontiguousarray(
            self.validate_rest_lengths(rest_lengths, batched=False))
        if max_lengths is None:
            lmax = np.full(n, np.inf)
        else:
            lmax = np.broadcast_to(np.asarray(max_lengths, dtype=np.float64), (n,)).copy()
            if np.any(np.isnan(lmax)):
                raise ValueError('max_lengths must not be NaN (use inf for no limit)')
            if np.any(lmax <= self.rest_lengths):
                bad = np.flatnonzero(lmax <= self.rest_lengths)
                raise ValueError(f'max_lengths must exceed rest_lengths (strings {bad.tolist()})')
        self.max_lengths = lmax
        self.max_stretch = lmax - self.rest_lengths

    def _joint_kernel(self) -> kernel.JointKernel | None:
        """The compiled kernel's handle of this model's constants (None without the library)."""
        return kernel.joint_kernel(self._p1, self._p2, self.k, self.max_stretch,
                                   FORCE_LAWS.index(self.force_law), MIN_STRING_LENGTH)

    @property
    def compiled_kernel(self) -> kernel.JointKernel | None:
        """The compiled kernel's handle of this model (its buffer offsets and calls), None on
        the numpy path."""
        return self._kernel

    @property
    def link1_string_nodes(self) -> FloatArray:
        """(n, 3) the link-1 node of each string in {1} (config order): the moment arm of its
        force (eq. 9)."""
        return self._p1

    @property
    def uses_kernel(self) -> bool:
        """True when evaluations run in the compiled kernel."""
        return self._kernel is not None

    # ------------------------------------------------------------------ construction
    @property
    def n_strings(self) -> int:
        """Number of strings."""
        return self.connections.shape[0]

    @classmethod
    def from_dict(cls, section: Mapping[str, Any], strict: bool = True) -> JointModel:
        """Build from the ``joint`` section of a config (see ``config/default_joint.yaml``).

        Keys: ``node_names`` (list), ``link1_nodes`` (flat xyz list, m), ``link2_nodes`` (flat,
        empty = same as link 1), ``link2_node_names`` (empty = same), ``string_names``,
        ``string_link1_nodes`` / ``string_link2_nodes`` (node names), ``stiffness`` (N/m, one per
        string or one for all), ``rest_lengths`` (m), ``max_lengths`` (m, empty = no limit),
        ``force_law``, ``initial_screw`` (the unloaded equilibrium: solved when missing, a
        :class:`~tensegrity_stiffness.mechanics.unloaded.InitialScrewWarning` when it is not
        one; :func:`~tensegrity_stiffness.mechanics.unloaded.resolve_initial_screw`). Errors
        name the offending key. A key outside :data:`JOINT_SECTION_KEYS` is refused with the
        nearest name (``strict=False``: warned about and ignored, for a file shared with other
        tools).
        """
        config.check_keys(section, JOINT_SECTION_KEYS, 'joint', strict)
        p1, names1, p2, names2 = _config_nodes(section)
        conn = _config_connections(section, names1, names2)
        n = len(conn)
        get = functools.partial(_config_value, section)
        raw_x0 = np.asarray(get('initial_screw', []), dtype=np.float64).ravel()
        stiffness = _config_per_string('stiffness', get('stiffness'), n)
        rest = _config_per_string('rest_lengths', get('rest_lengths'), n)
        max_lengths = _config_per_string('max_lengths', get('max_lengths', []), n,
                                         allow_empty=True)
        force_law = str(get('force_law', 'hooke'))
        string_names = [str(x) for x in get('string_names', [])] or None
        # The values are checked once, by the constructor; its errors name the argument, which
        # is the config key.
        try:
            model = cls(p1, conn, stiffness, rest, link2_nodes=p2, max_lengths=max_lengths,
                        force_law=force_law, node_names=names1, link2_node_names=names2,
                        string_names=string_names,
                        initial_screw=raw_x0 if raw_x0.size else None)
        except ValueError as exc:
            raise ValueError(f'joint.{exc}') from None
        # The one rule for a missing or non-equilibrium initial_screw (mechanics.unloaded).
        model.initial_screw = resolve_initial_screw(model, raw_x0 if raw_x0.size else None)
        return model

    @classmethod
    def from_yaml(cls, path: str | Path) -> JointModel:
        """Load from a YAML file: a ROS parameter file (``<node>: ros__parameters: joint:``)
        or a plain file with a top-level ``joint`` mapping."""
        return cls.from_dict(config.load_section(path, 'joint'))

    def with_rest_lengths(self, rest_lengths: ArrayLike) -> JointModel:
        """A copy with new rest lengths (the maximum stretch of each string is kept): the
        same rest lengths, maximum lengths, stretches and kernel as a model built anew from
        this one's arguments, sharing this one's geometry, stiffnesses and names (validated
        when it was built and never changed in place): 45 us instead of the 86 us of building
        one (a node takes rest-length commands at 500 Hz)."""
        rest = self.validate_rest_lengths(rest_lengths, batched=False)
        model = copy.copy(self)
        model._set_rest_lengths(rest, rest + self.max_stretch)
        model._kernel = model._joint_kernel() if self.uses_kernel else None
        return model

    # ------------------------------------------------------------------ validation
    def validate_rest_lengths(self, rest_lengths: ArrayLike | None, batched: bool = True
                              ) -> FloatArray:
        """Rest lengths as float array (n,) (or (N, n) when ``batched``): finite, > 0;
        :class:`~tensegrity_stiffness.geometry.errors.BadRestLengthsError` (a ValueError)
        otherwise."""
        if rest_lengths is None:
            return self.rest_lengths
        try:
            arr = finite_array('rest_lengths', rest_lengths)
        except ValueError as exc:
            raise BadRestLengthsError(str(exc)) from None
        n = self.n_strings
        if not (arr.shape == (n,) or (batched and arr.ndim == 2 and arr.shape[1] == n)):
            raise BadRestLengthsError(f'rest_lengths must have shape ({n},)'
                             + (f' or (N, {n})' if batched else '') + f', got {arr.shape}')
        if np.any(arr <= 0.0):
            raise BadRestLengthsError(f'rest_lengths must be > 0, got minimum {arr.min()}')
        return arr

    # ------------------------------------------------------------------ core evaluation
    def string_forces(self, lengths: FloatArray, rest: FloatArray
                       ) -> tuple[FloatArray, FloatArray, NDArray[np.bool_], NDArray[np.bool_]]:
        """Tension phi (N), d phi / d l (N/m), slack and saturated masks (eq. 8, corrected):
        :func:`string_forces` with this model's strings."""
        return string_forces(lengths, rest, self.k, self.max_stretch, self.force_law)

    def evaluate(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None) -> JointState:
        """All quantities at screw ``xi`` (6,) or a batch (N, 6); rest lengths (n,) or (N, n)."""
        arr = np.asarray(xi, dtype=np.float64)
        if arr.shape == (6,) and (rest_lengths is None or rest_lengths is self.rest_lengths):
            return self._evaluate_single(arr, self.rest_lengths, True)
        xi = as_screws(arr)
        rest = self.validate_rest_lengths(rest_lengths)
        if rest.ndim == 2 and (xi.ndim != 2 or xi.shape[0] != rest.shape[0]):
            raise ValueError(f'batched rest_lengths {rest.shape} need screws of shape '
                             f'({rest.shape[0]}, 6), got {xi.shape}')
        if xi.ndim == 2:
            return self._evaluate_batch(xi, rest)
        return self._evaluate_single(xi, rest, True)

    def _evaluate_single(self, xi: FloatArray, rest: FloatArray, full: bool
                         ) -> JointState | FloatArray:
        """One screw (6,) with validated rest lengths (n,): the :class:`JointState`, or ``K``
        alone when not ``full``; in the compiled kernel when it is loaded."""
        _check_single_screw(xi)
        if self._kernel is not None:
            result = self._evaluate_single_kernel(xi, rest, full)
            if result is not None:
                return result
        state = self._evaluate_numpy(xi, rest)
        return state if full else state.stiffness

    def _evaluate_single_kernel(self, xi: FloatArray, rest: FloatArray, full: bool
                                ) -> JointState | FloatArray | None:
        """:meth:`_evaluate_single` in the compiled kernel (``tsk_joint_evaluate_packed``):
        ``None`` when a string has zero length (the numpy path then raises the error that
        names it)."""
        kn = self._kernel
        buf = _packed_input(kn, xi, rest)
        status = kn.evaluate_packed(kn.model, kernel.MODE_FULL if full else kernel.MODE_STIFFNESS,
                                    kernel.address(buf), kn.size)
        if status != kernel.OK and _zero_length(status, 'tsk_joint_evaluate_packed'):
            return None
        if not full:
            return buf[kn.stiffness:kn.cartesian].reshape(6, 6)
        return _kernel_state(kn, xi, buf)

    def measure_in_kernel(self, xi: FloatArray, rest: FloatArray
                               ) -> tuple[JointState, FloatArray] | None:
        """The :class:`JointState` of one screw (6,) with validated rest lengths (n,) and the
        string measurements' Jacobians (the kernel's measurement buffer, ``JointKernel.
        measure_*`` offsets) in one call of ``tsk_joint_measure_packed``: the compiled twin of
        :func:`~tensegrity_stiffness.estimation.sensor_models.string_predictions_unchecked`.
        ``None``
        without the kernel or when a string has zero length (the numpy path then raises the
        error that names it)."""
        kn = self._kernel
        if kn is None:
            return None
        _check_single_screw(xi)
        # One buffer: the packed evaluation, then the measurement block (both written by C).
        buf = _packed_input(kn, xi, rest, kn.measure_size)
        start = kernel.address(buf)
        status = kn.measure_packed(kn.model, kernel.MODE_FULL, start, kn.size,
                                   start + 8 * kn.size, kn.measure_size)
        if status != kernel.OK and _zero_length(status, 'tsk_joint_measure_packed'):
            return None
        return _kernel_state(kn, xi, buf), buf[kn.size:]

    def _check_lengths(self, lengths: FloatArray) -> None:
        if lengths.min(initial=math.inf) < MIN_STRING_LENGTH:
            bad = np.unique(np.nonzero(lengths < MIN_STRING_LENGTH)[-1]).tolist()
            raise ValueError(f'strings {bad} have zero length at this screw')

    def _evaluate_batch(self, xi: FloatArray, rest: FloatArray, wrench_only: bool = False
                        ) -> JointState:
        """(N, 6) screws with validated rest lengths (n,) or (N, n). With ``wrench_only`` the
        stiffness matrices are left out (they are NaN): the honest baseline of
        :meth:`numerical_stiffness`. With the compiled kernel the whole batch is one call."""
        if self._kernel is not None:
            state = self._evaluate_batch_kernel(xi, rest, wrench_only)
            if state is not None:
                return state
        if xi.shape[0] <= BATCH_CHUNK:
            return self._evaluate_numpy(xi, rest, wrench_only)
        chunks = [self._evaluate_numpy(xi[i:i + BATCH_CHUNK],
                                       rest if rest.ndim == 1 else rest[i:i + BATCH_CHUNK],
                                       wrench_only)
                  for i in range(0, xi.shape[0], BATCH_CHUNK)]
        return JointState(*(np.concatenate([getattr(c, f.name) for c in chunks])
                            for f in fields(JointState)))

    def _evaluate_numpy(self, xi: FloatArray, rest: FloatArray, wrench_only: bool = False
                        ) -> JointState:
        """The model's equations step by step for one screw (6,) or a batch (N, 6) (leading
        axes ``...``): the numpy implementation, fallback of the kernel and its reference."""
        kin = ScrewKinematics(xi)
        # eq. 7: q_j = T p2_j (link-2 ends in {1}), s_j = p1_j - q_j, l_j = |s_j|.
        q = self._p2 @ np.swapaxes(kin.R, -1, -2) + kin.t[..., None, :]  # (..., n, 3)
        s = self._p1 - q
        l2 = np.sum(s * s, axis=-1)
        lengths = np.sqrt(l2)
        self._check_lengths(lengths)
        # eq. 8: tensions phi_j, their derivatives phi'_j and the regions.
        phi, dphi, slack, saturated = self.string_forces(lengths, rest)
        # eq. 9: f_j = phi_j s_j / l_j, F = sum_j [f_j; p1_j x f_j] = sum_j Z_j f_j.
        beta = phi / lengths
        f = beta[..., None] * s
        wrench = np.sum(self._Z @ f[..., None], axis=-3)[..., 0]
        if wrench_only:
            nan = np.full(xi.shape[:-1] + (6, 6), np.nan)
            return JointState(xi, kin.T, s, lengths, phi, slack, saturated, wrench, nan,
                              nan.copy())
        # eq. 10: A_j = df/ds = gamma_j s_j s_j^T + beta_j I, gamma = (phi' - beta) / l^2;
        # H_D = sum_j Z_j A_j, H_G = sum_j Z_j A_j hat(q_j).
        gamma = (dphi - beta) / l2
        A = (gamma[..., None, None] * s[..., :, None] * s[..., None, :]
             + beta[..., None, None] * _EYE3)
        ZA = self._Z @ A  # (..., n, 6, 3)
        H_D = ZA.sum(axis=-3)
        H_G = (ZA @ hat3(q)).sum(axis=-3)
        # K = [H_G G - H_D Q, -H_D G], K_c = [H_D, -H_G].
        K = np.concatenate([H_G @ kin.G - H_D @ kin.Q, -(H_D @ kin.G)], axis=-1)
        Kc = np.concatenate([H_D, -H_G], axis=-1)
        return JointState(xi, kin.T, s, lengths, phi, slack, saturated, wrench, K, Kc)

    def _evaluate_batch_kernel(self, xi: FloatArray, rest: FloatArray, wrench_only: bool
                               ) -> JointState | None:
        """:meth:`_evaluate_batch` in the compiled kernel (``tsk_joint_evaluate``): ``None``
        for no screws or when a string has zero length (the numpy path then raises the error
        that names it)."""
        N, n = xi.shape[0], self.n_strings
        if N == 0:
            return None
        kn = self._kernel
        # Bound to names: the (possibly copied) inputs must outlive the call.
        xi = np.ascontiguousarray(xi)
        rest_c = np.ascontiguousarray(rest)
        # All outputs in one buffer (kernel.h: blocks T, s, lengths, tensions, wrench, K, K_c,
        # then the flags as bytes).
        o = kn.batch_layout(N)
        buf = np.empty(o.size)
        status = kn.evaluate(kn.model, N, kernel.address(xi), kernel.address(rest_c),
                             rest_c.size,
                             kernel.MODE_WRENCH if wrench_only else kernel.MODE_FULL,
                             kernel.address(buf), buf.size)
        if status != kernel.OK and _zero_length(status, 'tsk_joint_evaluate'):
            return None
        K = buf[o.stiffness:o.cartesian].reshape(N, 6, 6)
        Kc = buf[o.cartesian:o.flags].reshape(N, 6, 6)
        if wrench_only:
            K.fill(np.nan)
            Kc.fill(np.nan)
        flags = buf[o.flags:].view(np.bool_)[:2 * N * n].reshape(2, N, n)
        T = buf[:o.strings].reshape(N, 4, 4)
        s = buf[o.strings:o.lengths].reshape(N, n, 3)
        lengths = buf[o.lengths:o.tensions].reshape(N, n)
        phi = buf[o.tensions:o.wrench].reshape(N, n)
        wrench = buf[o.wrench:o.stiffness].reshape(N, 6)
        return JointState(xi, T, s, lengths, phi, flags[0], flags[1], wrench, K, Kc)

    # ------------------------------------------------------------------ public shortcuts
    def wrench(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None) -> FloatArray:
        """String wrench on link 2, ``[f; m]`` in {1} about its origin (eq. 9): (6,) or (N, 6)."""
        return self.evaluate(xi, rest_lengths).wrench

    def stiffness(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None) -> FloatArray:
        """Analytical ``K = dF/dxi`` (eq. 10): (6, 6) or (N, 6, 6)."""
        arr = np.asarray(xi, dtype=np.float64)
        if arr.shape == (6,) and (rest_lengths is None or rest_lengths is self.rest_lengths):
            return self._evaluate_single(arr, self.rest_lengths, False)
        return self.evaluate(xi, rest_lengths).stiffness

    def cartesian_stiffness(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None
                            ) -> FloatArray:
        """``K_c = -dF/d[dv; dw]`` for a spatial twist in {1}: (6, 6) or (N, 6, 6)."""
        return self.evaluate(xi, rest_lengths).cartesian_stiffness

    def tensions(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None) -> FloatArray:
        """String tensions (N): (n,) or (N, n)."""
        return self.evaluate(xi, rest_lengths).tensions

    def link2_nodes_in_link1(self, transform: ArrayLike) -> FloatArray:
        """Link-2 nodes expressed in {1} for ``transform`` (4, 4) (or (N, 4, 4)): (..., n2, 3)."""
        T = np.asarray(transform, dtype=np.float64)
        return self.link2_nodes @ np.swapaxes(T[..., :3, :3], -1, -2) + T[..., None, :3, 3]

    def lengths(self, xi: ArrayLike) -> FloatArray:
        """String lengths (m): (n,) or (N, n)."""
        xi = as_screws(xi)
        T = exp_se3(xi)
        q = self._p2 @ np.swapaxes(T[..., :3, :3], -1, -2) + T[..., None, :3, 3]
        return np.linalg.norm(self._p1 - q, axis=-1)

    def energy(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None) -> FloatArray | float:
        """Elastic potential energy of the strings (J): float or (N,).

        Hooke: ``k (l - l0)^2 / 2``; paper law: ``k (l - l0 - l0 ln(l / l0))``; beyond lmax both
        continue linearly with the saturated tension, so that the tension is ``dU/dl``.
        """
        xi = as_screws(xi)
        rest = self.validate_rest_lengths(rest_lengths)
        lengths = self.lengths(xi)
        lmax = rest + self.max_stretch
        lc = np.minimum(lengths, lmax)
        if self.force_law == 'hooke':
            stored = 0.5 * self.k * (lc - rest) ** 2
        else:
            stored = self.k * (lc - rest - rest * np.log(lc / rest))
        phi, _, slack, saturated = self.string_forces(lengths, rest)
        extra = np.where(saturated, phi * (lengths - lmax), 0.0)
        total = np.sum(np.where(slack, 0.0, stored + extra), axis=-1)
        return float(total) if np.ndim(total) == 0 else total

    def numerical_stiffness(self, xi: ArrayLike, rest_lengths: ArrayLike | None = None,
                            step: float = NUMERICAL_STEP) -> FloatArray:
        """Central-difference ``dF/dxi`` with step ``step`` (eq. 21): (6, 6) or (N, 6, 6).

        All 12 perturbed screws go through one vectorised wrench-only evaluation (the fastest
        way to do central differences here, so that benchmarks compare against a fair baseline).
        """
        xi = as_screws(xi)
        if not (math.isfinite(step) and step > 0.0):
            raise ValueError(f'step must be finite and > 0, got {step}')
        rest = self.validate_rest_lengths(rest_lengths)
        eye = np.eye(6) * step
        plus = xi[..., None, :] + eye  # (..., 6, 6): row i perturbs coordinate i
        minus = xi[..., None, :] - eye
        both = np.concatenate([plus, minus], axis=-2).reshape(-1, 6)
        rest_b = rest if rest.ndim == 1 else np.repeat(rest, 12, axis=0)
        F = self._evaluate_batch(both, rest_b, wrench_only=True).wrench
        F = F.reshape(xi.shape[:-1] + (12, 6))
        return np.swapaxes((F[..., :6, :] - F[..., 6:, :]) / (2.0 * step), -1, -2)
