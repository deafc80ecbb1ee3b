"""Joint model: wrench, analytical K (eq. 10) and K_c against central differences and geometry."""

import math

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness import config
from tensegrity_stiffness.geometry.screw import dexp_se3, exp_se3, hat3, left_jacobian_se3, log_se3
from tensegrity_stiffness.mechanics.equilibrium import is_stable, solve_equilibrium
from tensegrity_stiffness.mechanics.interpretation import interpret_stiffness
from tensegrity_stiffness.mechanics.joint import JointModel

CONFIG = REPO / 'config' / 'default_joint.yaml'
CD_STEP = 1e-6
SWAP = np.block([[np.zeros((3, 3)), np.eye(3)], [np.eye(3), np.zeros((3, 3))]])


@pytest.fixture(scope='module')
def model():
    return JointModel.from_yaml(CONFIG)


@pytest.fixture(scope='module')
def rest_state(model):
    return model.evaluate(model.initial_screw)


def rel(a, b):
    return np.linalg.norm(a - b) / np.linalg.norm(b)


def central(f, x, step=CD_STEP):
    cols = []
    for i in range(len(x)):
        e = np.zeros(len(x))
        e[i] = step
        cols.append((f(x + e) - f(x - e)) / (2 * step))
    return np.stack(cols, axis=-1)


def direct_wrench(model, xi, rest=None, force_law=None):
    """Eqs. (7)-(9) evaluated string by string, the plain way (the geometry K comes from)."""
    rest = model.rest_lengths if rest is None else rest
    T = exp_se3(xi)
    F = np.zeros(6)
    for j, (a, b) in enumerate(model.connections):
        p1 = model.link1_nodes[a]
        s = p1 - (T[:3, :3] @ model.link2_nodes[b] + T[:3, 3])
        length = np.linalg.norm(s)
        lmax = rest[j] + model.max_stretch[j]
        if length <= rest[j]:
            tension = 0.0
        elif (force_law or model.force_law) == 'hooke':
            tension = model.k[j] * (min(length, lmax) - rest[j])
        else:
            lc = min(length, lmax)
            tension = model.k[j] * (lc - rest[j]) / lc
        f = tension * s / length
        F += np.r_[f, np.cross(p1, f)]
    return F


def test_default_config_and_its_unloaded_equilibrium(model, rest_state):
    assert model.n_strings == 12
    assert model.string_names[0] == 'cross_AA'
    np.testing.assert_allclose(model.rest_lengths[:4], 0.0381)
    np.testing.assert_allclose(model.max_lengths - model.rest_lengths, 0.02)
    np.testing.assert_allclose(np.linalg.norm(model.initial_screw[:3]), math.pi, atol=1e-12)
    assert np.linalg.norm(rest_state.wrench) < 1e-12
    assert not rest_state.slack.any() and not rest_state.saturated.any()
    # Link 2 is turned over: rotation by pi about (1, 0, -1)/sqrt(2).
    np.testing.assert_allclose(rest_state.transform[:3, :3],
                               [[0, 0, -1], [0, -1, 0], [-1, 0, 0]], atol=1e-12)
    assert is_stable(rest_state.cartesian_stiffness)


def test_wrench_matches_string_by_string_geometry(model):
    rng = np.random.default_rng(0)
    for _ in range(50):
        xi = model.initial_screw + rng.normal(scale=[0.2] * 3 + [0.005] * 3)
        np.testing.assert_allclose(model.wrench(xi), direct_wrench(model, xi), atol=1e-13)


@pytest.mark.slow
def test_k_against_central_differences_at_10000_equilibria(model):
    """The paper's check (Table II: 4.4e-10): equilibria under random external wrenches."""
    rng = np.random.default_rng(1)
    n = 10_000
    screws = np.zeros((n, 6))
    for i in range(n):
        W = np.r_[rng.normal(scale=0.1, size=3), rng.normal(scale=0.002, size=3)]
        result = solve_equilibrium(model, W)
        assert result.success, result.message
        screws[i] = result.screw
    analytic = model.stiffness(screws)
    numeric = model.numerical_stiffness(screws, step=CD_STEP)
    err = (np.linalg.norm((analytic - numeric).reshape(n, -1), axis=1)
           / np.linalg.norm(analytic.reshape(n, -1), axis=1))
    assert err.mean() <= 1e-8, err.mean()
    assert err.max() <= 1e-6


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_k_against_central_differences_in_every_region(model, force_law):
    """Taut, slack and saturated strings, away from the region boundaries (kinks)."""
    m = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                   max_lengths=model.max_lengths, force_law=force_law,
                   initial_screw=model.initial_screw)
    rng = np.random.default_rng(2)
    seen = {'slack': 0, 'saturated': 0}
    checked = 0
    while checked < 200:
        xi = m.initial_screw + rng.normal(scale=[0.4] * 3 + [0.012] * 3)
        st = m.evaluate(xi)
        lmax = m.rest_lengths + m.max_stretch
        margin = np.minimum(np.abs(st.lengths - m.rest_lengths), np.abs(st.lengths - lmax))
        if margin.min() < 1e-4:
            continue  # too close to a kink for central differences
        seen['slack'] += int(st.slack.any())
        seen['saturated'] += int(st.saturated.any())
        np.testing.assert_allclose(st.wrench, direct_wrench(m, xi), atol=1e-13)
        numeric = central(m.wrench, xi)
        assert rel(st.stiffness, numeric) < 1e-7
        checked += 1
    assert seen['slack'] > 10 and seen['saturated'] > 10


def test_k_at_theta_zero_and_beyond_pi():
    rng = np.random.default_rng(3)
    nodes = rng.normal(scale=0.05, size=(4, 3))
    conn = np.array([(a, b) for a in range(4) for b in range(3)])
    m = JointModel(nodes, conn, 50.0, np.full(12, 0.01))
    for xi in (np.r_[0, 0, 0, 0.01, 0.02, 0.1], np.r_[1e-9, 0, 0, 0.01, 0.02, 0.1],
               np.r_[0, 3.5, 0.5, 0.01, 0.02, 0.1]):
        assert rel(m.stiffness(xi), central(m.wrench, xi)) < 1e-7


def _paper_eq11(k, l0, s):
    length = np.linalg.norm(s)
    return k * (2 * l0 - length) / length**4 * np.outer(s, s) + k * (length - l0) / length**2 * \
        np.eye(3)


def test_eq11_differentiates_the_paper_law_not_hookes_law(model):
    """Errata (docs/errata.md): eq. (11) is d/ds of k (l - l0) s / l^2; mixed with Hooke's force
    one string's derivative is ~10x off and K of the default joint at rest 23.4x too large."""
    rng = np.random.default_rng(4)
    s = rng.normal(size=3) * 0.04
    k, l0 = 77.0, 0.02
    def paper_force(v):
        return k * (np.linalg.norm(v) - l0) * v / np.linalg.norm(v) ** 2

    def hooke_force(v):
        return k * (np.linalg.norm(v) - l0) * v / np.linalg.norm(v)

    np.testing.assert_allclose(_paper_eq11(k, l0, s), central(paper_force, s), atol=1e-6)
    assert rel(_paper_eq11(k, l0, s), central(hooke_force, s)) > 0.5
    length = np.linalg.norm(s)
    hooke = k * (1 - l0 / length) * np.eye(3) + k * l0 / length**3 * np.outer(s, s)
    np.testing.assert_allclose(hooke, central(hooke_force, s), atol=1e-6)
    # The whole joint: K assembled with eq. (11) but Hooke's forces is 23.4x too large.
    xi = model.initial_screw
    st = model.evaluate(xi)
    dT = dexp_se3(xi)  # (4, 4, 6), eqs. 12-18
    K_wrong = np.zeros((6, 6))
    for j, (a, b) in enumerate(model.connections):
        p1 = model.link1_nodes[a]
        ds = -np.einsum('abi,b->ai', dT, np.r_[model.link2_nodes[b], 1.0])[:3]
        df = _paper_eq11(model.k[j], model.rest_lengths[j], st.string_vectors[j]) @ ds
        K_wrong += np.vstack([df, hat3(p1) @ df])
    ratio = np.linalg.norm(K_wrong) / np.linalg.norm(st.stiffness)
    assert 23.3 < ratio < 23.4, ratio  # the figure docs/errata.md gives


def test_moment_arm_must_be_the_link1_node(model):
    """Errata (docs/errata.md), eq. (9)-(10): r_j = p1_{a_j}; holding T p2 fixed as arm gives
    ~1% error in K."""
    xi = model.initial_screw + np.r_[0.05, -0.03, 0.02, 0.002, 0.001, -0.001]
    st = model.evaluate(xi)
    K_arm_fixed = st.stiffness.copy()
    q = model.link2_nodes_in_link1(st.transform)[model.connections[:, 1]]
    p1 = model.link1_nodes[model.connections[:, 0]]
    # Replace hat(p1) df by hat(q) df in the moment rows: K_m' = K_m - sum hat(s_j) df_j/dxi.
    dfs = []
    for j in range(model.n_strings):
        def fj(x, j=j):
            s = model.evaluate(x).string_vectors[j]
            return model.tensions(x)[j] * s / np.linalg.norm(s)
        dfs.append(central(fj, xi))
    K_arm_fixed[3:] = sum(hat3(q[j]) @ dfs[j] for j in range(model.n_strings))
    np.testing.assert_allclose(st.stiffness[3:], sum(hat3(p1[j]) @ dfs[j]
                                                     for j in range(model.n_strings)), atol=1e-6)
    assert 1e-3 < rel(K_arm_fixed, st.stiffness) < 0.1


def test_cartesian_stiffness_against_spatial_twist_differences(model):
    rng = np.random.default_rng(5)
    for _ in range(20):
        xi = model.initial_screw + rng.normal(scale=[0.1] * 3 + [0.003] * 3)
        T = exp_se3(xi)
        st = model.evaluate(xi)

        def wrench_after_twist(delta, T=T, xi=xi):  # delta = [dv; dw]: T -> exp(hat(.)) T
            Tn = exp_se3(np.r_[delta[3:], delta[:3]]) @ T
            return model.wrench(log_se3(Tn, reference=xi))

        numeric = -central(wrench_after_twist, np.zeros(6))
        assert rel(st.cartesian_stiffness, numeric) < 1e-7
        # K = -K_c P J(xi), P the block swap.
        np.testing.assert_allclose(st.stiffness, -st.cartesian_stiffness @ SWAP
                                   @ left_jacobian_se3(xi), atol=1e-9)


def test_cartesian_stiffness_symmetric_and_definite_at_unloaded_equilibria(model, rest_state):
    Kc = rest_state.cartesian_stiffness
    assert np.abs(Kc - Kc.T).max() <= 1e-9 * np.abs(Kc).max()
    assert np.linalg.eigvalsh(0.5 * (Kc + Kc.T)).min() > 0
    # Other stable and unstable unloaded equilibria of the same joint.
    rng = np.random.default_rng(6)
    stable = converged = 0
    for _ in range(40):
        axis = rng.normal(size=3)
        x0 = np.r_[axis / np.linalg.norm(axis) * rng.uniform(0, math.pi), rng.normal(size=3)
                   * 0.02]
        res = solve_equilibrium(model, np.zeros(6), initial_screw=x0)
        if not res.success:
            continue
        Kc = res.cartesian_stiffness
        assert np.abs(Kc - Kc.T).max() <= 1e-9 * np.abs(Kc).max()
        eig = np.linalg.eigvalsh(0.5 * (Kc + Kc.T))
        assert res.stable == bool(eig.min() > 0)
        converged += 1
        stable += res.stable
    assert converged >= 30, converged
    assert stable >= 1, 'no stable unloaded equilibrium found'  # the default joint rests at one


def test_k_itself_is_not_symmetric(model, rest_state):
    K = rest_state.stiffness
    assert np.abs(K - K.T).max() > 1e-3 * np.abs(K).max()


def test_energy_gradient_and_hessian(model, rest_state):
    """Errata (docs/errata.md): dU/dxi = -J^T P F (not -F); at zero load S = -J^T P K is the
    Hessian of U."""
    rng = np.random.default_rng(7)
    for _ in range(10):
        xi = model.initial_screw + rng.normal(scale=[0.1] * 3 + [0.003] * 3)
        grad = central(lambda x: np.array(model.energy(x)), xi)
        J = left_jacobian_se3(xi)
        np.testing.assert_allclose(grad, -J.T @ SWAP @ model.wrench(xi), atol=1e-9)
        assert np.linalg.norm(grad + model.wrench(xi)) > 1e-3
    xi = model.initial_screw
    hess = central(lambda x: -left_jacobian_se3(x).T @ SWAP @ model.wrench(x), xi)
    S = -left_jacobian_se3(xi).T @ SWAP @ rest_state.stiffness
    np.testing.assert_allclose(S, hess, atol=1e-6 * np.abs(S).max())
    np.testing.assert_allclose(S, S.T, atol=1e-9 * np.abs(S).max())


def test_energy_is_the_integral_of_the_tension(model):
    m = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                   max_lengths=model.max_lengths, force_law='paper',
                   initial_screw=model.initial_screw)
    for mm in (model, m):
        xi0 = mm.initial_screw
        path = np.linspace(0.0, 1.0, 2001)
        direction = np.r_[0.3, -0.2, 0.4, 0.01, 0.02, -0.015]
        xs = xi0 + path[:, None] * direction
        F = mm.wrench(xs)
        J = left_jacobian_se3(xs)
        dU = -np.einsum('nij,nj->ni', np.swapaxes(J, 1, 2) @ SWAP, F) @ direction
        work = np.trapezoid(dU, path)
        assert abs(mm.energy(xs[-1]) - mm.energy(xs[0]) - work) < 1e-6 * abs(work) + 1e-12


def test_slack_and_saturated_flags(model):
    xi = model.initial_screw
    st = model.evaluate(xi, rest_lengths=model.rest_lengths * 2.0)
    assert st.slack.all() and np.all(st.tensions == 0.0) and np.all(st.stiffness == 0.0)
    short = model.rest_lengths * 0.3
    st = model.evaluate(xi, rest_lengths=short)
    assert st.saturated.all()
    np.testing.assert_allclose(st.tensions, model.k * model.max_stretch)
    assert rel(st.stiffness, central(lambda x: model.wrench(x, short), xi)) < 1e-7


def test_batched_equals_single(model):
    rng = np.random.default_rng(8)
    xs = model.initial_screw + rng.normal(scale=[0.3] * 3 + [0.01] * 3, size=(64, 6))
    rests = model.rest_lengths * rng.uniform(0.8, 1.2, size=(64, 12))
    batch = model.evaluate(xs, rests)
    for i in (0, 17, 63):
        single = model.evaluate(xs[i], rests[i])
        for name in ('transform', 'lengths', 'tensions', 'wrench', 'stiffness',
                     'cartesian_stiffness'):
            np.testing.assert_allclose(getattr(batch, name)[i], getattr(single, name),
                                       atol=1e-13, err_msg=name)
        np.testing.assert_array_equal(batch.slack[i], single.slack)
    np.testing.assert_allclose(model.energy(xs, rests)[5], model.energy(xs[5], rests[5]))
    assert model.numerical_stiffness(xs[:3], rests[:3]).shape == (3, 6, 6)
    # one rest-length set for all screws
    np.testing.assert_allclose(model.wrench(xs)[3], model.wrench(xs[3]), atol=1e-15)


def test_separate_link2_nodes_and_rest_length_override(model):
    rng = np.random.default_rng(9)
    p2 = model.link1_nodes + rng.normal(scale=0.003, size=(4, 3))
    m = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                   link2_nodes=p2, max_lengths=model.max_lengths)
    xi = model.initial_screw + 0.01
    np.testing.assert_allclose(m.wrench(xi), direct_wrench(m, xi), atol=1e-13)
    assert rel(m.stiffness(xi), central(m.wrench, xi)) < 1e-7
    new = model.with_rest_lengths(model.rest_lengths * 1.1)
    np.testing.assert_allclose(new.max_lengths - new.rest_lengths, model.max_stretch)
    np.testing.assert_allclose(new.wrench(xi), model.wrench(xi, model.rest_lengths * 1.1))


def test_interpretation(rest_state):
    K = rest_state.stiffness
    it = interpret_stiffness(K)
    np.testing.assert_allclose(it.block_norms, [np.linalg.norm(K[:3, :3]),
                                                np.linalg.norm(K[:3, 3:]),
                                                np.linalg.norm(K[3:, :3]),
                                                np.linalg.norm(K[3:, 3:])])
    np.testing.assert_allclose(it.column_norms, np.linalg.norm(K, axis=0))
    np.testing.assert_allclose(it.row_norms, np.linalg.norm(K, axis=1))
    np.testing.assert_array_equal(it.blocks['K_fv'], K[:3, 3:])
    with pytest.raises(ValueError, match='6, 6'):
        interpret_stiffness(np.eye(5))


def test_load_response_table_iii(model, rest_state):
    """Section VI: a small force at node A of link 2; the wrench change equals K dxi (< 1%)."""
    xi0 = model.initial_screw
    a2 = model.link2_nodes_in_link1(rest_state.transform)[model.link2_node_names.index('A')]
    for direction in np.eye(3):
        f = 0.01 * direction
        W = np.r_[f, np.cross(a2, f)]
        res = solve_equilibrium(model, W)
        assert res.success and res.stable
        dF = res.wrench - rest_state.wrench
        predicted = rest_state.stiffness @ (res.screw - xi0)
        assert rel(predicted, dF) < 0.01


def test_bad_input_raises(model):
    with pytest.raises(ValueError, match='rest_lengths must be > 0'):
        model.wrench(model.initial_screw, -model.rest_lengths)
    with pytest.raises(ValueError, match='rest_lengths must be > 0'):
        model.wrench(model.initial_screw, np.zeros(12))
    with pytest.raises(ValueError, match=r'rest_lengths must have shape \(12,\)'):
        model.wrench(model.initial_screw, np.ones(11))
    with pytest.raises(ValueError, match='rest_lengths must be finite'):
        model.wrench(model.initial_screw, np.full(12, np.nan))
    with pytest.raises(ValueError, match='xi must be finite'):
        model.stiffness(np.full(6, np.inf))
    with pytest.raises(ValueError, match='batched rest_lengths'):
        model.wrench(model.initial_screw, np.ones((3, 12)))
    with pytest.raises(ValueError, match='zero length'):
        JointModel(np.zeros((1, 3)), [[0, 0]], 1.0, [0.1]).wrench(np.zeros(6))
    with pytest.raises(ValueError, match='stiffness must be > 0'):
        JointModel(np.ones((1, 3)), [[0, 0]], -1.0, [0.1])
    with pytest.raises(ValueError, match='force_law'):
        JointModel(np.ones((1, 3)), [[0, 0]], 1.0, [0.1], force_law='linear')
    with pytest.raises(ValueError, match='max_lengths must exceed'):
        JointModel(np.ones((1, 3)), [[0, 0]], 1.0, [0.1], max_lengths=[0.05])
    with pytest.raises(ValueError, match=r'connections\[:, 1\]'):
        JointModel(np.ones((1, 3)), [[0, 3]], 1.0, [0.1])
    with pytest.raises(ValueError, match='step'):
        model.numerical_stiffness(model.initial_screw, step=0.0)


@pytest.mark.parametrize(('key', 'value', 'match'), [
    ('link1_nodes', [0.0, 1.0], 'joint.link1_nodes must be a flat list'),
    ('link1_nodes', [0.0, 1.0, float('nan')] * 4, 'joint.link1_nodes must be finite'),
    ('stiffness', [77.0] * 11, 'joint.stiffness must have 12 values'),
    ('stiffness', [-1.0], 'joint.stiffness must be > 0'),
    ('rest_lengths', [0.0] * 12, 'joint.rest_lengths must be > 0'),
    ('max_lengths', [0.01] * 12, 'joint.max_lengths must exceed'),
    ('string_link2_nodes', ['A'] * 11 + ['Z'], r"unknown nodes \['Z'\]"),
    ('force_law', 'cubic', 'joint.force_law must be one of'),
    ('initial_screw', [1.0] * 5, 'joint.initial_screw'),
    ('node_names', ['A', 'B'], 'joint.node_names has 2 names for 4 nodes'),
])
def test_config_errors_name_the_field(key, value, match):
    section = dict(config.load_section(CONFIG, 'joint'))
    section[key] = value
    with pytest.raises(ValueError, match=match):
        JointModel.from_dict(section)


def test_config_file_errors(tmp_path):
    with pytest.raises(ValueError, match='cannot read config'):
        JointModel.from_yaml(tmp_path / 'missing.yaml')
    bad = tmp_path / 'bad.yaml'
    bad.write_text('joint: [1, 2')
    with pytest.raises(ValueError, match='not valid YAML'):
        JointModel.from_yaml(bad)
    bad.write_text('other: 1\n')
    with pytest.raises(ValueError, match='no "joint" section'):
        JointModel.from_yaml(bad)
    section = dict(config.load_section(CONFIG, 'joint'))
    del section['rest_lengths']
    with pytest.raises(ValueError, match=r'joint\.rest_lengths is missing'):
        JointModel.from_dict(section)


def built_anew(model: JointModel, rest_lengths) -> JointModel:
    """What ``JointModel.with_rest_lengths`` returned before it copied (main at 3ac95f7): the
    model built anew from ``model``'s arguments."""
    rest = model.validate_rest_lengths(rest_lengths, batched=False)
    return JointModel(model.link1_nodes, model.connections, model.k, rest,
                      link2_nodes=model.link2_nodes, max_lengths=rest + model.max_stretch,
                      force_law=model.force_law, node_names=model.node_names,
                      link2_node_names=model.link2_node_names, string_names=model.string_names,
                      initial_screw=model.initial_screw, use_kernel=model.uses_kernel)


def test_with_rest_lengths_is_the_model_built_anew():
    """The copy ``with_rest_lengths`` makes (issue 37: a node takes commands at 500 Hz) holds
    bitwise what a model built anew from the same arguments holds, evaluates bitwise as it
    does, and refuses what it refuses with the same message; the original is unchanged."""
    model = JointModel.from_yaml(config.packaged_config_path())
    before = model.rest_lengths.copy()
    rng = np.random.default_rng(3)
    current = model
    for i in range(60):
        rest = model.rest_lengths * (1.0 + 0.05 * rng.standard_normal(model.n_strings))
        anew = built_anew(current, rest)
        copied = current.with_rest_lengths(rest)
        assert copied is not current and copied.uses_kernel == anew.uses_kernel
        for name in ('rest_lengths', 'max_lengths', 'max_stretch', 'link1_nodes',
                     'link2_nodes', 'connections', 'k', 'initial_screw',
                     'link1_string_nodes'):
            a, b = getattr(copied, name), getattr(anew, name)
            assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b), name
        assert (copied.node_names, copied.link2_node_names, copied.string_names,
                copied.force_law) == (anew.node_names, anew.link2_node_names,
                                      anew.string_names, anew.force_law)
        xi = model.initial_screw + 0.01 * rng.standard_normal(6)
        s1, s2 = copied.evaluate(xi), anew.evaluate(xi)
        for name in ('wrench', 'stiffness', 'cartesian_stiffness', 'tensions', 'lengths'):
            assert np.array_equal(getattr(s1, name), getattr(s2, name)), (i, name)
        current = copied
    np.testing.assert_array_equal(model.rest_lengths, before)
    for bad in (np.full(model.n_strings, np.nan), -model.rest_lengths, model.rest_lengths[:3],
                model.rest_lengths * 1e17):
        messages = []
        for build in (model.with_rest_lengths, lambda r: built_anew(model, r)):
            with pytest.raises(ValueError) as info:
                build(bad)
            messages.append((type(info.value), str(info.value)))
        assert messages[0] == messages[1], messages
