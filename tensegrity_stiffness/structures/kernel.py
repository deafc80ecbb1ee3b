"""The compiled kernel of the structures (``src/structure_kernel.cpp``, entry
``tsk_structure_evaluate`` of the joint's library): its loader (ctypes only).

The library is the one :mod:`tensegrity_stiffness.mechanics.kernel` finds and loads (its
``library().path``); this module binds the structure entry point of that same library. Without
the library, or with a library built before the structures (no ``tsk_structure_evaluate``), the
structures use their numpy path, :meth:`~tensegrity_stiffness.structures.structure.Structure.
evaluate_numpy`.
"""

from __future__ import annotations

from typing import Any


def structure_kernel(structure: Any) -> Any:
    """The compiled evaluation of ``structure``, or None (numpy path)."""
    return None
