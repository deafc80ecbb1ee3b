"""Chains of tensegrity joints: kinematics, exact tip stiffness, chain equilibria, config, CLI.

Every derivative is checked against central differences: the tip Jacobian against
``tip_transform``, the residual Jacobian against the residuals, and the tip stiffness against the
full equilibrium solve (perturb W, re-solve, tip twist by the log map; a 4th-order stencil).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from support import JOINT_CONFIG, REPO, SPINE_CONFIG
from support.screw_samples import moderate_wrench as joint_moderate_wrench

from tensegrity_stiffness import cli
from tensegrity_stiffness.cli.figure_commands import png_size
from tensegrity_stiffness.geometry.screw import exp_se3, hat3, log_se3
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
from tensegrity_stiffness.mechanics.equilibrium import is_stable, solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel

REPO = REPO
RESIDUAL_GOAL = 1e-9
#: Relative tolerances of the derivative checks (the issue's figures).
JACOBIAN_TOLERANCE = 1e-7
TIP_STIFFNESS_TOLERANCE = 1e-6
GRAVITY = np.array([0.0, -9.81, 0.0])
LINK_MASS = 0.02


@pytest.fixture(scope='module')
def model() -> JointModel:
    return JointModel.from_yaml(JOINT_CONFIG)


@pytest.fixture(scope='module')
def spine() -> JointChain:
    return JointChain.from_yaml(SPINE_CONFIG)


def perturbed(T: np.ndarray, rng: np.random.Generator, rotation: float = 0.2,
              translation: float = 0.005) -> np.ndarray:
    D = np.eye(4)
    D[:3, :3] = Rotation.from_rotvec(rng.normal(scale=rotation, size=3)).as_matrix()
    D[:3, 3] = rng.normal(scale=translation, size=3)
    return T @ D


def three_joints(model: JointModel, spine: JointChain, seed: int = 1, masses: bool = False
                 ) -> JointChain:
    """N = 3 with non-identity offsets (the spine's, perturbed) and a tilted, shifted tool."""
    rng = np.random.default_rng(seed)
    offsets = [perturbed(spine.link_offsets[0], rng) for _ in range(2)]
    tool = perturbed(spine.tool, rng, 0.5, 0.02)
    coms = rng.normal(scale=0.01, size=(3, 3))
    return JointChain([model] * 3, offsets, tool,
                      link_masses=[LINK_MASS] * 3 if masses else None, link_coms=coms)


def moderate_wrench(rng: np.random.Generator) -> np.ndarray:
    """The single joint's moderate load, a third of it: the tip of three vertebrae has a lever
    arm of ~0.1 m on joint 1."""
    return joint_moderate_wrench(rng) / 3.0


def twist(T: np.ndarray) -> np.ndarray:
    """[dv; dw] of a transform near I (log map, linear first)."""
    xi = log_se3(T)
    return np.r_[xi[3:], xi[:3]]


def block_errors(K: np.ndarray, K_ref: np.ndarray) -> np.ndarray:
    """Per 3x3 block |K - K_ref| / scale; scale = the block's norm, at least the geometric mean
    of the two diagonal blocks' norms (off-diagonal blocks can vanish by symmetry)."""
    out = np.empty((2, 2))
    norms = [np.linalg.norm(K_ref[3 * a:3 * a + 3, 3 * a:3 * a + 3]) for a in range(2)]
    for a in range(2):
        for b in range(2):
            ref = K_ref[3 * a:3 * a + 3, 3 * b:3 * b + 3]
            scale = max(np.linalg.norm(ref), math.sqrt(norms[a] * norms[b]))
            out[a, b] = np.linalg.norm(K[3 * a:3 * a + 3, 3 * b:3 * b + 3] - ref) / scale
    return out


def numerical_tip_stiffness(chain: JointChain, W: np.ndarray, g: np.ndarray | None,
                            screws: np.ndarray) -> np.ndarray:
    """dW/d(delta) from re-solved equilibria (4th-order central differences of the tip twist)."""
    T0_inv = np.linalg.inv(chain.tip_transform(screws))
    C = np.empty((6, 6))
    for k in range(6):
        h = 1e-3 if k < 3 else 1e-5  # N, N m
        twists = []
        for s in (2, 1, -1, -2):
            d = np.zeros(6)
            d[k] = s * h
            res = solve_chain_equilibrium(chain, W + d, g, initial_screws=screws,
                                          tolerance=1e-13)
            assert res.success, res.message
            twists.append(twist(res.tip_transform @ T0_inv))
        C[:, k] = (-twists[0] + 8 * twists[1] - 8 * twists[2] + twists[3]) / (12 * h)
    return np.linalg.inv(C)


# ---------------------------------------------------------------------------- kinematics
def test_tip_transform_is_the_product_of_joints_and_offsets(model, spine):
    chain = three_joints(model, spine)
    rng = np.random.default_rng(2)
    x = chain.unloaded_screws() + rng.normal(scale=0.1, size=(3, 6)) * [1, 1, 1, .01, .01, .01]
    T = [exp_se3(xi) for xi in x]
    off = chain.link_offsets
    expected = T[0] @ off[0] @ T[1] @ off[1] @ T[2] @ chain.tool
    np.testing.assert_allclose(chain.tip_transform(x), expected, atol=1e-15)
    L = chain.link_transforms(x)
    np.testing.assert_allclose(L[1], T[0] @ off[0] @ T[1], atol=1e-15)
    np.testing.assert_allclose(L[2] @ chain.tool, expected, atol=1e-15)


def test_jacobian_against_central_differences(model, spine):
    chain = three_joints(model, spine)
    rng = np.random.default_rng(3)
    h = 1e-6
    for _ in range(5):
        x = chain.unloaded_screws() + rng.normal(scale=0.3, size=(3, 6)) * [1, 1, 1, .01, .01,
                                                                             .01]
        J = chain.jacobian(x)
        assert J.shape == (6, 18)
        T0_inv = np.linalg.inv(chain.tip_transform(x))
        Jn = np.empty((6, 18))
        for c in range(18):
            d = np.zeros(18)
            d[c] = h
            plus = twist(chain.tip_transform(x + d.reshape(3, 6)) @ T0_inv)
            minus = twist(chain.tip_transform(x - d.reshape(3, 6)) @ T0_inv)
            Jn[:, c] = (plus - minus) / (2 * h)
        assert np.linalg.norm(J - Jn) <= JACOBIAN_TOLERANCE * np.linalg.norm(J)


def test_jacobian_at_zero_rotation_and_near_pi(model):
    chain = JointChain([model] * 2, [[0.0, 0.05, 0.0, 0.0, 0.0, 0.0, 1.0]])
    h = 1e-6
    for x in (np.zeros((2, 6)), np.array([[math.pi - 1e-7, 0, 0, 0.01, 0, 0],
                                          [0, 1e-9, 0, 0, 0.02, 0]])):
        J = chain.jacobian(x)
        T0_inv = np.linalg.inv(chain.tip_transform(x))
        for c in range(12):
            d = np.zeros(12)
            d[c] = h
            col = (twist(chain.tip_transform(x + d.reshape(2, 6)) @ T0_inv)
                   - twist(chain.tip_transform(x - d.reshape(2, 6)) @ T0_inv)) / (2 * h)
            np.testing.assert_allclose(J[:, c], col, atol=1e-8)


def test_batched_evaluation_matches_each_joint(model, spine):
    rng = np.random.default_rng(4)
    x = spine.unloaded_screws() + rng.normal(scale=0.05, size=(5, 6)) * [1, 1, 1, .01, .01, .01]
    state = spine.evaluate(x)
    for i in range(5):
        single = model.evaluate(x[i])
        np.testing.assert_allclose(state.wrenches[i], single.wrench, atol=1e-14)
        np.testing.assert_allclose(state.stiffness[i], single.stiffness, atol=1e-12)
        np.testing.assert_allclose(state.cartesian_stiffness[i], single.cartesian_stiffness,
                                   atol=1e-12)
        np.testing.assert_allclose(state.tensions[i], single.tensions, atol=1e-15)
    assert state.tensions.shape == (5, 12) and state.slack.dtype == bool


def test_residual_jacobian_against_central_differences(model, spine):
    chain = three_joints(model, spine, masses=True)
    rng = np.random.default_rng(5)
    x = chain.unloaded_screws() + rng.normal(scale=0.1, size=(3, 6)) * [1, 1, 1, .01, .01, .01]
    W = moderate_wrench(rng)
    for g in (None, GRAVITY):
        A = chain.residual_jacobian(x, W, g)
        h = 1e-7
        An = np.empty((18, 18))
        for c in range(18):
            d = np.zeros(18)
            d[c] = h
            An[:, c] = (chain.residuals(x + d.reshape(3, 6), W, g)
                        - chain.residuals(x - d.reshape(3, 6), W, g)).ravel() / (2 * h)
        assert np.linalg.norm(A - An) <= 1e-7 * np.linalg.norm(A)


# ---------------------------------------------------------------------------- tip stiffness
def test_one_joint_tip_stiffness_is_k_c(model):
    rng = np.random.default_rng(6)
    tool = perturbed(np.eye(4), rng, 0.5, 0.02)
    chain = JointChain([model], tool=tool)
    for W in (np.zeros(6), np.array([0.05, -0.1, 0.02, 0.001, 0.0, -0.002])):
        res = solve_chain_equilibrium(chain, W)
        single = solve_equilibrium(model, W)
        assert res.success and single.success
        np.testing.assert_allclose(res.screws[0], single.screw, atol=1e-9)
        Kc = single.cartesian_stiffness
        np.testing.assert_allclose(res.tip_stiffness, Kc, atol=1e-9 * np.abs(Kc).max())
        assert res.stable == single.stable
        Ad = np.zeros((6, 6))
        T = res.tip_transform
        R, p = T[:3, :3], T[:3, 3]
        Ad[:3, :3] = Ad[3:, 3:] = R
        Ad[:3, 3:] = hat3(p) @ R
        np.testing.assert_allclose(chain.tip_stiffness(res.screws, W, frame='tool'),
                                   Ad.T @ Kc @ Ad, atol=1e-9 * np.abs(Kc).max())
        np.testing.assert_allclose(res.tip_stiffness_tool, Ad.T @ Kc @ Ad,
                                   atol=1e-9 * np.abs(Kc).max())


def test_unloaded_tip_stiffness_is_the_compliance_sum(model, spine):
    for chain in (spine, three_joints(model, spine)):
        x = chain.unloaded_screws()
        state = chain.evaluate(x)
        C = np.zeros((6, 6))
        for P, Kc in zip(state.joint_frames, state.cartesian_stiffness, strict=True):
            A = np.zeros((6, 6))
            A[:3, :3] = A[3:, 3:] = P[:3, :3]
            A[:3, 3:] = hat3(P[:3, 3]) @ P[:3, :3]
            C += A @ np.linalg.solve(Kc, A.T)
        K = chain.tip_stiffness(x)
        np.testing.assert_allclose(K, np.linalg.inv(C), atol=1e-9 * np.abs(K).max())
        assert np.all(block_errors(K, np.linalg.inv(C)) < 1e-9)


@pytest.mark.parametrize('loaded', [False, True])
@pytest.mark.parametrize('weights', [False, True])
def test_tip_stiffness_against_re_solved_equilibria(model, spine, loaded, weights):
    chain = three_joints(model, spine, masses=weights)
    rng = np.random.default_rng(7)
    W = moderate_wrench(rng) if loaded else np.zeros(6)
    g = GRAVITY if weights else None
    res = solve_chain_equilibrium(chain, W, g, tolerance=1e-13)
    assert res.success and res.stable, res.message
    K = chain.tip_stiffness(res.screws, W, g)
    np.testing.assert_allclose(K, res.tip_stiffness, rtol=1e-12, atol=1e-12)
    errors = block_errors(K, numerical_tip_stiffness(chain, W, g, res.screws))
    assert np.all(errors <= TIP_STIFFNESS_TOLERANCE), errors
    if loaded or weights:  # the series sum is not the tangent under load
        state = chain.evaluate(res.screws)
        C = sum(np.linalg.inv(Kc) for Kc in state.cartesian_stiffness)
        assert np.abs(K - np.linalg.inv(C)).max() > 1e-3 * np.abs(K).max()


def test_tip_stiffness_in_the_tool_frame(model, spine):
    chain = three_joints(model, spine)
    x = chain.unloaded_screws()
    T = chain.tip_transform(x)
    Ad = np.zeros((6, 6))
    Ad[:3, :3] = Ad[3:, 3:] = T[:3, :3]
    Ad[:3, 3:] = hat3(T[:3, 3]) @ T[:3, :3]
    np.testing.assert_allclose(chain.tip_stiffness(x, frame='tool'),
                               Ad.T @ chain.tip_stiffness(x) @ Ad, rtol=1e-12, atol=1e-12)


# ---------------------------------------------------------------------------- equilibrium
def test_unloaded_spine_is_a_straight_upright_column(spine):
    res = solve_chain_equilibrium(spine, np.zeros(6))
    assert res.success and res.stable and res.iterations == 0
    L = res.state.link_transforms
    pitch = np.diff(L[:, :3, 3], axis=0)
    np.testing.assert_allclose(pitch, np.tile([0.0, 0.040002831454938, 0.0], (4, 1)),
                               atol=1e-12)
    np.testing.assert_allclose(res.tip_transform[:3, :3], np.eye(3), atol=1e-12)
    assert np.all(res.state.tensions > 0.0)
    # With identity offsets the default vertebra folds the chain back onto the base.
    folded = JointChain(spine.joints)
    x = folded.unloaded_screws()
    np.testing.assert_allclose(folded.link_transforms(x)[1], np.eye(4), atol=1e-12)


def test_implied_tip_wrench_and_joint_by_joint_balance(model, spine):
    chain = three_joints(model, spine, masses=True)
    rng = np.random.default_rng(8)
    W = moderate_wrench(rng)
    for g in (None, GRAVITY):
        res = solve_chain_equilibrium(chain, W, g)
        assert res.success, res.message
        np.testing.assert_allclose(chain.implied_tip_wrench(res.screws, g), W, atol=1e-9)
        assert np.abs(chain.residuals(res.screws, W, g)).max() <= RESIDUAL_GOAL


def test_one_joint_stability_is_the_single_joint_criterion(model):
    chain = JointChain([model])
    x = model.initial_screw[None]
    assert is_stable(chain.tangent_stiffness(x)) == is_stable(model.cartesian_stiffness(x[0]))
    np.testing.assert_allclose(chain.tangent_stiffness(x), model.cartesian_stiffness(x[0]),
                               atol=1e-12)


def test_a_load_the_strings_cannot_hold_fails_cleanly(model, spine):
    chain = three_joints(model, spine)
    res = solve_chain_equilibrium(chain, [0.0, 50.0, 0.0, 0.0, 0.0, 0.0], time_budget=2.0)
    assert not res.success and res.message
    assert res.screws.shape == (3, 6)


def test_joint_by_joint_fallback_agrees_with_newton(model, spine):
    chain = three_joints(model, spine)
    rng = np.random.default_rng(9)
    W = moderate_wrench(rng)
    res = solve_chain_equilibrium(chain, W)
    x = chain.unloaded_screws()
    P = np.eye(4)
    for i in range(3):
        Ad = np.zeros((6, 6))
        Ad[:3, :3] = Ad[3:, 3:] = P[:3, :3]
        Ad[:3, 3:] = hat3(P[:3, 3]) @ P[:3, :3]
        single = solve_equilibrium(model, Ad.T @ W, initial_screw=x[i])
        assert single.success
        np.testing.assert_allclose(single.screw, res.screws[i], atol=1e-8)
        P = P @ exp_se3(single.screw) @ (chain.link_offsets[i] if i < 2 else np.eye(4))


def _random_solves(chain: JointChain, g: np.ndarray | None, n: int, seed: int) -> None:
    rng = np.random.default_rng(seed)
    converged = 0
    for _ in range(n):
        W = moderate_wrench(rng)
        res = solve_chain_equilibrium(chain, W, g)
        if res.success:
            converged += 1
            assert res.residual <= RESIDUAL_GOAL
            assert np.abs(chain.residuals(res.screws, W, g)).max() <= RESIDUAL_GOAL
            assert np.all(np.linalg.norm(res.screws[:, :3], axis=1) < 2 * math.pi)
    assert converged >= 0.999 * n, converged


@pytest.mark.slow
def test_1000_moderate_tip_wrenches_converge(model, spine):
    _random_solves(three_joints(model, spine), None, 1000, 10)


@pytest.mark.slow
def test_1000_moderate_tip_wrenches_with_link_weights_converge(model, spine):
    _random_solves(three_joints(model, spine, masses=True), GRAVITY, 1000, 11)


# ---------------------------------------------------------------------------- bad input
def test_bad_input_names_the_field(model, spine):
    x = spine.unloaded_screws()
    with pytest.raises(ValueError, match='screws must have shape'):
        spine.evaluate(x[:4])
    with pytest.raises(ValueError, match='screws'):
        spine.tip_transform(np.full((5, 6), np.nan))
    with pytest.raises(ValueError, match='outside the chart'):
        spine.jacobian(np.tile([7.0, 0, 0, 0, 0, 0], (5, 1)))
    with pytest.raises(ValueError, match='tip_wrench'):
        spine.tip_stiffness(x, tip_wrench=[1.0, 2.0])
    with pytest.raises(ValueError, match='gravity'):
        spine.tip_stiffness(x, gravity=[0.0, np.inf, 0.0])
    with pytest.raises(ValueError, match='frame'):
        spine.tip_stiffness(x, frame='world')
    with pytest.raises(ValueError, match='link_masses must be >= 0'):
        JointChain([model] * 2, link_masses=[0.1, -0.1])
    with pytest.raises(ValueError, match='link_masses must have shape'):
        JointChain([model] * 2, link_masses=[0.1])
    with pytest.raises(ValueError, match='link_coms'):
        JointChain([model] * 2, link_coms=np.zeros((3, 3)))
    with pytest.raises(ValueError, match='link_offsets'):
        JointChain([model] * 3, link_offsets=[np.eye(4)])
    with pytest.raises(ValueError, match='tool'):
        JointChain([model], tool=2 * np.eye(4))
    with pytest.raises(ValueError, match='tool'):
        JointChain([model], tool=[0, 0, 0, 0, 0, 0, 3.0])
    with pytest.raises(ValueError, match='joints'):
        JointChain([])
    with pytest.raises(ValueError, match='rest_lengths'):
        spine.evaluate(x, rest_lengths=[None] * 4)
    with pytest.raises(ValueError, match='tip_wrench'):
        solve_chain_equilibrium(spine, [np.nan] * 6)
    with pytest.raises(ValueError, match='screws'):
        solve_chain_equilibrium(spine, np.zeros(6), initial_screws=np.zeros((2, 6)))


# ---------------------------------------------------------------------------- config
def _spine_document() -> dict:
    return yaml.safe_load(SPINE_CONFIG.read_text())


def _params(doc: dict) -> dict:
    return doc['/**']['ros__parameters']


def test_default_spine_config_uses_ros_parameter_types_only():
    def check(value, key):
        if isinstance(value, dict):
            for k, v in value.items():
                check(v, f'{key}.{k}')
        elif isinstance(value, list):
            assert value, f'{key}: empty arrays have no ROS type'
            kinds = {type(v) for v in value}
            assert len(kinds) == 1 and kinds <= {bool, int, float, str}, key
        else:
            assert isinstance(value, (bool, int, float, str)), key
    check(_params(_spine_document()), 'ros__parameters')


def test_default_spine_config_loads(model, spine):
    assert spine.n_joints == 5 and len({id(j) for j in spine.joints}) == 1
    np.testing.assert_allclose(spine.joints[0].rest_lengths, model.rest_lengths)
    assert spine.base_frame == 'spine_base' and spine.tool_frame == 'spine_tool'
    np.testing.assert_allclose(spine.gravity, GRAVITY)
    assert np.all(spine.link_masses == 0.0)


def test_config_overrides_and_bad_fields(tmp_path):
    doc = _spine_document()
    p = _params(doc)
    p['joint_2'] = {'stiffness': [100.0]}
    p['chain']['link_masses'] = [0.02]
    p['chain']['link_coms'] = [0.0, 0.01, 0.0]
    path = tmp_path / 'spine.yaml'
    path.write_text(yaml.safe_dump(doc))
    chain = JointChain.from_yaml(path)
    assert chain.joints[1].k[0] == 100.0 and chain.joints[0] is chain.joints[2]
    np.testing.assert_allclose(chain.link_masses, [0.02] * 5)
    np.testing.assert_allclose(chain.link_coms, np.tile([0.0, 0.01, 0.0], (5, 1)))
    x = chain.unloaded_screws()  # two models: two batched evaluations
    single = chain.joints[1].evaluate(x[1])
    np.testing.assert_allclose(chain.evaluate(x).stiffness[1], single.stiffness, atol=1e-12)
    for key, value, match in (('n_joints', 0, 'chain.n_joints'),
                              ('link_offsets', [0.0] * 8, 'chain.link_offsets'),
                              ('tool', [0.0] * 3, 'chain.tool'),
                              ('link_masses', [0.1, 0.2], 'chain.link_masses'),
                              ('link_coms', [0.0] * 4, 'chain.link_coms'),
                              ('gravity', [0.0, 'x', 0.0], 'chain.gravity')):
        bad = _spine_document()
        _params(bad)['chain'][key] = value
        path.write_text(yaml.safe_dump(bad))
        with pytest.raises(ValueError, match=match):
            JointChain.from_yaml(path)
    bad = _spine_document()
    _params(bad)['joint_3'] = {'rest_lengths': [-1.0]}
    path.write_text(yaml.safe_dump(bad))
    with pytest.raises(ValueError, match=r'joint_3: joint\.rest_lengths'):
        JointChain.from_yaml(path)


# ---------------------------------------------------------------------------- command line
def test_cli_chain_table_and_json(capsys, spine):
    assert cli.main(['chain', '--config', str(SPINE_CONFIG), '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    x = spine.unloaded_screws()
    np.testing.assert_allclose(out['tip_transform'], spine.tip_transform(x), atol=1e-12)
    np.testing.assert_allclose(out['tip_stiffness'], spine.tip_stiffness(x), rtol=1e-9,
                               atol=1e-9)
    assert out['success'] and out['stable'] and out['n_joints'] == 5
    W = [0.01, 0.0, 0.0, 0.0, 0.0, 0.0005]
    assert cli.main(['chain', '--tip-wrench', *map(str, W), '--json']) == 0
    out = json.loads(capsys.readouterr().out)
    res = solve_chain_equilibrium(spine, W)
    np.testing.assert_allclose(out['screws'], res.screws, atol=1e-9)
    np.testing.assert_allclose(out['tip_stiffness'], res.tip_stiffness, rtol=1e-6)
    screws = [str(v) for v in x.ravel()]
    assert cli.main(['chain', '--screws', *screws]) == 0
    text = capsys.readouterr().out
    assert 'tip stiffness' in text and 'tool frame' in text


def test_cli_chain_bad_input(capsys):
    assert cli.main(['chain', '--screws', '1', '2', '3']) == 2
    assert 'screws' in capsys.readouterr().err
    assert cli.main(['chain', '--gravity', '0', 'nan', '0']) == 2
    assert cli.main(['chain', '--config', '/nonexistent.yaml']) == 2
    assert cli.main(['chain', '--tip-wrench', '0', '50', '0', '0', '0', '0',
                     '--time-budget', '1']) == 1


def test_cli_plot_spine(tmp_path):
    out = tmp_path / 'spine.png'
    assert cli.main(['plot', 'spine', '--out', str(out), '--size', '300', '400']) == 0
    assert png_size(out) == (300, 400)
