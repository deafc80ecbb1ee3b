"""Documented import path of :mod:`tensegrity_stiffness.mechanics.interpretation`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import interpretation as moved

sys.modules[__name__] = moved
