"""What the viewers' configurations (``rviz/*.rviz``, ``foxglove/*.json``; docs/viewers.md) name:
their topics and frames, read from the files (YAML and JSON), for the tests that hold them to the
nodes' publications and frames."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from support import REPO

RVIZ = sorted((REPO / 'rviz').glob('*.rviz'))
FOXGLOVE = sorted((REPO / 'foxglove').glob('*.json'))
#: The namespace the configurations are written for (the twin demo's, scripts/run_twin.sh).
NAMESPACE = '/twin'


@dataclass(frozen=True)
class ViewerConfig:
    """One configuration: its ``path``, the ``node`` its topics are of (``stiffness_node`` or
    ``spine_node``), the ``topics`` and ``frames`` it names."""

    path: Path
    node: str
    topics: frozenset[str]
    frames: frozenset[str]


def _node_of(topics: set[str]) -> str:
    nodes = {t.split('/')[2] for t in topics}
    assert len(nodes) == 1 and all(t.startswith(NAMESPACE + '/') for t in topics), topics
    return nodes.pop()


def read_rviz(path: Path) -> ViewerConfig:
    """Topics of the displays, and the fixed frame (a display's own frames must be
    ``<Fixed Frame>``)."""
    document = yaml.safe_load(path.read_text())
    manager = document['Visualization Manager']
    topics = {display['Topic']['Value'] for display in manager['Displays'] if 'Topic' in display}
    frames = {manager['Global Options']['Fixed Frame']}
    for display in manager['Displays']:
        if 'Reference Frame' in display:
            assert display['Reference Frame'] == '<Fixed Frame>', display
    return ViewerConfig(path, _node_of(topics), frozenset(topics), frozenset(frames))


def _plot_topic(path: str) -> str:
    topic, _, field = path.partition('.')
    assert field, f'{path}: no message field'
    return topic


def read_foxglove(path: Path) -> ViewerConfig:
    """Topics of the 3D panels and of the plots' series; the frames the 3D panels follow."""
    document: dict[str, Any] = json.loads(path.read_text())
    topics: set[str] = set()
    frames: set[str] = set()
    for panel_id, panel in document['configById'].items():
        kind = panel_id.split('!')[0]
        if kind == '3D':
            topics |= set(panel['topics'])
            frames.add(panel['followTf'])
        elif kind == 'Plot':
            topics |= {_plot_topic(series['value']) for series in panel['paths']}
        else:
            raise AssertionError(f'{path}: a panel of kind {kind} is not checked')
    return ViewerConfig(path, _node_of(topics), frozenset(topics), frozenset(frames))


def viewer_configs() -> list[ViewerConfig]:
    return [read_rviz(p) for p in RVIZ] + [read_foxglove(p) for p in FOXGLOVE]
