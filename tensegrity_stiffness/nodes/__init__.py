"""The nodes' behaviour without ROS: each node's parameter table (:mod:`.parameters`, with the
generated docs of :mod:`.parameter_docs`), the labels and layouts of every output
(:mod:`.layouts`), the messages built through their fields for any message implementation
(:mod:`.messages`), and what a node does with one input: :mod:`.processing` (stiffness_node),
:mod:`.spine_processing` (spine_node), :mod:`.estimation_processing` (the estimators),
:mod:`.health` (the stability and chart margins of ``/diagnostics``).

The rclpy nodes (:mod:`tensegrity_stiffness.ros`) and the bag command
(:mod:`tensegrity_stiffness.recordings`) both run this code, so a recording gives what the nodes
publish. May import: mechanics, estimation, simulation, control, geometry, config; no rclpy.
"""
