"""Deprecated: use :mod:`tensegrity_stiffness.mechanics.planar_workspace`
(this name is that module itself, after a DeprecationWarning)."""

from tensegrity_stiffness.deprecation import replace_module
from tensegrity_stiffness.mechanics import planar_workspace as moved

replace_module(__name__, moved)
