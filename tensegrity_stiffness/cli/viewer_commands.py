"""The command ``viewers``: the package's RViz configuration and Foxglove layout (``rviz/``,
``foxglove/``; docs/viewers.md) written for a joint or spine config and a namespace: every topic
under the namespace the nodes run in, the fixed frame the config's, the grid in the plane across
the joint's own axis (+y for the vertebra, +z for a ring: the axis along which link 2 stands
off link 1 at the unloaded equilibrium,
:func:`~tensegrity_stiffness.cli.dynamics_plots.vertical_axis`) and the view centred on link 2. The
packaged files are the default joint's in the twin demo's namespace ``/twin``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.cli.common import EXIT_OK, PROG
from tensegrity_stiffness.cli.dynamics_plots import vertical_axis
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel

#: The namespace the packaged files are written for (scripts/run_twin.sh, twin.launch.py).
PACKAGED_NAMESPACE = '/twin'
#: The packaged files of each kind (share/tensegrity_stiffness/...), joint and spine.
PACKAGED = {False: ('rviz/tensegrity.rviz', 'foxglove/tensegrity_layout.json'),
            True: ('rviz/tensegrity_spine.rviz', 'foxglove/tensegrity_spine_layout.json')}
#: RViz's grid plane across each axis, and Foxglove's grid rotation (degrees) that lays its
#: default XY grid across it.
GRID_PLANES = {'x': 'YZ', 'y': 'XZ', 'z': 'XY'}
GRID_ROTATIONS = {'x': [0, 90, 0], 'y': [90, 0, 0], 'z': [0, 0, 0]}


def _namespace(text: str) -> str:
    """``/a/b`` from ``a/b``, ``/a/b/`` or ``/a/b``; '' for the root; ValueError for a name ROS
    refuses."""
    parts = [p for p in text.strip().split('/') if p]
    for part in parts:
        if not (part[0].isalpha() or part[0] == '_') or not all(
                c.isalnum() or c == '_' for c in part):
            raise ValueError(f"--namespace: '{text}' is not a ROS namespace (letters, digits and "
                             "'_' between '/', each part starting with a letter or '_')")
    return ''.join(f'/{p}' for p in parts)


def _retopic(topic: str, namespace: str) -> str:
    if not topic.startswith(PACKAGED_NAMESPACE + '/'):
        raise ValueError(f'packaged viewer topic {topic} is not under {PACKAGED_NAMESPACE}')
    return namespace + topic[len(PACKAGED_NAMESPACE):]


def _layout(document: Any, spine: bool) -> tuple[str, str, np.ndarray]:
    """(fixed frame, up axis, the point to look at in that frame) of a config document."""
    frames = config.section(document, 'frames', required=False)
    if spine:
        chain = JointChain.from_dict(document)
        tip = chain.tip_transform(chain.unloaded_screws())[:3, 3]
        return (str(frames.get('base') or chain.base_frame), vertical_axis(np.zeros(3), tip),
                0.5 * tip)
    model = JointModel.from_dict(config.section(document, 'joint'))
    link2 = model.link2_nodes_in_link1(exp_se3(model.initial_screw))
    up = vertical_axis(model.link1_nodes, link2)
    return (str(frames.get('link1') or 'tensegrity_link1'), up,
            0.5 * (model.link1_nodes.mean(axis=0) + link2.mean(axis=0)))


def rviz_text(packaged: str, namespace: str, frame: str, up: str, focus: np.ndarray,
              source: str = '') -> str:
    """The packaged RViz configuration (YAML text) for ``namespace``, ``frame``, ``up``
    (``source``: the config it was written for, named in its header)."""
    import yaml

    header = ''.join(line for line in packaged.splitlines(True)[:2] if line.startswith('#'))
    header += (f'# Written by {PROG} viewers for {source or "the packaged config"}, namespace '
               f'{namespace or "/"} (docs/viewers.md).\n')
    document = yaml.safe_load(packaged)
    manager = document['Visualization Manager']
    manager['Global Options']['Fixed Frame'] = frame
    for display in manager['Displays']:
        if 'Topic' in display:
            display['Topic']['Value'] = _retopic(display['Topic']['Value'], namespace)
        if display.get('Class') == 'rviz_default_plugins/Grid':
            display['Plane'] = GRID_PLANES[up]
    manager['Views']['Current']['Focal Point'] = dict(zip('XYZ', map(float, focus),
                                                          strict=True))
    return header + yaml.safe_dump(document, sort_keys=False, width=99)


def foxglove_text(packaged: str, namespace: str, frame: str, up: str) -> str:
    """The packaged Foxglove layout (JSON text) for ``namespace``, ``frame``, ``up``."""
    document = json.loads(packaged)
    for panel_id, panel in document['configById'].items():
        if panel_id.startswith('3D!'):
            panel['followTf'] = frame
            panel['topics'] = {_retopic(t, namespace): v for t, v in panel['topics'].items()}
            if 'grid' in panel.get('layers', {}):
                panel['layers']['grid']['rotation'] = GRID_ROTATIONS[up]
        elif panel_id.startswith('Plot!'):
            for series in panel['paths']:
                topic, _, field = series['value'].partition('.')
                series['value'] = f'{_retopic(topic, namespace)}.{field}'
    return json.dumps(document, indent=2) + '\n'


def write_viewers(config_path: str | Path | None, namespace: str, out: str | Path,
                  spine: bool = False) -> list[Path]:
    """The RViz configuration and the Foxglove layout of ``config_path`` (default: the packaged
    joint or spine) in ``namespace``, written into the folder ``out``; their paths."""
    ns = _namespace(namespace)
    folder = Path(out)
    if not folder.is_dir():
        raise ValueError(f'--out: {folder} is not a folder')
    default = 'default_spine.yaml' if spine else config.DEFAULT_JOINT_CONFIG
    document = config.load_yaml(Path(config_path) if config_path
                                else config.packaged_config_path(default))
    frame, up, focus = _layout(document, spine)
    rviz, foxglove = (config.packaged_path(name) for name in PACKAGED[spine])
    written = [folder / rviz.name, folder / foxglove.name]
    written[0].write_text(rviz_text(rviz.read_text(), ns, frame, up, focus,
                                    str(config_path or '')), encoding='utf-8')
    written[1].write_text(foxglove_text(foxglove.read_text(), ns, frame, up), encoding='utf-8')
    return written


def _cmd_viewers(args: argparse.Namespace) -> int:
    for path in write_viewers(args.config, args.namespace, args.out, args.spine):
        print(f'{PROG}: wrote {path}', file=sys.stderr)
    return EXIT_OK


def add_viewers_parser(sub: Any) -> None:
    """``viewers``."""
    p = sub.add_parser('viewers', help='the RViz configuration and Foxglove layout of a config '
                                       'in a namespace',
                       description='Write the package\'s RViz configuration and Foxglove '
                                   'layout for a joint (or, --spine, spine) config and the '
                                   'namespace its nodes run in: the topics under the '
                                   'namespace, the fixed frame the config\'s, the grid across '
                                   'the joint\'s own axis. docs/viewers.md.')
    p.add_argument('--config', metavar='YAML', help='config file (default: the packaged '
                                                    'default_joint.yaml, or default_spine.yaml '
                                                    'with --spine)')
    p.add_argument('--spine', action='store_true', help='the spine (spine_node) layouts')
    p.add_argument('--namespace', default=PACKAGED_NAMESPACE, metavar='NS',
                   help=f'the nodes\' namespace (default {PACKAGED_NAMESPACE}, the twin demo\'s; '
                        "'/' for none)")
    p.add_argument('--out', required=True, metavar='DIR', help='folder to write both files into')
    p.set_defaults(handler=_cmd_viewers)
