"""Seeded screws and loads the tests and the accuracy bench share, and the exact reference of
dT/dxi they are checked against."""

from __future__ import annotations

import math

import numpy as np
from scipy.linalg import expm

from tensegrity_stiffness.geometry.screw import hat


def random_screws(rng: np.random.Generator, n: int, max_angle: float = math.pi,
                  translation: float = 1.0) -> np.ndarray:
    """n screws (n, 6): a uniform random axis, an angle uniform in [0, max_angle), a normal
    translation part of scale ``translation``."""
    axis = rng.normal(size=(n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0.0, max_angle, size=(n, 1))
    return np.hstack([axis * angle, rng.normal(scale=translation, size=(n, 3))])


def reference_dexp(xi: np.ndarray) -> np.ndarray:
    """Exact dT/dxi (4, 4, 6) from the block-triangular matrix exponential (Van Loan):
    expm([[A, E], [0, A]]) has d/dt expm(A + t E) as its upper-right block."""
    A = hat(xi)
    out = np.zeros((4, 4, 6))
    for i in range(6):
        E = hat(np.eye(6)[i])
        block = np.block([[A, E], [np.zeros((4, 4)), A]])
        out[:, :, i] = expm(block)[:4, 4:]
    return out


def moderate_wrench(rng: np.random.Generator) -> np.ndarray:
    """A load of about a third of the default joint's preload: forces ~0.1 N (tensions
    0.3-0.55 N), moments ~2 mN m."""
    return np.r_[rng.normal(scale=0.1, size=3), rng.normal(scale=0.002, size=3)]
