"""Modes and the linear model of structures: the mass matrix against the kinetic energy, a bar
hanging from two strings against its closed-form frequencies (bounce sqrt(2k/m), the pendulum
sqrt(g/l) both ways, tilt and yaw) and damping ratio, and the zero modes of free structures
counted and named (rigid motions, bar spins, no mechanism of a prestress-stable 6-bar)."""

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


def test_massless_free_bodies_are_refused():
    structure = hanging_bar()
    document = structure.to_dict()
    document['structure']['bodies'][0]['mass'] = 0.0
    document['structure']['bodies'][0]['inertia'] = [0.0, 0.0, 0.0]
    massless = Structure.from_dict(document)
    result = solve_structure_equilibrium(massless)
    with pytest.raises(ValueError, match=r"\['bar'\] have none"):
        structure_modes(massless, result)
