"""The ctypes mirror in ``tensegrity_stiffness/mechanics/kernel.py`` against the kernel's one C
header (``include/tensegrity_stiffness/kernel.h``) and the loaded library: version, status codes,
modes, the ``tsk_joint_model`` struct (field names, order, size, offsets as the library reports
them), buffer sizes, and the model constants that come from their one Python home (the series
tables of ``screw.py``, its threshold, ``joint.MIN_STRING_LENGTH``). Also: the library checks
counts and buffer sizes and keeps no global state (no ``tsk_set_series``)."""

import ctypes
import re

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness.geometry import screw
from tensegrity_stiffness.mechanics import joint, kernel
from tensegrity_stiffness.mechanics.joint import JointModel

ROOT = REPO
CONFIG = ROOT / 'config' / 'default_joint.yaml'

pytestmark = pytest.mark.skipif(not kernel.available(), reason=kernel.status())


def header() -> str:
    for path in (ROOT / 'include',):
        h = path / 'tensegrity_stiffness' / 'kernel.h'
        if h.is_file():
            return h.read_text()
    pytest.fail('include/tensegrity_stiffness/kernel.h not found')


def defines(text: str) -> dict[str, int]:
    """``#define TSK_NAME value`` with an integer value (parenthesised or not)."""
    return {name: int(value) for name, value in
            re.findall(r'^#define (TSK_\w+) \(?(-?\d+)\)?', text, flags=re.MULTILINE)}


def test_constants_mirror_the_header():
    h = defines(header())
    assert kernel.ABI_VERSION == h['TSK_ABI_VERSION'] == kernel.library()._lib.tsk_abi_version()
    assert kernel.OK == h['TSK_OK'] == 0
    errors = {v: k.removeprefix('TSK_ERROR_') for k, v in h.items() if k.startswith('TSK_ERROR_')}
    assert errors == kernel.ERRORS and all(code < 0 for code in errors)
    assert kernel.ERRORS[kernel.ERROR_ZERO_LENGTH] == 'ZERO_LENGTH'
    assert kernel.ERRORS[kernel.ERROR_SINGULAR_SYSTEM] == 'SINGULAR_SYSTEM'
    assert kernel.ERRORS[kernel.ERROR_SINGULAR_COMPLIANCE] == 'SINGULAR_COMPLIANCE'
    assert (kernel.MODE_FULL, kernel.MODE_STIFFNESS, kernel.MODE_WRENCH) == (
        h['TSK_MODE_FULL'], h['TSK_MODE_STIFFNESS'], h['TSK_MODE_WRENCH'])
    assert (kernel.TIP_BASE, kernel.TIP_TOOL) == (h['TSK_TIP_BASE'], h['TSK_TIP_TOOL'])
    assert joint.FORCE_LAWS.index('hooke') == h['TSK_LAW_HOOKE']
    assert joint.FORCE_LAWS.index('paper') == h['TSK_LAW_PAPER']
    assert kernel.SERIES.shape[0] == h['TSK_SERIES_ROWS']


def test_model_struct_mirrors_the_header_and_the_library():
    body = re.search(r'typedef struct tsk_joint_model \{(.*?)\} tsk_joint_model;', header(),
                     flags=re.DOTALL).group(1)
    body = re.sub(r'/\*.*?\*/', '', body, flags=re.DOTALL)
    fields = re.findall(r'(int64_t|const double\*|double)\s+(\w+);', body)
    ctypes_of = {'int64_t': ctypes.c_int64, 'const double*': ctypes.c_void_p,
                 'double': ctypes.c_double}
    assert [(name, ctypes_of[c]) for c, name in fields] == kernel._ModelStruct._fields_
    assert len(fields) == defines(header())['TSK_MODEL_FIELDS']
    # The library's own sizeof / offsetof (what the compiler laid out) against ctypes'.
    assert kernel.library().model_layout == kernel.model_layout()
    assert kernel.model_layout()[0] == ctypes.sizeof(kernel._ModelStruct) == 80


def test_buffer_sizes_mirror_the_library():
    library = kernel.library()
    for n in (1, 2, 7, 12, 129):
        rng = np.random.default_rng(n)
        kn = kernel.joint_kernel(rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), np.ones(n),
                                 np.full(n, np.inf), 0, joint.MIN_STRING_LENGTH)
        assert kn.size == library.packed_size(n)
        for N in (1, 3, 1000):
            # joint.py's batch buffer: 16 + 5n + 78 doubles per screw, then 2nN flag bytes
            # (its offsets: _evaluate_batch_kernel).
            assert (16 + 5 * n + 78) * N + (2 * N * n + 7) // 8 == library.batch_size(n, N)
        # the measurement buffer: J 36, P 36, dl/dxi 6n, dphi/dxi 6n, dphi/dl n
        assert kn.measure_size == 72 + 13 * n == library.measure_size(n)
        assert (kn.measure_pose, kn.measure_lengths, kn.measure_tensions, kn.measure_slope) == (
            36, 72, 72 + 6 * n, 72 + 12 * n)
        # the linear model: W 6, F + W 6, J_l 36, M 36, R and M^-1 R 6 (18 + n) each, the flag
        assert kn.linear_size == 85 + 12 * (18 + n) == library.linear_size(n)
        assert (kn.linear_net, kn.linear_jacobian, kn.linear_mass, kn.linear_rhs,
                kn.linear_solved, kn.linear_flag) == (6, 12, 48, 84, 84 + 6 * (18 + n),
                                                      84 + 12 * (18 + n))
        # the pose terms: T 16, lengths n, B 6n, K0 36, M 36n
        assert kn.pose_terms_size == 52 + 43 * n == library.pose_terms_size(n)
        assert (kn.pose_lengths, kn.pose_B, kn.pose_K0, kn.pose_M) == (16, 16 + n, 16 + 7 * n,
                                                                       52 + 7 * n)
    assert library.packed_size(0) == library.batch_size(3, 0) == -2  # TSK_ERROR_COUNT
    assert library.measure_size(0) == -2
    assert library.linear_size(0) == library.pose_terms_size(0) == -2
    for n, m in ((1, 0), (12, 6), (60, 30)):
        assert kernel.qp_face_size(n, m) == library.qp_face_size(n, m)
    assert library.qp_face_size(0, 6) == library.qp_face_size(3, -1) == -2


def test_model_constants_come_from_their_python_home():
    model = JointModel.from_yaml(CONFIG)
    struct = model.compiled_kernel._struct
    assert struct.series == kernel.address(kernel.SERIES)
    assert struct.series_terms == kernel.SERIES.shape[1] == screw._SERIES_TERMS
    tables = (screw._A_SERIES, screw._B_SERIES, screw._C_SERIES, screw._B1_SERIES,
              screw._C1_SERIES)
    np.testing.assert_array_equal(kernel.SERIES, np.stack(tables))
    assert struct.series_threshold == screw.SERIES_THRESHOLD
    assert struct.min_string_length == joint.MIN_STRING_LENGTH
    assert struct.n_strings == model.n_strings and struct.law == 0
    with pytest.raises(AttributeError):
        kernel.library()._lib.tsk_set_series  # noqa: B018 (no global state set from Python)


def test_the_library_refuses_bad_counts_and_short_buffers():
    model = JointModel.from_yaml(CONFIG)
    kn = model.compiled_kernel
    rest = model.rest_lengths
    buf = np.zeros(kn.size)
    buf[:kn.rest] = model.initial_screw
    buf[kn.rest:kn.transform] = rest
    assert kn.evaluate_packed(kn.model, 0, kernel.address(buf), kn.size) == kernel.OK
    np.testing.assert_array_equal(buf[kn.cartesian:kn.flags].reshape(6, 6),
                                  model.evaluate(model.initial_screw).cartesian_stiffness)
    short = np.full(kn.size - 1, 7.0)
    assert kn.evaluate_packed(kn.model, 0, kernel.address(short), short.size) == -3
    assert (short == 7.0).all()  # nothing written
    assert kn.evaluate_packed(kn.model, 5, kernel.address(buf), kn.size) == -4
    assert kn.evaluate_packed(None, 0, kernel.address(buf), kn.size) == -1
    meas = np.full(kn.measure_size, 7.0)
    assert kn.measure_packed(kn.model, 0, kernel.address(buf), kn.size, kernel.address(meas),
                             kn.measure_size) == kernel.OK
    np.testing.assert_array_equal(meas[:36].reshape(6, 6),
                                  screw.ScrewKinematics(model.initial_screw).J)
    meas[:] = short[:] = 7.0
    assert kn.measure_packed(kn.model, 0, kernel.address(short), short.size,
                             kernel.address(meas), kn.measure_size) == -3
    assert kn.measure_packed(kn.model, 0, kernel.address(buf), kn.size, kernel.address(short),
                             kn.measure_size - 1) == -3
    assert kn.measure_packed(kn.model, 0, kernel.address(buf), kn.size, None, 0) == -1
    assert kn.measure_packed(kn.model, 5, kernel.address(buf), kn.size, kernel.address(meas),
                             kn.measure_size) == -4
    assert (short == 7.0).all() and (meas == 7.0).all()  # nothing written
    out = np.zeros(kernel.library().batch_size(kn.n, 2))
    xi = np.zeros((2, 6))
    assert kn.evaluate(kn.model, 0, kernel.address(xi), kernel.address(rest), kn.n, 0,
                       kernel.address(out), out.size) == -2
    assert kn.evaluate(kn.model, 2, kernel.address(xi), kernel.address(rest), kn.n + 1, 0,
                       kernel.address(out), out.size) == -3
    with pytest.raises(kernel.KernelError, match=r'tsk_joint_evaluate returned -3 '
                                                 r'\(TSK_ERROR_BUFFER_SIZE\)'):
        kernel.check(-3, 'tsk_joint_evaluate')


def test_the_linear_model_and_pose_terms_refuse_bad_arguments():
    """tsk_joint_linear_model and tsk_joint_pose_terms check pointers, sizes and the tolerance
    before writing anything; a zero-length string is TSK_ERROR_ZERO_LENGTH."""
    model = JointModel.from_yaml(CONFIG)
    kn = model.compiled_kernel
    buf = np.zeros(kn.size)
    buf[:kn.rest] = model.initial_screw
    buf[kn.rest:kn.transform] = model.rest_lengths
    inertia = np.eye(6) * 0.01
    lin = np.zeros(kn.linear_size)
    a = kernel.address
    assert kn.linear_model(kn.model, a(inertia), None, 1e-9, a(buf), kn.size, a(lin),
                           kn.linear_size) == kernel.OK
    np.testing.assert_array_equal(lin[kn.linear_jacobian:kn.linear_mass].reshape(6, 6),
                                  screw.ScrewKinematics(model.initial_screw).J)
    assert lin[kn.linear_flag] in (0.0, 1.0)
    short = np.full(kn.linear_size - 1, 7.0)
    fresh = np.full(kn.size, 7.0)
    for args, code in (((kn.model, None, None, 1e-9, a(fresh), kn.size, a(lin), kn.linear_size),
                        -1),
                       ((kn.model, a(inertia), None, 1e-9, a(fresh), kn.size, None, 0), -1),
                       ((None, a(inertia), None, 1e-9, a(fresh), kn.size, a(lin),
                         kn.linear_size), -1),
                       ((kn.model, a(inertia), None, 1e-9, a(fresh), kn.size, a(short),
                         short.size), -3),
                       ((kn.model, a(inertia), None, -1.0, a(fresh), kn.size, a(lin),
                         kn.linear_size), -4),
                       ((kn.model, a(inertia), None, float('nan'), a(fresh), kn.size, a(lin),
                         kn.linear_size), -4),
                       ((kn.model, a(inertia), None, 1e-9, a(fresh), kn.size - 1, a(lin),
                         kn.linear_size), -3)):
        lin[:] = 7.0
        assert kn.linear_model(*args) == code
        assert (fresh == 7.0).all() and (short == 7.0).all() and (lin == 7.0).all()
    assert kn.linear_model(kn.model, a(np.zeros((6, 6))), None, 1e-9, a(buf), kn.size, a(lin),
                           kn.linear_size) == kernel.ERROR_SINGULAR_SYSTEM
    pose = np.full(kn.pose_terms_size, 7.0)
    assert kn.pose_terms(kn.model, a(pose), kn.pose_terms_size - 1) == -3
    assert kn.pose_terms(kn.model, None, kn.pose_terms_size) == -1
    assert kn.pose_terms(None, a(pose), kn.pose_terms_size) == -1
    assert (pose == 7.0).all()
    # A pose that puts a link-2 node on its link-1 end: a zero-length string.
    p1, p2 = model.link1_string_nodes[0], model.link2_nodes[model.connections[0, 1]]
    T = np.eye(4)
    T[:3, 3] = p1 - p2
    pose[:16] = T.ravel()
    assert kn.pose_terms(kn.model, a(pose), kn.pose_terms_size) == kernel.ERROR_ZERO_LENGTH
    from tensegrity_stiffness.control.controller import pose_terms_at, pose_terms_numpy
    for terms in (pose_terms_at, pose_terms_numpy):
        with pytest.raises(ValueError, match='zero length'):
            terms(model, T)


def test_the_transform_is_exp_se3_and_refuses_bad_arguments():
    """tsk_joint_transform (JointKernel.exp_se3) equals geometry.screw.exp_se3 at angles from 0
    over the series threshold to pi; it checks its pointers and buffer before writing."""
    model = JointModel.from_yaml(CONFIG)
    kn = model.compiled_kernel
    rng = np.random.default_rng(5)
    for theta in (0.0, 1e-9, 1e-4, screw.SERIES_THRESHOLD * (1 - 1e-9), screw.SERIES_THRESHOLD,
                  screw.SERIES_THRESHOLD * (1 + 1e-9), 0.7, 2.0, np.pi - 1e-9, np.pi):
        u = rng.normal(size=3)
        xi = np.r_[theta * u / np.linalg.norm(u), rng.normal(scale=0.05, size=3)]
        np.testing.assert_allclose(kn.exp_se3(xi), screw.exp_se3(xi), rtol=0.0, atol=1e-15)
    buf = np.full(22, 7.0)
    library = kernel.library()
    assert library.transform(kn.model, kernel.address(buf), 21) == -3
    assert library.transform(kn.model, None, 22) == -1
    assert library.transform(None, kernel.address(buf), 22) == -1
    assert (buf == 7.0).all()


def test_the_warm_face_refuses_bad_arguments():
    library = kernel.library()
    n, m = 3, 1
    size = kernel.qp_face_size(n, m)
    buf = np.full(size, 7.0)
    a = kernel.address(buf)
    assert library.qp_warm_face(n, m, 1e-9, 1e-12, 1e-10, 1e-12, None, size) == -1
    assert library.qp_warm_face(n, m, 1e-9, 1e-12, 1e-10, 1e-12, a, size - 1) == -3
    assert library.qp_warm_face(0, m, 1e-9, 1e-12, 1e-10, 1e-12, a, size) == -2
    for bad in (-1.0, float('nan')):
        assert library.qp_warm_face(n, m, bad, 1e-12, 1e-10, 1e-12, a, size) == -4
        assert library.qp_warm_face(n, m, 1e-9, 1e-12, 1e-10, bad, a, size) == -4
    assert (buf == 7.0).all()  # nothing written
    # min 1/2 |t|^2 - t'1 s.t. t_0 + t_1 + t_2 = 3 on [0, 2]^3: t = 1, optimal with nothing fixed.
    P, c, A, b = np.eye(3), np.ones(3), np.ones((1, 3)), np.array([3.0])
    buf = np.concatenate([P.ravel(), c, A.ravel(), b, np.zeros(3), np.full(3, 2.0),
                          np.full(3, 0.5), np.zeros(3), np.zeros(3), np.zeros(n + m + 1)])
    assert library.qp_warm_face(n, m, 1e-9, 1e-12, 1e-10, 1e-12, kernel.address(buf),
                                size) == kernel.OK
    assert buf[-1] == kernel.FACE_OPTIMAL
    np.testing.assert_allclose(buf[-(n + m + 1):-1], [1.0, 1.0, 1.0, 0.0], atol=1e-15)


def test_address_refuses_a_strided_read_only_array():
    a = np.arange(12.0)[::2]
    a.flags.writeable = False
    with pytest.raises(ValueError, match='C-contiguous'):
        kernel.address(a)
