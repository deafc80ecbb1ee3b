"""The compiled joint kernel (``tensegrity_stiffness_kernel``) against the numpy path.

The numpy implementation of :class:`JointModel` (``use_kernel=False``) is the reference: the
kernel must give its results to 1e-13 (per quantity, relative to its largest entry; the wrench
relative to the sum of the moduli of its string contributions) and the same slack / saturated
decisions, for one screw and for batches, both force laws, every string region and the angle
branches of the kinematics (series below 0.5 rad, near pi, near 2 pi). ``test_joint_fast.py``
holds every evaluation path to the numpy implementation screw by screw as well.
"""

import math
import os
import pickle
import subprocess
import sys

import numpy as np
import pytest
from support import REPO
from support.joint_compare import assert_same, random_model

from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.joint import JointModel

CONFIG = REPO / 'config' / 'default_joint.yaml'

pytestmark = pytest.mark.skipif(
    os.environ.get(kernel.KERNEL_ENV, '').lower() in kernel.OFF_VALUES,
    reason=f'{kernel.KERNEL_ENV} selects the numpy path')


def pair(model: JointModel) -> tuple[JointModel, JointModel]:
    """``model`` with the kernel and the same model on the numpy path."""
    numpy_model = JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                             link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
                             force_law=model.force_law, use_kernel=False)
    assert model.uses_kernel and not numpy_model.uses_kernel
    return model, numpy_model


def angle_screws(rng, count: int) -> np.ndarray:
    """Screws over the kinematics' branches: tiny angles, the series, pi, near 2 pi."""
    angles = np.concatenate([[0.0, 1e-12, 1e-6, 0.3, 0.4999999, 0.5, 0.5000001, math.pi,
                              math.pi - 1e-9, 2 * math.pi - 1e-3],
                             rng.uniform(0.0, 2 * math.pi - 1e-3, count)])
    axes = rng.normal(size=(angles.size, 3))
    axes /= np.linalg.norm(axes, axis=1, keepdims=True)
    return np.hstack([axes * angles[:, None], rng.normal(scale=0.03, size=(angles.size, 3))])


def test_the_kernel_is_built_and_loaded():
    """The README's setup builds the kernel: the suite must run on it (or say why not)."""
    assert kernel.available(), kernel.status()
    assert JointModel.from_yaml(CONFIG).uses_kernel


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_single_and_batch_equal_the_numpy_path(force_law):
    rng = np.random.default_rng(31 if force_law == 'hooke' else 32)
    regions = np.zeros(3, dtype=int)
    for _ in range(20):
        fast, slow = pair(random_model(rng, force_law))
        X = angle_screws(rng, 30)
        batch = fast.evaluate(X)
        assert_same(fast, batch, slow.evaluate(X))
        for x in X:
            state = fast.evaluate(x)
            assert_same(fast, state, slow.evaluate(x))
            np.testing.assert_array_equal(fast.stiffness(x), state.stiffness)
        regions += [batch.slack.sum(), batch.saturated.sum(),
                    (~(batch.slack | batch.saturated)).sum()]
    assert np.all(regions > 100), regions  # slack, saturated and taut strings all occur


def test_default_joint_near_equilibrium_and_per_screw_rest_lengths():
    rng = np.random.default_rng(33)
    fast, slow = pair(JointModel.from_yaml(CONFIG))
    X = fast.initial_screw + rng.normal(scale=0.02, size=(700, 6))
    rest = fast.rest_lengths * rng.uniform(0.9, 1.1, size=(700, fast.n_strings))
    assert_same(fast, fast.evaluate(X, rest), slow.evaluate(X, rest))
    assert_same(fast, fast.evaluate(X), slow.evaluate(X))
    assert_same(fast, fast.evaluate(X[3], rest[3]), slow.evaluate(X[3], rest[3]))
    np.testing.assert_allclose(fast.numerical_stiffness(X[:20]), slow.numerical_stiffness(X[:20]),
                               rtol=0.0, atol=1e-9 * np.abs(slow.stiffness(X[:20])).max())


def test_input_layouts_and_read_only_arrays():
    rng = np.random.default_rng(34)
    fast, slow = pair(JointModel.from_yaml(CONFIG))
    X = fast.initial_screw + rng.normal(scale=0.02, size=(40, 6))
    fortran = np.asfortranarray(X)
    strided = np.repeat(X, 2, axis=0)[::2]
    read_only = X.copy()
    read_only.flags.writeable = False
    ref = slow.evaluate(X)
    for form in (fortran, strided, read_only, X.tolist()):
        assert_same(fast, fast.evaluate(form), ref)
    column = np.asfortranarray(np.repeat(X[:1], 3, axis=0))[:, :]  # (6,) rows are strided
    assert_same(fast, fast.evaluate(column[0]), slow.evaluate(X[0]))
    assert_same(fast, fast.evaluate(read_only[5]), slow.evaluate(X[5]))
    rest = np.repeat(fast.rest_lengths[None], 2, axis=0).T[:, 0].copy()
    assert_same(fast, fast.evaluate(X[1], rest[::1]), slow.evaluate(X[1], rest))
    empty = fast.evaluate(np.zeros((0, 6)))
    assert empty.stiffness.shape == (0, 6, 6) and empty.lengths.shape == (0, fast.n_strings)


def test_outputs_are_independent_arrays_per_call():
    fast, _ = pair(JointModel.from_yaml(CONFIG))
    a = fast.evaluate(fast.initial_screw)
    kept = a.stiffness.copy()
    b = fast.evaluate(fast.initial_screw + 0.01)
    np.testing.assert_array_equal(a.stiffness, kept)
    assert not np.shares_memory(a.stiffness, b.stiffness)


def test_zero_length_string_raises_as_the_numpy_path():
    model = JointModel(np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]), np.array([[0, 0], [1, 1]]),
                       100.0, [0.05, 0.05], link2_nodes=np.array([[0.0, 0.0, 0.0],
                                                                  [0.1, 0.0, 0.01]]))
    fast, slow = pair(model)
    for xi in (np.zeros(6), np.zeros((3, 6))):
        with pytest.raises(ValueError) as ref:
            slow.evaluate(xi)
        with pytest.raises(ValueError) as new:
            fast.evaluate(xi)
        assert str(new.value) == str(ref.value) and 'zero length' in str(new.value)


def test_stiffness_is_the_derivative_of_the_kernels_wrench():
    """Central differences of the kernel's own wrench (eq. 21) against its K (eq. 10)."""
    rng = np.random.default_rng(35)
    fast, _ = pair(random_model(rng, 'paper'))
    h = 1e-6
    for x in angle_screws(rng, 5)[2:]:
        K = fast.stiffness(x)
        numeric = np.column_stack([(fast.wrench(x + h * e) - fast.wrench(x - h * e)) / (2 * h)
                                   for e in np.eye(6)])
        np.testing.assert_allclose(K, numeric, rtol=0.0, atol=1e-6 * (1.0 + np.abs(K).max()))


def test_library_lookup(monkeypatch, tmp_path):
    monkeypatch.setenv(kernel.KERNEL_ENV, 'off')
    assert kernel.library_path() == (None, f'{kernel.KERNEL_ENV}=off')
    missing = tmp_path / 'nothing.so'
    monkeypatch.setenv(kernel.KERNEL_ENV, str(missing))
    path, why = kernel.library_path()
    assert path is None and 'is not a file' in why
    monkeypatch.delenv(kernel.KERNEL_ENV)
    monkeypatch.setenv('AMENT_PREFIX_PATH', str(tmp_path))
    path, why = kernel.library_path()
    assert path is None and 'not found on AMENT_PREFIX_PATH' in why
    (tmp_path / 'lib').mkdir()
    (tmp_path / 'lib' / kernel.LIBRARY_NAME).write_bytes(b'')
    assert kernel.library_path() == (tmp_path / 'lib' / kernel.LIBRARY_NAME, 'AMENT_PREFIX_PATH')


def test_a_pickled_model_keeps_the_kernel_in_another_process():
    """Models travel to the solver worker process by pickle: there they bind to that process's
    library and arrays (no address of this process may survive the trip)."""
    fast, _ = pair(JointModel.from_yaml(CONFIG))
    x = fast.initial_screw + 0.01
    code = ('import pickle, sys\n'
            'model, x = pickle.load(sys.stdin.buffer)\n'
            'assert model.uses_kernel\n'
            'state = model.evaluate(x)\n'
            'sys.stdout.buffer.write(pickle.dumps((state.stiffness, state.wrench, '
            'model.stiffness(x))))\n')
    done = subprocess.run([sys.executable, '-c', code], input=pickle.dumps((fast, x)),
                          capture_output=True, timeout=60, check=False)
    assert done.returncode == 0, done.stderr.decode()
    K, F, K_only = pickle.loads(done.stdout)
    ref = fast.evaluate(x)
    np.testing.assert_array_equal(K, ref.stiffness)
    np.testing.assert_array_equal(F, ref.wrench)
    np.testing.assert_array_equal(K_only, ref.stiffness)


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_string_measurements_equal_the_numpy_path(force_law):
    """``tsk_joint_measure_packed`` (the kernel's twin of ``sensor_models.
    string_predictions_unchecked`` and ``pose_jacobian``) against the numpy lines: lengths,
    tensions, dl/dxi, dphi/dxi, dphi/dl, the kinematics and the pose Jacobian, to 1e-13 of
    each quantity's largest entry, over every string region and angle branch."""
    from tensegrity_stiffness.estimation import sensor_models as sm
    from tensegrity_stiffness.geometry.screw import ScrewKinematics

    rng = np.random.default_rng(36 if force_law == 'hooke' else 37)
    models = [random_model(rng, force_law) for _ in range(6)]
    if force_law == 'hooke':
        models.append(JointModel.from_yaml(CONFIG))
    slopes = np.zeros(2, dtype=int)
    for model in models:
        fast, slow = pair(model)
        for x in angle_screws(rng, 10):
            try:
                ref = sm.string_predictions_unchecked(slow, x, slow.rest_lengths)
            except ValueError:  # a zero-length string: both paths raise it (test above)
                continue
            new = sm.string_predictions_unchecked(fast, x, fast.rest_lengths)
            assert type(new.kinematics) is sm.KernelKinematics
            assert type(ref.kinematics) is ScrewKinematics
            assert_same(fast, new.state, ref.state)
            for name in ('lengths', 'tensions', 'length_jacobian', 'tension_jacobian',
                         'tension_slope'):
                a, b = getattr(new, name), getattr(ref, name)
                assert a.shape == b.shape, name
                np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-13 * np.abs(b).max(),
                                           err_msg=name)
            for name in ('T', 'J', 'R', 't', 'G', 'Q', 'theta'):
                np.testing.assert_allclose(getattr(new.kinematics, name),
                                           getattr(ref.kinematics, name), rtol=0.0,
                                           atol=1e-13, err_msg=name)
            P = sm.pose_jacobian(x, new.kinematics)
            np.testing.assert_allclose(P, sm.pose_jacobian(x, ref.kinematics), rtol=0.0,
                                       atol=1e-13 * (1.0 + np.abs(P).max()))
            P[:] = np.nan  # a copy: the kernel's buffer is not handed out to be modified
            assert np.all(np.isfinite(sm.pose_jacobian(x, new.kinematics)))
            slopes += [np.sum(new.tension_slope == 0.0), np.sum(new.tension_slope > 0.0)]
    assert np.all(slopes > 20), slopes  # slack or saturated, and taut strings


def test_string_measurements_of_a_zero_length_string_raise_as_the_numpy_path():
    from tensegrity_stiffness.estimation import sensor_models as sm

    model = JointModel(np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0]]), np.array([[0, 0], [1, 1]]),
                       100.0, [0.05, 0.05], link2_nodes=np.array([[0.0, 0.0, 0.0],
                                                                  [0.1, 0.0, 0.01]]))
    fast, slow = pair(model)
    with pytest.raises(ValueError) as ref:
        sm.string_predictions_unchecked(slow, np.zeros(6), slow.rest_lengths)
    with pytest.raises(ValueError) as new:
        sm.string_predictions_unchecked(fast, np.zeros(6), fast.rest_lengths)
    assert str(new.value) == str(ref.value) and 'zero length' in str(new.value)
