"""Documented import path of :mod:`tensegrity_stiffness.mechanics.planar`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import planar as moved

sys.modules[__name__] = moved
