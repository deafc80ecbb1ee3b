"""``control_loop``: ``estimator_node`` and ``stiffness_controller`` in one process, for a robot
where both run on one computer: each estimate goes to the controller as the Python objects it is
(no message, no serialisation, no middleware in between;
:meth:`.StiffnessControllerNode.take_state`), the controller ticks on its own thread as in its own
process.

The same parameters and topics as the two nodes: two nodes named ``estimator_node`` and
``stiffness_controller`` (a parameter file's sections apply as they would to the processes), the
estimator's inputs and outputs, the controller's targets and commands. The controller has no
``~/pose_estimate`` / ``~/wrench_estimate`` subscriptions (the estimator's topics are still
published, for everyone else); the estimator still takes the commanded rest lengths on its
``~/rest_lengths`` (remap it to ``stiffness_controller/rest_lengths``, as for the processes).
A node-specific remap is written ``-r 'estimator_node:~/imu:=/sim_node/imu'``; an unprefixed one
applies to both nodes. docs/control.md, "One process".
"""

from __future__ import annotations

from typing import Any

from tensegrity_stiffness.nodes.parameter_docs import node_usage
from tensegrity_stiffness.ros.estimator_node import EstimatorNode
from tensegrity_stiffness.ros.runtime import runner
from tensegrity_stiffness.ros.stiffness_controller import StiffnessControllerNode

EXECUTABLE = 'control_loop'


def hand_over(controller: StiffnessControllerNode) -> Any:
    """The estimator's output listener that gives ``controller`` each estimate: the pose, the
    reading's stamp and the load estimate."""

    def take(outputs: Any, stamp: Any) -> None:
        est = outputs.estimate
        controller.take_state(est.transform, stamp.sec * 1_000_000_000 + stamp.nanosec,
                              est.external_wrench)

    return take


def make_nodes() -> tuple[EstimatorNode, StiffnessControllerNode]:
    """The two nodes of the process, the estimator's estimates wired into the controller."""
    controller = StiffnessControllerNode(state_topics=False)
    try:
        estimator = EstimatorNode()
    except Exception:
        controller.close()
        controller.destroy_node()
        raise
    estimator.output_listeners.append(hand_over(controller))
    return estimator, controller


def usage() -> str:
    """``--help``: what the process runs, then the two nodes' own usage texts."""
    return (f'usage: {EXECUTABLE} [-h] [--ros-args ...]\n\n'
            f'{EXECUTABLE}: estimator_node and stiffness_controller in one process (the '
            'estimates handed to the controller without a topic); docs/control.md, "One '
            'process". Each node takes its own parameters and remaps, as below.\n\n'
            + node_usage('estimator_node') + '\n' + node_usage('stiffness_controller'))


def main(args: list[str] | None = None) -> None:
    """Entry point of ``ros2 run tensegrity_stiffness control_loop``."""
    runner.run(make_nodes, args, usage=usage())


if __name__ == '__main__':
    main()
