"""Simulation: the MuJoCo digital twin of a joint or a spine (:mod:`.twin`), of any structure
(:mod:`.structure_twin`) and the structure's scripted roll (:mod:`.structure_gait`).

Import the modules (``from tensegrity_stiffness.simulation.twin import JointSimulation``). This
``__init__`` imports none of them: the names it used to re-export
(``from tensegrity_stiffness.simulation import JointSimulation``) still work, imported on first
use, with a DeprecationWarning naming the module
(:class:`tensegrity_stiffness.deprecation.MovedNames`).

May import: :mod:`tensegrity_stiffness.mechanics`, :mod:`tensegrity_stiffness.geometry`,
:mod:`tensegrity_stiffness.config`, :mod:`tensegrity_stiffness.structures`, numpy, mujoco
(imported when a twin is built).
"""

from tensegrity_stiffness.deprecation import MovedNames

__getattr__ = MovedNames(__name__, {'twin': None})
