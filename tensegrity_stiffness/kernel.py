"""The compiled kernel: loader and calling convention (pure Python, ctypes only).

``tensegrity_stiffness_kernel`` (a C++ package of this repository, built by colcon with the rest)
installs ``lib/libtensegrity_stiffness_kernel.so``: the per-string loop of
:class:`~tensegrity_stiffness.joint.JointModel` (eqs. 6-11: kinematics, string forces, wrench,
K and K_c) for one screw or a batch, and the frames, implied tip wrench and tip stiffness of a
:class:`~tensegrity_stiffness.chain.JointChain`, in compiled code. Both use it when it is found
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

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness import screw

#: Environment variable naming the library (a path) or ``off`` for the numpy path.
KERNEL_ENV = 'TENSEGRITY_STIFFNESS_KERNEL'
#: File name of the library under ``<prefix>/lib``.
LIBRARY_NAME = 'libtensegrity_stiffness_kernel.so'
#: ABI version this module speaks (``tsk_abi_version`` of the library).
ABI_VERSION = 1
#: Values of :data:`KERNEL_ENV` that select the numpy path.
OFF_VALUES = ('off', '0', 'no', 'false', 'numpy')
#: Modes of the kernel: everything; K without K_c; the wrench alone.
MODE_FULL, MODE_STIFFNESS, MODE_WRENCH = 0, 1, 2
#: Return value of a successful kernel call (else: index of the first screw with a zero-length
#: string, or -2 when the series tables were not set).
OK = -1

_P = ctypes.c_void_p
_I = ctypes.c_int64


class _ModelStruct(ctypes.Structure):
    """``struct Model`` of ``joint_kernel.cpp``: pointers into arrays the owner keeps alive."""

    _fields_ = [('n', _I), ('p1', _P), ('p2', _P), ('k', _P), ('max_stretch', _P), ('law', _I)]


def address(arr: NDArray) -> int:
    """Data address of a C-contiguous array (for the kernel's pointer arguments); a writable
    one through ctypes' buffer view (a third of the time of ``__array_interface__``)."""
    if arr.flags.writeable and arr.nbytes:
        return _addressof(_char_view(arr))
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
    """The loaded library with its two entry points typed."""

    def __init__(self, path: Path) -> None:
        lib = ctypes.CDLL(str(path))
        lib.tsk_abi_version.restype = _I
        lib.tsk_abi_version.argtypes = []
        version = lib.tsk_abi_version()
        if version != ABI_VERSION:
            raise OSError(f'{path} speaks ABI {version}, this package {ABI_VERSION}')
        lib.tsk_set_series.restype = None
        lib.tsk_set_series.argtypes = [_P]
        # The same Taylor coefficients as screw.rotation_coefficients (a, b, c, b1, c1).
        self._series = np.ascontiguousarray(np.stack([
            screw._A_SERIES, screw._B_SERIES, screw._C_SERIES, screw._B1_SERIES,
            screw._C1_SERIES]))
        lib.tsk_set_series(address(self._series))
        self.evaluate = lib.tsk_joint_evaluate
        self.evaluate.restype = _I
        self.evaluate.argtypes = [_P, _I, _P, _P, _I, _I] + [_P] * 9
        self.evaluate_packed = lib.tsk_joint_evaluate_packed
        self.evaluate_packed.restype = _I
        self.evaluate_packed.argtypes = [_P, _P, _I, _P]
        self.chain_frames = lib.tsk_chain_frames
        self.chain_frames.restype = None
        self.chain_frames.argtypes = [_I] + [_P] * 6
        self.chain_tip = lib.tsk_chain_tip
        self.chain_tip.restype = _I
        self.chain_tip.argtypes = [_I] + [_P] * 11
        self.path = path
        self._lib = lib


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


#: Status codes of ``tsk_chain_tip``.
CHAIN_SINGULAR_SYSTEM, CHAIN_SINGULAR_COMPLIANCE = 1, 2


class JointKernel:
    """The compiled evaluation of one joint model: its per-string constants, bound once.

    ``p1``, ``p2`` (n, 3) string ends in {1} and {2}, ``k`` (n,) N/m, ``max_stretch`` (n,) m
    (inf: no limit), ``law`` 0 (Hooke) or 1 (paper). The packed buffer of one screw holds
    ``xi`` (6), ``T`` (16), ``s`` (3n), lengths (n), tensions (n), wrench (6), ``K`` (36),
    ``K_c`` (36), then the slack and saturated flags as 2n bytes; the offsets are attributes.
    """

    def __init__(self, library: _Library, p1: NDArray, p2: NDArray, k: NDArray,
                 max_stretch: NDArray, law: int) -> None:
        n = p1.shape[0]
        self.n = n
        self.law = law
        self._arrays = [np.ascontiguousarray(a, dtype=np.float64)
                        for a in (p1, p2, k, max_stretch)]
        self._struct = _ModelStruct(n, *(address(a) for a in self._arrays), law)
        self.model = ctypes.addressof(self._struct)
        self.evaluate = library.evaluate
        self.evaluate_packed = library.evaluate_packed
        self.transform = 6
        self.strings = self.transform + 16
        self.lengths = self.strings + 3 * n
        self.tensions = self.lengths + n
        self.wrench = self.tensions + n
        self.stiffness = self.wrench + 6
        self.cartesian = self.stiffness + 36
        self.flags = self.cartesian + 36
        self.size = self.flags + (2 * n + 7) // 8

    def __reduce__(self) -> tuple:
        """Pickled as its constants (a model sent to the solver worker process): the receiving
        process binds them to its own library, or gets ``None`` (numpy) without one."""
        return joint_kernel, (*self._arrays, self.law)


def joint_kernel(p1: NDArray, p2: NDArray, k: NDArray, max_stretch: NDArray, law: int
                 ) -> JointKernel | None:
    """A :class:`JointKernel` for these constants, or ``None`` when the library is not loaded."""
    library = _load()[0]
    if library is None:
        return None
    return JointKernel(library, p1, p2, k, max_stretch, law)
