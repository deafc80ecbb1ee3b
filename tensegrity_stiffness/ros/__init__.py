"""The ROS 2 layer of tensegrity_stiffness: every module that imports rclpy lives here.

``stiffness_node`` (the joint node) and ``spine_node`` (a whole spine,
:mod:`tensegrity_stiffness.mechanics.chain`) are both a :class:`.node_base.StreamingNode`: one
skeleton
that wires the shared parts and leaves each node its parameters, streams, outputs and services.
The parts: the parameter binding (:mod:`.parameters`, from the one table in the node's module
in :mod:`tensegrity_stiffness.nodes`), the solver worker process (:mod:`.solver_worker`) and
the awaited calls into it (:mod:`.worker_calls`), the fast lane (:mod:`.fast_lane`), draining
subscriptions (:mod:`.draining_subscription`), the last input (:mod:`.last_input`), guarded
callbacks and throttled reports (:mod:`.reporting`), QoS and publishers (:mod:`.topics`), the
middleware memory settings (:mod:`.middleware`) and the process runner with clean stops
(:mod:`.runner`); the services' request handling is in :mod:`.joint_services` and
:mod:`.spine_services`.
"""
