"""Shared checks of the joint tests: random joint models and the 1e-13 comparison of two
:class:`~tensegrity_stiffness.mechanics.joint.JointState` (per quantity, relative to its largest
entry; the
wrench relative to the sum of the moduli of its string contributions, as it cancels to ~0 at an
equilibrium; region masks equal)."""

import numpy as np

from tensegrity_stiffness.mechanics.joint import JointModel

RTOL = 1e-13
FIELDS = ('transform', 'string_vectors', 'lengths', 'tensions', 'stiffness',
          'cartesian_stiffness')


def random_model(rng, force_law='hooke', n1=5, n2=4, n=9):
    """Own link-2 node set, random strings, stiffnesses, rest lengths and (some) limits."""
    p1 = rng.normal(scale=0.05, size=(n1, 3))
    p2 = rng.normal(scale=0.04, size=(n2, 3))
    conn = np.column_stack([rng.integers(0, n1, n), rng.integers(0, n2, n)])
    rest = rng.uniform(0.02, 0.08, n)
    lmax = rest + rng.uniform(0.005, 0.05, n)
    lmax[rng.random(n) < 0.3] = np.inf
    return JointModel(p1, conn, rng.uniform(20.0, 120.0, n), rest, link2_nodes=p2,
                      max_lengths=lmax, force_law=force_law)


def assert_same(model, state, ref):
    """``state`` equals ``ref`` to RTOL (see the module docstring)."""
    np.testing.assert_array_equal(state.slack, ref.slack)
    np.testing.assert_array_equal(state.saturated, ref.saturated)
    np.testing.assert_array_equal(state.screw, ref.screw)
    for name in FIELDS:
        new, old = getattr(state, name), getattr(ref, name)
        assert new.shape == old.shape and new.dtype == old.dtype, name
        scale = np.max(np.abs(old), initial=0.0)
        np.testing.assert_allclose(new, old, rtol=0.0, atol=RTOL * scale, err_msg=name)
    arm = 1.0 + np.max(np.linalg.norm(model.link1_nodes, axis=1))
    scale = np.sum(np.abs(ref.tensions), axis=-1, keepdims=True) * arm
    assert state.wrench.shape == ref.wrench.shape
    assert np.all(np.abs(state.wrench - ref.wrench) <= RTOL * scale + 1e-300)
