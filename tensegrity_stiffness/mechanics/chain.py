"""Spines: serial chains of six-DOF tensegrity joints (Monke & Vikas joints as vertebrae).

Conventions
-----------
* Joint i (1..N) joins link i-1 (its link 1, frame {1}_i) to link i (its link 2, frame {2}_i),
  with its own :class:`~tensegrity_stiffness.mechanics.joint.JointModel` and screw ``xi_i``;
  ``T_i = exp(hat(xi_i))`` (eq. 2) maps {2}_i into {1}_i. Link 0 is the base, {1}_1 the base frame.
* ``O_i`` (i = 1..N-1, ``link_offsets``) is the pose of {1}_{i+1} in {2}_i; ``O_tool`` the pose of
  the tool frame in {2}_N. ``P_i = T_1 O_1 ... T_{i-1} O_{i-1}`` is the pose of {1}_i in the base,
  ``L_i = P_i T_i`` that of {2}_i, ``T_tip = L_N O_tool``.
* Twists ``delta = [dv; dw]`` (linear first, as ROS) are spatial, applied as
  ``T -> exp(hat(delta)) T``; wrenches ``[f; m]``. ``Ad_P = [[R, hat(p) R], [0, R]]`` moves a twist
  of a frame with pose ``P = (R, p)`` into the base; ``Ad_P^T`` moves a base wrench (about the base
  origin) into that frame (about its origin).
* Loads: the tip wrench ``W`` acts on link N, constant in the base frame about its origin (as
  the single-joint solver's external wrench). Link k carries a dead weight ``G_k = m_k g`` at
  ``x_k = L_k c_k`` (``c_k`` in {2}_k), i.e. the base wrench ``w_k = [G_k; x_k x G_k]``.

Equilibrium (the single joint's ``F + W = 0`` of Section VI, joint by joint)
---------------------------------------------------------------------------
``F_i(xi_i)`` is joint i's string wrench on link i in {1}_i (eq. 9 of Monke & Vikas). Each joint
balances every load above it: ``r_i = F_i + Ad_{P_i}^T B_i = 0``, ``B_i = W + sum_{k >= i} w_k``.

Tangent (implicit differentiation). A change ``dxi_j`` moves every frame above joint j by the
spatial twist ``S_j dxi_j``, ``S_j = Ad_{P_j} Pi J_j`` (``J_j`` the SE(3) left Jacobian in
[omega; v] order, ``Pi`` the swap of the 3-blocks); ``[S_1 ... S_N]`` is the tip Jacobian. A base
wrench ``B`` seen from a frame moved by ``s`` changes by ``Ad_P^T M(B) s`` with
``M([f; m]) = [[0, hat(f)], [hat(f), hat(m)]]`` (from ``Ad_exp(s)^T = I + ad_s^T``); a dead
weight moved by ``s`` changes by ``N_k s``, ``N_k = [[0, 0], [-hat(G_k), hat(G_k) hat(x_k)]]``.
So the 6N x 6N Jacobian of the residuals has the blocks

    dr_i/dxi_j = [i = j] K_i + Ad_{P_i}^T E_ij S_j,
    E_ij = [j < i] M(B_i) + sum_{k >= max(i, j)} N_k,

with ``K_i = dF_i/dxi_i`` (eq. 10 of Monke & Vikas), and ``dr_i/dW = Ad_{P_i}^T``. In the
joints' own twists ``delta_j = Pi J_j dxi_j`` (spatial in {1}_j, [dv; dw]) the Jacobians drop out:
``K_j J_j^-1 Pi = -K_c,j`` (``K = -K_c Pi J``) and ``S_j J_j^-1 Pi = Ad_{P_j}``, so

    D_ij = dr_i/d(delta_j) = -[i = j] K_c,i + Ad_{P_i}^T E_ij Ad_{P_j},

which is what the code builds (``K_c`` from the batched joint evaluation; Newton multiplies by
``diag(Pi J_j)`` to get ``dr/dxi``). Without weights, ``r_i`` depends on ``xi_1..xi_i`` only (block
lower triangular). At an equilibrium ``D delta = -Ad^T dW`` and the tip twist is
``sum_j Ad_{P_j} delta_j``, so the tip compliance is ``C = -[Ad_{P_1} ... Ad_{P_N}] D^-1 Ad^T``
and the tip stiffness ``K_tip = C^-1`` (rows ``[f; m]``, columns ``[dv; dw]`` in the base). At an
unloaded equilibrium without weights ``D = -diag(K_c,i)`` and
``C = sum_i Ad_{P_i} K_c,i^-1 Ad_{P_i}^T`` (joint compliances in series); for N = 1
``K_tip = K_c``. In the tool frame ``K_tool = Ad_{T_tip}^T K_tip Ad_{T_tip}``.

Stability: ``-D`` is the chain's tangent stiffness in the joints' twists (for N = 1 it is
``K_c``); an equilibrium is stable when its symmetric part is positive definite (the scaled test
of :func:`~tensegrity_stiffness.mechanics.equilibrium.is_stable`). Under weights alone
(conservative) it is
symmetric at an equilibrium.

Solver: damped Newton on all 6N unknowns with the analytic ``dr/dxi`` from each joint's unloaded
equilibrium; without weights, if Newton stalls, joint-by-joint solves (the triangular structure:
joint i under ``Ad_{P_i}^T W`` once joints 1..i-1 are solved, with the single-joint solver and its
fallbacks); last, load stepping.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.screw import (
    BLOCK_SWAP,
    ScrewKinematics,
    check_in_chart,
    exp_se3,
    hat3,
    log_se3,
)
from tensegrity_stiffness.geometry.transforms import adjoint, rigid_transform
from tensegrity_stiffness.geometry.validation import finite_array, optional_vector
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.equilibrium import (
    CONTINUATION_STEPS,
    MAX_NEWTON_ITERATIONS,
    MAX_ROTATION_STEP,
    MAX_TRANSLATION_STEP,
    RECHART_ANGLE,
    RESIDUAL_TOLERANCE,
    is_stable,
    solve_equilibrium,
)
from tensegrity_stiffness.mechanics.joint import JOINT_SECTION_KEYS, JointModel
from tensegrity_stiffness.mechanics.newton import damped_newton, solve_deadline

FloatArray = NDArray[np.float64]

#: Packaged spine configuration (5 default vertebrae, stacked).
DEFAULT_SPINE_CONFIG = 'default_spine.yaml'
#: The most joints a spine may have (the nodes' ``chain.n_joints`` range, ``new-config
#: --spine``): the work per evaluation grows with N^2.
MAX_JOINTS = 100
#: The keys of a config's ``chain`` section (:meth:`JointChain.from_dict`; ``link_inertias``
#: read by :func:`~tensegrity_stiffness.mechanics.inertia.chain_inertias_from_config`).
CHAIN_KEYS = ('n_joints', 'link_offsets', 'tool', 'link_masses', 'link_coms', 'gravity',
              'link_inertias')


def _load_transport(B: FloatArray) -> FloatArray:
    """``M(B) = [[0, hat(f)], [hat(f), hat(m)]]`` for (..., 6) wrenches: (..., 6, 6)."""
    out = np.zeros(B.shape[:-1] + (6, 6))
    hf = hat3(B[..., :3])
    out[..., :3, 3:] = hf
    out[..., 3:, :3] = hf
    out[..., 3:, 3:] = hat3(B[..., 3:])
    return out


@dataclass(slots=True)
class ChainState:
    """Everything :meth:`JointChain.evaluate` computes at one configuration (N joints).

    ``screws`` (N, 6); ``transforms`` (N, 4, 4) T_i ({2}_i in {1}_i); ``joint_frames`` (N, 4, 4)
    P_i ({1}_i in the base); ``link_transforms`` (N, 4, 4) L_i ({2}_i in the base);
    ``tip_transform`` (4, 4); ``wrenches`` (N, 6) F_i in {1}_i; ``stiffness`` (N, 6, 6) K_i;
    ``cartesian_stiffness`` (N, 6, 6) K_c,i; ``tensions``,
    ``lengths``, ``slack``, ``saturated``: one array per joint (stacked (N, n) when every joint
    has n strings).
    """

    screws: FloatArray
    transforms: FloatArray
    joint_frames: FloatArray
    link_transforms: FloatArray
    tip_transform: FloatArray
    wrenches: FloatArray
    stiffness: FloatArray
    cartesian_stiffness: FloatArray
    tensions: Any
    lengths: Any
    slack: Any
    saturated: Any


class JointChain:
    """N tensegrity joints in series (see the module docstring for frames and loads).

    Parameters
    ----------
    joints : sequence of :class:`JointModel` (one per joint; the same model may repeat, and
        repeated models are evaluated in one batch).
    link_offsets : N-1 poses of {1}_{i+1} in {2}_i, each a (4, 4) transform or
        ``[x y z qx qy qz qw]``; ``None``: identity.
    tool : pose of the tool frame in {2}_N (same forms); ``None``: identity.
    link_masses : (N,) kg, >= 0 (link i = link 2 of joint i); ``None``: massless.
    link_coms : (N, 3) centre of mass of link i in {2}_i (m); ``None``: the origins.
    gravity : (3,) m/s^2 in the base frame, used when a call passes ``gravity=None``;
        ``None``: zero.
    use_kernel : frames, implied tip wrench and tip stiffness in the compiled kernel
        (:mod:`~tensegrity_stiffness.mechanics.kernel`) when it is available (default); ``False``
        keeps
        the numpy implementation, its reference. The joints' own models choose for themselves.
    """

    def __init__(self, joints: Sequence[JointModel], link_offsets: ArrayLike | None = None,
                 tool: ArrayLike | None = None, link_masses: ArrayLike | None = None,
                 link_coms: ArrayLike | None = None, *, gravity: ArrayLike | None = None,
                 base_frame: str = 'spine_base', tool_frame: str = 'spine_tool',
                 use_kernel: bool = True) -> None:
        joints = list(joints)
        if not joints or not all(isinstance(j, JointModel) for j in joints):
            raise ValueError('joints must be a non-empty sequence of JointModel')
        n = len(joints)
        self.joints = joints
        if link_offsets is None:
            offsets = np.broadcast_to(np.eye(4), (n - 1, 4, 4)).copy()
        else:
            raw = finite_array('link_offsets', link_offsets)
            if raw.ndim == 1 and raw.size == 7 * (n - 1):
                raw = raw.reshape(n - 1, 7)
            if raw.ndim not in (2, 3) or raw.shape[0] != n - 1:
                raise ValueError(f'link_offsets must hold N - 1 = {n - 1} poses ((N-1, 4, 4) or '
                                 f'(N-1, 7)), got shape {raw.shape}')
            offsets = np.array([rigid_transform(o, f'link_offsets[{i}]')
                                for i, o in enumerate(raw)]
                               ).reshape(n - 1, 4, 4)
        self.link_offsets = offsets
        self.tool = np.eye(4) if tool is None else rigid_transform(tool, 'tool')
        if link_masses is None:
            masses = np.zeros(n)
        else:
            masses = finite_array('link_masses', link_masses)
            if masses.shape != (n,):
                raise ValueError(f'link_masses must have shape ({n},), got {masses.shape}')
            if np.any(masses < 0.0):
                raise ValueError(f'link_masses must be >= 0, got {masses.tolist()}')
        self.link_masses = masses.copy()
        if link_coms is None:
            coms = np.zeros((n, 3))
        else:
            coms = finite_array('link_coms', link_coms)
            if coms.shape == (3 * n,):
                coms = coms.reshape(n, 3)
            if coms.shape != (n, 3):
                raise ValueError(f'link_coms must have shape ({n}, 3), got {coms.shape}')
        self.link_coms = coms.copy()
        self._massive = bool(np.any(self.link_masses > 0.0))
        self.gravity = np.zeros(3) if gravity is None else gravity
        self.base_frame = str(base_frame)
        self.tool_frame = str(tool_frame)
        # Joints grouped by model (one batched evaluation per distinct model).
        groups: dict[int, list[int]] = {}
        for i, model in enumerate(joints):
            groups.setdefault(id(model), []).append(i)
        self._groups = [(joints[idx[0]], np.array(idx)) for idx in groups.values()]
        # Keyed by the model itself (identity), not its id: a pickled chain (the solver worker's)
        # keeps the mapping, where ids would be stale.
        self._unloaded: dict[JointModel, FloatArray] = {}
        # Block masks of the 6N x 6N tangent: [j < i] per block, and the joint indices.
        self._strictly_lower = np.kron(np.tri(n, n, -1), np.ones((6, 6)))
        self._index = np.arange(n)
        self.use_kernel = use_kernel
        self._offsets_c = np.ascontiguousarray(self.link_offsets, dtype=np.float64)
        self._tool_c = np.ascontiguousarray(self.tool, dtype=np.float64)

    # ------------------------------------------------------------------ construction
    @property
    def n_joints(self) -> int:
        """Number of joints N."""
        return len(self.joints)

    @classmethod
    def from_dict(cls, document: Mapping[str, Any], strict: bool = True) -> JointChain:
        """Build from a config document (a ROS parameter file or a plain mapping): see
        ``config/default_spine.yaml``. Sections: ``joint`` (the vertebra, keys of
        ``default_joint.yaml``), optional ``joint_<i>`` (i = 1..N: keys that override ``joint``
        for joint i), ``chain`` (``n_joints``; ``link_offsets`` flat [x y z qx qy qz qw] per
        offset: N-1 of them, or one for all, or empty = identity; ``tool`` [x y z qx qy qz qw];
        ``link_masses`` N values or one for all (kg); ``link_coms`` flat [x y z] per link or
        one for all; ``gravity`` [3]), optional ``frames`` (``base``, ``tool``). Unknown keys of
        ``joint``, ``joint_<i>`` and ``chain`` are refused with the nearest name (``strict=False``:
        warned about)."""
        vertebra = dict(config.section(document, 'joint'))
        chain = config.section(document, 'chain')
        config.check_keys(chain, CHAIN_KEYS, 'chain', strict)
        frames = config.section(document, 'frames', required=False)
        raw_n = chain.get('n_joints')
        if (isinstance(raw_n, bool) or not isinstance(raw_n, (int, np.integer))
                or not 1 <= raw_n <= MAX_JOINTS):
            raise ValueError(f'chain.n_joints must be an integer in [1, {MAX_JOINTS}] '
                             f'(MAX_JOINTS), got {raw_n!r}')
        n = int(raw_n)
        base_model = JointModel.from_dict(vertebra, strict)
        joints = []
        for i in range(1, n + 1):
            override = config.section(document, f'joint_{i}', required=False)
            if override:
                config.check_keys(override, JOINT_SECTION_KEYS, f'joint_{i}', strict)
                try:
                    joints.append(JointModel.from_dict({**vertebra, **override}, strict))
                except ValueError as exc:
                    raise ValueError(f'joint_{i}: {exc}') from None
            else:
                joints.append(base_model)

        def flat(key: str, width: int, count: int) -> FloatArray | None:
            """chain.<key> as a flat array: empty -> None; one entry of ``width`` values ->
            repeated ``count`` times."""
            arr = finite_array(f'chain.{key}', chain.get(key, [])).ravel()
            if arr.size == 0 or count == 0:
                return None if arr.size == 0 else arr
            return np.tile(arr, count) if arr.size == width else arr

        offsets = flat('link_offsets', 7, n - 1)
        if offsets is not None and offsets.size != 7 * (n - 1):
            raise ValueError(f'chain.link_offsets must have 7 (N - 1) = {7 * (n - 1)} values '
                             f'(or 7 for all, or none), got {offsets.size}')
        tool = finite_array('chain.tool', chain.get('tool', [])).ravel()
        if tool.size not in (0, 7):
            raise ValueError(f'chain.tool must have 7 values [x y z qx qy qz qw] or none, got '
                             f'{tool.size}')
        masses = flat('link_masses', 1, n)
        if masses is not None and masses.size != n:
            raise ValueError(f'chain.link_masses must have {n} values (or one for all), got '
                             f'{masses.size}')
        coms = flat('link_coms', 3, n)
        if coms is not None and coms.size != 3 * n:
            raise ValueError(f'chain.link_coms must have 3 N = {3 * n} values (or 3 for all), '
                             f'got {coms.size}')
        gravity = flat('gravity', 3, 1)
        kwargs = {}
        for key in ('base', 'tool'):
            if frames.get(key) is not None:
                kwargs[f'{key}_frame'] = str(frames[key])
        try:
            return cls(joints, None if offsets is None else offsets.reshape(n - 1, 7),
                       tool if tool.size else None,
                       masses, coms, gravity=gravity, **kwargs)
        except ValueError as exc:
            raise ValueError(f'chain: {exc}') from None

    @classmethod
    def from_yaml(cls, path: str | Path) -> JointChain:
        """Load from a YAML file (ROS parameter file or plain), see :meth:`from_dict`."""
        return cls.from_dict(config.load_yaml(path))

    # ------------------------------------------------------------------ validation
    def resolved_gravity(self, gravity: ArrayLike | None) -> FloatArray:
        """``gravity`` (3,) validated, or the chain's default for None."""
        if gravity is None:
            return self.gravity
        g = finite_array('gravity', gravity)
        if g.shape != (3,):
            raise ValueError(f'gravity must have shape (3,), got {g.shape}')
        return g

    def validated_screws(self, screws: ArrayLike) -> FloatArray:
        """``screws`` as (N, 6), one per joint (6N flat accepted), finite and in the chart."""
        xi = finite_array('screws', screws)
        n = self.n_joints
        if xi.shape == (6 * n,):
            xi = xi.reshape(n, 6)
        if xi.shape != (n, 6):
            raise ValueError(f'screws must have shape ({n}, 6) (one screw per joint), '
                             f'got {xi.shape}')
        check_in_chart(xi, 'screws')
        return xi

    def rest_lengths_per_joint(self, rest_lengths: Any) -> list[FloatArray | None]:
        """Per-joint rest lengths: None, an (N, n) array, or a sequence of N arrays/None."""
        n = self.n_joints
        if rest_lengths is None:
            return [None] * n
        if len(rest_lengths) != n:
            raise ValueError(f'rest_lengths must hold one entry per joint ({n}), '
                             f'got {len(rest_lengths)}')
        return [None if r is None else model.validate_rest_lengths(r, batched=False)
                for model, r in zip(self.joints, rest_lengths, strict=True)]

    @property
    def gravity(self) -> FloatArray:
        """(3,) m/s^2 in the base frame: the default of every ``gravity=None`` (read-only array;
        assign a new value to change it)."""
        return self._default_gravity

    @gravity.setter
    def gravity(self, value: ArrayLike) -> None:
        g = self.resolved_gravity(value).copy()
        g.flags.writeable = False
        self._default_gravity = g
        self._weighted = self._massive and bool(np.any(g != 0.0))

    def has_weights(self, g: FloatArray) -> bool:
        """True when the links' weights under the (resolved) gravity ``g`` load the chain."""
        if g is self._default_gravity:
            return self._weighted
        return self._massive and bool(np.any(g != 0.0))

    # ------------------------------------------------------------------ kinematics
    def _library(self) -> Any:
        """The compiled kernel's library, or ``None`` for the numpy path."""
        return kernel.library() if self.use_kernel else None

    def _frames(self, T: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray]:
        """(P (N, 4, 4), L (N, 4, 4), T_tip) from the joint transforms T_i."""
        n = self.n_joints
        lib = self._library()
        if lib is not None:
            T = np.ascontiguousarray(T, dtype=np.float64)  # a name: it outlives the call
            out = np.empty(32 * n + 16)
            kernel.check(lib.chain_frames(n, kernel.address(T), kernel.address(self._offsets_c),
                                          kernel.address(self._tool_c), kernel.address(out),
                                          out.size), 'tsk_chain_frames')
            return (out[:16 * n].reshape(n, 4, 4), out[16 * n:32 * n].reshape(n, 4, 4),
                    out[32 * n:].reshape(4, 4))
        P = np.empty((n, 4, 4))
        L = np.empty((n, 4, 4))
        current = np.eye(4)
        for i in range(n):
            P[i] = current
            L[i] = current @ T[i]
            if i < n - 1:
                current = L[i] @ self.link_offsets[i]
        return P, L, L[-1] @ self.tool

    def link_transforms(self, screws: ArrayLike) -> FloatArray:
        """Pose of each {2}_i in the base: (N, 4, 4)."""
        return self._frames(exp_se3(self.validated_screws(screws)))[1]

    def tip_transform(self, screws: ArrayLike) -> FloatArray:
        """Pose of the tool frame in the base, ``T_1 O_1 ... T_N O_tool``: (4, 4)."""
        return self._frames(exp_se3(self.validated_screws(screws)))[2]

    def jacobian(self, screws: ArrayLike) -> FloatArray:
        """Tip spatial twist ``[dv; dw]`` (base) per joint screw change: (6, 6N), joint-major
        columns ``[wx wy wz vx vy vz]`` of each joint."""
        xi = self.validated_screws(screws)
        kin = ScrewKinematics(xi)
        P = self._frames(kin.T)[0]
        return np.concatenate(list(adjoint(P) @ kin.J[:, BLOCK_SWAP]), axis=1)

    # ------------------------------------------------------------------ evaluation
    def evaluate(self, screws: ArrayLike, rest_lengths: Any = None) -> ChainState:
        """Every joint's wrench, K, K_c, tensions and flags (one batched evaluation per distinct
        model) and the chain's frames at ``screws`` (N, 6)."""
        xi = self.validated_screws(screws)
        rest = self.rest_lengths_per_joint(rest_lengths)
        n = self.n_joints
        wrenches = np.empty((n, 6))
        K = np.empty((n, 6, 6))
        Kc = np.empty((n, 6, 6))
        if len(self._groups) == 1:
            model, _ = self._groups[0]
            batch_rest = None if all(x is None for x in rest) else np.array(
                [model.rest_lengths if x is None else x for x in rest])
            state = model.evaluate(xi, batch_rest)
            P, L, tip = self._frames(state.transform)
            return ChainState(xi, state.transform, P, L, tip, state.wrench, state.stiffness,
                              state.cartesian_stiffness, state.tensions, state.lengths,
                              state.slack, state.saturated)
        T = np.empty((n, 4, 4))
        per_joint: list[list[Any]] = [[None] * n for _ in range(4)]
        for model, idx in self._groups:
            r = [rest[i] for i in idx]
            batch_rest = None if all(x is None for x in r) else np.array(
                [model.rest_lengths if x is None else x for x in r])
            state = model.evaluate(xi[idx], batch_rest)
            T[idx] = state.transform
            wrenches[idx] = state.wrench
            K[idx] = state.stiffness
            Kc[idx] = state.cartesian_stiffness
            for k, values in enumerate((state.tensions, state.lengths, state.slack,
                                        state.saturated)):
                for j, i in enumerate(idx):
                    per_joint[k][i] = values[j]
        if len({a.shape for a in per_joint[0]}) == 1:
            stacked = [np.array(a) for a in per_joint]
        else:
            stacked = per_joint
        P, L, tip = self._frames(T)
        return ChainState(xi, T, P, L, tip, wrenches, K, Kc, *stacked)

    def link_weights(self, L: FloatArray, g: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Base wrenches w_k (N, 6) of the link weights and their transport N_k (N, 6, 6)."""
        G = self.link_masses[:, None] * g  # (N, 3)
        x = (L[:, :3, :3] @ self.link_coms[:, :, None])[:, :, 0] + L[:, :3, 3]
        w = np.concatenate([G, np.cross(x, G)], axis=1)
        hG = hat3(G)
        Nk = np.zeros((self.n_joints, 6, 6))
        Nk[:, 3:, :3] = -hG
        Nk[:, 3:, 3:] = hG @ hat3(x)
        return w, Nk

    def equilibrium_system(self, state: ChainState, W: FloatArray, g: FloatArray,
                           tangent: bool = True
                           ) -> tuple[FloatArray, FloatArray | None, FloatArray, FloatArray]:
        """Residuals r (N, 6); ``dr/d(delta)`` (6N, 6N) with respect to the joints' twists
        ``delta_j`` (spatial in {1}_j, [dv; dw]; None unless ``tangent``), i.e. minus the chain's
        tangent stiffness, blocks ``-[i = j] K_c,i + Ad_{P_i}^T E_ij Ad_{P_j}``;
        ``Ad_{P_i}^T`` (N, 6, 6) = dr_i/dW; ``Ad_{P_i}`` (N, 6, 6)."""
        n = self.n_joints
        Ad = adjoint(state.joint_frames)
        AdT = np.swapaxes(Ad, 1, 2)
        weights = self.has_weights(g)
        if weights:
            w, Nk = self.link_weights(state.link_transforms, g)
            B = W + np.cumsum(w[::-1], axis=0)[::-1]
            r = state.wrenches + (AdT @ B[:, :, None])[:, :, 0]
        else:
            r = state.wrenches + AdT @ W
        if not tangent:
            return r, None, AdT, Ad
        if weights:
            E = np.zeros((n, n, 6, 6))
            lower = np.tri(n, n, -1, dtype=bool)  # [j < i]
            E[lower] = np.broadcast_to(_load_transport(B)[:, None], (n, n, 6, 6))[lower]
            Nsum = np.cumsum(Nk[::-1], axis=0)[::-1]
            E += Nsum[np.maximum.outer(np.arange(n), np.arange(n))]
            blocks = AdT[:, None] @ E @ Ad[None, :]
            D = blocks.transpose(0, 2, 1, 3).reshape(6 * n, 6 * n)
        elif n > 1 and np.any(W):
            # One load B = W for every joint: all blocks j < i are Ad_i^T M(W) Ad_j.
            D = AdT.reshape(6 * n, 6) @ (_load_transport(W) @ Ad.transpose(1, 0, 2).reshape(
                6, 6 * n))
            D *= self._strictly_lower
        else:
            D = np.zeros((6 * n, 6 * n))
        diag = D.reshape(n, 6, n, 6)
        diag[self._index, :, self._index, :] -= state.cartesian_stiffness
        return r, D, AdT, Ad

    def residual_screw_jacobian(self, D: FloatArray, screws: FloatArray) -> FloatArray:
        """``dr/dxi = dr/d(delta) diag(Pi J_j)`` (6N, 6N) from the twist form ``D``."""
        n = self.n_joints
        PJ = ScrewKinematics(screws).J[:, BLOCK_SWAP]
        return np.einsum('ajb,jbc->ajc', D.reshape(6 * n, n, 6), PJ).reshape(6 * n, 6 * n)

    def _tip(self, state: ChainState, W: FloatArray | None, g: FloatArray, base: bool,
             tool: bool) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """The tip at an evaluated ``state`` under the tip wrench ``W`` (None: the implied one,
        ``-Ad_{P_N}^-T F_N - w_N``) and the weights under ``g``: (W, K_tip in the base frame
        if ``base``, in the tool frame if ``tool``; else None). In the compiled kernel when it
        is available; singular systems raise ``LinAlgError``."""
        lib = self._library()
        if lib is not None:
            return self._tip_in_kernel(lib, state, W, g, base, tool)
        if W is None:
            AdT_N = adjoint(state.joint_frames[-1]).T
            W = -np.linalg.solve(AdT_N, state.wrenches[-1])
            if self.has_weights(g):
                W -= self.link_weights(state.link_transforms, g)[0][-1]
        if not (base or tool):
            return W, None, None
        _, D, AdT, Ad = self.equilibrium_system(state, W, g)
        n = self.n_joints
        # Twist coordinates: dr = D delta + Ad^T dW = 0, tip twist = sum_j Ad_j delta_j.
        X = np.linalg.solve(D, AdT.reshape(6 * n, 6))
        C = -Ad.transpose(1, 0, 2).reshape(6, 6 * n) @ X
        K = np.linalg.inv(C)
        K_tool = None
        if tool:
            Ad_tip = adjoint(state.tip_transform)
            K_tool = Ad_tip.T @ K @ Ad_tip
        return W, K if base else None, K_tool

    def _tip_in_kernel(self, lib: Any, state: ChainState, W: FloatArray | None, g: FloatArray,
                       base: bool, tool: bool
                       ) -> tuple[FloatArray, FloatArray | None, FloatArray | None]:
        """:meth:`_tip` in the compiled ``tsk_chain_tip``."""
        address = kernel.address
        # Every array whose address goes to C is bound to a name that outlives the call (a
        # copy made inside the argument list would be freed before C reads it).
        inputs = [np.ascontiguousarray(a, dtype=np.float64) for a in (
            state.joint_frames, state.link_transforms, state.tip_transform, state.wrenches,
            state.cartesian_stiffness)]
        weights = coms = None
        if self.has_weights(g):
            weights = self.link_masses[:, None] * g
            coms = np.ascontiguousarray(self.link_coms, dtype=np.float64).reshape(self.n_joints, 3)
        W_c = None if W is None else np.ascontiguousarray(W, dtype=np.float64)
        out = np.empty(kernel.TIP_SIZE)
        status = lib.chain_tip(
            self.n_joints, *(address(a) for a in inputs),
            None if weights is None else address(weights),
            None if coms is None else address(coms),
            None if W_c is None else address(W_c),
            (kernel.TIP_BASE if base else 0) | (kernel.TIP_TOOL if tool else 0),
            address(out), out.size)
        if status in (kernel.ERROR_SINGULAR_SYSTEM, kernel.ERROR_SINGULAR_COMPLIANCE):
            raise np.linalg.LinAlgError('Singular matrix')
        kernel.check(status, 'tsk_chain_tip')
        return (out[:6], out[6:42].reshape(6, 6) if base else None,
                out[42:].reshape(6, 6) if tool else None)

    def tip_outputs_from_state(self, state: ChainState, gravity: ArrayLike | None = None
                               ) -> tuple[FloatArray, FloatArray, FloatArray]:
        """At an evaluated ``state``: the implied tip wrench ``W`` (base) and the exact tip
        stiffness under ``W`` and the link weights, in the base and in the tool frame (what
        ``spine_node`` publishes per input). Singular configurations raise ``LinAlgError``."""
        return self._tip(state, None, self.resolved_gravity(gravity), True, True)

    def tip_stiffness_from_state(self, state: ChainState, tip_wrench: ArrayLike | None = None,
                                 gravity: ArrayLike | None = None, frame: str = 'base'
                                 ) -> FloatArray:
        """:meth:`tip_stiffness` at an evaluated ``state`` (no second evaluation)."""
        if frame not in ('base', 'tool'):
            raise ValueError(f"frame must be 'base' or 'tool', got {frame!r}")
        _, base, tool = self._tip(state, optional_vector('tip_wrench', tip_wrench),
                                  self.resolved_gravity(gravity), frame == 'base',
                                  frame == 'tool')
        return base if frame == 'base' else tool

    def tip_stiffness(self, screws: ArrayLike, tip_wrench: ArrayLike | None = None,
                      gravity: ArrayLike | None = None, frame: str = 'base',
                      rest_lengths: Any = None) -> FloatArray:
        """Exact tip stiffness ``K_tip = dW/d(delta)`` (6, 6) at ``screws`` under the tip wrench
        ``W`` (base, about its origin; default 0) and the link weights under ``gravity``
        (default: ``self.gravity``). Rows ``[f; m]``, columns ``[dv; dw]``; ``frame='tool'``:
        the same map in tool coordinates, ``Ad^T K Ad`` with ``Ad = Ad_{T_tip}``. Meaningful at
        an equilibrium of that load (see the module docstring); singular configurations raise
        ``numpy.linalg.LinAlgError``."""
        return self.tip_stiffness_from_state(self.evaluate(screws, rest_lengths), tip_wrench,
                                             gravity, frame)

    def residuals(self, screws: ArrayLike, tip_wrench: ArrayLike | None = None,
                  gravity: ArrayLike | None = None, rest_lengths: Any = None) -> FloatArray:
        """Equilibrium residuals ``r_i = F_i + Ad_{P_i}^T B_i`` (N, 6)."""
        state = self.evaluate(screws, rest_lengths)
        return self.equilibrium_system(state, optional_vector('tip_wrench', tip_wrench),
                                       self.resolved_gravity(gravity), False)[0]

    def residual_jacobian(self, screws: ArrayLike, tip_wrench: ArrayLike | None = None,
                          gravity: ArrayLike | None = None, rest_lengths: Any = None
                          ) -> FloatArray:
        """``dr/dxi`` (6N, 6N), joint-major rows and columns."""
        state = self.evaluate(screws, rest_lengths)
        D = self.equilibrium_system(state, optional_vector('tip_wrench', tip_wrench),
                                       self.resolved_gravity(gravity))[1]
        return self.residual_screw_jacobian(D, state.screws)

    def tangent_stiffness(self, screws: ArrayLike, tip_wrench: ArrayLike | None = None,
                          gravity: ArrayLike | None = None, rest_lengths: Any = None
                          ) -> FloatArray:
        """The chain's tangent stiffness (6N, 6N): minus the residuals' derivative with respect
        to the joints' spatial twists in {1}_i ([dv; dw]); K_c for one joint."""
        state = self.evaluate(screws, rest_lengths)
        return -self.equilibrium_system(state, optional_vector('tip_wrench', tip_wrench),
                                       self.resolved_gravity(gravity))[1]

    def implied_tip_wrench(self, screws: ArrayLike, gravity: ArrayLike | None = None,
                           rest_lengths: Any = None) -> FloatArray:
        """The tip wrench (base) that the last joint balances at ``screws``:
        ``-Ad_{P_N}^-T F_N - w_N`` (less the weight of link N when masses are set)."""
        return self.implied_tip_wrench_from_state(self.evaluate(screws, rest_lengths), gravity)

    def implied_tip_wrench_from_state(self, state: ChainState, gravity: ArrayLike | None = None
                                      ) -> FloatArray:
        """:meth:`implied_tip_wrench` at an evaluated ``state`` (no second evaluation)."""
        return self._tip(state, None, self.resolved_gravity(gravity), False, False)[0]

    def unloaded_screws(self, rest_lengths: Any = None) -> FloatArray:
        """Each joint's unloaded equilibrium (single-joint solver from its ``initial_screw``;
        cached per model for the configured rest lengths): (N, 6)."""
        rest = self.rest_lengths_per_joint(rest_lengths)
        out = np.empty((self.n_joints, 6))
        for i, (model, r) in enumerate(zip(self.joints, rest, strict=True)):
            if r is None and model in self._unloaded:
                out[i] = self._unloaded[model]
                continue
            res = solve_equilibrium(model, np.zeros(6), r)
            x = res.screw if res.success else model.initial_screw
            if r is None:
                self._unloaded[model] = x
            out[i] = x
        return out


# ---------------------------------------------------------------------------- equilibrium
@dataclass(frozen=True)
class ChainEquilibriumResult:
    """Outcome of :func:`solve_chain_equilibrium`.

    ``screws`` (N, 6) the equilibrium (or the best iterate when ``success`` is False);
    ``residual`` = |r| over all joints (N, N m); ``tip_transform`` (4, 4); ``tip_stiffness``
    (6, 6) in the base frame and ``tip_stiffness_tool`` in the tool frame (None when not
    converged or singular); ``stable``: the symmetric part of the chain's tangent stiffness is
    positive definite; ``state`` the :class:`ChainState` at ``screws``.
    """

    success: bool
    message: str
    screws: FloatArray
    residual: float
    iterations: int
    tip_transform: FloatArray | None
    tip_stiffness: FloatArray | None
    stable: bool
    tip_stiffness_tool: FloatArray | None = None
    state: ChainState | None = field(default=None, repr=False)

    @property
    def joint_wrenches(self) -> FloatArray | None:
        """String wrench of every joint at the solution (N, 6)."""
        return None if self.state is None else self.state.wrenches


def _clip_steps(step: FloatArray, lengths: FloatArray) -> FloatArray:
    """Scale the whole Newton step so that no joint turns by more than MAX_ROTATION_STEP or
    moves by more than MAX_TRANSLATION_STEP mean rest lengths."""
    rot = np.linalg.norm(step[:, :3], axis=1) / MAX_ROTATION_STEP
    tra = np.linalg.norm(step[:, 3:], axis=1) / (MAX_TRANSLATION_STEP * lengths)
    return step / max(float(rot.max()), float(tra.max()), 1.0)


def _rechart(x: FloatArray) -> FloatArray:
    theta = np.linalg.norm(x[:, :3], axis=1)
    if np.all(theta < RECHART_ANGLE):
        return x
    x = x.copy()
    for i in np.flatnonzero(theta >= RECHART_ANGLE):
        x[i] = log_se3(exp_se3(x[i]))
    return x


class _Problem:
    """One chain equilibrium problem: residual and Jacobian evaluation with guards."""

    def __init__(self, chain: JointChain, W: FloatArray, g: FloatArray, rest: Any,
                 deadline: float) -> None:
        self.chain, self.W, self.g, self.rest, self.deadline = chain, W, g, rest, deadline
        self.lengths = np.array([float(np.mean(m.rest_lengths if r is None else r))
                                 for m, r in zip(chain.joints, rest, strict=True)])

    def evaluate(self, x: FloatArray, scale: float = 1.0, tangent: bool = True
                 ) -> tuple[ChainState, FloatArray, FloatArray | None] | None:
        """(state, residuals (N, 6), dr/d(delta) or None); None when ``x`` is not admissible."""
        try:
            state = self.chain.evaluate(x, self.rest)
        except ValueError:  # a string of zero length, or out of the chart
            return None
        r, D, _, _ = self.chain.equilibrium_system(state, scale * self.W, scale * self.g, tangent)
        if not np.all(np.isfinite(r)):
            return None
        return state, r, D

    def newton(self, x: FloatArray, scale: float, max_iterations: int, tolerance: float
               ) -> tuple[FloatArray, float, int]:
        """Damped Newton (:func:`.newton.damped_newton`) on r(xi) with the analytic dr/dxi."""

        def evaluate(xi: FloatArray, tangent: bool
                     ) -> tuple[FloatArray, tuple[ChainState, FloatArray | None]] | None:
            got = self.evaluate(xi, scale, tangent)
            return None if got is None else (got[1], (got[0], got[2]))

        def jacobian(xi: FloatArray, context: tuple[ChainState, FloatArray | None]
                     ) -> FloatArray:
            state, D = context
            if D is None:
                D = self.chain.equilibrium_system(state, scale * self.W, scale * self.g)[1]
            return self.chain.residual_screw_jacobian(D, xi)

        return damped_newton(x, evaluate, jacobian, lambda step: _clip_steps(step, self.lengths),
                             _rechart, tolerance, max_iterations, self.deadline)

    def joint_by_joint(self, x0: FloatArray, tolerance: float, max_iterations: int
                       ) -> tuple[FloatArray, float, int] | None:
        """Without weights: solve joint 1, then joint 2 under the load moved into its frame,
        ... (the block-triangular structure), each with the single-joint solver."""
        chain = self.chain
        x = x0.copy()
        iterations = 0
        P = np.eye(4)
        for i, model in enumerate(chain.joints):
            load = adjoint(P).T @ self.W
            budget = self.deadline - time.perf_counter()
            if budget <= 0.0:
                return None
            res = solve_equilibrium(model, load, self.rest[i], x[i], tolerance=tolerance,
                                    max_iterations=max_iterations,
                                    time_budget=None if math.isinf(budget) else budget)
            iterations += res.iterations
            if not res.success:
                return None
            x[i] = res.screw
            P = P @ exp_se3(x[i])
            if i < chain.n_joints - 1:
                P = P @ chain.link_offsets[i]
        got = self.evaluate(x, tangent=False)
        if got is None:
            return None
        return x, float(np.linalg.norm(got[1])), iterations


def solve_chain_equilibrium(
    chain: JointChain,
    tip_wrench: ArrayLike,
    gravity: ArrayLike | None = None,
    rest_lengths: Any = None,
    initial_screws: ArrayLike | None = None,
    *,
    tolerance: float = RESIDUAL_TOLERANCE,
    max_iterations: int = MAX_NEWTON_ITERATIONS,
    time_budget: float | None = None,
) -> ChainEquilibriumResult:
    """Screws with ``F_i + Ad_{P_i}^T (W + weights of links i..N) = 0`` for every joint.

    ``tip_wrench`` W (6,) on link N in the base frame about its origin; ``gravity`` (3,) m/s^2
    in the base (default ``chain.gravity``); ``rest_lengths`` per joint (None, (N, n) or a
    sequence of N arrays or None); ``initial_screws`` (N, 6), default each joint's unloaded
    equilibrium. Bad input raises ValueError naming the field; an equilibrium that is not found
    returns ``success=False`` with the reason.
    """
    W = optional_vector('tip_wrench', tip_wrench)
    g = chain.resolved_gravity(gravity)
    rest = chain.rest_lengths_per_joint(rest_lengths)
    x0 = chain.unloaded_screws(rest) if initial_screws is None else chain.validated_screws(
        initial_screws).copy()
    deadline = solve_deadline(tolerance, max_iterations, time_budget)
    problem = _Problem(chain, W, g, rest, deadline)
    if problem.evaluate(x0, tangent=False) is None:
        return ChainEquilibriumResult(False, 'initial screws are not admissible (a string of '
                                      'zero length)', x0, math.inf, 0, None, None, False)
    x, norm, iterations = _search(problem, x0, tolerance, max_iterations)
    got = problem.evaluate(x)
    if got is None:
        return ChainEquilibriumResult(False, 'no usable equilibrium: the last iterate cannot '
                                      'be evaluated', x, math.inf, iterations, None, None, False)
    state, _, D = got
    if norm > tolerance:
        reason = 'time budget exhausted' if time.perf_counter() >= deadline else 'no convergence'
        return ChainEquilibriumResult(False, f'{reason}: residual |r| = {norm:.3e} after '
                                      f'{iterations} iterations', x, norm, iterations,
                                      state.tip_transform, None, False, None, state)
    return _equilibrium_result(chain, x, norm, iterations, state, D, W, g)


def _search(problem: _Problem, x0: FloatArray, tolerance: float, max_iterations: int
            ) -> tuple[FloatArray, float, int]:
    """Newton on the full load from ``x0``; if that stalls within the time budget, joint by
    joint (no link weights) and then continuation in the load. ``(x, |r|, iterations)``."""
    chain, deadline = problem.chain, problem.deadline
    x, norm, iterations = problem.newton(x0, 1.0, max_iterations, tolerance)
    if norm > tolerance and not chain.has_weights(problem.g) and time.perf_counter() < deadline:
        got = problem.joint_by_joint(x0, tolerance, max_iterations)
        if got is not None:
            iterations += got[2]
            if got[1] < norm:
                x, norm = got[0], got[1]
    if norm > tolerance and time.perf_counter() < deadline:
        y = x0
        for fraction in np.linspace(0.0, 1.0, CONTINUATION_STEPS + 1)[1:]:
            y, y_norm, extra = problem.newton(y, float(fraction), max_iterations, tolerance)
            iterations += extra
            if y_norm > tolerance:
                break
        else:
            x, norm = y, y_norm
    return x, norm, iterations


def _equilibrium_result(chain: JointChain, x: FloatArray, norm: float, iterations: int,
                        state: ChainState, D: FloatArray, W: FloatArray, g: FloatArray
                        ) -> ChainEquilibriumResult:
    """The result at a converged ``x``: failed when a joint's strings are all slack, else its
    stability (of ``-D``), tip stiffness (None when singular) and message."""
    slack = [int(np.count_nonzero(s)) for s in state.slack]
    loose = [i + 1 for i, (s, m) in enumerate(zip(slack, chain.joints, strict=True))
             if s == m.n_strings]
    if loose:
        return ChainEquilibriumResult(False, f'all strings of joints {loose} are slack: the '
                                      'chain is unconstrained', x, norm, iterations,
                                      state.tip_transform, None, False, None, state)
    stable = is_stable(-D)
    try:
        K = chain.tip_stiffness_from_state(state, W, g)
        Ad = adjoint(state.tip_transform)
        K_tool = Ad.T @ K @ Ad
    except np.linalg.LinAlgError:
        K = K_tool = None
    message = 'converged'
    if sum(slack):
        message += f' ({sum(slack)} slack strings)'
    if not stable:
        message += '; equilibrium is not stable'
    if K is None:
        message += '; tip stiffness is singular'
    return ChainEquilibriumResult(True, message, x, norm, iterations, state.tip_transform, K,
                                  stable, K_tool, state)
