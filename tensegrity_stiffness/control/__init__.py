"""Control: the stiffness controller that turns a target pose and a target K_c plus what the
robot measures into rest-length commands a motor can follow, for a joint and a spine
(:mod:`.controller`).

Import the module (``from tensegrity_stiffness.control.controller import StiffnessController``).
This ``__init__`` imports nothing: the names it used to re-export
(``from tensegrity_stiffness.control import StiffnessController``) still work, imported on first
use, with a DeprecationWarning naming the module
(:class:`tensegrity_stiffness.deprecation.MovedNames`).

May import: :mod:`tensegrity_stiffness.mechanics`, :mod:`tensegrity_stiffness.geometry`,
:mod:`tensegrity_stiffness.config`, numpy, scipy.
"""

from tensegrity_stiffness.deprecation import MovedNames

__getattr__ = MovedNames(__name__, {'controller': None})
