"""Simulation: the MuJoCo digital twin of a joint or a spine (:mod:`.twin`, re-exported here:
``tensegrity_stiffness.simulation`` is the documented path), of any structure
(:mod:`.structure_twin`, imported from there: it loads the structures) and the structure's
scripted roll (:mod:`.structure_gait`).

May import: :mod:`tensegrity_stiffness.mechanics`, :mod:`tensegrity_stiffness.geometry`,
:mod:`tensegrity_stiffness.config`, :mod:`tensegrity_stiffness.structures`, numpy, mujoco
(imported when a twin is built).
"""

from tensegrity_stiffness.simulation.twin import *  # noqa: F403
from tensegrity_stiffness.simulation.twin import __all__  # noqa: F401
