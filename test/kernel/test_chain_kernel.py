"""The compiled chain kernel (frames, implied tip wrench, tip stiffness) against the numpy path.

``JointChain(use_kernel=False)`` is the reference (itself checked against re-solved equilibria
in ``test_chain.py``). The kernel must give the same frames to 1e-14, the implied tip wrench to
1e-12 of the joint wrenches' scale and the tip stiffness (base and tool frames) to 1e-10 of its
largest entry, with and without link weights and tip loads, for N = 1..6 and chains of distinct
joint models; singular configurations raise ``LinAlgError`` on both paths.
"""

from __future__ import annotations

import os
import pickle

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from support import REPO

from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.spine_node import spine_outputs

REPO = REPO
GRAVITY = np.array([0.0, -9.81, 0.0])

pytestmark = pytest.mark.skipif(
    os.environ.get(kernel.KERNEL_ENV, '').lower() in kernel.OFF_VALUES,
    reason=f'{kernel.KERNEL_ENV} selects the numpy path')


def pose(rng: np.random.Generator, rotation: float, translation: float,
         base: np.ndarray | None = None) -> np.ndarray:
    T = np.eye(4)
    T[:3, :3] = Rotation.from_rotvec(rng.normal(scale=rotation, size=3)).as_matrix()
    T[:3, 3] = rng.normal(scale=translation, size=3)
    return T if base is None else base @ T


def chains(rng: np.random.Generator, n: int, masses: bool) -> tuple[JointChain, JointChain]:
    """A chain of ``n`` joints (two distinct models, perturbed offsets, a tilted tool) with the
    kernel and the same chain on the numpy path."""
    spine = JointChain.from_yaml(REPO / 'config' / 'default_spine.yaml')
    base_model = spine.joints[0]
    other = base_model.with_rest_lengths(base_model.rest_lengths * 1.02)
    joints = [base_model if i % 2 == 0 else other for i in range(n)]
    offsets = [pose(rng, 0.2, 0.005, spine.link_offsets[0]) for _ in range(n - 1)]
    tool = pose(rng, 0.5, 0.02, spine.tool)
    kwargs = dict(link_masses=np.full(n, 0.02) if masses else None,
                  link_coms=rng.normal(scale=0.01, size=(n, 3)), gravity=GRAVITY)
    fast = JointChain(joints, offsets, tool, **kwargs)
    slow = JointChain(joints, offsets, tool, use_kernel=False, **kwargs)
    return fast, slow


def near_unloaded(chain: JointChain, rng: np.random.Generator) -> np.ndarray:
    x = chain.unloaded_screws()
    return x + rng.normal(scale=[0.02] * 3 + [0.001] * 3, size=x.shape)


def assert_close(a: np.ndarray, b: np.ndarray, rtol: float, name: str) -> None:
    scale = np.max(np.abs(b), initial=0.0)
    np.testing.assert_allclose(a, b, rtol=0.0, atol=rtol * scale + 1e-300, err_msg=name)


def test_the_chain_kernel_is_loaded():
    assert kernel.available(), kernel.status()
    fast, slow = chains(np.random.default_rng(1), 2, False)
    assert fast._library() is not None and slow._library() is None


@pytest.mark.parametrize('masses', [False, True])
@pytest.mark.parametrize('n', [1, 2, 3, 6])
def test_frames_wrench_and_tip_stiffness_equal_the_numpy_path(n, masses):
    rng = np.random.default_rng(10 * n + masses)
    fast, slow = chains(rng, n, masses)
    for _ in range(15):
        x = near_unloaded(fast, rng)
        a, b = fast.evaluate(x), slow.evaluate(x)
        for name in ('joint_frames', 'link_transforms', 'tip_transform'):
            assert_close(getattr(a, name), getattr(b, name), 1e-14, name)
        W_fast = fast.implied_tip_wrench_from_state(a)
        W_slow = slow.implied_tip_wrench_from_state(b)
        wrench_scale = np.abs(b.wrenches).max()
        np.testing.assert_allclose(W_fast, W_slow, rtol=0.0, atol=1e-12 * wrench_scale)
        for W in (None, W_slow, rng.normal(scale=[0.3] * 3 + [0.01] * 3)):
            for frame in ('base', 'tool'):
                assert_close(fast.tip_stiffness_from_state(a, W, frame=frame),
                             slow.tip_stiffness_from_state(b, W, frame=frame), 1e-10,
                             f'K_tip ({frame}, W={W})')
        for new, old in zip(fast.tip_outputs_from_state(a), slow.tip_outputs_from_state(b),
                            strict=True):
            assert_close(new, old, 1e-10, 'tip outputs')
        # The same at zero gravity (weights off) and under another gravity vector.
        for g in (np.zeros(3), np.array([0.0, 0.0, -9.81])):
            assert_close(fast.tip_stiffness_from_state(a, W_slow, g),
                         slow.tip_stiffness_from_state(b, W_slow, g), 1e-10, f'g={g}')


def test_spine_outputs_equal_the_numpy_path():
    rng = np.random.default_rng(5)
    fast, slow = chains(rng, 5, True)
    for _ in range(20):
        x = near_unloaded(fast, rng)
        a, b = spine_outputs(fast, x), spine_outputs(slow, x)
        for name in ('tip_wrench', 'tip_stiffness_tool', 'tip_stiffness_base'):
            assert_close(getattr(a, name), getattr(b, name), 1e-10, name)


def test_a_singular_chain_raises_on_both_paths():
    """All strings slack: K_c = 0 and the chain has no stiffness."""
    spine = JointChain.from_yaml(REPO / 'config' / 'default_spine.yaml')
    model = spine.joints[0]
    loose = model.with_rest_lengths(model.rest_lengths * 10.0)
    x = spine.unloaded_screws()[:2]
    for use_kernel in (True, False):
        chain = JointChain([loose, loose], spine.link_offsets[:1], use_kernel=use_kernel)
        state = chain.evaluate(x)
        assert state.slack.all()
        with pytest.raises(np.linalg.LinAlgError):
            chain.tip_stiffness_from_state(state)
        with pytest.raises(ValueError, match='singular'):
            spine_outputs(chain, x)


def test_a_pickled_chain_keeps_the_kernel_and_its_cache():
    fast, _ = chains(np.random.default_rng(7), 3, True)
    x = near_unloaded(fast, np.random.default_rng(8))  # fills the unloaded-screw cache
    copy = pickle.loads(pickle.dumps(fast))
    assert copy._library() is not None
    np.testing.assert_array_equal(copy.tip_stiffness(x), fast.tip_stiffness(x))
    # The cache travels keyed by the copied models themselves, one entry per distinct model.
    assert set(copy._unloaded) == set(copy.joints)
    np.testing.assert_array_equal(copy.unloaded_screws(), fast.unloaded_screws())


def test_joint_models_in_a_chain_use_the_kernel():
    fast, _ = chains(np.random.default_rng(9), 3, False)
    assert all(isinstance(m, JointModel) and m.uses_kernel for m in fast.joints)
