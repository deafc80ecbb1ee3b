"""The shared parts every node is built from: the node skeleton (:mod:`.node_base`), parameter
declaration from a node's table (:mod:`.declared_parameters`), the solver worker process
(:mod:`.solver_worker`) and the awaited calls into it (:mod:`.worker_calls`), the fast lane
(:mod:`.fast_lane`), draining subscriptions (:mod:`.draining_subscription`), the last input
(:mod:`.last_input`), guarded callbacks and throttled reports (:mod:`.reporting`), QoS and
publishers (:mod:`.topics`), the middleware memory settings (:mod:`.middleware`) and the
process runner with clean stops (:mod:`.runner`).
"""
