"""Deprecated: use :mod:`tensegrity_stiffness.estimation.calibration`
(this name is that module itself, after a DeprecationWarning)."""

from tensegrity_stiffness.deprecation import replace_module
from tensegrity_stiffness.estimation import calibration as moved

replace_module(__name__, moved)
