"""Documented import path of :mod:`tensegrity_stiffness.geometry.screw`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.geometry import screw as moved

sys.modules[__name__] = moved
