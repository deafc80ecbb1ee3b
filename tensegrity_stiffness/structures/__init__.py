"""Structures: any set of rigid bodies (a bar is a body with two nodes on its axis) joined by
strings, free or fixed, with gravity and the ground (docs/structures.md).

Modules: the model and its evaluation (``structure``: :class:`~.structure.Structure`,
:class:`~.structure.StructureState`), the schema of a structure config (``schema``), the joint
and the spine as structures (``joints``), the compiled kernel's loader (``kernel``), equilibria
with gravity, the ground and friction (``equilibrium``), modes and the linear model (``modes``)
and the MuJoCo export (``mjcf``).

Rank between ``mechanics`` and the rank-2 concerns (docs/architecture.md): it may import
``geometry``, ``config`` and ``mechanics``; ``estimation``, ``simulation`` and ``control`` may
import it. This ``__init__`` imports nothing.
"""
