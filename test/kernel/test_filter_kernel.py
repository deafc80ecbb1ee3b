"""The joint filter's entry points of the compiled kernel (``tsk_filter_body_dynamics``,
``tsk_filter_propagate``, ``tsk_filter_update``, ``tsk_filter_motion_rows``, ``tsk_filter_output``)
against their numpy references in ``estimation/joint_filter.py`` (``body_dynamics``,
``JointFilter._substep``, ``kalman_update``, ``JointFilter._rows``, ``JointFilter._output_numpy``)
to 1e-12 of each quantity's scale, and their boundary: counts, null pointers, short buffers and bad
arguments are refused before anything is written, and poisoned calls (every freed small buffer
handed out again and overwritten with NaN before C runs, as ``test_kernel_boundary.py``) give the
same results."""

import ctypes

import numpy as np
import pytest
from support import REPO
from support.kernel_checks import poisoned

from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.joint_filter import (
    JointFilter,
    body_dynamics,
    body_dynamics_kernel,
    kalman_update,
)
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.dynamics import JointDynamics
from tensegrity_stiffness.mechanics.joint import JointModel

pytestmark = pytest.mark.skipif(not kernel.available(), reason=kernel.status())

CONFIG = REPO / 'config' / 'default_joint.yaml'
SPREAD = np.array([0.02] * 3 + [5e-4] * 3)
FIELDS = ('screw_rate', 'twist_rate', 'body_inverse', 'd_screw', 'd_twist', 'd_load')


@pytest.fixture(scope='module')
def model():
    return JointModel.from_yaml(CONFIG)


def assert_close(a, b, rel=1e-12):
    scale = max(float(np.abs(b).max()), 1e-300)
    np.testing.assert_allclose(a, b, rtol=0, atol=rel * scale)


def states(model, rng, count=20):
    for _ in range(count):
        yield (model.initial_screw + rng.normal(scale=SPREAD),
               rng.normal(scale=[0.5] * 3 + [0.02] * 3),
               rng.normal(scale=[0.05] * 3 + [0.001] * 3))


@pytest.mark.parametrize('damping', [0.0, 0.5])
def test_body_dynamics_equals_numpy(model, damping):
    jd = JointDynamics(model, None, np.linspace(0.1, 1.0, 12) * damping)
    Gi = np.linalg.inv(jd.spatial_inertia)
    rng = np.random.default_rng(31)
    for xi, V, W in states(model, rng):
        pred = sm.string_predictions_unchecked(model, xi, model.rest_lengths)
        ref = body_dynamics(jd, pred, V, W, Gi)
        got = body_dynamics_kernel(kernel.library(), jd, pred, V, W, Gi)
        for name in FIELDS:
            assert_close(getattr(got, name), getattr(ref, name))
        assert_close(got.packed_buffer(), ref.packed_buffer())


@pytest.mark.parametrize('load', ['unknown', 'known'])
def test_propagate_equals_numpy(model, load):
    """One substep (with and without the last update's correction) of a kernel filter and a
    numpy one from the same state: the same state and covariance."""
    rng = np.random.default_rng(32)
    pair = [JointFilter(model, load=load, string_damping=0.5, use_kernel=flag)
            for flag in (True, False)]
    size = pair[0].size
    for xi, V, W in states(model, rng, 10):
        x = np.r_[xi, V, W][:size]
        A = rng.normal(size=(size, size)) * 1e-3
        P = A @ A.T + np.eye(size) * 1e-6
        dx = rng.normal(scale=1e-6, size=size)
        for with_dx in (False, True):
            for flt in pair:
                flt.set_state(x, P)
                dyn = flt._linearize(x[:6], x[6:12], x[12:] if size == 18 else W,
                                     model.rest_lengths)
                if with_dx:
                    flt._cache = (flt._x, model.rest_lengths.copy(), W.copy(), dyn, dx)
                flt._substep(7e-4, model.rest_lengths, W)
            assert_close(pair[0].state, pair[1].state)
            assert_close(pair[0].covariance, pair[1].covariance)


@pytest.mark.parametrize('rows, size', [(1, 12), (18, 18), (40, 18), (7, 66)])
def test_update_equals_numpy(rows, size):
    rng = np.random.default_rng(33 + rows)
    A = rng.normal(size=(size, size))
    P = A @ A.T * 1e-3 + np.eye(size) * 1e-6
    H = rng.normal(size=(rows, size))
    r = rng.normal(size=rows) * 0.1
    readings = [(f'r{i}', np.array([i]), 1) for i in range(rows)]
    ref = kalman_update(P, r, H, readings, set(), 0.95, reject_outliers=False)
    got = kalman_update(P, r, H, readings, set(), 0.95, reject_outliers=False, use_kernel=True)
    assert (got.consistent, got.dof, got.left_out) == (ref.consistent, ref.dof, ref.left_out)
    assert got.nis == pytest.approx(ref.nis, rel=1e-12)
    assert_close(got.correction, ref.correction)
    assert_close(got.covariance, ref.covariance)


def test_failed_update_goes_to_the_outlier_search():
    """A failing NIS test with rejection on: the numpy path names the reading (the kernel
    result is not used)."""
    rng = np.random.default_rng(34)
    P = np.eye(12) * 1e-4
    H = rng.normal(size=(15, 12))
    r = rng.normal(size=15) * 0.5
    r[4] = 40.0
    readings = [(f'r{i}', np.array([i]), 1) for i in range(15)]
    ref = kalman_update(P, r, H, readings, set(), 0.95)
    got = kalman_update(P, r, H, readings, set(), 0.95, use_kernel=True)
    assert got.left_out == ref.left_out and got.left_out[0][0] == 'r4'
    assert_close(got.covariance, ref.covariance)


# ------------------------------------------------------------------ boundary
def test_sizes_and_counts():
    lib = kernel.library()
    assert kernel.FILTER_BODY_SIZE == 156
    for size in (12, 18):
        assert lib.filter_propagate_size(size) == 2 * size + size * size + 12
    for size in (0, 11, 13, 19, -1):
        assert lib.filter_propagate_size(size) == kernel.ERROR_COUNT
    assert lib.filter_update_size(18, 15) == 18 * 18 * 2 + 15 + 15 * 18 + 1 + 18
    for size, rows in ((0, 3), (3, 0), (-1, 2), (2, 1 << 13)):
        assert lib.filter_update_size(size, rows) == kernel.ERROR_COUNT


def _body_args(model):
    jd = JointDynamics(model, None, 0.5)
    pred = sm.string_predictions_unchecked(model, model.initial_screw, model.rest_lengths)
    arrays = [np.ascontiguousarray(a) for a in (
        pred.kinematics.T, pred.kinematics.J, pred.length_jacobian, pred.state.wrench,
        pred.state.stiffness, np.full(6, 0.1), np.zeros(6), jd.spatial_inertia,
        np.linalg.inv(jd.spatial_inertia), jd.string_damping)]
    return arrays, [kernel.address(a) for a in arrays]


def test_body_dynamics_refuses_bad_arguments(model):
    lib = kernel.library()
    _arrays, ptrs = _body_args(model)
    out = np.full(kernel.FILTER_BODY_SIZE, 7.0)
    o = kernel.address(out)
    call = lib.filter_body_dynamics
    assert call(12, 1, *ptrs, o, out.size) == kernel.OK
    out[:] = 7.0
    assert call(0, 1, *ptrs, o, out.size) == kernel.ERROR_COUNT
    assert call(12, 2, *ptrs, o, out.size) == kernel.ERROR_ARGUMENT
    assert call(12, 1, *ptrs, o, out.size - 1) == kernel.ERROR_BUFFER_SIZE
    assert call(12, 1, *ptrs, None, out.size) == kernel.ERROR_NULL_POINTER
    for k in range(len(ptrs)):
        bad = list(ptrs)
        bad[k] = None
        status = call(12, 1, *bad, o, out.size)
        assert status == kernel.ERROR_NULL_POINTER, k
        # undamped: dl/dxi and the damping are not read
        if k in (2, 9):
            assert call(12, 0, *bad, o, out.size) == kernel.OK
            out[:] = 7.0
    assert np.all(out == 7.0)  # nothing written on a refusal
    singular = np.zeros(36)
    bad = list(ptrs)
    bad[1] = kernel.address(singular)
    assert call(12, 1, *bad, o, out.size) == kernel.ERROR_SINGULAR_SYSTEM


def test_propagate_and_update_refuse_bad_arguments(model):
    lib = kernel.library()
    dyn = np.zeros(kernel.FILTER_BODY_SIZE)
    dyn[12:48] = np.eye(6).ravel()
    q = np.ones(6)
    buf = np.zeros(lib.filter_propagate_size(18))
    d, qa, b = kernel.address(dyn), kernel.address(q), kernel.address(buf)
    call = lib.filter_propagate
    assert call(18, 1e-3, d, None, qa, qa, b, buf.size) == kernel.OK
    buf[:] = 3.0
    assert call(13, 1e-3, d, None, qa, qa, b, buf.size) == kernel.ERROR_COUNT
    assert call(18, 1e-3, d, None, qa, qa, b, buf.size - 1) == kernel.ERROR_BUFFER_SIZE
    for h in (0.0, -1e-3, np.nan, np.inf):
        assert call(18, h, d, None, qa, qa, b, buf.size) == kernel.ERROR_ARGUMENT
    assert call(18, 1e-3, None, None, qa, qa, b, buf.size) == kernel.ERROR_NULL_POINTER
    assert call(18, 1e-3, d, None, None, qa, b, buf.size) == kernel.ERROR_NULL_POINTER
    assert call(18, 1e-3, d, None, qa, None, b, buf.size) == kernel.ERROR_NULL_POINTER
    assert call(18, 1e-3, d, None, qa, qa, None, buf.size) == kernel.ERROR_NULL_POINTER
    assert np.all(buf == 3.0)
    small = np.zeros(lib.filter_propagate_size(12))
    assert call(12, 1e-3, d, None, qa, None, kernel.address(small), small.size) == kernel.OK
    ub = np.zeros(lib.filter_update_size(3, 2))
    u = kernel.address(ub)
    assert lib.filter_update(3, 2, u, ub.size - 1) == kernel.ERROR_BUFFER_SIZE
    assert lib.filter_update(3, 2, None, ub.size) == kernel.ERROR_NULL_POINTER
    assert lib.filter_update(0, 2, u, ub.size) == kernel.ERROR_COUNT
    ub[:9] = np.eye(3).ravel() * -1.0  # P = -I, H = [I 0]: S = H P H^T + I = 0
    ub[9:11] = 1.0
    ub[11:17] = [1.0, 0, 0, 0, 1.0, 0]
    assert lib.filter_update(3, 2, u, ub.size) == kernel.ERROR_SINGULAR_SYSTEM


def test_poisoned_calls_give_the_same_run(model, monkeypatch):
    """Every array the filter hands to these entry points lives until the call returns: with
    the freed small buffers overwritten before C runs, a seeded run gives the same estimates."""
    def run():
        rng = np.random.default_rng(35)
        flt = JointFilter(model, string_damping=0.5)
        xi = model.initial_screw + rng.normal(scale=SPREAD)
        st = model.evaluate(xi)
        out = []
        for k in range(15):
            m = sm_readings(st, rng)
            out.append(flt.step(k * 1.3e-3, m).screw_covariance)
        return np.array(out)

    clean = run()
    library = kernel.library()
    for name in ('filter_body_dynamics', 'filter_propagate', 'filter_update',
                 'filter_motion_rows', 'filter_output'):
        monkeypatch.setattr(library, name, poisoned(getattr(library, name)))
    np.testing.assert_array_equal(run(), clean)


def sm_readings(st, rng):
    from tensegrity_stiffness.estimation.estimators import Measurements
    return Measurements(tensions=st.tensions + rng.normal(scale=0.05, size=12), tension_std=0.05,
                        specific_force=-st.transform[:3, :3].T @ [0.0, -9.81, 0.0]
                        + rng.normal(scale=0.05, size=3), specific_force_std=0.05,
                        angular_velocity=rng.normal(scale=0.01, size=3),
                        angular_velocity_std=0.01)


def test_no_ctypes_mismatch():
    """The loader's argument types match the header's parameter counts."""
    lib = kernel.library()
    assert len(lib.filter_motion_rows.argtypes) == 7
    assert len(lib.filter_output.argtypes) == 7
    assert len(lib.filter_body_dynamics.argtypes) == 14
    assert len(lib.filter_propagate.argtypes) == 8
    assert len(lib.filter_update.argtypes) == 4
    assert lib.filter_update.restype is ctypes.c_int64


def all_readings(model, rng, load):
    from tensegrity_stiffness.estimation.estimators import Measurements
    xi = model.initial_screw + rng.normal(scale=SPREAD)
    st = model.evaluate(xi)
    lengths = st.lengths + rng.normal(scale=1e-4, size=12)
    lengths[4:] = np.nan
    return Measurements(
        tensions=st.tensions + rng.normal(scale=0.05, size=12), tension_std=0.05,
        lengths=lengths, length_std=1e-4,
        pose=st.transform, pose_covariance=np.eye(6) * 1e-6,
        specific_force=rng.normal(size=3) + [0.0, 9.81, 0.0], specific_force_std=0.05,
        gravity=[0.0, -1.0, 0.0], gravity_std=0.01, gravity_base=[0.0, -1.0, 0.0],
        angular_velocity=rng.normal(scale=0.01, size=3), angular_velocity_std=0.01,
        external_wrench=rng.normal(scale=0.01, size=6) if load == 'unknown' else None,
        wrench_covariance=np.eye(6) * 1e-4 if load == 'unknown' else None)


@pytest.mark.parametrize('load', ['unknown', 'known'])
def test_measurement_rows_equal_numpy(model, load):
    """Every kind of reading (tensions, lengths, pose, accelerometer, gravity direction,
    gyro, wrench): the whitened residual and its Jacobian of a kernel filter equal the numpy
    filter's at moving states."""
    rng = np.random.default_rng(36)
    pair = [JointFilter(model, load=load, string_damping=0.5, use_kernel=flag)
            for flag in (True, False)]
    size = pair[0].size
    for xi, V, W in states(model, rng, 8):
        m = all_readings(model, rng, load)
        got = []
        for flt in pair:
            flt.set_state(np.r_[xi, V, W][:size], np.eye(size) * 1e-6)
            got.append(flt.measurement_model(m, known_load=W if load == 'known' else None))
        assert got[0][2] == got[1][2] and 'gravity' in got[0][2] and 'imu' in got[0][2]
        assert_close(got[0][0], got[1][0])
        assert_close(got[0][1], got[1][1])


def test_output_equals_numpy(model):
    rng = np.random.default_rng(37)
    flt = JointFilter(model)
    for xi, V, W in states(model, rng, 8):
        x = np.r_[xi, V, W]
        A = rng.normal(size=(18, 18)) * 1e-3
        P = A @ A.T
        pred = sm.string_predictions_unchecked(model, xi, model.rest_lengths)
        T = pred.kinematics.T
        Pj = sm.pose_jacobian(xi, pred.kinematics)
        got = flt._output_kernel(P, x, T, Pj)
        ref = flt._output_numpy(P, x, T, Pj, P[:6, :6].copy())
        for a, b in zip(got, ref, strict=True):
            assert_close(a, b)


def test_motion_rows_and_output_refuse_bad_arguments(model):
    lib = kernel.library()
    inp = np.zeros(kernel.FILTER_MOTION_INPUT)
    inp[:16] = np.eye(4).ravel()
    inp[16:52] = np.eye(6).ravel()
    dyn = np.zeros(kernel.FILTER_BODY_SIZE)
    r = np.full(9, 5.0)
    H = np.full((9, 18), 5.0)
    i, d, ra, Ha = (kernel.address(a) for a in (inp, dyn, r, H))
    call = lib.filter_motion_rows
    every = kernel.FILTER_SPECIFIC_FORCE | kernel.FILTER_GRAVITY | kernel.FILTER_GYRO
    assert call(13, every, 1e-9, i, d, ra, Ha) == kernel.ERROR_COUNT
    assert call(18, 8, 1e-9, i, d, ra, Ha) == kernel.ERROR_ARGUMENT
    assert call(18, -1, 1e-9, i, d, ra, Ha) == kernel.ERROR_ARGUMENT
    assert call(18, every, -1.0, i, d, ra, Ha) == kernel.ERROR_ARGUMENT
    for k in range(4):
        args = [i, d, ra, Ha]
        args[k] = None
        assert call(18, every, 1e-9, *args) == kernel.ERROR_NULL_POINTER
    assert np.all(r == 5.0) and np.all(H == 5.0)
    # zero specific force (no gravity, at rest): a gravity reading is refused, as numpy's
    # gravity_direction_jacobian raises
    assert call(18, kernel.FILTER_GRAVITY, 1e-9, i, d, ra, Ha) == kernel.ERROR_ARGUMENT
    with pytest.raises(ValueError, match='specific force'):
        sm.gravity_direction_jacobian(np.zeros(3))
    assert call(18, kernel.FILTER_SPECIFIC_FORCE | kernel.FILTER_GYRO, 1e-9, i, d, ra,
                Ha) == 6
    assert call(12, 0, 1e-9, i, d, ra, Ha) == 0
    out = np.full(kernel.FILTER_OUTPUT_SIZE, 5.0)
    P = np.eye(18)
    x = np.zeros(18)
    Pj = np.eye(6)
    args = [kernel.address(a) for a in (P, x, inp, Pj, out)]
    out_call = lib.filter_output
    assert out_call(11, *args, out.size) == kernel.ERROR_COUNT
    assert out_call(18, *args, out.size - 1) == kernel.ERROR_BUFFER_SIZE
    for k in range(5):
        bad = list(args)
        bad[k] = None
        assert out_call(18, *bad, out.size) == kernel.ERROR_NULL_POINTER
    assert np.all(out == 5.0)
    assert out_call(18, *args, out.size) == kernel.OK
