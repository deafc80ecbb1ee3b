"""Documented import path of :mod:`tensegrity_stiffness.estimation.calibration`
(this name is the same module object)."""

import sys

from tensegrity_stiffness.estimation import calibration as moved

sys.modules[__name__] = moved
