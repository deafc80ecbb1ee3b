"""Dynamics of a joint's link 2 in screw coordinates: mass matrix, equations of motion, linear
model and modes.

The joint's link 2 is a rigid body moved by its screw coordinates ``xi = [omega; v]``
(``T = exp(hat(xi))``, eq. 2 of Monke & Vikas); this module gives the Euler-Lagrange equations
in those coordinates, their linearisation (for LQR / MPC) and the vibration modes
(:mod:`~tensegrity_stiffness.mechanics.modes`); the link's mass properties are
:mod:`~tensegrity_stiffness.mechanics.inertia`'s, a spine's dynamics
:mod:`~tensegrity_stiffness.mechanics.chain_dynamics`'. numpy / scipy only; time integration is
the twin's (MuJoCo, :mod:`~tensegrity_stiffness.simulation.twin`), which the tests use to prove
these models.

Conventions (every twist here is in the ``[omega; v]`` order of the screws, every wrench in the
matching ``[m; f]`` order, unless it says ``[f; m]`` / ``[v; w]`` as the rest of the package)
------------------------------------------------------------------------------------------
* Body twist of link 2, in {2}: ``hat(V_b) = T^-1 dT/dt``, ``V_b = J_b(xi) xi_dot`` with
  ``J_b(xi) = J_r(xi) = J_l(-xi)`` (the SE(3) right Jacobian, from the closed-form left Jacobian
  of :class:`~tensegrity_stiffness.geometry.screw.ScrewKinematics`: exact at every angle, including
  ``|omega| -> 0`` (series branch) and near ``pi``).
* Spatial inertia ``G`` about the origin of {2}, in {2}
  (:meth:`~tensegrity_stiffness.mechanics.inertia.LinkInertia.spatial_inertia`).
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
* Modes: those of ``A`` (:func:`~tensegrity_stiffness.mechanics.modes.state_matrix_modes`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.screw import (
    BLOCK_SWAP,
    ScrewKinematics,
    single_screw,
    small_adjoint,
)
from tensegrity_stiffness.geometry.screw_jacobians import body_jacobian_rate, jacobian_derivatives
from tensegrity_stiffness.geometry.transforms import adjoint_screw_order, inverse_transform
from tensegrity_stiffness.geometry.validation import finite_array, optional_vector
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.inertia import LinkInertia
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.modes import (
    ComplexArray,
    JointModes,
    frequency_response,
    state_matrix_modes,
    undamped_modes,
)
from tensegrity_stiffness.mechanics.plausibility import check_dynamics

FloatArray = NDArray[np.float64]

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
#: A state counts as an equilibrium when ``|F + W|`` (N, N m) is at most this times the largest
#: string tension (plus 1e-300): the linear model then skips the derivatives of ``J`` and ``M``.
EQUILIBRIUM_TOLERANCE = 1e-9


def config_string_damping(document: Any) -> Any:
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


def per_string_damping(value: ArrayLike, n: int, name: str = 'string_damping') -> FloatArray:
    """The string damping (n,) N s/m of ``value`` (a scalar or one per string, each >= 0);
    ValueError naming ``name`` otherwise."""
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
        self._string_damping = per_string_damping(string_damping, model.n_strings)
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
        damping = config_string_damping(document)  # the section's keys checked even when given
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
        return self.length_jacobian(state.string_vectors, state.lengths,
                                     ScrewKinematics(x).J)

    def _unit_wrenches(self, s: FloatArray, lengths: FloatArray) -> FloatArray:
        """(n, 6) ``[p1_j x u_j, u_j]`` (``[m; f]``): each string's wrench per newton."""
        u = s / lengths[:, None]
        out = np.empty((u.shape[0], 6))
        out[:, :3] = self._p1_yzx * u[:, self._zxy] - self._p1_zxy * u[:, self._yzx]
        out[:, 3:] = u
        return out

    def length_jacobian(self, s: FloatArray, lengths: FloatArray, Jl: FloatArray) -> FloatArray:
        """``L = dl/dxi`` (n, 6) of the string vectors ``s`` (n, 3) and lengths (n,) of a state
        and the left Jacobian ``J_l`` at its screw (what :meth:`string_length_jacobian`
        computes from a screw)."""
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
            L = self.length_jacobian(state.string_vectors, state.lengths, Jl)
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

    def rest_derivative(self, state: Any, rest: FloatArray,
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
            parts.append(Jl.T @ self.rest_derivative(state, rest, unit))
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
            return undamped_modes(A21, Jl[BLOCK_SWAP], x)
        A = np.zeros((12, 12))
        A[:6, 6:] = np.eye(6)
        A[6:, :6] = A21
        A[6:, 6:] = A22
        return state_matrix_modes(A, Jl[BLOCK_SWAP], x, self.damped)

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
        return frequency_response(A, B[:, -6:], C, frequencies_hz)
