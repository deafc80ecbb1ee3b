"""The ROS 2 layer of tensegrity_stiffness: every module that imports rclpy lives here.

``stiffness_node`` (the joint node) and ``spine_node`` (a whole spine,
:mod:`tensegrity_stiffness.mechanics.chain`) are both a
:class:`.runtime.node_base.StreamingNode`: one skeleton that wires the shared parts and leaves
each node its parameters, streams, outputs and services. The parts are in :mod:`.runtime`: the
parameter declaration (:mod:`.runtime.declared_parameters`, from the one table in
:mod:`tensegrity_stiffness.nodes.parameters`), the solver worker process
(:mod:`.runtime.solver_worker`) and the awaited calls into it (:mod:`.runtime.worker_calls`), the
fast lane (:mod:`.runtime.fast_lane`), draining subscriptions
(:mod:`.runtime.draining_subscription`), the last input (:mod:`.runtime.last_input`), guarded
callbacks and throttled reports (:mod:`.runtime.reporting`), QoS and publishers
(:mod:`.runtime.topics`), the middleware memory settings (:mod:`.runtime.middleware`) and the
process runner with clean stops (:mod:`.runtime.runner`); the services' request handling is in
:mod:`.services.joint_services` and :mod:`.services.spine_services`, the numpy <-> message
conversions in :mod:`.conversions`.
"""
