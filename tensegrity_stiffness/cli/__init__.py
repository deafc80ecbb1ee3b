"""The command line ``tensegrity-stiffness``: :mod:`.parser` (``main`` and the parser, which asks
each command group to add its commands), one module per command group (:mod:`.joint_commands`:
joint, equilibrium, design; :mod:`.planar_commands`: planar-fk, planar-ik; :mod:`.spine_commands`:
chain; :mod:`.figure_commands`: plot, figures; :mod:`.recording_commands`: bag, calibrate,
export-mjcf; :mod:`.dynamics_commands`: modes), what they share (:mod:`.common`: exit codes,
number parsing, tables, JSON; :mod:`.progress`: progress bars), the figures (:mod:`.plots`,
:mod:`.dynamics_plots`) and the calibration reports (:mod:`.calibration_report`; a structure's:
:mod:`.structure_calibration_report`).

May import: every library layer (recordings, nodes, control, estimation, simulation, mechanics,
geometry, config); no rclpy.
"""

from tensegrity_stiffness.cli.parser import main

__all__ = ['main']
