"""The compiled kernel of the structures (``src/structure_kernel.cpp``, the entry points
``tsk_structure_size`` and ``tsk_structure_evaluate`` of the joint's library): its loader and
calling convention (ctypes only).

The library is the one :mod:`tensegrity_stiffness.mechanics.kernel` finds and loads
(``kernel.library().path``; ``TENSEGRITY_STIFFNESS_KERNEL=off`` turns both off); this module
binds the structure entry points of that same file (``dlopen`` hands out the loaded library
again). Without the library, or with a library built before the structures, the structures use
their numpy path, :meth:`~tensegrity_stiffness.structures.structure.Structure.evaluate_numpy`.
:func:`status` says which, and why.

Output buffer of one evaluation (doubles): ``s`` (3n), lengths (n), tensions (n), wrenches (6N),
``K`` (36 N^2), then the slack and saturated flags as 2n bytes.
"""

from __future__ import annotations

import ctypes
import functools
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.joint import FORCE_LAWS, MIN_STRING_LENGTH

_P = ctypes.c_void_p
_I = ctypes.c_int64
_D = ctypes.c_double

#: The structure entry points this module binds.
ENTRY_POINTS = ('tsk_structure_size', 'tsk_structure_evaluate')


@functools.lru_cache(maxsize=1)
def _load() -> tuple[Any, str]:
    library = kernel.library()
    if library is None:
        return None, f'numpy ({kernel.status()})'
    try:
        lib = ctypes.CDLL(str(library.path))
        size, evaluate = (kernel.bind(lib, name, argtypes) for name, argtypes in zip(
            ENTRY_POINTS, ([_I, _I], [_I, _I, _P, _P, _P, _P, _P, _I, _D, _P, _I, _P, _I]),
            strict=True))
    except (OSError, AttributeError) as exc:
        return None, f'numpy ({library.path} has no structure kernel: {exc}; rebuild: bash ' \
                     'scripts/setup_env.sh)'
    return (size, evaluate), f'compiled kernel {library.path}'


def status() -> str:
    """Which implementation the structures get, and why."""
    return _load()[1]


def available() -> bool:
    """True when the structure kernel is loaded."""
    return _load()[0] is not None


class StructureKernel:
    """The compiled evaluation of one structure: its per-string constants, bound once (the
    arrays whose addresses C reads live as long as this object)."""

    def __init__(self, structure: Any, size: Any, evaluate: Any) -> None:
        self.structure = structure
        self.n_bodies = structure.n_bodies
        self.n = structure.n_strings
        self.ends = np.ascontiguousarray(structure.string_bodies, dtype=np.int64)
        self.points = np.ascontiguousarray(structure.string_points, dtype=np.float64)
        self.k = np.ascontiguousarray(structure.k, dtype=np.float64)
        self.max_stretch = np.ascontiguousarray(structure.max_stretch, dtype=np.float64)
        self.law = FORCE_LAWS.index(structure.force_law)
        self.size = int(size(self.n_bodies, self.n))
        kernel.check(min(self.size, 0), 'tsk_structure_size')
        self.call = evaluate
        self._constants = [kernel.address(a) for a in (self.ends, self.points, self.k)]
        self._stretch = kernel.address(self.max_stretch)
        n, nb = self.n, self.n_bodies
        self.lengths = 3 * n
        self.tensions = 4 * n
        self.wrenches = 5 * n
        self.stiffness = 5 * n + 6 * nb
        self.flags = self.stiffness + 36 * nb * nb

    def run(self, T: NDArray, rest: NDArray, wrench_only: bool) -> NDArray | None:
        """The output buffer at the (N, 4, 4) transforms ``T`` with rest lengths (n,); None
        when a string has zero length (the numpy path then raises the error that names it)."""
        T = np.ascontiguousarray(T, dtype=np.float64)  # names: they outlive the call
        rest = np.ascontiguousarray(rest, dtype=np.float64)
        out = np.empty(self.size)
        status = self.call(self.n_bodies, self.n, *self._constants, kernel.address(rest),
                           self._stretch, self.law, MIN_STRING_LENGTH, kernel.address(T),
                           kernel.MODE_WRENCH if wrench_only else kernel.MODE_FULL,
                           kernel.address(out), out.size)
        if status == kernel.ERROR_ZERO_LENGTH:
            return None
        kernel.check(status, 'tsk_structure_evaluate')
        return out

    def evaluate(self, T: NDArray, rest: NDArray, wrench_only: bool) -> Any:
        """The :class:`~tensegrity_stiffness.structures.structure.StructureState` at ``T``, or
        None (see :meth:`run`)."""
        out = self.run(T, rest, wrench_only)
        if out is None:
            return None
        n, nb = self.n, self.n_bodies
        K = out[self.stiffness:self.flags].reshape(6 * nb, 6 * nb)
        if wrench_only:
            K = np.full((6 * nb, 6 * nb), np.nan)
        flags = out[self.flags:].view(np.bool_)
        return self.structure.state(
            T, out[self.wrenches:self.stiffness].reshape(nb, 6), K,
            out[:self.lengths].reshape(n, 3), out[self.lengths:self.tensions],
            out[self.tensions:self.wrenches], flags[:n], flags[n:2 * n])


def structure_kernel(structure: Any) -> StructureKernel | None:
    """The compiled evaluation of ``structure``, or None (numpy path)."""
    loaded = _load()[0]
    if loaded is None:
        return None
    return StructureKernel(structure, *loaded)
