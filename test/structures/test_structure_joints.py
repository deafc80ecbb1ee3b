"""The joint and the spine through Structure equal today's results to 1e-12: the wrench and
K_c of a joint, every joint's wrench and the tip stiffness of a spine, their equilibria."""

import numpy as np
import pytest
from support.joint_compare import random_model

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.structures.joints import structure_from_chain
from tensegrity_stiffness.structures.structure import Structure

RTOL = 1e-12


def default_joint() -> JointModel:
    return JointModel.from_yaml(config.packaged_config_path())


def default_spine() -> JointChain:
    return JointChain.from_yaml(config.packaged_config_path('default_spine.yaml'))


def assert_close(new, old, name, rtol=RTOL):
    scale = max(np.max(np.abs(old)), 1e-300)
    np.testing.assert_allclose(new, old, rtol=0, atol=rtol * scale, err_msg=name)


def joint_cases():
    rng = np.random.default_rng(11)
    models = [default_joint(), random_model(rng), random_model(rng, 'paper')]
    for model in models:
        x0 = model.initial_screw
        yield model, x0
        for _ in range(3):
            yield model, x0 + rng.normal(scale=0.05, size=6)


@pytest.mark.parametrize('use_kernel', [False, True])
def test_a_joint_through_structure_has_its_wrench_and_cartesian_stiffness(use_kernel):
    for model, xi in joint_cases():
        structure = Structure.from_joint(model, use_kernel=use_kernel)
        T = np.array([np.eye(4), exp_se3(xi)])
        state = structure.evaluate(T)
        ref = model.evaluate(xi)
        arm = 1.0 + np.max(np.linalg.norm(model.link1_nodes, axis=1))
        scale = np.sum(np.abs(ref.tensions)) * arm
        assert np.max(np.abs(state.wrenches[1] - ref.wrench)) <= RTOL * scale
        assert_close(state.stiffness[6:, 6:], ref.cartesian_stiffness, 'K_c')
        np.testing.assert_allclose(state.tensions, ref.tensions, rtol=0,
                                   atol=RTOL * ref.tensions.max())
        np.testing.assert_array_equal(state.slack, ref.slack)
        np.testing.assert_array_equal(state.saturated, ref.saturated)


def test_a_spine_through_structure_has_every_joint_s_wrench():
    chain = default_spine()
    rng = np.random.default_rng(4)
    xi = chain.unloaded_screws() + rng.normal(scale=0.02, size=(chain.n_joints, 6))
    structure = structure_from_chain(chain, xi, use_kernel=False)
    state = structure.evaluate()
    ref = chain.evaluate(xi)
    # Joint i's wrench on link i in {1}_i is Ad_{P_i}^T of the strings' wrench about the base
    # origin; the structure's wrench on link i adds joint i+1's strings (on its link 1).
    from tensegrity_stiffness.geometry.transforms import adjoint

    Ad = adjoint(ref.joint_frames)
    base = np.linalg.solve(np.swapaxes(Ad, 1, 2), ref.wrenches[:, :, None])[:, :, 0]
    expected = base.copy()
    expected[:-1] -= base[1:]
    scale = np.sum(np.abs(ref.tensions))
    assert np.max(np.abs(state.wrenches[1:] - expected)) <= RTOL * scale
    np.testing.assert_allclose(state.poses[1:], ref.link_transforms, rtol=0, atol=1e-14)


def test_a_joint_s_equilibrium_through_structure_is_the_joint_s():
    from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
    from tensegrity_stiffness.structures.equilibrium import (
        body_stiffness,
        solve_structure_equilibrium,
    )

    model = default_joint()
    structure = Structure.from_joint(model)
    for W in (np.zeros(6), np.array([0.3, -0.2, 0.5, 0.004, 0.002, -0.003])):
        ref = solve_equilibrium(model, W, tolerance=1e-13)
        assert ref.success
        got = solve_structure_equilibrium(structure, loads={'link2': W}, tolerance=1e-13)
        assert got.success, got.message
        np.testing.assert_allclose(got.poses[1], exp_se3(ref.screw), rtol=0, atol=1e-12)
        assert got.stable == ref.stable
        # The stiffness a wrench on link 2 meets is K_c, at the joint's own solution exactly.
        at_ref = Structure.from_joint(model, pose=exp_se3(ref.screw)).evaluate()
        K = body_stiffness(at_ref.stiffness, structure.fixed, 1)
        assert_close(K, ref.cartesian_stiffness, 'K_c')


def test_a_spine_s_equilibrium_and_tip_stiffness_through_structure_are_the_spine_s():
    from tensegrity_stiffness.mechanics.chain import solve_chain_equilibrium
    from tensegrity_stiffness.structures.equilibrium import (
        body_stiffness,
        solve_structure_equilibrium,
    )

    chain = default_spine()
    chain = JointChain(chain.joints, chain.link_offsets, chain.tool,
                       link_masses=np.full(chain.n_joints, 0.02),
                       link_coms=np.tile([0.0, 0.0, 0.005], (chain.n_joints, 1)),
                       gravity=[0.0, -9.81, 0.0])
    W = np.array([0.1, 0.05, -0.2, 0.002, -0.001, 0.003])
    ref = solve_chain_equilibrium(chain, W, tolerance=1e-13)
    assert ref.success, ref.message
    structure = structure_from_chain(chain)
    tip = structure.body_names[-1]
    # Both solved to 1e-13: a residual r moves the poses by up to r / sigma_min, and this
    # balanced (not stable) equilibrium is soft, sigma_min = 3.8e-3 (docs/structures.md). At a
    # tolerance of 1e-12 the structure's solver stops where the poses differ by up to 5e-13.
    got = solve_structure_equilibrium(structure, loads={tip: W}, tolerance=1e-13)
    assert got.success, got.message
    np.testing.assert_allclose(got.poses[1:], ref.state.link_transforms, rtol=0, atol=RTOL)
    assert got.stable == ref.stable
    # The tip stiffness at the spine's own solution, exactly.
    at_ref = structure_from_chain(chain, ref.screws)
    T = at_ref.start_poses()
    K = at_ref.evaluate(T).stiffness + at_ref.gravity_wrenches(T)[1]
    assert_close(body_stiffness(K, at_ref.fixed, chain.n_joints), ref.tip_stiffness, 'K_tip')


@pytest.mark.parametrize('damping', [0.0, 0.05])
def test_a_joint_s_modes_through_structure_are_the_joint_dynamics(damping):
    """The structure's modes (twists, its own mass matrix and damping) and the joint's
    dynamics (screw coordinates, Euler-Lagrange) give the same frequencies and damping ratios
    at the unloaded equilibrium."""
    from tensegrity_stiffness.mechanics.dynamics import JointDynamics, LinkInertia
    from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
    from tensegrity_stiffness.structures.modes import structure_modes

    model = default_joint()
    inertia = LinkInertia(0.02, (0.001, -0.002, 0.003), (2e-6, 3e-6, 4e-6))
    ref = JointDynamics(model, inertia, string_damping=damping).modes(model.initial_screw)
    structure = Structure.from_joint(model, inertia=inertia, string_damping=damping)
    modes = structure_modes(structure, solve_structure_equilibrium(structure, tolerance=1e-13))
    assert modes.zero_modes == ()
    np.testing.assert_allclose(modes.frequencies, ref.frequencies, rtol=1e-8)
    if damping:
        np.testing.assert_allclose(modes.damping_ratios, ref.damping_ratios, rtol=1e-6)


@pytest.mark.parametrize('damping', [0.0, 0.05])
def test_a_spine_s_modes_through_structure_are_the_chain_dynamics(damping):
    from tensegrity_stiffness.mechanics.dynamics import ChainDynamics, twin_link_inertias
    from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
    from tensegrity_stiffness.structures.modes import structure_modes

    chain = default_spine()
    inertias = twin_link_inertias(chain)
    ref = ChainDynamics(chain, inertias, damping).modes(chain.unloaded_screws())
    structure = structure_from_chain(chain, inertias=inertias, string_damping=damping)
    result = solve_structure_equilibrium(structure, tolerance=1e-12)
    assert result.success, result.message
    modes = structure_modes(structure, result)
    assert modes.zero_modes == ()
    np.testing.assert_allclose(modes.frequencies, ref.frequencies, rtol=1e-7)
    if damping:
        np.testing.assert_allclose(modes.damping_ratios, ref.damping_ratios, rtol=1e-6)
