"""The body Jacobian of screw coordinates and its derivatives, from the exponential of
block-bidiagonal matrices (exact to rounding at every angle).

A screw ``xi = [omega; v]`` moves link 2 to ``T = exp(hat(xi))`` (eq. 2 of Monke & Vikas); its
body twist in {2} is ``hat(V_b) = T^-1 dT/dt = hat(J_b(xi) xi_dot)`` with ``J_b(xi) = J_l(-xi)``
(the SE(3) right Jacobian, from the closed-form left Jacobian of
:class:`~tensegrity_stiffness.geometry.screw.ScrewKinematics`). The second derivatives of
``exp`` along ``xi + t rate`` are the (1, 3) block of the exponential of
``[[X, E, 0], [0, X, E], [0, 0, X]]`` (``X = hat(xi)``, ``E = hat(rate)``). The dynamics
(:mod:`~tensegrity_stiffness.mechanics.dynamics`) and the filters are built on them.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg
from numpy.typing import ArrayLike, NDArray

from tensegrity_stiffness.geometry.screw import ScrewKinematics, hat, single_screw, vee
from tensegrity_stiffness.geometry.transforms import inverse_transform
from tensegrity_stiffness.geometry.validation import optional_vector

FloatArray = NDArray[np.float64]


def body_jacobian(xi: ArrayLike) -> FloatArray:
    """``J_b(xi) = J_l(-xi)`` (6, 6): ``xi_dot`` to link 2's body twist ``[w; v]`` in {2}
    (``hat(V_b) = T^-1 dT/dt``). Exact at every angle (closed form with series branch)."""
    return ScrewKinematics(-single_screw(xi, 'xi')).J


def block_exponential(xi: FloatArray, rate: FloatArray) -> tuple[FloatArray, ...]:
    """``T``, ``dT/dt`` and ``d^2 T / dt^2 / 2`` along ``xi + t rate`` at t = 0: blocks of the
    exponential of ``[[X, E, 0], [0, X, E], [0, 0, X]]`` (``X = hat(xi)``, ``E = hat(rate)``)."""
    X, E = hat(xi), hat(rate)
    big = np.zeros((12, 12))
    for k in range(3):
        big[4 * k:4 * k + 4, 4 * k:4 * k + 4] = X
    big[:4, 4:8] = E
    big[4:8, 8:] = E
    P = scipy.linalg.expm(big)
    return P[:4, :4], P[:4, 4:8], P[:4, 8:]


def body_jacobian_rate(xi: ArrayLike, xi_dot: ArrayLike) -> FloatArray:
    """``(d J_b / dt) xi_dot`` (6,) along ``xi + t xi_dot``: ``vee(T^-1 Tddot - hat(V_b)^2)``
    with ``Tddot`` the second derivative of ``exp`` (the Coriolis part of the body
    acceleration, ``V_b_dot = J_b xi_ddot + Jdot_b xi_dot``)."""
    x, r = single_screw(xi, 'xi'), optional_vector('xi_dot', xi_dot)
    T, T1, S = block_exponential(x, r)
    Ti = inverse_transform(T)
    Vh = Ti @ T1
    return vee(Ti @ (2.0 * S) - Vh @ Vh)


def exp_second_derivatives(xi: FloatArray) -> FloatArray:
    """All mixed second derivatives ``d^2 T / dxi_i dxi_k`` (6, 6, 4, 4) by polarization of
    ``D^2 exp[E, E] = 2 S(E)`` (21 block exponentials)."""
    E = np.eye(6)
    S = np.empty((6, 4, 4))
    for i in range(6):
        S[i] = block_exponential(xi, E[i])[2]
    out = np.empty((6, 6, 4, 4))
    for i in range(6):
        out[i, i] = 2.0 * S[i]
        for k in range(i + 1, 6):
            mixed = block_exponential(xi, E[i] + E[k])[2] - S[i] - S[k]
            out[i, k] = out[k, i] = mixed
    return out


def jacobian_derivatives(xi: ArrayLike) -> tuple[FloatArray, FloatArray]:
    """``dJ_l/dxi_i`` and ``dJ_b/dxi_i`` (each (6, 6, 6), index i first), from the mixed second
    derivatives of ``exp``: column k of ``J_l`` is ``vee(dT/dxi_k T^-1)``, of ``J_b``
    ``vee(T^-1 dT/dxi_k)``."""
    x = single_screw(xi, 'xi')
    T, _, _ = block_exponential(x, np.zeros(6))
    Ti = inverse_transform(T)
    first = np.empty((6, 4, 4))
    for k in range(6):
        first[k] = block_exponential(x, np.eye(6)[k])[1]
    second = exp_second_derivatives(x)
    dJl = np.empty((6, 6, 6))
    dJb = np.empty((6, 6, 6))
    for i in range(6):
        for k in range(6):
            dJl[i, :, k] = vee(second[i, k] @ Ti - first[k] @ Ti @ first[i] @ Ti)
            dJb[i, :, k] = vee(Ti @ second[i, k] - Ti @ first[i] @ Ti @ first[k])
    return dJl, dJb
