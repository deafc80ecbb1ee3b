"""The viewers' configurations (docs/viewers.md) parse, name only topics of the node they are for
(its outputs of ``nodes/layouts.py``, its markers and eigenvalues) and only frames that node
broadcasts (``nodes/frames.py`` with the default parameters), and are installed under
``share/tensegrity_stiffness/``. ``test/ros/test_viewers.py`` holds the topics to a running
node's publications and checks the plotted eigenvalues."""

from __future__ import annotations

from pathlib import Path

import pytest
from support.viewer_configs import FOXGLOVE, RVIZ, viewer_configs

from tensegrity_stiffness.nodes import frames, parameters
from tensegrity_stiffness.nodes.layouts import JOINT_OUTPUTS, SPINE_OUTPUTS
from tensegrity_stiffness.nodes.structure_node import STRUCTURE_OUTPUTS

#: The frames each node broadcasts with its default parameters (docs/nodes.md, TF).
SPINE_JOINTS = parameters.by_name(parameters.CHAIN_PARAMETERS)['chain.n_joints'].default
BROADCAST = {
    'stiffness_node': {'tensegrity_link1', 'tensegrity_link2'},
    'spine_node': {'spine_base', 'spine_tool', *(frames.spine_link_frame('spine_base', i)
                                                 for i in range(1, SPINE_JOINTS + 1))},
    'structure_node': {'world', 'x1', 'x2', 'y1', 'y2', 'z1', 'z2'},  # the packaged 6-bar
}
#: Every topic the node classes publish under ~/ (the per-input outputs, markers, eigenvalues).
PUBLISHED = {
    'stiffness_node': {*JOINT_OUTPUTS, 'markers', 'stiffness_eigenvalues', 'natural_frequencies'},
    'spine_node': {*SPINE_OUTPUTS, 'markers', 'tip_stiffness_eigenvalues', 'natural_frequencies'},
    'structure_node': {*STRUCTURE_OUTPUTS, 'markers'},
}


def test_there_is_a_configuration_of_each_kind() -> None:
    assert [p.name for p in RVIZ] == ['tensegrity.rviz', 'tensegrity_spine.rviz',
                                      'tensegrity_structure.rviz']
    assert [p.name for p in FOXGLOVE] == ['tensegrity_layout.json',
                                          'tensegrity_spine_layout.json',
                                          'tensegrity_structure_layout.json']


@pytest.mark.parametrize('config', viewer_configs(), ids=lambda c: c.path.name)
def test_topics_and_frames_are_the_nodes(config) -> None:
    names = {topic.rsplit('/', 1)[1] for topic in config.topics}
    assert names <= PUBLISHED[config.node], names - PUBLISHED[config.node]
    assert any(t.endswith('/markers') for t in config.topics)
    assert config.frames and config.frames <= BROADCAST[config.node], config.frames
    if config.path.suffix == '.json':  # the plots of the principal stiffnesses (a structure's:
        # of the tensions and bar forces)
        plotted = 'string_tensions' if config.node == 'structure_node' else 'stiffness_eigenvalues'
        assert any(t.endswith(plotted) for t in config.topics)


def test_installed_under_share() -> None:
    ament = pytest.importorskip('ament_index_python.packages')
    try:
        share = ament.get_package_share_directory('tensegrity_stiffness')
    except ament.PackageNotFoundError:
        pytest.skip('tensegrity_stiffness is not installed (scripts/setup_env.sh)')
    for path in [*RVIZ, *FOXGLOVE]:
        installed = Path(share) / path.parent.name / path.name
        assert installed.is_file() and installed.read_text() == path.read_text(), installed
