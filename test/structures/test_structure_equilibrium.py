"""Equilibria of structures against what others published and against the physics they must
satisfy: the regular p-prism's twist 90 - 180/p degrees (Tibert & Pellegrino 2003, for any
rest lengths that keep the strings taut), the 6-bar expanded octahedron with equal strings
(strut / string length sqrt(8/3), parallel bars half a bar length apart), a structure on the
ground with Coulomb friction (forces inside the cone, the weight carried, no node below the
ground, sliding contacts at the cone against their slip), the gauge of a free structure."""

import copy
import math

import numpy as np
import pytest
from structure_fixtures import SIXBAR, example, mixed_document, perturbed, prism_document

from tensegrity_stiffness.geometry.screw import exp_so3
from tensegrity_stiffness.structures.equilibrium import (
    MIN_NEWTON_ITERATIONS,
    solve_structure_equilibrium,
)
from tensegrity_stiffness.structures.structure import Structure, twist_exp


def axis_angle(center_bottom, center_top, bottom, top, axis):
    """The angle (deg) of ``top - center_top`` from ``bottom - center_bottom`` about ``axis``."""
    u = bottom - center_bottom
    v = top - center_top
    u -= (u @ axis) * axis
    v -= (v @ axis) * axis
    return math.degrees(math.atan2(np.cross(u, v) @ axis, u @ v))


def prism_twists(structure, result):
    """(bar spans, vertical-string spans) in degrees about the prism's axis."""
    p = structure.n_bodies
    x = result.state.node_positions
    bottom = np.array([x[f'bar{i}.a'] for i in range(p)])
    top = np.array([x[f'bar{i}.b'] for i in range(p)])
    cb, ct = bottom.mean(axis=0), top.mean(axis=0)
    axis = (ct - cb) / np.linalg.norm(ct - cb)
    bars = [axis_angle(cb, ct, bottom[i], top[i], axis) for i in range(p)]
    verticals = [axis_angle(cb, ct, bottom[i], top[(i - 1) % p], axis) for i in range(p)]
    return np.array(bars), np.array(verticals)


@pytest.mark.parametrize('p', [3, 4, 5, 6])
@pytest.mark.parametrize('ratios', [(0.9, 0.9), (0.8, 0.95), (0.92, 0.8)])
def test_a_regular_prism_twists_by_90_minus_180_over_p(p, ratios):
    # Start 12 degrees off the equilibrium twist, with the given rest-length ratios.
    document = prism_document(p, twist_deg=90.0 + 180.0 / p + 12.0, ring_ratio=ratios[0],
                              vertical_ratio=ratios[1])
    structure = Structure.from_dict(document)
    rng = np.random.default_rng(p)
    result = solve_structure_equilibrium(structure,
                                         start=perturbed(structure.start_poses(), rng, 0.005))
    assert result.success, result.message
    assert not result.state.slack.any()
    assert result.stable, result.stability_margin
    bars, verticals = prism_twists(structure, result)
    np.testing.assert_allclose(np.abs(verticals), 90.0 - 180.0 / p, atol=1e-7)
    np.testing.assert_allclose(np.abs(bars), 90.0 + 180.0 / p, atol=1e-7)
    # Every bar in equilibrium: the strings' wrench on it vanishes, the bar is compressed.
    assert np.max(np.abs(result.state.wrenches)) < 1e-8
    assert np.all(result.state.bar_forces > 0)


def test_the_six_bar_with_equal_strings_has_the_published_form():
    structure = example(SIXBAR)
    rng = np.random.default_rng(1)
    start = perturbed(structure.start_poses(), rng, 0.03)
    result = solve_structure_equilibrium(structure, start=start)
    assert result.success and result.stable, result.message
    lengths = result.state.lengths
    np.testing.assert_allclose(lengths, lengths.mean(), rtol=1e-9)
    strut = structure.body('x_up').length
    np.testing.assert_allclose(strut / lengths.mean(), math.sqrt(8.0 / 3.0), rtol=1e-9)
    x = result.state.node_positions
    for first, second in (('x_up', 'x_down'), ('y_front', 'y_back'), ('z_left', 'z_right')):
        c1 = 0.5 * (x[f'{first}.a'] + x[f'{first}.b'])
        c2 = 0.5 * (x[f'{second}.a'] + x[f'{second}.b'])
        e = x[f'{first}.b'] - x[f'{first}.a']
        e /= np.linalg.norm(e)
        assert abs(e @ (x[f'{second}.b'] - x[f'{second}.a']) / strut - 1.0) < 1e-9  # parallel
        gap = (c2 - c1) - ((c2 - c1) @ e) * e
        np.testing.assert_allclose(np.linalg.norm(gap), strut / 2, rtol=1e-9)


def test_a_free_structure_s_equilibrium_is_taken_nearest_the_start():
    """The gauge: from a rigidly moved start the free 6-bar reaches the same shape (node
    distances), and each solve keeps the nodes' centroid and mean turn where the start had them
    (to second order in the start's distance from equilibrium)."""
    structure = example(SIXBAR)
    rng = np.random.default_rng(2)
    start = perturbed(structure.start_poses(), rng, 0.03)
    G = twist_exp(np.array([0.3, -0.2, 0.1, 0.4, 0.2, -0.3]))
    first = solve_structure_equilibrium(structure, start=start)
    moved = solve_structure_equilibrium(structure, start=np.array([G @ P for P in start]))
    assert first.success and moved.success

    def nodes(result):
        return np.array([result.state.node_positions[k] for k in structure.node_names])

    def distances(x):
        return np.linalg.norm(x[:, None] - x[None], axis=-1)

    np.testing.assert_allclose(distances(nodes(moved)), distances(nodes(first)), atol=1e-10)
    x0 = structure.node_positions(start)
    x1 = nodes(first)
    assert np.linalg.norm(x1.mean(axis=0) - x0.mean(axis=0)) < 0.03 ** 2
    # The equilibrium after the rigid motion is the rigidly moved one to second order too.
    np.testing.assert_allclose(nodes(moved), x1 @ G[:3, :3].T + G[:3, 3], atol=1e-4)


def on_the_ground(friction, gravity=(0.0, 0.0, -9.81)):
    """The 6-bar with a triangular face (nodes x_up.b, y_front.b, z_left.b) on the ground."""
    document = copy.deepcopy(example(SIXBAR).to_dict())
    document['structure']['gravity'] = list(gravity)
    document['structure']['ground'] = {'normal': [0, 0, 1], 'height': 0.0,
                                       'friction': friction}
    structure = Structure.from_dict(document)
    u, v = np.ones(3) / math.sqrt(3.0), np.array([0.0, 0.0, -1.0])
    axis = np.cross(u, v)
    G = np.eye(4)
    G[:3, :3] = exp_so3(axis / np.linalg.norm(axis) * math.acos(u @ v))
    G[:3, 3] = [0.3, 0.1, 1.0]
    return structure, np.array([G @ P for P in structure.start_poses()])


def assert_balanced(structure, result):
    """Each free body's strings, weight and contact forces sum to zero (recomputed here)."""
    T = result.poses
    W = result.state.wrenches + structure.gravity_wrenches(T)[0]
    for name, f in result.contacts.items():
        body = structure.body_index(name.split('.')[0])
        x = result.state.node_positions[name]
        W[body] += np.r_[f, np.cross(x, f)]
    assert np.max(np.abs(W[~structure.fixed])) < 1e-9


@pytest.mark.parametrize('friction', [0.8, 0.05])
def test_on_the_ground_the_forces_stay_in_the_friction_cone(friction):
    structure, start = on_the_ground(friction)
    result = solve_structure_equilibrium(structure, start=start)
    assert result.success and result.stable, result.message
    assert sorted(result.contacts) == ['x_up.b', 'y_front.b', 'z_left.b']
    assert not result.sliding
    weight = sum(b.mass for b in structure.bodies) * 9.81
    total = sum(result.contacts.values())
    np.testing.assert_allclose(total, [0, 0, weight], atol=1e-9)
    for f in result.contacts.values():
        assert f[2] > 0 and np.linalg.norm(f[:2]) <= friction * f[2]
    heights = {k: v[2] for k, v in result.state.node_positions.items()}
    for name, h in heights.items():
        if name in result.contacts:
            assert abs(h) < 1e-12
        else:
            assert h > 0.05
    assert_balanced(structure, result)
    # The contacts stick where the structure touched (the start dropped onto the ground).
    x0 = structure.node_positions(start)
    for name in result.contacts:
        drop_xy = x0[structure.node_index(name), :2]
        np.testing.assert_allclose(result.state.node_positions[name][:2], drop_xy, atol=1e-12)


def test_a_slippery_ground_lets_the_contacts_slide_at_the_cone():
    structure, start = on_the_ground(0.001)
    result = solve_structure_equilibrium(structure, start=start)
    assert result.success and result.stable, result.message
    assert sorted(result.sliding) == ['x_up.b', 'y_front.b', 'z_left.b']
    x0 = structure.node_positions(start)
    for name, f in result.contacts.items():
        tangential = f[:2]
        np.testing.assert_allclose(np.linalg.norm(tangential), 0.001 * f[2], rtol=1e-9)
        slip = result.state.node_positions[name][:2] - x0[structure.node_index(name), :2]
        assert np.linalg.norm(slip) > 1e-6
        # Against the slip.
        np.testing.assert_allclose(tangential / np.linalg.norm(tangential),
                                   -slip / np.linalg.norm(slip), atol=1e-6)
    assert_balanced(structure, result)


def test_a_frictionless_ground_has_the_plane_motions_as_gauge():
    structure, start = on_the_ground(0.0)
    result = solve_structure_equilibrium(structure, start=start)
    assert result.success and result.stable, result.message
    for f in result.contacts.values():
        np.testing.assert_allclose(f[:2], 0.0, atol=1e-12)
    # Gauge: 6 bar spins, 2 translations and the turn about the normal.
    assert result.gauge.shape[1] == 9
    assert_balanced(structure, result)


def test_the_tangent_stiffness_is_symmetric_at_a_conservative_equilibrium():
    structure, start = on_the_ground(0.8)
    result = solve_structure_equilibrium(structure, start=start)
    K = result.tangent_stiffness
    # Symmetric up to the residual moments' terms: at an equilibrium under conservative forces.
    scale = np.max(np.abs(K))
    assert np.max(np.abs(K - K.T)) < 1e-9 * scale
    # The gauge twists are null vectors of the strings' stiffness.
    spins = result.gauge
    assert np.max(np.abs(result.state.stiffness @ spins[:, :6])) < 1e-9 * scale


def test_bad_loads_are_named():
    structure = example(SIXBAR)
    with pytest.raises(ValueError, match="no body 'x_upp'"):
        solve_structure_equilibrium(structure, loads={'x_upp': np.zeros(6)})
    with pytest.raises(ValueError, match=r"loads\['x_up'\] must be 6 values"):
        solve_structure_equilibrium(structure, loads={'x_up': [1, 2]})
    with pytest.raises(ValueError, match=r'loads must have shape \(6, 6\)'):
        solve_structure_equilibrium(structure, loads=np.zeros((5, 6)))


def test_a_free_structure_under_gravity_without_ground_falls():
    document = copy.deepcopy(example(SIXBAR).to_dict())
    document['structure']['gravity'] = [0.0, 0.0, -9.81]
    result = solve_structure_equilibrium(Structure.from_dict(document))
    assert not result.success
    assert 'the structure falls' in result.message


def test_a_ground_above_a_node_lifts_it():
    """A start with a node below the ground: that node is a contact at its projection and the
    structure is pushed out (no node below the ground at the solution)."""
    structure, start = on_the_ground(0.8)
    dropped = start.copy()
    dropped[:, 2, 3] -= structure.node_positions(start)[:, 2].min() + 0.002
    result = solve_structure_equilibrium(structure, start=dropped)
    assert result.success, result.message
    heights = np.array([x[2] for x in result.state.node_positions.values()])
    assert heights.min() > -1e-12
    assert_balanced(structure, result)


def test_an_oversized_prism_on_the_ground_slides_inwards_to_the_cone():
    """A 3-prism whose strings are all 10 % short stands on its bottom nodes: it contracts, the
    bottom nodes slide inwards until the ground's outward friction is at the cone."""
    document = prism_document(3)
    document['structure']['gravity'] = [0.0, 0.0, -9.81]
    document['structure']['ground'] = {'friction': 0.5}
    structure = Structure.from_dict(document)
    result = solve_structure_equilibrium(structure)
    assert result.success and result.stable, result.message
    assert sorted(result.sliding) == ['bar0.a', 'bar1.a', 'bar2.a']
    x0 = structure.node_positions(structure.start_poses())
    for name, f in result.contacts.items():
        np.testing.assert_allclose(f[2], 3 * 0.05 * 9.81 / 3, rtol=1e-9)
        np.testing.assert_allclose(np.linalg.norm(f[:2]), 0.5 * f[2], rtol=1e-9)
        start = x0[structure.node_index(name), :2]
        now = result.state.node_positions[name][:2]
        assert np.linalg.norm(now) < np.linalg.norm(start)  # inwards
        assert f[:2] @ now > 0  # pushed outwards
    assert_balanced(structure, result)


def six_bar_on_ground(friction=0.8):
    document = copy.deepcopy(example(SIXBAR).to_dict())
    document['structure']['gravity'] = [0.0, 0.0, -9.81]
    document['structure']['ground'] = {'friction': friction}
    return Structure.from_dict(document)


def assert_resting(structure, result):
    """Stable on three contacts that carry the weight, the centre of mass above their
    triangle, no node below the ground, every body balanced."""
    assert result.success and result.stable, result.message
    assert len(result.contacts) == 3
    heights = np.array([x[2] for x in result.state.node_positions.values()])
    assert heights.min() > -1e-12
    assert_balanced(structure, result)
    masses = np.array([b.mass for b in structure.bodies])
    centre = masses @ result.poses[:, :3, 3] / masses.sum()
    corners = np.array([result.state.node_positions[k][:2] for k in result.contacts])
    # Barycentric coordinates of the centre's projection: all positive inside.
    A = np.vstack([corners.T, np.ones(3)])
    weights = np.linalg.solve(A, np.r_[centre[:2], 1.0])
    assert np.all(weights > 0), weights


@pytest.mark.parametrize('seed', range(6))
def test_a_six_bar_set_down_in_any_orientation_tips_onto_a_face(seed):
    """Placed anywhere (even through the ground), the free 6-bar under gravity is moved onto the
    ground, tipped over its node and edge by its weight, and comes to rest on three nodes."""
    structure = six_bar_on_ground()
    rng = np.random.default_rng(seed)
    G = twist_exp(np.r_[0.0, 0.0, 0.0, rng.uniform(-math.pi, math.pi, 3)])
    start = np.array([G @ P for P in structure.start_poses()])
    assert_resting(structure, solve_structure_equilibrium(structure, start=start))


def test_a_six_bar_balanced_on_an_edge_is_rolled_over():
    """The symmetric start stands on the edge z_left.a - z_right.a, balanced: the solver finds
    it not stable and rolls it onto the nearer face; without rolling it reports the balance."""
    structure = six_bar_on_ground()
    balanced = solve_structure_equilibrium(structure, roll=False)
    assert balanced.success and not balanced.stable
    assert sorted(balanced.contacts) == ['z_left.a', 'z_right.a']
    assert 'not stable' in balanced.message
    rolled = solve_structure_equilibrium(structure)
    assert 'rolled over once' in rolled.message
    assert_resting(structure, rolled)
    assert {'z_left.a', 'z_right.a'} < set(rolled.contacts)


def test_rest_lengths_time_budget_and_a_structure_of_fixed_bodies():
    structure = example(SIXBAR)
    shorter = solve_structure_equilibrium(structure, rest_lengths=structure.rest_lengths * 0.8)
    assert shorter.success
    stretch = shorter.state.lengths - 0.8 * structure.rest_lengths
    np.testing.assert_allclose(shorter.state.tensions, structure.k * stretch)
    start = perturbed(structure.start_poses(), np.random.default_rng(0), 0.05)
    spent = solve_structure_equilibrium(structure, start=start, time_budget=0.0)
    assert not spent.success and 'time budget exhausted' in spent.message
    assert spent.iterations == MIN_NEWTON_ITERATIONS  # the steps no budget cuts short
    # The config's start on the ground converges in those steps: a budget spent before the
    # first step (a CPU-starved node) still gives the answer.
    easy = solve_structure_equilibrium(structure, time_budget=0.0)
    assert easy.success and easy.iterations <= MIN_NEWTON_ITERATIONS, easy.message
    document = copy.deepcopy(mixed_document())
    for body in document['structure']['bodies']:
        body['fixed'] = True
    held = Structure.from_dict(document)
    result = solve_structure_equilibrium(held)
    assert result.success and result.stable
    np.testing.assert_array_equal(result.poses, held.start_poses())


@pytest.mark.parametrize('mode', ['stick', 'slide', 'frictionless'])
def test_the_newton_jacobian_matches_central_differences(mode):
    """The exact Jacobian of the equilibrium equations (strings, weights, contact forces and
    their moment arms, the sticking and the sliding law, the increments' Pi J) against central
    differences of the residuals, away from an equilibrium."""
    from tensegrity_stiffness.structures.equilibrium import SLIDE, Contact, _Problem

    structure, start = on_the_ground(0.0 if mode == 'frictionless' else 0.3)
    start[:, 2, 3] -= structure.node_positions(start)[:, 2].min()
    x0 = structure.node_positions(start)
    contacts = []
    for name in ('x_up.b', 'y_front.b', 'z_left.b'):
        j = structure.node_index(name)
        anchor = x0[j] + np.array([0.01, -0.02, 0.0])  # slipped from where it touched
        contacts.append(Contact(j, int(structure.node_bodies[j]), anchor,
                                'stick' if mode == 'stick' else SLIDE))
    rng = np.random.default_rng(3)
    loads = rng.normal(scale=0.3, size=(structure.n_bodies, 6))
    problem = _Problem(structure, loads, structure.rest_lengths, start, contacts)
    x = np.concatenate([rng.normal(scale=0.02, size=6 * structure.n_bodies),
                        rng.normal(scale=0.5, size=9) + np.tile([0, 0, 2.0], 3)])
    A = problem.residual_jacobian(x, problem.evaluate(x)[1])
    step = 1e-6
    numeric = np.empty_like(A)
    for k in range(x.size):
        e = np.zeros(x.size)
        e[k] = step
        numeric[:, k] = (problem.evaluate(x + e)[0] - problem.evaluate(x - e)[0]) / (2 * step)
    np.testing.assert_allclose(A, numeric, rtol=0, atol=1e-6 * np.max(np.abs(A)))
