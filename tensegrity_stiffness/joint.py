"""Documented import path of :mod:`tensegrity_stiffness.mechanics.joint`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import joint as moved

sys.modules[__name__] = moved
