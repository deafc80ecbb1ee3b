"""The physical range of each quantity a joint takes as input: one home per quantity (issue
#42), each range derived from the joint itself, so a 3 cm vertebra and a 30 cm lab joint get
their own. A value outside its range is finite but absurd (a pose 1 m away, a rest length of
1 um, a load of 1e308 N, a target stiffness of 1e12 N/m): the doors (the library's solvers and
design, the nodes' topics, parameters and services, the command line) refuse it with a
ValueError naming the value and the range, before any work is spent on it.

The ranges (:data:`PLAUSIBILITY_MARGIN` = 10 on forces and stiffnesses and :data:`REACH_MARGIN`
= 2 on lengths are the slack a model that is not exact needs; neither is a physical limit):

* **size** (:func:`joint_size`): the largest distance of a node from its link's origin.
* **string length** (:func:`string_length_limits`): a string can be no longer than its maximum
  length, or, without one, than :data:`UNBOUNDED_STRETCH` times its rest length (a real elastic
  cable does not follow Hooke's law that far).
* **reach** (:func:`reach`): how far link 2's origin can be from link 1's with every string
  within its length: ``max_j |p1_j| + l_j,max + |p2_j|``. A screw or a pose whose translation
  is beyond ``REACH_MARGIN * reach`` is refused.
* **rest lengths** (:func:`check_rest_lengths`): at least :data:`MIN_REST_FRACTION` of the size
  (a longer one than the reach leaves its string slack, which the solvers say).
* **load** (:func:`check_wrench`): the strings' capacity (:func:`string_capacity`, the sum of
  each string's largest tension) bounds the force they can balance; a force beyond ``MARGIN``
  times it, or a moment beyond ``MARGIN * capacity * reach``, is refused.
* **target stiffness** (:func:`check_target_stiffness`): a restoring stiffness has a positive
  semidefinite symmetric part (to a relative 1e-9) and an antisymmetric part no larger than
  that part and what the load explains; its size is bounded by what the strings can give,
  ``MARGIN`` times :func:`stiffness_scale` (N/m, with moments over the size).
* **a spine's tip** (:func:`chain_reach`, :func:`check_chain_translation`,
  :func:`check_chain_wrench`): the tool frame can be no farther from the base than the joints'
  reaches, the links' offsets and the tool's translation end to end; every joint carries the
  whole tip force, so the weakest joint's capacity bounds it, and the moment is bounded by that
  force at the spine's reach.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.geometry.validation import finite_array_of_shape

if TYPE_CHECKING:  # types only: joint reads its config through this module (no import circle)
    from tensegrity_stiffness.mechanics.chain import JointChain
    from tensegrity_stiffness.mechanics.joint import JointModel

FloatArray = NDArray[np.float64]

#: How far past what its strings can pull or give a force or a stiffness may lie before it is
#: refused (a margin for a model that is not exact, not a physical limit).
PLAUSIBILITY_MARGIN = 10.0
#: The same for a length: a translation or a rest length past this many reaches is refused.
REACH_MARGIN = 2.0
#: The longest a string without a maximum length may be, in rest lengths.
UNBOUNDED_STRETCH = 3.0
#: The shortest rest length, as a fraction of the joint's size.
MIN_REST_FRACTION = 1e-2
#: Relative asymmetry (and negative eigenvalue) of a target stiffness counted as rounding.
SYMMETRY_TOLERANCE = 1e-9


@dataclass(frozen=True)
class JointRanges:
    """The ranges of one joint at one set of rest lengths (see the module docstring): ``size``
    and ``reach`` (m), ``capacity`` (N), ``stiffness_scale`` (N/m)."""

    size: float
    reach: float
    capacity: float
    stiffness_scale: float


#: The ranges of the last rest lengths of each model (a node checks every input against them).
_RANGES: weakref.WeakKeyDictionary[JointModel, tuple[bytes, JointRanges]] = \
    weakref.WeakKeyDictionary()


#: The ranges of each model at its own rest lengths (a model's rest lengths do not change:
#: :meth:`JointModel.with_rest_lengths` makes a new model).
_OWN_RANGES: weakref.WeakKeyDictionary[JointModel, JointRanges] = weakref.WeakKeyDictionary()


def joint_ranges(model: JointModel, rest_lengths: ArrayLike | None = None) -> JointRanges:
    """:class:`JointRanges` of ``model`` at ``rest_lengths`` (default the model's), kept for the
    last rest lengths of each model (and for the model's own, looked up without a copy: a
    node's per-message path)."""
    if rest_lengths is None:
        own = _OWN_RANGES.get(model)
        if own is not None:
            return own
        own = _OWN_RANGES[model] = joint_ranges(model, model.rest_lengths)
        return own
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    key = rest.tobytes()
    cached = _RANGES.get(model)
    if cached is not None and cached[0] == key:
        return cached[1]
    limits = string_length_limits(model, rest)
    ends1 = np.linalg.norm(model.link1_string_nodes, axis=1)
    ends2 = np.linalg.norm(model.link2_nodes[model.connections[:, 1]], axis=1)
    size = _node_size(model)
    # The strings' own force law (eq. 8) just short of their longest: the largest tension and
    # its slope of each (the paper's law is not Hooke's).
    tension, slope, _, _ = model.string_forces(rest + (limits - rest) * (1.0 - 1e-9), rest)
    ranges = JointRanges(size=size, reach=float(np.max(ends1 + limits + ends2)),
                         capacity=float(np.sum(tension)),
                         stiffness_scale=float(np.sum(slope + tension / rest)))
    _RANGES[model] = (key, ranges)
    return ranges


def string_length_limits(model: JointModel, rest_lengths: ArrayLike | None = None
                         ) -> FloatArray:
    """The longest each string can be (n,) m: its maximum length, or
    :data:`UNBOUNDED_STRETCH` rest lengths without one."""
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    lmax = rest + model.max_stretch
    return np.where(np.isfinite(lmax), lmax, UNBOUNDED_STRETCH * rest)


def _node_size(model: JointModel) -> float:
    """The largest distance of a node from its link's origin (m), computed."""
    return float(max(np.linalg.norm(model.link1_nodes, axis=1).max(),
                     np.linalg.norm(model.link2_nodes, axis=1).max()))


def joint_size(model: JointModel) -> float:
    """The largest distance of a node from its link's origin (m): the model's ranges' when
    they are kept, else computed from the nodes alone (it does not depend on the rest lengths:
    a model made for each rest-length command checks the next one without its ranges)."""
    own = _OWN_RANGES.get(model)
    return own.size if own is not None else _node_size(model)


def reach(model: JointModel, rest_lengths: ArrayLike | None = None) -> float:
    """How far link 2's origin can be from link 1's (m) with every string within
    :func:`string_length_limits`: ``max_j |p1_j| + l_j,max + |p2_j|``."""
    return joint_ranges(model, rest_lengths).reach


def string_capacity(model: JointModel, rest_lengths: ArrayLike | None = None) -> float:
    """The sum of the strings' largest tensions (N), each at :func:`string_length_limits`
    under the joint's force law."""
    return joint_ranges(model, rest_lengths).capacity


def stiffness_scale(model: JointModel, rest_lengths: ArrayLike | None = None) -> float:
    """The size of the stiffness the strings can give (N/m): the sum of their largest axial
    stiffnesses ``dphi/dl`` and of their largest tensions over their rest lengths (the
    geometric term), under the joint's force law."""
    return joint_ranges(model, rest_lengths).stiffness_scale


def _norm(v: FloatArray) -> float:
    """``|v|`` without overflow (1e308 stays 1.7e308, not inf)."""
    top = float(np.abs(v).max()) if v.size else 0.0
    return top * float(np.linalg.norm(v / top)) if 0.0 < top < math.inf else top


def _range_error(name: str, value: float, limit: float, unit: str, what: str,
                 of: str = 'this joint') -> ValueError:
    return ValueError(f'{name}: {value:.4g} {unit} is outside the range of {of} '
                      f'(at most {limit:.4g} {unit}: {what})')


def check_translation(model: JointModel, translation: ArrayLike, name: str) -> None:
    """ValueError when link 2's origin at ``translation`` (3,) m is beyond
    ``REACH_MARGIN * reach``."""
    distance = _norm(np.asarray(translation, dtype=np.float64))
    limit = REACH_MARGIN * reach(model)
    if not distance <= limit:
        raise _range_error(name, distance, limit, 'm from link 1',
                           f'{REACH_MARGIN:g} x the reach of its strings')


def check_screw(model: JointModel, screw: ArrayLike, name: str = 'screw') -> None:
    """ValueError when the pose ``exp(hat(screw))`` puts link 2 out of reach
    (:func:`check_translation`); ``screw`` (6,) finite with |omega| < 2 pi (checked by the
    caller). The translation is ``t = G(omega) v`` with every singular value of ``G`` at most
    1, so ``|v|`` within reach passes without the exponential."""
    xi = np.asarray(screw, dtype=np.float64)
    v = xi[3:].tolist()
    limit = REACH_MARGIN * joint_ranges(model).reach
    if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] <= limit * limit:  # the fast path: a norm
        return
    with np.errstate(over='ignore', invalid='ignore'):
        T = exp_se3(xi)
    check_translation(model, T[:3, 3] if np.all(np.isfinite(T)) else [math.inf] * 3, name)


def check_rest_lengths(model: JointModel, rest_lengths: ArrayLike,
                       name: str = 'rest_lengths') -> FloatArray:
    """``rest_lengths`` (n,) validated (:meth:`JointModel.validate_rest_lengths`) and at least
    ``MIN_REST_FRACTION`` of the joint's size; ValueError names the first string below. (A
    rest length too long leaves its string slack, which the solvers report as such.)"""
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    low = MIN_REST_FRACTION * joint_size(model)
    bad = np.flatnonzero(rest < low)
    if bad.size:
        j = int(bad[0])
        raise ValueError(f'{name}: {model.string_names[j]} = {rest[j]:.4g} m is below the '
                         f'range of this joint (at least {low:.4g} m: {MIN_REST_FRACTION:g} x '
                         'its size)')
    return rest


def check_wrench(model: JointModel, wrench: ArrayLike, name: str = 'external_wrench',
                 rest_lengths: ArrayLike | None = None) -> FloatArray:
    """``wrench`` (6,) ``[f; m]`` finite, with ``|f|`` at most ``PLAUSIBILITY_MARGIN`` times
    the strings' capacity and ``|m|`` that times the reach; ValueError otherwise."""
    W = finite_array_of_shape(name, wrench, (6,))
    capacity = PLAUSIBILITY_MARGIN * string_capacity(model, rest_lengths)
    force, moment = _norm(W[:3]), _norm(W[3:])
    if not force <= capacity:
        raise _range_error(f'{name} force', force, capacity, 'N',
                           f'{PLAUSIBILITY_MARGIN:g} x what all its strings can pull')
    arm = reach(model, rest_lengths)
    if not moment <= capacity * arm:
        raise _range_error(f'{name} moment', moment, capacity * arm, 'N m',
                           f'{PLAUSIBILITY_MARGIN:g} x what all its strings can pull at its '
                           'reach')
    return W


def chain_reach(chain: JointChain) -> float:
    """How far a spine's tool frame can be from its base (m): ``REACH_MARGIN`` times each
    joint's :func:`reach` plus the links' offsets and the tool's translation, end to end."""
    joints = sum(REACH_MARGIN * reach(model) for model in chain.joints)
    offsets = float(np.linalg.norm(chain.link_offsets[:, :3, 3], axis=1).sum())
    return joints + offsets + float(np.linalg.norm(chain.tool[:3, 3]))


def check_chain_translation(chain: JointChain, translation: ArrayLike, name: str) -> None:
    """ValueError when a spine's tool frame at ``translation`` (3,) m from the base is beyond
    :func:`chain_reach`."""
    distance = _norm(np.asarray(translation, dtype=np.float64))
    limit = chain_reach(chain)
    if not distance <= limit:
        raise _range_error(name, distance, limit, 'm from the base',
                           f"its joints' reaches end to end ({REACH_MARGIN:g} x each)",
                           'this spine')


def check_chain_wrench(chain: JointChain, wrench: ArrayLike, name: str = 'tip_wrench'
                       ) -> FloatArray:
    """A spine's tip load ``wrench`` (6,) ``[f; m]`` finite, with ``|f|`` at most
    ``PLAUSIBILITY_MARGIN`` times the weakest joint's :func:`string_capacity` (each joint
    carries all of it) and ``|m|`` that force at :func:`chain_reach`; ValueError otherwise."""
    W = finite_array_of_shape(name, wrench, (6,))
    capacity = PLAUSIBILITY_MARGIN * min(string_capacity(model) for model in chain.joints)
    force, moment = _norm(W[:3]), _norm(W[3:])
    if not force <= capacity:
        raise _range_error(f'{name} force', force, capacity, 'N',
                           f'{PLAUSIBILITY_MARGIN:g} x what the strings of its weakest joint '
                           'can pull', 'this spine')
    arm = chain_reach(chain)
    if not moment <= capacity * arm:
        raise _range_error(f'{name} moment', moment, capacity * arm, 'N m',
                           'that force at its reach', 'this spine')
    return W


def check_target_stiffness(model: JointModel, target: ArrayLike,
                           name: str = 'target_stiffness', length_scale: float | None = None,
                           wrench: ArrayLike | None = None) -> FloatArray:
    """A target ``K_c`` (6, 6) (rows ``[f; m]``, columns ``[linear; angular]``), judged scaled
    (``S K S``, ``S = diag(1, 1, 1, 1/L, 1/L, 1/L)``, ``L`` the size): finite, not zero, its
    symmetric part positive semidefinite to a relative :data:`SYMMETRY_TOLERANCE` and its
    largest eigenvalue at most ``PLAUSIBILITY_MARGIN * stiffness_scale``; its antisymmetric
    part no larger than its symmetric part plus what the load ``wrench`` (default none)
    explains: under a load ``W = [f; m]`` the strings' ``K_c - K_c^T`` is made of the
    components of ``f`` and ``m`` (a constant wrench is not conservative on SE(3)), so
    ``|S (K - K^T) S|`` is at most ``2 (|f| / L + |m| / L^2)``; an antisymmetric part beyond
    that is unreachable but harmless to the design (a constant error), one beyond the
    symmetric part is no stiffness. ValueError saying which."""
    K = finite_array_of_shape(name, target, (6, 6))
    L = joint_ranges(model).size if length_scale is None else float(length_scale)
    S = np.array([1.0, 1.0, 1.0, 1.0 / L, 1.0 / L, 1.0 / L])
    with np.errstate(over='ignore', invalid='ignore'):
        Ks = K * S[:, None] * S[None, :]
        size = float(np.abs(Ks).max())
    if not np.isfinite(size):
        raise ValueError(f'{name}: entries too large to be a stiffness (|K| overflows)')
    if size == 0.0:
        raise ValueError(f'{name}: zero (no restoring stiffness: give a positive definite K_c)')
    W = np.zeros(6) if wrench is None else np.asarray(wrench, dtype=np.float64)
    explained = 2.0 * (_norm(W[:3]) / L + _norm(W[3:]) / L ** 2)
    symmetric = 0.5 * (Ks + Ks.T)
    asymmetry = float(np.abs(Ks - Ks.T).max())
    if asymmetry > explained + float(np.abs(symmetric).max()):
        raise ValueError(f'{name}: mostly antisymmetric (largest |K - K^T| {asymmetry:.3g} '
                         f'N/m, scaled, beyond its symmetric part and the {explained:.3g} the '
                         "load explains): the strings' K_c is symmetric but for the load's "
                         'part')
    eigenvalues = np.linalg.eigvalsh(symmetric)
    if eigenvalues[0] < -SYMMETRY_TOLERANCE * size:
        raise ValueError(f'{name}: not positive semidefinite (smallest eigenvalue '
                         f'{eigenvalues[0]:.3g} N/m, scaled): a target must restore')
    limit = PLAUSIBILITY_MARGIN * joint_ranges(model).stiffness_scale
    if eigenvalues[-1] > limit:
        raise ValueError(f'{name}: {eigenvalues[-1]:.4g} N/m (largest eigenvalue, scaled) is '
                         f'outside the range of this joint (at most {limit:.4g} N/m: '
                         f'{PLAUSIBILITY_MARGIN:g} x what its strings can give)')
    return K


#: The lightest moving link (kg): below it the modes' frequencies are those of no real link.
MIN_LINK_MASS = 1e-6
#: Standard gravity (m/s^2), for the heaviest link the strings can hold.
_GRAVITY = 9.80665


def check_dynamics(model: JointModel, mass: float, com: ArrayLike,
                   string_damping: ArrayLike,
                   names: tuple[str, str, str] = ('link mass', 'link com', 'string_damping')
                   ) -> None:
    """ValueError naming the field (``names`` of mass, com and damping: a node passes its
    parameters') when link 2's dynamics are outside the joint's range
    (issue #42): ``mass`` (kg) from :data:`MIN_LINK_MASS` to ``PLAUSIBILITY_MARGIN`` times the
    weight its strings can hold (capacity / g); ``com`` (3,) m within ``REACH_MARGIN`` sizes of
    link 2's origin; each ``string_damping`` (N s/m) at most ``PLAUSIBILITY_MARGIN ** 2`` times
    the link's critical damping ``2 sqrt(stiffness_scale * mass)`` (more stops every mode)."""
    ranges = joint_ranges(model)
    heaviest = PLAUSIBILITY_MARGIN * ranges.capacity / _GRAVITY
    if not MIN_LINK_MASS <= mass <= heaviest:
        raise ValueError(f'{names[0]}: {mass:.4g} kg is outside the range of this joint '
                         f'({MIN_LINK_MASS:g} to {heaviest:.4g} kg: {PLAUSIBILITY_MARGIN:g} x '
                         'the weight its strings can hold)')
    offset = _norm(np.asarray(com, dtype=np.float64))
    if not offset <= REACH_MARGIN * ranges.size:
        raise _range_error(names[1], offset, REACH_MARGIN * ranges.size,
                           "m from link 2's origin", f'{REACH_MARGIN:g} x its size')
    critical = 2.0 * math.sqrt(ranges.stiffness_scale * mass)
    damping = float(np.max(np.asarray(string_damping, dtype=np.float64), initial=0.0))
    if not damping <= PLAUSIBILITY_MARGIN ** 2 * critical:
        raise _range_error(names[2], damping, PLAUSIBILITY_MARGIN ** 2 * critical,
                           'N s/m', f"{PLAUSIBILITY_MARGIN ** 2:g} x link 2's critical damping "
                           '2 sqrt(stiffness scale x mass)')
