"""``structure_node``'s ROS-free part (:mod:`tensegrity_stiffness.nodes.structure_node`): its
settings from the parameter table, the input checks, the outputs against the library, the
contact forces and the health against the equilibrium solver, the service jobs."""

from __future__ import annotations

import numpy as np
import pytest

from tensegrity_stiffness.mechanics.templates import pose_vector
from tensegrity_stiffness.nodes import structure_node as sn
from tensegrity_stiffness.nodes.parameter_specs import defaults
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import twist_exp


def settings_of(**values):
    return sn.structure_node_settings({**defaults(sn.STRUCTURE_NODE_PARAMETERS), **values})


@pytest.fixture(scope='module')
def six_bar():
    settings = settings_of()
    eq = solve_structure_equilibrium(settings.structure)
    assert eq.success, eq.message
    return settings, eq


@pytest.mark.parametrize('example, bodies', [('six_bar.yaml', 6), ('three_bar.yaml', 3)])
def test_settings_of_the_packaged_examples(example, bodies):
    settings = settings_of(**{'structure.config': example})
    assert settings.n_bodies == bodies
    assert settings.body_frames == tuple(settings.structure.body_names)
    layouts = sn.structure_output_layouts(settings.structure)
    assert list(layouts) == list(sn.STRUCTURE_OUTPUTS)  # both have a ground
    assert layouts['stiffness'].size == (6 * bodies) ** 2


@pytest.mark.parametrize('values, message', [
    ({'structure.config': 'nope.yaml'}, r'structure\.config: no file'),
    ({'frames.world': ' '}, r'frames\.world must not be empty'),
    ({'joint.rest_length_offsets': [0.0, 0.1]}, r'joint\.rest_length_offsets must have 1 or 24'),
    ({'limits.max_array_length': 30}, r'limits\.max_array_length = 30 is below'),
])
def test_bad_settings_name_the_parameter(values, message):
    with pytest.raises(ValueError, match=message):
        settings_of(**values)


def test_pose_values_are_read_as_the_structure_reads_them(six_bar):
    settings, eq = six_bar
    rng = np.random.default_rng(1)
    values = np.array([pose_vector(twist_exp(0.1 * rng.standard_normal(6)) @ P)
                       for P in eq.poses])
    values[:, 3:] *= 1.0 + 1e-4  # renormalised within the tolerance, as Structure.transforms
    s = settings.structure
    np.testing.assert_allclose(sn.pose_values_input(values.ravel(), s), s.transforms(values),
                               rtol=0.0, atol=1e-15)


@pytest.mark.parametrize('change, message', [
    (lambda v: v[:-1], r'expected 7 N = 42 values'),
    (lambda v: np.r_[v[:10], np.zeros(4), v[14:]], r'poses\[1\] \(x2\).*zero norm'),
    (lambda v: np.r_[v[:10], 2.0 * v[10:14], v[14:]], r'poses\[1\] \(x2\).*not a unit'),
])
def test_bad_pose_values_name_the_body(six_bar, change, message):
    settings, eq = six_bar
    values = np.ravel([pose_vector(P) for P in eq.poses])
    with pytest.raises(ValueError, match=message):
        sn.pose_values_input(change(values), settings.structure)


def test_poses_input_checks_the_frame_and_count(six_bar):
    _, eq = six_bar
    np.testing.assert_array_equal(sn.poses_input('', list(eq.poses), 'world', 6), eq.poses)
    with pytest.raises(ValueError, match=r"'map' is not the world frame 'world'"):
        sn.poses_input('map', list(eq.poses), 'world', 6)
    with pytest.raises(ValueError, match=r'expected N = 6 poses'):
        sn.poses_input('world', list(eq.poses[:5]), 'world', 6)


def test_outputs_are_the_librarys_and_the_contacts_the_equilibriums(six_bar):
    settings, eq = six_bar
    out = sn.structure_outputs(settings, eq.poses)
    state = settings.structure.evaluate(eq.poses)
    for got, want in zip(sn.output_arrays(out)[:4], (state.wrenches, state.stiffness,
                                                      state.tensions, state.bar_forces),
                         strict=True):
        np.testing.assert_array_equal(got, want)
    nodes = sn.body_nodes(settings.structure)
    assert [nodes[i] for i in np.flatnonzero(np.any(out.contact_forces, axis=1))] == list(
        eq.contacts)
    for name, f in eq.contacts.items():
        np.testing.assert_allclose(out.contact_forces[nodes.index(name)], f, atol=1e-9)
    skipped = sn.structure_outputs(settings, eq.poses, contacts=False)
    assert not skipped.contacts and not np.any(skipped.contact_forces)


def test_health_at_the_equilibrium_is_its_stability(six_bar):
    settings, eq = six_bar
    health = sn.structure_health(settings, sn.structure_outputs(settings, eq.poses,
                                                                contacts=False))
    assert health.stable and not health.problems and health.contacts == list(eq.contacts)
    assert health.stability_margin == pytest.approx(eq.stability_margin, rel=1e-9)
    assert health.smallest_eigenvalue > 0.0


def test_commanded_rest_lengths_take_the_offsets(six_bar):
    settings, _ = six_bar
    rest = settings.structure.rest_lengths
    offset = settings_of(**{'joint.rest_length_offsets': [0.01]})
    updated = sn.with_commanded_rest_lengths(offset, rest - 0.01)
    np.testing.assert_allclose(updated.rest_lengths, rest, rtol=0.0, atol=1e-15)
    with pytest.raises(ValueError, match=r'expected 24 values'):
        sn.with_commanded_rest_lengths(settings, rest[:3])
    with pytest.raises(ValueError, match=r'rest_lengths must be 24 values > 0'):
        sn.with_commanded_rest_lengths(settings, -rest)


def test_equilibrium_jobs(six_bar):
    settings, eq = six_bar
    job = sn.equilibrium_job(settings, [], [], [], True, True, eq.poses)
    assert job.structure.gravity is None and job.structure.ground is None
    assert job.loads is None and job.start is eq.poses
    result = solve_structure_equilibrium(*job.args(), **job.kwargs())
    assert result.success and not result.contacts
    with pytest.raises(ValueError, match=r'loads: expected 6 N = 36'):
        sn.equilibrium_job(settings, [0.0] * 5, [], [], False, False, None)
    with pytest.raises(ValueError, match=r'start: expected 7 N = 42'):
        sn.equilibrium_job(settings, [], [0.0] * 5, [], False, False, None)
    with pytest.raises(ValueError, match=r'rest_lengths:'):
        sn.equilibrium_job(settings, [], [], [1.0], False, False, None)
    assert sn.equilibrium_job(settings, [], [], [], False, False, None).structure is (
        settings.structure)
