"""The ROS 2 layer of tensegrity_stiffness: every module that imports rclpy lives here.

``stiffness_node`` (the joint node) is built from shared parts: the parameter binding
(:mod:`.parameters`, from the one table in :mod:`tensegrity_stiffness.parameters`), the solver
worker process (:mod:`.solver_worker`), draining subscriptions (:mod:`.draining_subscription`),
guarded callbacks and throttled reports (:mod:`.reporting`), the middleware memory settings
(:mod:`.middleware`) and the process runner with clean stops (:mod:`.runner`). ``spine_node``
(a whole spine, :mod:`tensegrity_stiffness.chain`) is built from the same parts, with
:mod:`.spine_services`; both nodes await their worker through :mod:`.worker_calls`.
"""
