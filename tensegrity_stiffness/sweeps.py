"""Documented import path of :mod:`tensegrity_stiffness.mechanics.sweeps`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import sweeps as moved

sys.modules[__name__] = moved
