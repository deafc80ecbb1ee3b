"""Control: the stiffness controller that turns a target pose and a target K_c plus what the
robot measures into rest-length commands a motor can follow, for a joint and a spine
(:mod:`.controller`, re-exported here: ``tensegrity_stiffness.control`` is the documented path).

May import: :mod:`tensegrity_stiffness.mechanics`, :mod:`tensegrity_stiffness.geometry`,
:mod:`tensegrity_stiffness.config`, numpy, scipy.
"""

from tensegrity_stiffness.control.controller import *  # noqa: F403
from tensegrity_stiffness.control.controller import __all__  # noqa: F401
