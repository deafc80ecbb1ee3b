"""Documented import path of :mod:`tensegrity_stiffness.mechanics.chain`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import chain as moved

sys.modules[__name__] = moved
