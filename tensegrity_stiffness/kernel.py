"""Deprecated: use :mod:`tensegrity_stiffness.mechanics.kernel`
(this name is that module itself, after a DeprecationWarning)."""

from tensegrity_stiffness.deprecation import replace_module
from tensegrity_stiffness.mechanics import kernel as moved

replace_module(__name__, moved)
