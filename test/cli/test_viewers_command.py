"""``tensegrity-stiffness viewers`` (issue #39, TF in every setup: the layouts follow the
namespace and the joint's axis): the packaged RViz configuration and Foxglove layout written for
a config and a namespace name the same topics under that namespace, the config's fixed frame and
a grid across the joint's own axis (+y for the vertebra, +z for a ring)."""

from __future__ import annotations

import json

import pytest
import yaml

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.parser import main
from tensegrity_stiffness.cli.viewer_commands import PACKAGED, PACKAGED_NAMESPACE


def topics(rviz: dict, foxglove: dict) -> set[str]:
    out = {d['Topic']['Value'] for d in rviz['Visualization Manager']['Displays']
           if 'Topic' in d}
    for panel_id, panel in foxglove['configById'].items():
        if panel_id.startswith('3D!'):
            out |= set(panel['topics'])
        else:
            out |= {series['value'].partition('.')[0] for series in panel['paths']}
    return out


def read(folder, spine: bool = False) -> tuple[dict, dict]:
    rviz, foxglove = (folder / name.split('/')[1] for name in PACKAGED[spine])
    return yaml.safe_load(rviz.read_text()), json.loads(foxglove.read_text())


def packaged(spine: bool = False) -> tuple[dict, dict]:
    rviz, foxglove = (config.packaged_path(name) for name in PACKAGED[spine])
    return yaml.safe_load(rviz.read_text()), json.loads(foxglove.read_text())


@pytest.mark.parametrize(('template', 'plane', 'rotation'), [('vertebra', 'XZ', [90, 0, 0]),
                                                             ('ring', 'XY', [0, 0, 0])])
def test_the_layouts_follow_the_namespace_frame_and_axis(tmp_path, capsys, template, plane,
                                                        rotation):
    path = tmp_path / 'joint.yaml'
    assert main(['new-config', '--template', template, '--out', str(path)]) == 0
    document = config.load_yaml(path)
    config.parameters(document)['frames'] = {'link1': 'lab_base', 'link2': 'lab_top'}
    path.write_text(yaml.safe_dump(document))
    assert main(['viewers', '--config', str(path), '--namespace', 'lab/joint_1',
                 '--out', str(tmp_path)]) == 0
    rviz, foxglove = read(tmp_path)
    old = {t[len(PACKAGED_NAMESPACE):] for t in topics(*packaged())}
    assert topics(rviz, foxglove) == {f'/lab/joint_1{t}' for t in old}
    assert rviz['Visualization Manager']['Global Options']['Fixed Frame'] == 'lab_base'
    grid = next(d for d in rviz['Visualization Manager']['Displays']
                if d['Class'] == 'rviz_default_plugins/Grid')
    assert grid['Plane'] == plane
    panel = foxglove['configById']['3D!tensegrity']
    assert panel['followTf'] == 'lab_base' and panel['layers']['grid']['rotation'] == rotation
    assert 'namespace /lab/joint_1' in (tmp_path / 'tensegrity.rviz').read_text()


def test_the_spine_and_the_root_namespace(tmp_path):
    assert main(['viewers', '--spine', '--namespace', '/', '--out', str(tmp_path)]) == 0
    rviz, foxglove = read(tmp_path, spine=True)
    assert all(t.startswith('/spine_node/') for t in topics(rviz, foxglove))


@pytest.mark.parametrize('namespace', ['1lab', 'lab-joint', 'a//b c'])
def test_a_bad_namespace_is_refused(tmp_path, capsys, namespace):
    assert main(['viewers', '--namespace', namespace, '--out', str(tmp_path)]) == 2
    assert 'is not a ROS namespace' in capsys.readouterr()[1]
