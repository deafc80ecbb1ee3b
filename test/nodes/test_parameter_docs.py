"""docs/parameters.md is generated from the parameter tables
(tensegrity_stiffness.nodes.parameters):
the committed page is exactly what ``python -m tensegrity_stiffness.nodes.parameter_docs --write``
writes, every registered node and parameter is on it, and ``--check`` tells a stale page."""

from __future__ import annotations

import os
import subprocess
import sys

from support import REPO

from tensegrity_stiffness.nodes import parameter_docs, parameters
from tensegrity_stiffness.nodes.parameter_specs import NodeTable, ParameterSpec

REPO = REPO
PAGE = REPO / 'docs' / 'parameters.md'


def test_committed_page_is_the_generated_one():
    problem = parameter_docs.check(PAGE)
    assert not problem, (f'{problem}\ndocs/parameters.md is stale: run '
                         f'{parameter_docs.COMMAND} from the repository root')


def test_every_registered_table_and_parameter_is_on_the_page():
    page = PAGE.read_text(encoding='utf-8')
    tables = parameters.node_tables()
    nodes = [t.node for t in tables]
    assert {'stiffness_node', 'spine_node'} <= set(nodes)
    assert len(nodes) == len(set(nodes)), 'a node is registered twice'
    for table in tables:
        assert f'## `{table.node}`' in page, table.node
        if table.config:
            assert (REPO / table.config).is_file(), table.config
        section = page.split(f'## `{table.node}`', 1)[1].split('\n## ', 1)[0]
        for spec in table.parameters:
            shown = parameter_docs._NUMBERED.sub(r'\g<prefix>_<i>.\g<key>', spec.name)
            assert f'| `{shown}` |' in section, (table.node, spec.name)


def test_the_node_tables_are_the_nodes_tables():
    """The registry lists the very tables the nodes declare (one home for each fact)."""
    by_node = {t.node: t.parameters for t in parameters.node_tables()}
    assert by_node['stiffness_node'] == parameters.STIFFNESS_NODE_PARAMETERS
    assert by_node['spine_node'] == parameters.spine_node_parameters()


def test_numbered_copies_collapse_to_one_row_and_nothing_else_does():
    specs = parameters.spine_node_parameters(3)
    rows = parameter_docs.collapsed_rows(specs)
    names = [name for name, _, _ in rows]
    assert len(names) == len(set(names))
    overrides = [n for n in names if n.startswith('joint_<i>.')]
    assert len(overrides) == len(parameters.JOINT_PARAMETERS)
    assert len(rows) == len(specs) - 2 * len(parameters.JOINT_PARAMETERS)
    description = dict((n, d) for n, _, d in rows)['joint_<i>.rest_lengths']
    assert description.startswith('joint <i>: overrides joint.rest_lengths')


def test_a_new_table_renders_with_its_defaults_ranges_and_choices():
    table = NodeTable('example_node', (
        ParameterSpec('a.rate', 'double', 0.5, 'a rate | with a pipe, Hz', range=(0.0, 2.0)),
        ParameterSpec('a.mode', 'string', 'fast', 'mode', read_only=True,
                      choices=('fast', 'slow')),
        ParameterSpec('a.gains', 'double_array', [1.0] * 6, 'gains'),
    ), 'config/example.yaml', 'an example')
    text = parameter_docs.render([table])
    assert '## `example_node`' in text and 'An example.' in text
    assert '| `a.rate` | double | `0.5` | [0, 2] | a rate \\| with a pipe, Hz |' in text
    assert "| `a.mode` | string | `'fast'` | read-only; `fast` \\| `slow` | mode |" in text
    assert '| `a.gains` | double[] | 6 x `1` |  | gains |' in text


def test_command_writes_and_checks(tmp_path, capsys):
    out = tmp_path / 'parameters.md'
    assert parameter_docs.main(['--check', '--out', str(out)]) == 1
    assert 'missing' in capsys.readouterr().err
    assert parameter_docs.main(['--write', '--out', str(out)]) == 0
    assert out.read_text(encoding='utf-8') == parameter_docs.render()
    assert parameter_docs.main(['--check', '--out', str(out)]) == 0
    row = '| `qos.depth` | int | `100`'
    out.write_text(out.read_text(encoding='utf-8').replace(row, row.replace('100', '101'), 1),
                   encoding='utf-8')
    assert parameter_docs.main(['--check', '--out', str(out)]) == 1
    err = capsys.readouterr().err
    assert '+' + row in err and 'is stale' in err
    assert parameter_docs.main(['--write', '--out', str(tmp_path / 'no' / 'p.md')]) == 2


def test_module_command_checks_the_committed_page():
    """``python -m tensegrity_stiffness.nodes.parameter_docs --check`` from the repository root,
    as a
    user (or CI) runs it."""
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(filter(None, [str(REPO), env.get('PYTHONPATH', '')]))
    done = subprocess.run([sys.executable, '-m', 'tensegrity_stiffness.nodes.parameter_docs',
                           '--check'],
                          cwd=REPO, env=env, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert 'up to date' in done.stdout
