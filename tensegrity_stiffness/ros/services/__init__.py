"""The services' request handling: :mod:`.joint_services` (stiffness_node: equilibrium, design,
planar kinematics) and :mod:`.spine_services` (spine_node: the chain equilibrium)."""
