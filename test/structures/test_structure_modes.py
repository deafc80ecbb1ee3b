"""Modes and the linear model of structures: the mass matrix against the kinetic energy, a bar
hanging from two strings against its closed-form frequencies (bounce sqrt(2k/m), the pendulum
sqrt(g/l) both ways, tilt and yaw) and damping ratio, and the zero modes of free structures
counted and named (rigid motions, bar spins, no mechanism of a prestress-stable 6-bar; the plane
motions of the 6-bar on a frictionless ground; the mechanism of a body held on a line)."""

import math

import numpy as np
import pytest
from structure_fixtures import SIXBAR, example, perturbed

from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.modes import mass_matrix, structure_modes
from tensegrity_stiffness.structures.structure import Structure

M, L, K, L0, G, C = 0.1, 0.4, 200.0, 0.3, 9.81, 0.05


def hanging_bar(damping=0.0):
    """A bar along x hanging from two vertical strings at its ends."""
    s = math.sqrt(0.5)
    return Structure.from_dict({'structure': {
        'gravity': [0.0, 0.0, -G],
        'bodies': [{'name': 'bar', 'type': 'bar', 'length': L, 'mass': M,
                    'pose': [0.0, 0.0, 0.5 - L0, 0.0, s, 0.0, s]}],
        'world_nodes': {'left': [-L / 2, 0.0, 0.5], 'right': [L / 2, 0.0, 0.5]},
        'strings': [
            {'from': 'world.left', 'to': 'bar.a', 'stiffness': K, 'rest_length': L0,
             'damping': damping},
            {'from': 'world.right', 'to': 'bar.b', 'stiffness': K, 'rest_length': L0,
             'damping': damping}]}})


def test_the_mass_matrix_gives_the_kinetic_energy():
    structure = example(SIXBAR)
    rng = np.random.default_rng(0)
    T = perturbed(structure.start_poses(), rng, 0.3)
    Mm = mass_matrix(structure, T)
    twist = rng.normal(size=6 * structure.n_bodies)
    energy = 0.0
    for i, body in enumerate(structure.bodies):
        v, w = twist[6 * i:6 * i + 3], twist[6 * i + 3:6 * i + 6]
        c = T[i, :3, :3] @ body.com + T[i, :3, 3]
        Iw = T[i, :3, :3] @ body.inertia @ T[i, :3, :3].T
        vc = v + np.cross(w, c)
        energy += 0.5 * body.mass * vc @ vc + 0.5 * w @ Iw @ w
    np.testing.assert_allclose(0.5 * twist @ Mm @ twist, energy, rtol=1e-12)
    np.testing.assert_allclose(Mm, Mm.T, atol=1e-15)


def test_a_hanging_bar_has_its_closed_form_frequencies():
    structure = hanging_bar()
    result = solve_structure_equilibrium(structure)
    assert result.success and result.stable, result.message
    modes = structure_modes(structure, result)
    length = L0 + M * G / (2 * K)  # the stretched strings
    bar = structure.body('bar')
    inertia = bar.inertia[0, 0]  # transverse, about the centre
    expected = sorted([
        math.sqrt(2 * K / M),  # bounce
        math.sqrt(G / length), math.sqrt(G / length),  # pendulum across and along the bar
        math.sqrt(2 * K * (L / 2) ** 2 / inertia),  # tilt
        math.sqrt(M * G * (L / 2) ** 2 / (length * inertia)),  # yaw (bifilar pendulum)
    ])
    np.testing.assert_allclose(modes.frequencies * 2 * math.pi, expected, rtol=1e-9)
    assert modes.zero_modes == ('spin of bar',)
    assert modes.counts == {'rigid': 0, 'spins': 1, 'mechanisms': 0}
    assert modes.stable
    assert modes.A.shape == (12, 12) and modes.B.shape == (12, 6)


def test_string_damping_gives_the_bounce_its_damping_ratio():
    structure = hanging_bar(C)
    modes = structure_modes(structure, solve_structure_equilibrium(structure))
    bounce = int(np.argmin(np.abs(modes.frequencies * 2 * math.pi - math.sqrt(2 * K / M))))
    np.testing.assert_allclose(modes.damping_ratios[bounce], C / math.sqrt(2 * K * M),
                               rtol=1e-6)


def test_a_free_six_bar_has_rigid_motions_and_spins_as_its_zero_modes():
    structure = example(SIXBAR)
    result = solve_structure_equilibrium(structure)
    modes = structure_modes(structure, result)
    assert modes.counts == {'rigid': 6, 'spins': 6, 'mechanisms': 0}
    assert modes.zero_modes.count('rigid motion') == 6
    assert sorted(n for n in modes.zero_modes if n.startswith('spin')) == sorted(
        f'spin of {b}' for b in structure.bar_names)
    assert len(modes.frequencies) == 36 - 12 and np.all(modes.frequencies > 0)
    assert modes.stable


@pytest.mark.parametrize('friction', [0.0, 0.8])
def test_on_a_frictionless_ground_the_plane_motions_are_zero_modes(friction):
    """The 6-bar resting on a face: frictionless, it slides and turns freely along the ground
    (3 plane motions beside the 6 spins); with friction the contacts hold (the spins only)."""
    from test_structure_equilibrium import on_the_ground

    structure, start = on_the_ground(friction)
    result = solve_structure_equilibrium(structure, start=start)
    assert result.success and result.stable, result.message
    modes = structure_modes(structure, result)
    planes = 3 if friction == 0.0 else 0
    assert modes.counts == {'rigid': planes, 'spins': 6, 'mechanisms': 0}
    assert modes.zero_modes.count('plane motion') == planes
    assert 'rigid motion' not in modes.zero_modes and 'mechanism' not in modes.zero_modes
    # Three contacts hold 3 coordinates each, frictionless only the normal one.
    held = 3 * (1 if friction == 0.0 else 3)
    assert modes.basis.shape[1] == 36 - held
    assert len(modes.frequencies) == 36 - held - 6 - planes and np.all(modes.frequencies > 0)
    T, K = result.poses, result.tangent_stiffness
    X = structure.node_positions(T)
    body_of = [structure.body_index(n.split('.')[0]) for n in structure.node_names]
    shapes = modes.zero_shapes[[k for k, n in enumerate(modes.zero_modes)
                                if n == 'plane motion']]
    for shape in shapes:
        twist = shape.reshape(-1, 6)
        assert np.abs(K @ shape).max() < 1e-9 * np.abs(K).max()
        # Every node moves along the ground, as one rigid motion of the whole (a bar's spin
        # mixed in moves none of its nodes).
        dx = np.array([twist[b, :3] + np.cross(twist[b, 3:], x) for b, x in zip(body_of, X,
                                                                                 strict=True)])
        np.testing.assert_allclose(dx[:, 2], 0.0, atol=1e-12)
        n = len(X)
        rigid = np.zeros((2 * n, 3))  # (vx, vy, w): dx = v + w e_z x x
        rigid[0::2, 0], rigid[1::2, 1] = 1.0, 1.0
        rigid[0::2, 2], rigid[1::2, 2] = -X[:, 1], X[:, 0]
        fit = np.linalg.lstsq(rigid, dx[:, :2].ravel(), rcond=None)[0]
        np.testing.assert_allclose(rigid @ fit, dx[:, :2].ravel(), atol=1e-12)
    if planes:
        # Together they are the two translations and the turn about the normal.
        plane = np.zeros((3, 6 * structure.n_bodies))
        plane[0, 0::6], plane[1, 1::6], plane[2, 5::6] = 1.0, 1.0, 1.0
        span = modes.zero_shapes.T
        coefficients = np.linalg.lstsq(span, plane.T, rcond=None)[0]
        np.testing.assert_allclose(span @ coefficients, plane.T, atol=1e-12)


def held_on_a_line(kind):
    """A ``kind`` (general body or bar) held along z between two world anchors by two strings
    on one line, no gravity: tension T = k (l - l0) = 10 N in strings of length l = 0.3 m."""
    body = {'name': 'hub', 'type': kind, 'mass': M, 'pose': [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]}
    if kind == 'body':
        body.update(nodes={'a': [0.0, 0.0, -0.1], 'b': [0.0, 0.0, 0.1]},
                    inertia=[1e-3, 1e-3, 2e-4])
    else:
        body['length'] = 0.2
    return Structure.from_dict({'structure': {
        'bodies': [body],
        'world_nodes': {'below': [0.0, 0.0, -0.4], 'above': [0.0, 0.0, 0.4]},
        'strings': [
            {'from': 'world.below', 'to': 'hub.a', 'stiffness': K, 'rest_length': 0.2},
            {'from': 'hub.b', 'to': 'world.above', 'stiffness': K, 'rest_length': 0.2}]}})


def test_a_body_held_on_a_line_has_its_turn_about_it_as_a_mechanism():
    """A general body whose two strings lie on one line: its turn about that line moves no node
    (no string and no prestress resists it), a mechanism; sideways it is held by the prestress
    (T / l per string), along the line by the strings' stiffness, its tilt by both."""
    structure = held_on_a_line('body')
    result = solve_structure_equilibrium(structure)
    assert result.success, result.message
    assert not result.stable  # the mechanism has no stiffness
    modes = structure_modes(structure, result)
    assert modes.zero_modes == ('mechanism',)
    assert modes.counts == {'rigid': 0, 'spins': 0, 'mechanisms': 1}
    turn = modes.zero_shapes[0] * np.sign(modes.zero_shapes[0][5])
    np.testing.assert_allclose(turn, [0, 0, 0, 0, 0, 1.0], atol=1e-12)
    tension, length, arm, inertia = K * 0.1, 0.3, 0.1, 1e-3
    sideways = math.sqrt(2 * tension / (length * M))
    tilt = math.sqrt(2 * tension * arm * (1 + arm / length) / inertia)
    np.testing.assert_allclose(modes.frequencies * 2 * math.pi,
                               sorted([sideways, sideways, math.sqrt(2 * K / M), tilt, tilt]),
                               rtol=1e-9)
    assert modes.stable  # no mode with negative stiffness
    # The same held bar: the motion is its spin, a gauge, not a mechanism.
    bar = held_on_a_line('bar')
    bar_modes = structure_modes(bar, solve_structure_equilibrium(bar))
    assert bar_modes.zero_modes == ('spin of hub',)
    assert bar_modes.counts == {'rigid': 0, 'spins': 1, 'mechanisms': 0}


def test_massless_free_bodies_are_refused():
    structure = hanging_bar()
    document = structure.to_dict()
    document['structure']['bodies'][0]['mass'] = 0.0
    document['structure']['bodies'][0]['inertia'] = [0.0, 0.0, 0.0]
    massless = Structure.from_dict(document)
    result = solve_structure_equilibrium(massless)
    with pytest.raises(ValueError, match=r"\['bar'\] have none"):
        structure_modes(massless, result)
