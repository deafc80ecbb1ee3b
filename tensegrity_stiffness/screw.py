"""Deprecated: use :mod:`tensegrity_stiffness.geometry.screw`
(this name is that module itself, after a DeprecationWarning)."""

from tensegrity_stiffness.deprecation import replace_module
from tensegrity_stiffness.geometry import screw as moved

replace_module(__name__, moved)
