"""Documented import path of :mod:`tensegrity_stiffness.mechanics.planar_workspace`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import planar_workspace as moved

sys.modules[__name__] = moved
