"""Documented import path of :mod:`tensegrity_stiffness.geometry.quaternion`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.geometry import quaternion as moved

sys.modules[__name__] = moved
