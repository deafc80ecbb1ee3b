"""The nodes' behaviour without ROS, one module per node named as its twin in
:mod:`tensegrity_stiffness.ros` (:mod:`.stiffness_node`, :mod:`.spine_node`, :mod:`.sim_node`,
:mod:`.estimator_node`, :mod:`.spine_estimator_node`, :mod:`.stiffness_controller`,
:mod:`.stiffness_bridge`, :mod:`.structure_node`, :mod:`.structure_sim_node`,
:mod:`.structure_estimator_node`): its parameter table, its settings and what it does with one
input. Shared by them: the parameter machinery
(:mod:`.parameter_specs`), the sections several nodes share (:mod:`.shared_parameters`), the
registry (:mod:`.registry`, with the generated docs of :mod:`.parameter_docs`), the labels,
layouts and output tables of every output (:mod:`.layouts`), the messages built through their
fields for any message implementation (:mod:`.messages`), the frames (:mod:`.frames`) and the
health figures of ``/diagnostics`` (:mod:`.health`). :mod:`.parameters`, :mod:`.processing`,
:mod:`.spine_processing`, :mod:`.control_processing` and :mod:`.estimation_processing` are the
old names, kept as faces that re-export.

The rclpy nodes (:mod:`tensegrity_stiffness.ros`) and the bag command
(:mod:`tensegrity_stiffness.recordings`) both run this code, so a recording gives what the nodes
publish. May import: mechanics, estimation, simulation, control, geometry, config; no rclpy.
"""
