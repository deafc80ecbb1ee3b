"""Documented import path of :mod:`tensegrity_stiffness.mechanics.interpretation`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.mechanics import interpretation as _module

sys.modules[__name__] = _module
