"""Every array whose address goes to the compiled kernel lives until the call returns.

A copy made inside a call's argument list (``address(np.ascontiguousarray(x))``) is freed before
C reads it: C then reads freed memory, which the next allocation of that size gets. Two proofs:

* poisoned calls: the library's entry points are wrapped so that, after Python evaluated the
  arguments and before C runs, every freed buffer below 1024 bytes is handed out again (numpy's
  small-buffer cache gives the just-freed block to the next allocation of its size) and
  overwritten with NaN; the results must still equal the numpy path's. Strided rest lengths
  (one screw, a batch) and a strided tip wrench (a spine) are the inputs that are copied;
* AddressSanitizer (slow): the kernel compiled with ``-fsanitize=address`` evaluates a joint of
  200 strings (rest lengths of 1600 bytes, which numpy returns to malloc) with strided rest
  lengths, one screw and a batch with per-screw rest lengths; ASan must report nothing.

Both fail on the code before this test (commit 5525cc4) and pass now.
"""

import ctypes
import textwrap

import numpy as np
import pytest
from support.joint_compare import assert_same, random_model
from support.kernel_checks import assert_asan_clean, poisoned

from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel

pytestmark = pytest.mark.skipif(not kernel.available(), reason=kernel.status())

#: The entry points of the library that take addresses.
ENTRY_POINTS = ('evaluate', 'evaluate_packed', 'chain_frames', 'chain_tip', 'linear_model',
                'pose_terms', 'qp_warm_face', 'transform')


@pytest.fixture
def poisoned_library(monkeypatch):
    library = kernel.library()
    for name in ENTRY_POINTS:
        monkeypatch.setattr(library, name, poisoned(getattr(library, name)))
    return library


def numpy_twin(model: JointModel) -> JointModel:
    return JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                      link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
                      force_law=model.force_law, use_kernel=False)


@pytest.mark.parametrize('doubles', [6, 12, 120])
def test_poisoning_overwrites_freed_memory_before_the_call(doubles):
    """The poison works (a tip wrench, 12 and 120 rest lengths): a buffer freed before the
    call holds NaN when the wrapped function reads it."""
    seen = []

    def read(address: int, count: int) -> None:
        seen.extend((ctypes.c_double * count).from_address(address))

    freed = np.arange(1.0, doubles + 1.0)
    address = kernel.address(freed)
    del freed
    poisoned(read)(address, doubles)
    assert np.isnan(seen).all()


def test_strided_rest_lengths_outlive_the_call(poisoned_library):
    rng = np.random.default_rng(41)
    for force_law in ('hooke', 'paper'):
        model = random_model(rng, force_law, n=12)
        assert model.uses_kernel
        plain = numpy_twin(model)
        xi = np.r_[rng.normal(scale=0.3, size=3), rng.normal(scale=0.01, size=3)]
        rests = np.repeat(model.rest_lengths[:, None], 2, axis=1) * [1.0, 1.1]
        strided = rests[:, 1]  # a (n,) view with stride 16: copied for C
        assert not strided.flags.c_contiguous
        assert_same(model, model.evaluate(xi, strided), plain.evaluate(xi, strided))
        np.testing.assert_array_equal(model.stiffness(xi, strided),
                                      model.evaluate(xi, strided).stiffness)
        # A batch with strided per-screw rest lengths and strided screws.
        X = np.repeat(xi[None] + rng.normal(scale=0.01, size=(5, 6)), 2, axis=0)[::2]
        R = np.asfortranarray(np.repeat(rests[:, 1][None], 5, axis=0))  # copied for C
        assert_same(model, model.evaluate(X, R), plain.evaluate(X, R))


def test_a_strided_tip_wrench_outlives_the_call(poisoned_library):
    rng = np.random.default_rng(42)
    joints = [random_model(rng, 'hooke', n=12) for _ in range(3)]
    offsets = np.repeat(np.eye(4)[None], 2, axis=0)
    offsets[:, 2, 3] = 0.05
    fast = JointChain(joints, offsets)
    slow = JointChain(joints, offsets, use_kernel=False)
    screws = rng.normal(scale=[0.05] * 3 + [0.002] * 3, size=(3, 6))
    wrenches = np.zeros((6, 2))
    wrenches[:, 1] = [0.3, -0.2, 0.5, 0.01, 0.02, -0.01]
    W = wrenches[:, 1]  # strided: copied for C
    assert not W.flags.c_contiguous
    for frame in ('base', 'tool'):
        K_fast = fast.tip_stiffness(screws, tip_wrench=W, frame=frame)
        K_slow = slow.tip_stiffness(screws, tip_wrench=W, frame=frame)
        assert np.isfinite(K_fast).all()
        np.testing.assert_allclose(K_fast, K_slow, rtol=0.0, atol=1e-9 * np.abs(K_slow).max())


def test_the_linear_model_and_pose_terms_outlive_the_call(poisoned_library):
    """tsk_joint_linear_model (strided rest lengths and a strided load: copied into its
    buffers; strided string damping, copied for C) and tsk_joint_pose_terms (a strided pose)
    under the poisoned calls equal the numpy path."""
    from tensegrity_stiffness.control.controller import pose_terms_at, pose_terms_numpy
    from tensegrity_stiffness.mechanics.dynamics import JointDynamics, LinkInertia

    rng = np.random.default_rng(44)
    for force_law in ('hooke', 'paper'):
        model = random_model(rng, force_law, n=12)
        plain = numpy_twin(model)
        xi = np.r_[rng.normal(scale=0.3, size=3), rng.normal(scale=0.01, size=3)]
        rests = np.repeat(model.evaluate(xi).lengths[:, None], 2, axis=1) * [1.0, 0.95]
        rest = rests[:, 1]
        loads = np.zeros((6, 2))
        loads[:, 1] = -model.evaluate(xi, rest).wrench
        W = loads[:, 1]
        assert not rest.flags.c_contiguous and not W.flags.c_contiguous
        inertia = LinkInertia(0.02, (0.001, 0.0, -0.002), (2e-6, 3e-6, 4e-6))
        damping = rng.uniform(0.1, 0.5, (12, 2))[:, 1]  # strided: copied for C
        assert not damping.flags.c_contiguous
        fast, slow = JointDynamics(model, inertia, damping), JointDynamics(plain, inertia, damping)
        for new, old in zip(fast.linearize(xi, rest, W), slow.linearize(xi, rest, W),
                            strict=True):
            assert np.isfinite(new).all()
            np.testing.assert_allclose(new, old, rtol=0.0, atol=1e-12 * np.abs(old).max())
        T = np.asfortranarray(model.evaluate(xi).transform)  # copied into the kernel's buffer
        screws = np.repeat(xi[:, None], 2, axis=1)
        np.testing.assert_allclose(model.compiled_kernel.exp_se3(screws[:, 1]), T, rtol=0.0,
                                   atol=1e-15)  # a strided screw, copied into its buffer
        new, old = pose_terms_at(model, T), pose_terms_numpy(model, T)
        for name in ('lengths', 'B', 'K0', 'M', 'cap'):
            np.testing.assert_allclose(getattr(new, name), getattr(old, name), rtol=0.0,
                                       atol=1e-13 * np.abs(getattr(old, name)).max())


def test_the_warm_face_outlives_the_call(poisoned_library):
    """tsk_qp_warm_face with strided (copied) inputs under the poisoned calls equals the numpy
    path."""
    from tensegrity_stiffness.control.controller import warm_face, warm_face_numpy

    rng = np.random.default_rng(45)
    n, m = 12, 6
    G = rng.normal(size=(36, n))
    P = np.asfortranarray(G.T @ G)
    A = np.asfortranarray(rng.normal(size=(m, n)))
    lo, hi = rng.uniform(0.1, 0.4, (n, 2))[:, 0], rng.uniform(0.8, 1.5, (n, 2))[:, 1]
    t0 = 0.5 * (lo + hi)
    c, b = P @ t0 + A.T @ rng.normal(size=m), A @ t0
    free = np.zeros(n, bool)
    new = warm_face(P, c, A, b, lo, hi, t0, free, free)
    old = warm_face_numpy(P, c, A, b, lo, hi, t0, free, free)
    assert new is not None and old is not None
    np.testing.assert_allclose(new, old, rtol=0.0, atol=1e-12)


ASAN_SCRIPT = textwrap.dedent('''
    import numpy as np
    from tensegrity_stiffness.mechanics.joint import JointModel
    rng = np.random.default_rng(43)
    n = 200  # rest lengths of 1600 bytes: numpy frees such buffers to malloc (no cache)
    p1 = rng.normal(scale=0.05, size=(n, 3))
    p2 = rng.normal(scale=0.04, size=(n, 3)) + [0.0, 0.0, 0.1]
    conn = np.column_stack([np.arange(n), np.arange(n)])
    model = JointModel(p1, conn, 100.0, np.full(n, 0.05), link2_nodes=p2)
    assert model.uses_kernel
    rests = np.full((n, 2), 0.05)
    x = np.r_[0.01, -0.02, 0.03, 0.0, 0.0, 0.001]
    single = model.evaluate(x, rests[:, 1])
    X = np.repeat(x[None], 4, axis=0)
    R = np.asfortranarray(np.full((4, n), 0.05))
    batch = model.evaluate(X, R)
    assert np.isfinite(single.stiffness).all() and np.isfinite(batch.stiffness).all()
    print('ok')
''')


@pytest.mark.slow
def test_addresssanitizer_finds_no_use_after_free(tmp_path):
    assert_asan_clean(tmp_path, ASAN_SCRIPT)
