"""The command line ``tensegrity-stiffness`` (:mod:`.commands`: the parser and the commands), its
figures (:mod:`.plots`) and the calibration report (:mod:`.calibration_report`).

May import: every library layer (recordings, nodes, control, estimation, simulation, mechanics,
geometry, config); no rclpy.
"""

from tensegrity_stiffness.cli.commands import main

__all__ = ['main']
