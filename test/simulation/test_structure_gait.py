"""The scripted roll of the 6-bar: the plan (library equilibria on the ground) and the MuJoCo
twin running it, which rolls onto the planned face with the planned move of its centre of
mass in a bounded simulated time."""

import numpy as np
import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.simulation.structure_gait import (
    DONE,
    TIP_MARGIN,
    RollGait,
    centre_of_mass,
    face_across,
    plan_roll_step,
    rolled_onto,
    run_roll,
)
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure

mujoco = pytest.importorskip('mujoco')


@pytest.fixture(scope='module')
def six_bar():
    return Structure.from_yaml(config.example_config_path('six_bar.yaml'))


@pytest.fixture(scope='module')
def step(six_bar):
    return plan_roll_step(six_bar, direction=(1.0, 0.0, 0.0))


def test_the_plan_rolls_over_an_edge_of_the_support_face_onto_the_hull_face_across(six_bar,
                                                                                   step):
    base = solve_structure_equilibrium(six_bar)
    assert set(step.start_face) == set(base.contacts)
    assert set(step.edge) < set(step.start_face) and set(step.edge) < set(step.next_face)
    assert step.next_face != step.start_face
    # The rigid roll puts the next face on the ground, every other node above it.
    T = rolled_onto(six_bar, base.poses, step.edge, step.next_face)
    x = six_bar.node_positions(T)
    heights = {n: x[six_bar.node_index(n), 2] for n in six_bar.node_names}
    base_x = six_bar.node_positions(base.poses)
    assert max(abs(heights[n] - base_x[six_bar.node_index(step.edge[0]), 2])
               for n in step.next_face) < 1e-12
    assert min(h for n, h in heights.items() if n not in step.next_face) > 1e-3
    # The tipping command: only the tipping strings shortened, by the planned fraction; its
    # equilibrium on the start face has the centre of mass past the edge by the margin.
    changed = np.flatnonzero(step.tip_rest_lengths != step.nominal_rest_lengths)
    assert [six_bar.string_names[j] for j in changed] == list(step.strings)
    np.testing.assert_allclose(step.tip_rest_lengths[changed],
                               (1 - step.contraction) * six_bar.rest_lengths[changed])
    assert 0 < step.contraction <= 0.5
    assert step.margin >= TIP_MARGIN * 0.05  # the 6-bar's support face: inradius 53 mm
    # The landing face is an equilibrium of the library, stable, with the planned COM move.
    assert len(step.landing_face) == 3 and set(step.edge) < set(step.landing_face)
    move = centre_of_mass(six_bar, step.landing_poses) - centre_of_mass(six_bar, base.poses)
    np.testing.assert_allclose(move[:2], step.com_step[:2], atol=1e-12)
    assert 0.05 < np.linalg.norm(step.com_step) < 0.15


def test_the_hull_face_across_an_edge(six_bar):
    base = solve_structure_equilibrium(six_bar)
    face = tuple(sorted(base.contacts, key=six_bar.node_names.index))
    for a in range(3):
        edge = (face[a], face[(a + 1) % 3])
        other = face_across(six_bar, base.poses, face, edge)
        assert set(edge) < set(other) and set(other) != set(face)
    with pytest.raises(ValueError, match='no hull face'):
        face_across(six_bar, base.poses, face, ('x1.a', 'x1.b'))


def test_the_twin_rolls_onto_the_planned_face(six_bar, step):
    """Quasi-static motors (0.02 m/s): the twin tips over the planned edge, lands on the planned
    face and its centre of mass moves as planned, within 20 s of simulated time."""
    from tensegrity_stiffness.simulation.structure_twin import StructureSimulation

    base = solve_structure_equilibrium(six_bar)
    sim = StructureSimulation(six_bar, poses=base.poses, rest_length_rate=0.02)
    start = sim.centre_of_mass()
    record = run_roll(sim, n_steps=1, direction=(1.0, 0.0, 0.0), max_time=20.0)
    assert record.phases[-1] == DONE
    assert record.steps[0].landing_face == step.landing_face
    assert sim.contact_nodes() == list(step.landing_face)
    assert set(record.contacts[0]) == set(step.start_face)
    move = (sim.centre_of_mass() - start)[:2]
    planned = step.com_step[:2]
    assert abs(np.linalg.norm(move) / np.linalg.norm(planned) - 1.0) < 0.3
    assert move @ planned / (np.linalg.norm(move) * np.linalg.norm(planned)) > 0.95
    assert record.times[-1] - record.times[0] < 20.0
    # The phases in order: tip, recover, done.
    phases = [p for i, p in enumerate(record.phases) if i == 0 or p != record.phases[i - 1]]
    assert phases == ['tip', 'recover', 'done']


def test_the_gait_follows_the_contacts(step):
    gait = RollGait(step, timeout=5.0)
    np.testing.assert_array_equal(gait.update(0.0, list(step.start_face), True),
                                  step.tip_rest_lengths)
    assert gait.update(0.5, list(step.start_face), True) is None and gait.phase == 'tip'
    new = next(n for n in step.next_face if n not in step.edge)
    np.testing.assert_array_equal(gait.update(1.0, [*step.edge, new], False),
                                  step.nominal_rest_lengths)
    assert gait.phase == 'recover'
    assert gait.update(1.5, list(step.next_face), False) is None and gait.phase == 'recover'
    gait.update(2.0, list(step.next_face), True)
    assert gait.phase == DONE and not gait.failed
    stuck = RollGait(step, timeout=1.0)
    stuck.update(0.0, list(step.start_face), True)
    stuck.update(2.0, list(step.start_face), True)
    assert stuck.phase == DONE and stuck.failed


def test_bad_plans_are_refused(six_bar):
    document = six_bar.to_dict()
    document['structure'].pop('ground')
    with pytest.raises(ValueError, match='gravity and a ground'):
        plan_roll_step(Structure.from_dict(document))
    with pytest.raises(ValueError, match='along the ground normal'):
        plan_roll_step(six_bar, direction=(0, 0, 1))
    with pytest.raises(ValueError, match='n_strings'):
        plan_roll_step(six_bar, n_strings=0)
