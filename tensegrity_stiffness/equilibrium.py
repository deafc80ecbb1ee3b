"""Documented import path of :mod:`tensegrity_stiffness.mechanics.equilibrium`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import equilibrium as moved

sys.modules[__name__] = moved
