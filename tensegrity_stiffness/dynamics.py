"""Documented import path of :mod:`tensegrity_stiffness.mechanics.dynamics`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import dynamics as moved

sys.modules[__name__] = moved
