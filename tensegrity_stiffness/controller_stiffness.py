"""Documented import path of :mod:`tensegrity_stiffness.mechanics.controller_stiffness`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import controller_stiffness as moved

sys.modules[__name__] = moved
