"""The frames the nodes broadcast on /tf (tensegrity_stiffness.nodes.frames), without ROS: the
library's poses under the documented parent and child names."""

from __future__ import annotations

import numpy as np
from support import REPO

from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import frames, parameters


def test_joint_frame_is_link1_to_link2_at_the_screw() -> None:
    model = JointModel.from_yaml(REPO / 'config' / 'default_joint.yaml')
    state = model.evaluate(model.initial_screw)
    (frame,) = frames.joint_frame_transforms('tensegrity_link1', 'tensegrity_link2',
                                             state.transform)
    assert (frame.parent, frame.child) == ('tensegrity_link1', 'tensegrity_link2')
    np.testing.assert_array_equal(frame.transform, state.transform)


def test_spine_frames_compose_to_the_tip_pose() -> None:
    chain = JointChain.from_yaml(REPO / 'config' / 'default_spine.yaml')
    state = chain.evaluate(chain.unloaded_screws())
    links = frames.spine_frame_transforms('spine_base', state.link_transforms)
    assert [(f.parent, f.child) for f in links] == [
        ('spine_base', f'spine_base_link_{i}') for i in range(1, chain.n_joints + 1)]
    tool = frames.spine_tool_transform('spine_base', chain.n_joints, 'spine_tool', chain.tool)
    assert (tool.parent, tool.child) == ('spine_base_link_5', 'spine_tool')
    np.testing.assert_allclose(links[-1].transform @ tool.transform, state.tip_transform,
                               rtol=0.0, atol=1e-15)


def test_the_twins_imu_frame_is_the_last_link_frame() -> None:
    values = parameters.defaults(parameters.sim_node_parameters(spine=True, n_joints=3))
    settings = parameters.sim_node_settings({**values, 'sim.spine': True, 'chain.n_joints': 3})
    assert settings.imu_frame == frames.spine_link_frame('spine_base', 3) == 'spine_base_link_3'
