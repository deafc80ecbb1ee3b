"""The structure model: its schema (from_dict / to_dict, errors that name the entry, unknown
keys), and its evaluation: the closed-form stiffness against central differences of the
wrenches, the balance of the internal forces, the bar forces."""

import copy
import warnings

import numpy as np
import pytest
from structure_fixtures import PRISM3, SIXBAR, example, mixed_document, perturbed

from tensegrity_stiffness.config import UnknownKeyWarning
from tensegrity_stiffness.structures.structure import Structure


def assert_same_document(a, b, where='') -> None:
    """Equal documents, floats to 1e-14 (a pose's quaternion is read and written again)."""
    assert type(a) is type(b), where
    if isinstance(a, dict):
        assert list(a) == list(b), where
        for key in a:
            assert_same_document(a[key], b[key], f'{where}.{key}')
    elif isinstance(a, list):
        assert len(a) == len(b), where
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            assert_same_document(x, y, f'{where}[{i}]')
    elif isinstance(a, float):
        assert abs(a - b) <= 1e-14 * max(1.0, abs(b)), where
    else:
        assert a == b, where


def numpy_structure(document, **kwargs):
    return Structure.from_dict(document, use_kernel=False, **kwargs)


def test_the_packaged_examples_load():
    prism = example(PRISM3)
    assert prism.n_bodies == 3 and prism.n_strings == 9
    assert prism.bar_names == ['bar0', 'bar1', 'bar2']
    six = example(SIXBAR)
    assert six.n_bodies == 6 and six.n_strings == 24
    assert 'x_up.a' in six.node_names
    np.testing.assert_allclose(six.body('x_up').nodes['b'], [0, 0, 0.5])


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_to_dict_reads_back_to_the_same_structure(force_law):
    document = mixed_document(force_law)
    document['structure']['ground'] = {'normal': [0, 0, 2], 'height': -0.1, 'friction': 0.5}
    first = numpy_structure(document)
    second = numpy_structure(first.to_dict())
    assert_same_document(second.to_dict(), first.to_dict())
    rng = np.random.default_rng(3)
    T = perturbed(first.start_poses(), rng)
    a, b = first.evaluate(T), second.evaluate(T)
    np.testing.assert_allclose(b.wrenches, a.wrenches, rtol=0, atol=1e-12)
    np.testing.assert_allclose(b.stiffness, a.stiffness, rtol=0, atol=1e-10)
    np.testing.assert_allclose(second.ground.normal, [0, 0, 1])


def test_a_ros_parameter_file_layout_is_read():
    document = {'/**': {'ros__parameters': mixed_document()}}
    assert numpy_structure(document).n_strings == 7


@pytest.mark.parametrize('edit, message', [
    (lambda s: s['strings'][3].update({'to': 'bar1.c'}),
     "structure.strings[3].to: no node 'c' on body 'bar1'"),
    (lambda s: s['strings'][0].update({'from': 'hubb.A'}),
     "structure.strings[0].from: no body 'hubb' (did you mean 'hub'?)"),
    (lambda s: s['strings'][1].pop('stiffness'), 'structure.strings[1].stiffness is missing'),
    (lambda s: s['strings'][2].update({'rest_length': -1.0}),
     'structure.strings[2].rest_length must be > 0'),
    (lambda s: s['bodies'][1].pop('length'), 'structure.bodies[1].length is missing'),
    (lambda s: s['bodies'][0].update({'inertia': [1, 2]}), 'structure.bodies[0].inertia'),
    (lambda s: s['bodies'][0].update({'pose': [0, 0, 0, 0, 0, 0, 2]}),
     'structure.bodies[0].pose'),
    (lambda s: s['bodies'][2].update({'name': 'bar0'}), "structure.bodies[2].name: 'bar0'"),
    (lambda s: s['bodies'][2].update({'type': 'rod'}), 'structure.bodies[2].type'),
    (lambda s: s.update({'force_law': 'linear'}), 'structure.force_law'),
    (lambda s: s.update({'gravity': [0, 0]}), 'structure.gravity'),
    (lambda s: s.update({'ground': {'normal': [0, 0, 0]}}), 'structure.ground.normal'),
    (lambda s: s['strings'][4].update({'from': 'world.w9'}),
     "structure.strings[4].from: no world node 'w9'"),
    (lambda s: s['bodies'][0]['nodes'].update({'A.1': [0, 0, 0]}),
     'structure.bodies[0].nodes: a node name must be non-empty and without "."'),
])
def test_errors_name_the_entry(edit, message):
    document = copy.deepcopy(mixed_document())
    edit(document['structure'])
    with pytest.raises(ValueError) as info:
        numpy_structure(document)
    assert message in str(info.value)


def test_unknown_keys_are_refused_with_the_nearest_name():
    """All named at once, in the one format of every reader (issue #39); strict=False warns."""
    document = copy.deepcopy(mixed_document())
    document['structure']['strings'][0]['stifness'] = 3.0
    document['structure']['strings'][0]['stiffness'] = 3.0
    document['structure']['bodies'][1]['lenght'] = 2.0
    document['structure']['gravty'] = [0, 0, -1]
    expected = ('structure.strings[0].stifness: unknown key (did you mean '
                'structure.strings[0].stiffness?)',
                'structure.bodies[1].lenght: unknown key (did you mean '
                'structure.bodies[1].length?)',
                'structure.gravty: unknown key (did you mean structure.gravity?)')
    with pytest.raises(ValueError) as caught:
        numpy_structure(document)
    assert all(line in str(caught.value) for line in expected), caught.value
    with warnings.catch_warnings(record=True) as warned:
        warnings.simplefilter('always')
        numpy_structure(document, strict=False)
    texts = [str(w.message) for w in warned if issubclass(w.category, UnknownKeyWarning)]
    assert all(any(line in t for t in texts) for line in expected), texts


def test_bars_have_their_nodes_on_their_axis():
    six = example(SIXBAR, use_kernel=False)
    state = six.evaluate()
    # The 6-bar's start: node x_up.a at (-0.5, 0, 0.25), b at (0.5, 0, 0.25).
    np.testing.assert_allclose(state.node_positions['x_up.a'], [-0.5, 0, 0.25], atol=1e-12)
    np.testing.assert_allclose(state.node_positions['x_up.b'], [0.5, 0, 0.25], atol=1e-12)


def _structures():
    return [('prism3', example(PRISM3, use_kernel=False)),
            ('sixbar', example(SIXBAR, use_kernel=False)),
            ('mixed hooke', numpy_structure(mixed_document('hooke'))),
            ('mixed paper', numpy_structure(mixed_document('paper')))]


@pytest.mark.parametrize('seed', [0, 1, 2])
@pytest.mark.parametrize('index', range(4))
def test_stiffness_matches_central_differences_of_the_wrenches(index, seed):
    name, structure = _structures()[index]
    rng = np.random.default_rng(seed)
    T = perturbed(structure.start_poses(), rng, 0.03)
    state = structure.evaluate(T)
    K_num = structure.numerical_stiffness(T)
    scale = np.max(np.abs(state.stiffness))
    # Central differences with step 1e-6: truncation ~ step^2 |d3W|, rounding ~ eps |W| / step.
    np.testing.assert_allclose(state.stiffness, K_num, rtol=0, atol=2e-7 * scale,
                               err_msg=name)


def test_regions_are_reported():
    structure = numpy_structure(mixed_document())
    state = structure.evaluate()
    slack = dict(zip(structure.string_names, state.slack, strict=True))
    assert slack['bar0.a-bar1.a']
    assert state.tensions[state.slack].max(initial=0.0) == 0.0
    assert np.all(state.tensions[~state.slack] > 0)
    np.testing.assert_allclose(state.lengths, np.linalg.norm(state.string_vectors, axis=1))


def test_internal_forces_cancel_and_poses_in_both_forms_agree():
    """Without world nodes the strings' wrenches on all bodies sum to zero (about the world
    origin); a pose as [x y z qx qy qz qw] is the same as its matrix."""
    six = example(SIXBAR, use_kernel=False)
    rng = np.random.default_rng(5)
    T = perturbed(six.start_poses(), rng, 0.05)
    state = six.evaluate(T)
    total = state.wrenches.sum(axis=0)
    assert np.max(np.abs(total)) <= 1e-13 * np.sum(np.abs(state.tensions))
    from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion

    vectors = np.array([np.r_[P[:3, 3], rotation_to_quaternion(P[:3, :3])] for P in T])
    np.testing.assert_allclose(six.evaluate(vectors).wrenches, state.wrenches, rtol=0,
                               atol=1e-12)


def test_bar_forces_are_the_compressions_at_a_symmetric_form():
    """At the 6-bar's symmetric start every bar carries the same compression: each node has
    four strings of tension t at the same angle to the bar."""
    six = example(SIXBAR, use_kernel=False)
    state = six.evaluate()
    assert np.all(state.bar_forces > 0)
    np.testing.assert_allclose(state.bar_forces, state.bar_forces[0], rtol=1e-12)
    t = state.tensions[0]
    # Node x_up.a at (-a, 0, b) has strings to (-b, +-a, 0) and (0, +-b, a): their unit vectors'
    # components along the bar (+x) are (a - b) / l twice and a / l twice.
    a, b, length = 0.5, 0.25, 0.5 * np.sqrt(1.5)
    np.testing.assert_allclose(state.bar_forces[0], t * (2 * (a - b) + 2 * a) / length, rtol=1e-12)


def test_bad_poses_are_refused():
    six = example(SIXBAR, use_kernel=False)
    with pytest.raises(ValueError, match=r'poses must have shape \(6, 4, 4\) or \(6, 7\)'):
        six.evaluate(np.zeros((5, 7)))
    bad = six.start_poses()
    bad[2, :3, :3] *= 2
    with pytest.raises(ValueError, match=r'poses\[2\] \(y_front\)'):
        six.evaluate(bad)


def test_a_structure_pickles_with_its_kernel_bound_again():
    import pickle

    for use_kernel in (True, False):
        six = example(SIXBAR, use_kernel=use_kernel)
        copy_ = pickle.loads(pickle.dumps(six))
        assert copy_.uses_kernel == six.uses_kernel
        T = perturbed(six.start_poses(), np.random.default_rng(1))
        np.testing.assert_array_equal(copy_.evaluate(T).stiffness, six.evaluate(T).stiffness)


def test_copies_with_new_rest_lengths_or_poses():
    structure = numpy_structure(mixed_document())
    rest = structure.rest_lengths * 1.1
    longer = structure.with_rest_lengths(rest)
    np.testing.assert_array_equal(longer.rest_lengths, rest)
    np.testing.assert_array_equal(longer.max_stretch, structure.max_stretch)
    T = perturbed(structure.start_poses(), np.random.default_rng(0))
    np.testing.assert_array_equal(longer.evaluate(T).tensions,
                                  structure.evaluate(T, rest).tensions)
    moved = structure.with_poses(T)
    np.testing.assert_allclose(moved.start_poses(), T, atol=1e-15)
    assert_same_document(numpy_structure(moved.to_dict()).to_dict(), moved.to_dict())


def test_the_weights_stiffness_matches_central_differences():
    from tensegrity_stiffness.structures.structure import twist_exp

    structure = numpy_structure(mixed_document())
    T = perturbed(structure.start_poses(), np.random.default_rng(2), 0.2)
    K = structure.gravity_wrenches(T)[1]
    step = 1e-6
    numeric = np.zeros_like(K)
    for i in range(structure.n_bodies):
        for k in range(6):
            delta = np.zeros(6)
            delta[k] = step
            plus, minus = T.copy(), T.copy()
            plus[i] = twist_exp(delta) @ T[i]
            minus[i] = twist_exp(-delta) @ T[i]
            numeric[:, 6 * i + k] = -(structure.gravity_wrenches(plus)[0]
                                      - structure.gravity_wrenches(minus)[0]).ravel() / (2 * step)
    np.testing.assert_allclose(K, numeric, rtol=0, atol=1e-8 * np.max(np.abs(K)))
