"""``stiffness_node`` with ``dynamics.enabled``: ``~/natural_frequencies`` of every input, the
library's modes of the joint held at that pose (real node, real middleware)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from std_msgs.msg import Float64MultiArray  # noqa: E402
from support import REPO  # noqa: E402
from support.ros_harness import NodeProcess, RosClient, repeat_until, unique_namespace  # noqa: E402

from tensegrity_stiffness.mechanics.dynamics import JointDynamics, LinkInertia  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402
from tensegrity_stiffness.nodes.layouts import (  # noqa: E402
    NATURAL_FREQUENCIES_LABEL,
    natural_frequencies_label,
)

CONFIG = REPO / 'config' / 'default_joint.yaml'


def frequencies_and_input(ros: RosClient, base: str, topic: str) -> tuple[Any, Any]:
    """The subscription to the node ``base``'s ``natural_frequencies`` and a publisher on its
    input ``topic`` that the node has subscribed to."""
    frequencies = ros.subscribe(Float64MultiArray, f'{base}/natural_frequencies')
    publisher = ros.publisher(Float64MultiArray, f'{base}/{topic}')
    ros.wait_for_subscribers(publisher)
    return frequencies, publisher


@pytest.mark.ros
def test_natural_frequencies_are_the_library_s_modes_at_each_input() -> None:
    model = JointModel.from_yaml(CONFIG)
    inertia = LinkInertia(mass=0.02, com=(0.0, 0.001, 0.0))
    dynamics = JointDynamics(model, inertia, string_damping=0.3)
    ns = unique_namespace('dynamics')
    proc = NodeProcess(ns, CONFIG, extra_args=[
        '-p', 'dynamics.enabled:=true', '-p', 'dynamics.string_damping:=0.3',
        '-p', 'joint.link2_mass:=0.02', '-p', 'joint.link2_com:=[0.0, 0.001, 0.0]'])
    ros = RosClient('dynamics_test')
    try:
        frequencies, screw = frequencies_and_input(ros, f'{ns}/stiffness_node', 'screw')
        for step in (np.zeros(6), np.array([0.05, -0.02, 0.03, 1e-3, 0.0, -5e-4])):
            xi = model.initial_screw + step
            expected = dynamics.modes_at_pose(xi)[0].frequencies
            frequencies.clear()
            msg = repeat_until(
                lambda xi=xi: screw.publish(Float64MultiArray(data=xi.tolist())),
                lambda expected=expected: next((m for m in frequencies.messages if np.allclose(
                    m.data, expected, rtol=1e-12, atol=0.0)), None))
            modes = dynamics.modes_at_pose(xi)[0]
            assert msg.layout.dim[0].label == natural_frequencies_label(
                modes.stable, np.flatnonzero(modes.overdamped).tolist())
            assert msg.layout.dim[0].label.startswith(NATURAL_FREQUENCIES_LABEL)
            assert msg.layout.dim[0].size == 6
            assert np.all(np.diff(msg.data) >= 0.0)
    finally:
        ros.close()
        code = proc.stop()
    assert code == 0, proc.log()


def test_dynamics_are_built_only_when_enabled() -> None:
    """The node creates ``~/natural_frequencies`` only for settings with dynamics."""
    from tensegrity_stiffness.nodes.stiffness_node import (
        STIFFNESS_NODE_PARAMETERS,
        joint_node_settings,
    )

    values = {spec.name: spec.default for spec in STIFFNESS_NODE_PARAMETERS}
    assert joint_node_settings(values).dynamics is None
    values.update({'dynamics.enabled': True, 'joint.link2_inertia': [1e-6, 2e-6, 3e-6]})
    dynamics = joint_node_settings(values).dynamics
    assert isinstance(dynamics, JointDynamics)
    np.testing.assert_allclose(np.diag(dynamics.inertia.inertia_matrix(
        dynamics.model.link2_nodes)), [1e-6, 2e-6, 3e-6])
    values['joint.link2_mass'] = -1.0
    with pytest.raises(ValueError, match='link2_mass'):
        joint_node_settings(values)


@pytest.mark.ros
def test_spine_natural_frequencies_at_an_equilibrium_and_none_off_it() -> None:
    from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
    from tensegrity_stiffness.mechanics.dynamics import ChainDynamics

    spine_config = REPO / 'config' / 'default_spine.yaml'
    chain = JointChain.from_yaml(spine_config)
    tip = np.array([0.02, 0.0, 0.0, 0.0, 0.0, 0.0])
    solved = solve_chain_equilibrium(chain, tip)
    assert solved.success
    expected = ChainDynamics(chain, string_damping=0.2).modes(solved.screws,
                                                              tip_wrench=tip).frequencies
    ns = unique_namespace('spinedyn')
    proc = NodeProcess(ns, spine_config, executable='spine_node', extra_args=[
        '-p', 'dynamics.enabled:=true', '-p', 'dynamics.string_damping:=0.2'])
    ros = RosClient('spine_dynamics_test')
    try:
        frequencies, screws = frequencies_and_input(ros, f'{ns}/spine_node', 'screws')
        msg = repeat_until(
            lambda: screws.publish(Float64MultiArray(data=solved.screws.ravel().tolist())),
            lambda: frequencies.messages[-1] if len(frequencies) else None)
        np.testing.assert_allclose(msg.data, expected, rtol=1e-9)
        assert len(msg.data) == 6 * chain.n_joints
        # Off equilibrium: no frequencies. The node answers its inputs in order on each
        # topic, so once the equilibrium sent after `off` is answered, an answer to `off` would
        # have come before it, and every message since the clear is the equilibrium's.
        frequencies.clear()
        screws.publish(Float64MultiArray(data=(solved.screws + 0.01).ravel().tolist()))
        repeat_until(
            lambda: screws.publish(Float64MultiArray(data=solved.screws.ravel().tolist())),
            lambda: True if len(frequencies) else None)
        for got in list(frequencies.messages):
            np.testing.assert_allclose(got.data, expected, rtol=1e-9)
    finally:
        ros.close()
        code = proc.stop()
    assert code == 0, proc.log()
