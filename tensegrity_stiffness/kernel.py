"""Documented import path of :mod:`tensegrity_stiffness.mechanics.kernel`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import kernel as moved

sys.modules[__name__] = moved
