"""Mechanics: the joint model and its compiled kernel (:mod:`.joint`, :mod:`.kernel`), equilibria
(:mod:`.equilibrium`, with the damped Newton solver of :mod:`.newton`), spines (:mod:`.chain`),
stiffness design (:mod:`.design`), sweeps (:mod:`.sweeps`), the interpretation of K
(:mod:`.interpretation`), the controller-ready stiffness (:mod:`.controller_stiffness`) and the
planar mechanism (:mod:`.planar`, :mod:`.planar_workspace`).

May import: :mod:`tensegrity_stiffness.geometry`, :mod:`tensegrity_stiffness.config`, numpy,
scipy, PyYAML.
"""
