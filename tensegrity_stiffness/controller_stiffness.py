"""Deprecated: use :mod:`tensegrity_stiffness.mechanics.controller_stiffness`
(this name is that module itself, after a DeprecationWarning)."""

from tensegrity_stiffness.deprecation import replace_module
from tensegrity_stiffness.mechanics import controller_stiffness as moved

replace_module(__name__, moved)
