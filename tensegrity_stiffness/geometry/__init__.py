"""Geometry: screw algebra on SE(3) and SO(3) (:mod:`.screw`), quaternions (:mod:`.quaternion`),
rigid transforms and poses (:mod:`.transforms`: the one pose parser and the adjoint), the names
of wrench, screw and twist components (:mod:`.components`) and array checks
(:mod:`.validation`).

May import: numpy, scipy and its own modules only.
"""
