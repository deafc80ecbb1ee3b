"""The joint model's evaluation paths against its readable numpy implementation.

``JointModel.evaluate`` / ``stiffness`` (single screw and batched) must give what the numpy
implementation (``JointModel._evaluate_numpy`` on a ``use_kernel=False`` model, the reference)
gives, to 1e-13 relative: per quantity, relative to its largest entry; for the wrench, relative
to the sum of the moduli of its string contributions (it cancels to ~0 at an equilibrium). Region
masks are equal. Every test runs twice: on the compiled kernel and on the numpy path
(``implementation``); on the numpy path it checks single against batch and chunked evaluation.
"""

import math

import numpy as np
import pytest
from support import REPO
from support.joint_compare import RTOL, assert_same, random_model

from tensegrity_stiffness.geometry.screw import as_screws
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.interpretation import (
    interpret_stiffness,
    interpretation_vector,
)
from tensegrity_stiffness.mechanics.joint import BATCH_CHUNK, JointModel

CONFIG = REPO / 'config' / 'default_joint.yaml'
TWO_PI = 2.0 * math.pi


@pytest.fixture(scope='module', params=['kernel', 'numpy'], autouse=True)
def implementation(request):
    """The compiled kernel (when built) or the numpy path, for every model the tests make."""
    with pytest.MonkeyPatch.context() as patch:
        if request.param == 'numpy':
            patch.setattr(kernel, 'joint_kernel', lambda *args: None)
        elif not kernel.available():
            pytest.skip(kernel.status())
        yield request.param


@pytest.fixture(scope='module')
def model(implementation):
    m = JointModel.from_yaml(CONFIG)
    assert m.uses_kernel == (implementation == 'kernel')
    return m


class _Reference:
    """The numpy implementation of a model, evaluated one screw at a time (the reference)."""

    @staticmethod
    def plain(model: JointModel) -> JointModel:
        ref = model.__dict__.get('_test_numpy_twin')
        # with_rest_lengths copies the model, this cache included: a twin of other rest lengths
        # is not this model's
        if ref is None or not (np.array_equal(ref.rest_lengths, model.rest_lengths)
                               and np.array_equal(ref.max_lengths, model.max_lengths)):
            ref = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                             link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
                             force_law=model.force_law, use_kernel=False)
            model.__dict__['_test_numpy_twin'] = ref
        return ref

    def evaluate(self, model: JointModel, xi, rest=None):
        """``_evaluate_numpy`` with the validation of ``evaluate``; a batch screw by screw
        (independent of the batched code it is compared with)."""
        ref = self.plain(model)
        xi = as_screws(xi)
        rest = ref.validate_rest_lengths(rest)
        if rest.ndim == 2 and (xi.ndim != 2 or xi.shape[0] != rest.shape[0]):
            raise ValueError(f'batched rest_lengths {rest.shape} need screws of shape '
                             f'({rest.shape[0]}, 6), got {xi.shape}')
        if xi.ndim == 1:
            return ref._evaluate_numpy(xi, rest)
        states = [ref._evaluate_numpy(x, rest if rest.ndim == 1 else rest[i])
                  for i, x in enumerate(xi)]
        if not states:
            return ref._evaluate_numpy(xi, rest)
        return type(states[0])(*(np.stack([getattr(s, f) for s in states])
                                 for f in type(states[0]).__slots__))


reference = _Reference()


def check_single(model, xi, rest=None):
    state = model.evaluate(xi, rest)
    ref = reference.evaluate(model, xi, rest)
    assert_same(model, state, ref)
    np.testing.assert_array_equal(model.stiffness(xi, rest), state.stiffness)
    return state


def special_screws(rng, base):
    """theta = 0 exactly, -> 0 across the series threshold, -> pi, near 2 pi; v kept."""
    v = base[3:]
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    thetas = [0.0, 1e-300, 1e-12, 1e-8, 1e-4, 0.3, 0.5 - 1e-12, 0.5, 0.5 + 1e-12,
              math.pi - 1e-9, math.pi, math.pi + 1e-9, TWO_PI - 1e-3, TWO_PI - 1e-7]
    return [np.r_[t * axis, v] for t in thetas]


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_single_screw_matches_reference_on_the_default_joint(model, force_law):
    m = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                   max_lengths=model.max_lengths, force_law=force_law,
                   initial_screw=model.initial_screw)
    rng = np.random.default_rng(10)
    regions = {'taut': 0, 'slack': 0, 'saturated': 0}
    for scale in (0.02, 0.3, 0.8):
        for _ in range(150):
            xi = m.initial_screw + rng.normal(scale=[scale] * 3 + [scale / 30] * 3)
            if np.linalg.norm(xi[:3]) >= TWO_PI:
                continue
            state = check_single(m, xi)
            regions['slack'] += int(state.slack.any())
            regions['saturated'] += int(state.saturated.any())
            regions['taut'] += int(not (state.slack.any() or state.saturated.any()))
    assert min(regions.values()) > 20, regions
    check_single(m, m.initial_screw)


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_single_screw_matches_reference_on_random_joints(force_law):
    rng = np.random.default_rng(11)
    checked = 0
    for _ in range(30):
        m = random_model(rng, force_law)
        for _ in range(20):
            xi = np.r_[rng.uniform(-1, 1, 3) * rng.uniform(0, 6.2), rng.normal(scale=0.03,
                                                                               size=3)]
            if np.linalg.norm(xi[:3]) >= TWO_PI:
                continue
            check_single(m, xi)
            checked += 1
        for xi in special_screws(rng, np.r_[0, 0, 0, rng.normal(scale=0.03, size=3)]):
            check_single(m, xi)
    assert checked > 400


def test_special_angles_on_the_default_joint(model):
    rng = np.random.default_rng(12)
    for _ in range(5):
        # Translated so that no string of the coincident node sets has zero length at theta 0.
        base = np.r_[0, 0, 0, 0.01, -0.02, 0.03] + rng.normal(scale=0.003, size=6)
        for xi in special_screws(rng, base):
            check_single(model, xi)
    pi_axis = model.initial_screw[:3] / np.linalg.norm(model.initial_screw[:3])
    for t in (math.pi - 1e-12, math.pi, math.pi + 1e-12):
        check_single(model, np.r_[t * pi_axis, model.initial_screw[3:]])


def test_every_string_slack_and_every_string_saturated(model):
    xi = model.initial_screw
    lengths = model.evaluate(xi).lengths
    expected = {'slack': 'all', 'saturated': 'all', 'slack ': 'all', 'taut': 'none',
                'mixed': 'any'}
    rests = (lengths * 1.5, lengths * 0.2, lengths, np.nextafter(lengths, 0.0),
             np.where(np.arange(12) % 3 == 0, lengths * 1.1, lengths * 0.5))
    for (region, how), rest in zip(expected.items(), rests, strict=True):
        m = model.with_rest_lengths(rest)
        state = check_single(m, xi)
        check_single(model, xi, rest)
        mask = state.slack | state.saturated
        assert {'all': mask.all(), 'none': not mask.any(), 'any': mask.any()}[how], region
    # A string exactly at its rest length is slack (l <= l0), exactly at lmax saturated.
    state = check_single(model.with_rest_lengths(lengths), xi)
    assert state.slack.all() and not state.tensions.any()
    m = JointModel(model.link1_nodes, model.connections, model.k, lengths * 0.9,
                   max_lengths=lengths)
    state = check_single(m, xi)
    assert state.saturated.all()


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
@pytest.mark.parametrize('n', [0, 1, 2, BATCH_CHUNK - 1, BATCH_CHUNK, BATCH_CHUNK + 1,
                               2 * BATCH_CHUNK + 3])
def test_batch_matches_reference_and_single(model, force_law, n):
    rng = np.random.default_rng(13 + n)
    m = random_model(rng, force_law) if n % 2 else JointModel(
        model.link1_nodes, model.connections, model.k, model.rest_lengths,
        max_lengths=model.max_lengths, force_law=force_law)
    xs = np.r_[model.initial_screw] + rng.normal(scale=[0.6] * 3 + [0.02] * 3, size=(n, 6))
    if n >= 14:
        xs[:14] = special_screws(rng, np.r_[0, 0, 0, 0.01, -0.02, 0.03])
    state = m.evaluate(xs)
    assert_same(m, state, reference.evaluate(m, xs))
    assert state.stiffness.shape == (n, 6, 6) and state.transform.shape == (n, 4, 4)
    assert state.string_vectors.shape == (n, m.n_strings, 3)
    for k in sorted({0, n // 2, n - 1}) if n else ():
        assert_same(m, m.evaluate(xs[k]), reference.evaluate(m, xs[k]))
    # Batched rest lengths (N, n).
    rest = m.rest_lengths * rng.uniform(0.7, 1.3, size=(n, m.n_strings))
    assert_same(m, m.evaluate(xs, rest), reference.evaluate(m, xs, rest))


def test_numerical_stiffness_wrench_only_batch_matches_reference(model):
    rng = np.random.default_rng(14)
    xs = model.initial_screw + rng.normal(scale=[0.3] * 3 + [0.01] * 3, size=(300, 6))
    new = model._evaluate_batch(xs, model.rest_lengths, wrench_only=True)
    ref = reference.evaluate(model, xs)
    scale = np.sum(np.abs(ref.tensions), axis=-1, keepdims=True)
    assert np.all(np.abs(new.wrench - ref.wrench) <= RTOL * scale)
    assert np.isnan(new.stiffness).all() and np.isnan(new.cartesian_stiffness).all()
    np.testing.assert_allclose(model.numerical_stiffness(xs[:5]),
                               model.stiffness(xs[:5]), rtol=1e-6, atol=1e-6)


BAD_SCREWS = [np.zeros(5), np.zeros((2, 3)), np.zeros((2, 2, 6)), [1.0, np.nan, 0, 0, 0, 0],
              [np.inf, 0, 0, 0, 0, 0], np.array([[0, 0, 0, 0, 0, -np.inf]] * 2), 'abcdef']


@pytest.mark.parametrize('xi', BAD_SCREWS)
def test_bad_screws_raise_the_same_errors(model, xi):
    with pytest.raises(ValueError) as ref:
        as_screws(xi)
    for call in (model.evaluate, model.stiffness, model.wrench):
        with pytest.raises(ValueError) as new:
            call(xi)
        assert str(new.value) == str(ref.value)


def test_zero_length_strings_and_bad_rest_lengths_raise_the_same_errors(model):
    for xi in (np.zeros(6), np.zeros((3, 6))):
        with pytest.raises(ValueError) as ref:
            reference.evaluate(model, xi)
        with pytest.raises(ValueError) as new:
            model.evaluate(xi)
        assert str(new.value) == str(ref.value) and 'zero length' in str(new.value)
    for rest in (np.zeros(12), np.ones(11), np.ones((2, 12)), np.full(12, np.nan)):
        with pytest.raises(ValueError) as ref:
            reference.evaluate(model, model.initial_screw, rest)
        with pytest.raises(ValueError) as new:
            model.evaluate(model.initial_screw, rest)
        assert str(new.value) == str(ref.value)


def test_overflowing_but_finite_screw_behaves_as_before(model):
    xi = np.array([1e308, 1e308, 0.0, 0.0, 0.0, 0.0])
    with pytest.raises(OverflowError):
        reference.evaluate(model, xi)
    for call in (model.evaluate, model.stiffness):
        with pytest.raises(OverflowError):
            call(xi)


def test_input_forms_and_rest_length_identity(model):
    xi = model.initial_screw + 0.01
    ref = reference.evaluate(model, xi)
    for form in (xi.tolist(), tuple(xi), xi.astype(np.float32).astype(np.float64)):
        state = model.evaluate(form)
        assert_same(model, state, reference.evaluate(model, form))
    assert_same(model, model.evaluate(xi, model.rest_lengths.copy()), ref)
    assert_same(model, model.evaluate(xi, list(model.rest_lengths)), ref)


def test_interpretation_vector_matches_interpret_stiffness():
    rng = np.random.default_rng(15)
    for _ in range(500):
        K = rng.normal(size=(6, 6)) * 10.0 ** rng.uniform(-6, 6, size=(6, 6))
        it = interpret_stiffness(K)
        ref = np.concatenate([it.block_norms, it.column_norms, it.row_norms])
        np.testing.assert_allclose(interpretation_vector(K), ref, rtol=RTOL, atol=0.0)
    np.testing.assert_array_equal(interpretation_vector(np.zeros((6, 6))), np.zeros(16))
    np.testing.assert_allclose(interpretation_vector(np.eye(6).tolist())[:4],
                               [math.sqrt(3), 0, 0, math.sqrt(3)])
    with pytest.raises(ValueError, match=r'stiffness must have shape \(6, 6\)'):
        interpretation_vector(np.zeros(36))
