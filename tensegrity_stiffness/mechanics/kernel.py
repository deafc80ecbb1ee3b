"""The compiled kernel: loader and calling convention (pure Python, ctypes only).

``tensegrity_stiffness_kernel`` (a C++ package of this repository, built by colcon with the rest)
installs ``lib/libtensegrity_stiffness_kernel.so``: the per-string loop of
:class:`~tensegrity_stiffness.mechanics.joint.JointModel` (eqs. 6-11: kinematics, string forces,
wrench,
K and K_c) for one screw or a batch, and the frames, implied tip wrench and tip stiffness of a
:class:`~tensegrity_stiffness.mechanics.chain.JointChain`, in compiled code. Both use it when it
is found
and keep their numpy implementations as the fallback and as the reference the tests compare it
with.

Where the library comes from, first match wins:

* ``TENSEGRITY_STIFFNESS_KERNEL`` (:data:`KERNEL_ENV`): a path to the library, or ``off`` to
  use numpy only;
* ``lib/`` of every prefix on ``AMENT_PREFIX_PATH`` (what ``source install/setup.bash`` or
  ``scripts/env.sh`` sets).

:func:`status` says which path is in use, and why (the bench and ``/diagnostics`` print it).
"""

from __future__ import annotations

import ctypes
import functools
import os
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.geometry import screw

#: Strings shorter than this (m) have no defined direction: evaluation raises ValueError (the
#: kernel's zero-length status, the numpy path's check; ``joint.MIN_STRING_LENGTH``).
MIN_STRING_LENGTH = 1e-12
#: Environment variable naming the library (a path) or ``off`` for the numpy path.
KERNEL_ENV = 'TENSEGRITY_STIFFNESS_KERNEL'
#: File name of the library under ``<prefix>/lib``.
LIBRARY_NAME = 'libtensegrity_stiffness_kernel.so'
#: Values of :data:`KERNEL_ENV` that select the numpy path.
OFF_VALUES = ('off', '0', 'no', 'false', 'numpy')

# The mirror of include/tensegrity_stiffness/kernel.h (test/kernel/test_kernel_abi.py holds it
# to the library: version, struct layout, buffer sizes, status codes).
#: ABI version this module speaks (``TSK_ABI_VERSION``, ``tsk_abi_version()``).
ABI_VERSION = 5
#: Status codes (``TSK_OK``, ``TSK_ERROR_*``): 0 success, negative errors.
OK = 0
ERRORS = {-1: 'NULL_POINTER', -2: 'COUNT', -3: 'BUFFER_SIZE', -4: 'ARGUMENT', -5: 'ZERO_LENGTH',
          -6: 'SINGULAR_SYSTEM', -7: 'SINGULAR_COMPLIANCE', -8: 'INTERNAL'}
ERROR_ZERO_LENGTH, ERROR_SINGULAR_SYSTEM, ERROR_SINGULAR_COMPLIANCE = -5, -6, -7
ERROR_NULL_POINTER, ERROR_COUNT, ERROR_BUFFER_SIZE, ERROR_ARGUMENT = -1, -2, -3, -4
#: Modes of the joint evaluation (``TSK_MODE_*``): everything; K without K_c; the wrench alone.
MODE_FULL, MODE_STIFFNESS, MODE_WRENCH = 0, 1, 2
#: Outcomes of ``tsk_qp_warm_face`` (``TSK_FACE_*``): optimal, rejected, singular KKT system.
FACE_OPTIMAL, FACE_REJECTED, FACE_SINGULAR = 0, 1, 2
#: Outputs of ``tsk_chain_tip`` besides the tip wrench (``TSK_TIP_*``, a bit mask).
TIP_BASE, TIP_TOOL = 1, 2
#: Doubles of ``tsk_chain_tip``'s output buffer: tip wrench 6, K_tip base 36, tool 36.
TIP_SIZE = 78
#: Doubles of ``tsk_filter_body_dynamics``' output (``TSK_FILTER_BODY_SIZE``): ``dxi/dt`` 6,
#: ``dV/dt`` 6, ``J_b^-1`` 36, its Jacobians in the screw, twist and load 36 each.
FILTER_BODY_SIZE = 156
#: Readings of ``tsk_filter_motion_rows`` (``TSK_FILTER_*``, a bit mask) and the doubles of its
#: input (``TSK_FILTER_MOTION_INPUT``).
FILTER_SPECIFIC_FORCE, FILTER_GRAVITY, FILTER_GYRO = 1, 2, 4
FILTER_MOTION_INPUT = 79
#: Doubles of ``tsk_filter_output``'s output (``TSK_FILTER_OUTPUT_SIZE``): the pose covariance
#: 36, the twist 6 and its covariance 36.
FILTER_OUTPUT_SIZE = 78

_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double

#: The Taylor tables of the rotation coefficients a, b, c, b1, c1 (``TSK_SERIES_ROWS`` x
#: terms), taken from :mod:`~tensegrity_stiffness.geometry.screw` (their one home); every model
#: points to this array, which lives as long as the module.
SERIES = np.ascontiguousarray(np.stack(screw.ROTATION_SERIES))
SERIES.flags.writeable = False
#: File name of the C view of the constants every model passes (:func:`defaults_header`).
DEFAULTS_HEADER = 'kernel_defaults.h'


class KernelError(RuntimeError):
    """A kernel call refused its arguments (a bug of the caller: the numpy path is the
    reference; never raised for a model's own conditions, which have their own errors)."""


class _ModelStruct(ctypes.Structure):
    """``tsk_joint_model`` of ``kernel.h``: pointers into arrays the owner keeps alive."""

    _fields_ = [('n_strings', _I), ('p1', _P), ('p2', _P), ('k', _P), ('max_stretch', _P),
                ('law', _I), ('series_terms', _I), ('series', _P), ('series_threshold', _D),
                ('min_string_length', _D)]


def model_layout() -> list[int]:
    """This module's mirror of ``tsk_joint_model_layout``: its size and field offsets."""
    return [ctypes.sizeof(_ModelStruct)] + [getattr(_ModelStruct, name).offset
                                            for name, _ in _ModelStruct._fields_]


def check(status: int, call: str) -> None:
    """:class:`KernelError` naming ``call`` and the status unless it is ``OK``."""
    if status != OK:
        raise KernelError(f'{call} returned {status} '
                          f'(TSK_ERROR_{ERRORS.get(status, "UNKNOWN")})')



def bind(lib: ctypes.CDLL, name: str, argtypes: list[Any]) -> Any:
    """The entry point ``name`` of a loaded kernel ``lib``, typed: ``argtypes`` (ctypes types)
    and the ``int64`` status or size every ``tsk_*`` function returns; AttributeError when
    ``lib`` lacks it."""
    function = getattr(lib, name)
    function.restype = _I
    function.argtypes = argtypes
    return function

def address(arr: NDArray) -> int:
    """Data address of a C-contiguous array for a pointer argument of the kernel (a writable
    one through ctypes' buffer view: a third of the time of ``__array_interface__``).

    The address is valid only while ``arr`` lives: bind every array to a name that outlives
    the call (never ``address(np.ascontiguousarray(x))``: a copy is freed before C reads it).
    """
    if arr.flags.writeable and arr.nbytes:
        return _addressof(_char_view(arr))
    if not arr.flags.c_contiguous:
        raise ValueError('kernel.address needs a C-contiguous array')
    return arr.__array_interface__['data'][0]


_addressof = ctypes.addressof
_char_view = ctypes.c_char.from_buffer


def library_path() -> tuple[Path | None, str]:
    """The library to load and where it was found, or ``None`` and the reason."""
    setting = os.environ.get(KERNEL_ENV, '').strip()
    if setting.lower() in OFF_VALUES:
        return None, f'{KERNEL_ENV}={setting}'
    if setting:
        path = Path(setting)
        return (path, f'{KERNEL_ENV}') if path.is_file() else (
            None, f'{KERNEL_ENV}={setting} is not a file')
    for prefix in os.environ.get('AMENT_PREFIX_PATH', '').split(os.pathsep):
        if prefix:
            path = Path(prefix) / 'lib' / LIBRARY_NAME
            if path.is_file():
                return path, 'AMENT_PREFIX_PATH'
    return None, (f'{LIBRARY_NAME} not found on AMENT_PREFIX_PATH (build the workspace: '
                  'bash scripts/setup_env.sh, then source scripts/env.sh)')


class _Library:
    """The loaded library with its entry points typed (``kernel.h``)."""

    def __init__(self, path: Path) -> None:
        lib = ctypes.CDLL(str(path))
        lib.tsk_abi_version.restype = _I
        lib.tsk_abi_version.argtypes = []
        version = lib.tsk_abi_version()
        if version != ABI_VERSION:
            raise OSError(f'{path} speaks ABI {version}, this package {ABI_VERSION}')
        model_layout_of = bind(lib, 'tsk_joint_model_layout', [_P, _I])
        layout = np.zeros(32, dtype=np.int64)
        count = model_layout_of(address(layout), layout.size)
        self.model_layout = layout[:max(count, 0)].tolist()
        if self.model_layout != model_layout():
            raise OSError(f'{path}: tsk_joint_model layout {self.model_layout} differs from '
                          f'the ctypes mirror {model_layout()}')
        self.packed_size = bind(lib, 'tsk_joint_packed_size', [_I])
        self.batch_size = bind(lib, 'tsk_joint_batch_size', [_I, _I])
        self.evaluate = bind(lib, 'tsk_joint_evaluate', [_P, _I, _P, _P, _I, _I, _P, _I])
        self.evaluate_packed = bind(lib, 'tsk_joint_evaluate_packed', [_P, _I, _P, _I])
        self.measure_size = bind(lib, 'tsk_joint_measure_size', [_I])
        self.measure_packed = bind(lib, 'tsk_joint_measure_packed', [_P, _I, _P, _I, _P, _I])
        self.linear_size = bind(lib, 'tsk_joint_linear_size', [_I])
        self.pose_terms_size = bind(lib, 'tsk_joint_pose_terms_size', [_I])
        self.linear_model = bind(lib, 'tsk_joint_linear_model',
                                 [_P, _P, _P, _D, _P, _I, _P, _I])
        self.pose_terms = bind(lib, 'tsk_joint_pose_terms', [_P, _P, _I])
        self.transform = bind(lib, 'tsk_joint_transform', [_P, _P, _I])
        self.qp_face_size = bind(lib, 'tsk_qp_face_size', [_I, _I])
        self.qp_warm_face = bind(lib, 'tsk_qp_warm_face', [_I, _I, _D, _D, _D, _D, _P, _I])
        self.chain_frames = bind(lib, 'tsk_chain_frames', [_I, _P, _P, _P, _P, _I])
        self.chain_tip = bind(lib, 'tsk_chain_tip', [_I] + [_P] * 8 + [_I, _P, _I])
        self._bind_filter(lib)
        self.path = path
        self._lib = lib


    def _bind_filter(self, lib: ctypes.CDLL) -> None:
        """The joint filter's entry points (``tsk_filter_*``), typed."""
        self.filter_body_dynamics = bind(lib, 'tsk_filter_body_dynamics',
                                         [_I, _I] + [_P] * 11 + [_I])
        self.filter_propagate_size = bind(lib, 'tsk_filter_propagate_size', [_I])
        self.filter_update_size = bind(lib, 'tsk_filter_update_size', [_I, _I])
        self.filter_propagate = bind(lib, 'tsk_filter_propagate',
                                     [_I, _D, _P, _P, _P, _P, _P, _I])
        self.filter_update = bind(lib, 'tsk_filter_update', [_I, _I, _P, _I])
        self.filter_motion_rows = bind(lib, 'tsk_filter_motion_rows',
                                       [_I, _I, _D, _P, _P, _P, _P])
        self.filter_output = bind(lib, 'tsk_filter_output', [_I, _P, _P, _P, _P, _P, _I])


@functools.lru_cache(maxsize=1)
def _load() -> tuple[_Library | None, str]:
    path, where = library_path()
    if path is None:
        return None, f'numpy ({where})'
    try:
        return _Library(path), f'compiled kernel {path} (from {where})'
    except OSError as exc:
        return None, f'numpy (could not load {path}: {exc})'


def status() -> str:
    """Which implementation :class:`JointKernel` users get, and why."""
    return _load()[1]


def available() -> bool:
    """True when the compiled kernel is loaded."""
    return _load()[0] is not None


def library() -> _Library | None:
    """The loaded library, or ``None`` (numpy path)."""
    return _load()[0]


class BatchLayout(NamedTuple):
    """Where each block of a batch's output buffer starts (doubles; ``T`` at 0) and its size."""

    strings: int
    lengths: int
    tensions: int
    wrench: int
    stiffness: int
    cartesian: int
    flags: int
    size: int


class JointKernel:
    """The compiled evaluation of one joint model: its per-string constants, bound once.

    ``p1``, ``p2`` (n, 3) string ends in {1} and {2}, ``k`` (n,) N/m, ``max_stretch`` (n,) m
    (inf: no limit), ``law`` 0 (Hooke) or 1 (paper), ``min_string_length`` (m). The packed
    buffer of one screw holds the inputs ``xi`` (6) and the rest lengths (n), then ``T`` (16),
    ``s`` (3n), lengths (n), tensions (n), wrench (6), ``K`` (36), ``K_c`` (36), then the slack
    and saturated flags as 2n bytes; the offsets are attributes (``size`` is
    ``tsk_joint_packed_size(n)``). Inputs copied into it need no lifetime care.

    ``tsk_joint_measure_packed`` evaluates the same buffer and writes the string measurements'
    Jacobians to a second one (``measure_size`` doubles, offsets ``measure_*`` from its start):
    the SE(3) left Jacobian ``J`` (36), the pose Jacobian ``P`` (36), ``dl/dxi`` (6n),
    ``dphi/dxi`` (6n) and ``dphi/dl`` (n).

    ``tsk_joint_linear_model`` evaluates it too and writes the linear model of the dynamics to a
    second buffer (``linear_size`` doubles, offsets ``linear_*``): the external wrench (input,
    6), ``F + W`` (6), ``J_l`` (36), ``M`` (36), the right-hand sides ``R`` (6 x
    ``linear_width``), ``M^-1 R`` (the same) and the equilibrium flag (1).
    ``tsk_joint_pose_terms`` fills a buffer of ``pose_terms_size`` doubles: the pose ``T`` (input,
    16), then at offsets ``pose_*`` the lengths (n), ``B`` (6 x n), ``K0`` (36), ``M`` (n x 36).
    :meth:`exp_se3` is ``tsk_joint_transform``.
    """

    def __init__(self, library: _Library, p1: NDArray, p2: NDArray, k: NDArray,
                 max_stretch: NDArray, law: int, min_string_length: float) -> None:
        n = p1.shape[0]
        self.n = n
        self.law = law
        self.min_string_length = min_string_length
        # The struct points into these arrays (and SERIES): they live as long as this object.
        self._arrays = [np.ascontiguousarray(a, dtype=np.float64)
                        for a in (p1, p2, k, max_stretch)]
        self._series = SERIES
        self._struct = _ModelStruct(n, *(address(a) for a in self._arrays), law,
                                    SERIES.shape[1], address(SERIES), screw.SERIES_THRESHOLD,
                                    min_string_length)
        self.model = ctypes.addressof(self._struct)
        self.evaluate = library.evaluate
        self.evaluate_packed = library.evaluate_packed
        self.measure_packed = library.measure_packed
        self.linear_model = library.linear_model
        self.pose_terms = library.pose_terms
        self._transform = library.transform
        self.rest = 6
        self.transform = self.rest + n
        self.strings = self.transform + 16
        self.lengths = self.strings + 3 * n
        self.tensions = self.lengths + n
        self.wrench = self.tensions + n
        self.stiffness = self.wrench + 6
        self.cartesian = self.stiffness + 36
        self.flags = self.cartesian + 36
        self.size = self.flags + (2 * n + 7) // 8
        self.measure_pose = 36
        self.measure_lengths = 72
        self.measure_tensions = 72 + 6 * n
        self.measure_slope = 72 + 12 * n
        self.measure_size = 72 + 13 * n
        self.linear_width = 18 + n
        self.linear_net = 6
        self.linear_jacobian = 12
        self.linear_mass = 48
        self.linear_rhs = 84
        self.linear_solved = 84 + 6 * self.linear_width
        self.linear_flag = 84 + 12 * self.linear_width
        self.linear_size = self.linear_flag + 1
        self.pose_lengths = 16
        self.pose_B = 16 + n
        self.pose_K0 = 16 + 7 * n
        self.pose_M = 52 + 7 * n
        self.pose_terms_size = 52 + 43 * n

    def exp_se3(self, xi: NDArray) -> NDArray:
        """``T = exp(hat(xi))`` (4, 4) of one finite screw (6,) in the kernel
        (``tsk_joint_transform``): the compiled twin of ``geometry.screw.exp_se3`` (the same
        formulas and series tables), at a sixth of its cost."""
        buf = np.empty(22)
        buf[:6] = xi
        check(self._transform(self.model, address(buf), 22), 'tsk_joint_transform')
        return buf[6:].reshape(4, 4)

    def batch_layout(self, N: int) -> BatchLayout:
        """Offsets (in doubles) of the blocks of a batch's output buffer for ``N`` screws, in
        the order of ``kernel.h``, and its size (``tsk_joint_batch_size(n, N)``)."""
        n = self.n
        strings = 16 * N
        lengths = strings + 3 * n * N
        tensions = lengths + n * N
        wrench = tensions + n * N
        stiffness = wrench + 6 * N
        cartesian = stiffness + 36 * N
        flags = cartesian + 36 * N
        return BatchLayout(strings, lengths, tensions, wrench, stiffness, cartesian, flags,
                           flags + (2 * N * n + 7) // 8)

    def __reduce__(self) -> tuple:
        """Pickled as its constants (a model sent to the solver worker process): the receiving
        process binds them to its own library, or gets ``None`` (numpy) without one."""
        return joint_kernel, (*self._arrays, self.law, self.min_string_length)


def qp_face_size(n: int, m: int) -> int:
    """Doubles of ``tsk_qp_warm_face``'s buffer for ``n`` variables and ``m`` equalities (the
    inputs P, c, A, b, lo, hi, t0, at_lo, at_hi, then t, nu and the outcome; ``kernel.h``)."""
    return n * n + m * n + 7 * n + 2 * m + 1


def defaults_header() -> str:
    """Text of ``kernel_defaults.h``: the constants every model of this package passes to the
    kernel (:data:`SERIES`, ``screw.SERIES_THRESHOLD``, :data:`MIN_STRING_LENGTH`) as exact
    hexadecimal C literals, for C and C++ callers (``joint_kernel.hpp``).

    The build writes it from this function (``cmake/kernel_defaults.py``), so the values have
    their one home in the Python modules that the numpy path reads as well.
    """
    rows, terms = SERIES.shape
    values = [float(x).hex() for x in SERIES.ravel()]
    table = ',\\\n'.join('  ' + ', '.join(values[i:i + 4]) for i in range(0, len(values), 4))
    return f"""/* Generated at build time by cmake/kernel_defaults.py from
 * tensegrity_stiffness.mechanics.kernel.defaults_header(): do not edit. The constants every
 * tsk_joint_model of the Python package carries, from their one home: the Taylor tables and
 * threshold of tensegrity_stiffness/geometry/screw.py and joint.MIN_STRING_LENGTH. */
#ifndef TENSEGRITY_STIFFNESS__KERNEL_DEFAULTS_H_
#define TENSEGRITY_STIFFNESS__KERNEL_DEFAULTS_H_

/* Terms per row of the series table (tsk_joint_model.series_terms). */
#define TSK_DEFAULT_SERIES_TERMS {terms}
/* Initializer of the TSK_SERIES_ROWS ({rows}) x TSK_DEFAULT_SERIES_TERMS table, row-major:
 * coefficients in theta^2 of a, b, c, b1, c1, highest power first. */
#define TSK_DEFAULT_SERIES {{\\
{table}}}
/* tsk_joint_model.series_threshold (rad) and .min_string_length (m). */
#define TSK_DEFAULT_SERIES_THRESHOLD {float(screw.SERIES_THRESHOLD).hex()}
#define TSK_DEFAULT_MIN_STRING_LENGTH {float(MIN_STRING_LENGTH).hex()}

#endif  /* TENSEGRITY_STIFFNESS__KERNEL_DEFAULTS_H_ */
"""


def joint_kernel(p1: NDArray, p2: NDArray, k: NDArray, max_stretch: NDArray, law: int,
                 min_string_length: float) -> JointKernel | None:
    """A :class:`JointKernel` for these constants, or ``None`` when the library is not loaded."""
    library = _load()[0]
    if library is None:
        return None
    return JointKernel(library, p1, p2, k, max_stretch, law, min_string_length)
