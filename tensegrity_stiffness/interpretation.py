"""Deprecated: use :mod:`tensegrity_stiffness.mechanics.interpretation`
(this name is that module itself, after a DeprecationWarning)."""

from tensegrity_stiffness.deprecation import replace_module
from tensegrity_stiffness.mechanics import interpretation as moved

replace_module(__name__, moved)
