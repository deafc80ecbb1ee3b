"""The services' request handling: :mod:`.joint_services` (stiffness_node: equilibrium, design,
planar kinematics), :mod:`.spine_services` (spine_node: the chain equilibrium) and what they
share (:mod:`.responses`)."""
