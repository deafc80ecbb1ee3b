"""Documented import path of :mod:`tensegrity_stiffness.mechanics.controller_stiffness`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import controller_stiffness as _module

sys.modules[__name__] = _module
