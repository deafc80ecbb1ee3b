"""Documented import path of :mod:`tensegrity_stiffness.mechanics.design`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import design as moved

sys.modules[__name__] = moved
