"""Dynamics of a spine (:class:`~tensegrity_stiffness.mechanics.chain.JointChain`) in its joints'
screw coordinates (6N, joint-major): mass matrix, equations of motion, linear model at an
equilibrium and modes, built on each joint's
(:class:`~tensegrity_stiffness.mechanics.joint_dynamics.JointDynamics`, whose module docstring
gives the conventions).

* Link i's body twist ``V_i = Ad_{X_i^-1} V_{i-1} + J_b(xi_i) xi_dot_i`` with
  ``X_i = O_{i-1} T_i`` (:mod:`~tensegrity_stiffness.mechanics.chain`); ``M = sum_i Jc_i^T G_i
  Jc_i`` over the links' body Jacobians ``Jc_i`` (6, 6N); the generalized force of joint i is
  ``J_l(xi_i)^T Pi r_i`` with ``r_i`` the chain's equilibrium residual (strings, tip wrench and
  link weights above joint i), so that ``dQ/dxi = diag(J_l^T Pi) dr/dxi`` at an equilibrium with
  the chain's closed-form residual Jacobian.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import (
    BLOCK_SWAP,
    ScrewKinematics,
    check_in_chart,
    small_adjoint,
)
from tensegrity_stiffness.geometry.screw_jacobians import body_jacobian_rate
from tensegrity_stiffness.geometry.transforms import (
    adjoint,
    adjoint_screw_order,
    inverse_transform,
)
from tensegrity_stiffness.geometry.validation import finite_array, optional_vector
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.inertia import (
    LinkInertia,
    chain_inertias_from_config,
    twin_link_inertias,
)
from tensegrity_stiffness.mechanics.joint_dynamics import (
    EQUILIBRIUM_TOLERANCE,
    JointDynamics,
    config_string_damping,
    per_string_damping,
)
from tensegrity_stiffness.mechanics.modes import (
    ComplexArray,
    JointModes,
    frequency_response,
    state_matrix_modes,
    undamped_modes,
)

FloatArray = NDArray[np.float64]


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
        self.string_damping = [per_string_damping(c, m.n_strings, f'string_damping[{i}]')
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
        damping = config_string_damping(document)  # the section's keys checked even when given
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
                L = jd.length_jacobian(state.string_vectors, state.lengths, Jl)
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
            dQdl[blk, starts[i]:starts[i + 1]] = Jl.T @ jd.rest_derivative(states[i], rest[i])
            dQdW[blk] = JT[blk, blk] @ Ad[i].T
            if jd.damped:
                L = jd.length_jacobian(states[i].string_vectors, states[i].lengths, Jl)
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
            return undamped_modes(A[m:, :m], twist, xi)
        return state_matrix_modes(A, twist, xi, True)

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
        return frequency_response(A, B[:, -6:], C, frequencies_hz)


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
