"""``docs/parameters.md`` generated from the parameter tables (one home for each fact).

Every node's table is registered once, in
:func:`tensegrity_stiffness.nodes.registry.node_tables`;
this module renders them all as Markdown. From the repository root::

    python -m tensegrity_stiffness.nodes.parameter_docs --write   # (re)write docs/parameters.md
    python -m tensegrity_stiffness.nodes.parameter_docs --check   # exit 1 when the page is stale
    python -m tensegrity_stiffness.nodes.parameter_docs           # print the page

``test/nodes/test_parameter_docs.py`` fails when the committed page differs from what ``--write``
writes. Per-joint override rows of a spine (``joint_1.rest_lengths`` ... ``joint_5.rest_lengths``)
are shown once as ``joint_<i>.rest_lengths``. No ROS import.
"""

from __future__ import annotations

import argparse
import difflib
import itertools
import math
import re
import sys
from collections.abc import Iterable, Sequence
from pathlib import Path

from tensegrity_stiffness.nodes.parameter_specs import STRICT_PARAMETERS, NodeTable, ParameterSpec
from tensegrity_stiffness.nodes.registry import node_tables

#: Where ``--write`` and ``--check`` look by default (relative to the working directory: run
#: the command from the repository root).
DEFAULT_PAGE = Path('docs') / 'parameters.md'
#: The command that regenerates the page (printed in it and in the ``--check`` message).
COMMAND = 'python -m tensegrity_stiffness.nodes.parameter_docs --write'

_TYPE_NAMES = {'bool': 'bool', 'int': 'int', 'double': 'double', 'string': 'string',
               'double_array': 'double[]', 'string_array': 'string[]'}
#: ``<prefix>_<number>.<key>``: a numbered copy of a parameter (a spine's per-joint override).
_NUMBERED = re.compile(r'^(?P<prefix>[A-Za-z]+)_(?P<index>\d+)\.(?P<key>.+)$')
#: Longest array default written out in full; longer ones are summarised.
_MAX_LISTED = 12


def _number(value: float | int) -> str:
    """A number as the page writes it: ints plainly, multiples of pi as such, else the shortest
    text that reads back as the same float."""
    if isinstance(value, int):
        return str(value)
    for factor, text in ((1.0, 'pi'), (-1.0, '-pi'), (2.0, '2 pi'), (-2.0, '-2 pi'),
                         (0.5, 'pi/2'), (-0.5, '-pi/2')):
        if value == factor * math.pi:
            return text
    short = format(value, 'g')
    return short if float(short) == value else repr(value)


def _default(spec: ParameterSpec) -> str:
    value = spec.check(spec.default)
    if isinstance(value, bool):
        return f'`{str(value).lower()}`'
    if isinstance(value, (int, float)):
        return f'`{_number(value)}`'
    if isinstance(value, str):
        return f"`'{value}'`" if value else 'empty'
    if not value:
        return 'empty'
    if spec.type == 'string_array':
        return '`[' + ', '.join(value) + ']`'
    runs = [(v, len(list(group))) for v, group in itertools.groupby(value)]
    if len(runs) <= len(value) // 3:  # runs of equal values: 4 x 0.0381, 8 x 0.03175
        return ', '.join(f'{n} x `{_number(v)}`' if n > 1 else f'`{_number(v)}`'
                         for v, n in runs)
    if len(value) > _MAX_LISTED:
        return f'{len(value)} values'
    return '`[' + ', '.join(_number(v) for v in value) + ']`'


def _constraints(spec: ParameterSpec) -> str:
    parts = []
    if spec.read_only:
        parts.append('read-only')
    if spec.range is not None:
        parts.append(f'[{_number(spec.range[0])}, {_number(spec.range[1])}]')
    if spec.choices:
        parts.append(' \\| '.join(f'`{c}`' if c else 'empty' for c in spec.choices))
    return '; '.join(parts)


def _cell(text: str) -> str:
    """Table-cell text: no line breaks; pipes and angle brackets escaped (``<i>`` would be
    HTML)."""
    text = ' '.join(text.split()).replace('|', '\\|')
    return text.replace('<', '&lt;').replace('>', '&gt;')


def collapsed_rows(specs: Iterable[ParameterSpec]) -> list[tuple[str, ParameterSpec, str]]:
    """``(shown name, spec, description)`` per row, numbered copies shown once: the rows
    ``joint_1.key`` ... ``joint_N.key`` that differ only in their number become one row
    ``joint_<i>.key`` (the description's number as ``<i>``), at the place of the first."""
    rows: list[tuple[str, ParameterSpec, str]] = []
    seen: set[tuple[str, ...]] = set()
    for spec in specs:
        match = _NUMBERED.match(spec.name)
        if match is None:
            rows.append((spec.name, spec, spec.description))
            continue
        index = match['index']
        name = f"{match['prefix']}_<i>.{match['key']}"
        description = re.sub(rf'\b{index}\b', '<i>', spec.description)
        key = (name, spec.type, repr(spec.default), repr(spec.range), repr(spec.choices),
               str(spec.read_only), description)
        if key in seen:
            continue
        seen.add(key)
        rows.append((name, spec, description))
    return rows


def render_table(table: NodeTable) -> str:
    """One node's section: heading, summary, source and the Markdown table."""
    lines = [f'## `{table.node}`', '']
    if table.summary:
        lines += [table.summary[0].upper() + table.summary[1:] + '.', '']
    if table.config:
        lines += [f'Defaults as in `{table.config}`.', '']
    lines += ['| parameter | type | default | constraints | description |',
              '| --- | --- | --- | --- | --- |']
    for name, spec, description in collapsed_rows(table.parameters):
        lines.append(f'| `{name}` | {_TYPE_NAMES[spec.type]} | {_default(spec)} | '
                     f'{_constraints(spec)} | {_cell(description)} |')
    return '\n'.join(lines) + '\n'


def render(tables: Sequence[NodeTable] | None = None) -> str:
    """The whole page for ``tables`` (default: every registered table)."""
    tables = node_tables() if tables is None else tables
    head = [
        '# Node parameters',
        '',
        '<!-- Generated from the node tables of tensegrity_stiffness/nodes/: do not edit by '
        'hand. -->',
        f'Generated by `{COMMAND}` from the tables of the node modules '
        '`tensegrity_stiffness/nodes/<node>.py` (registered in `registry.node_tables()`); '
        '`test/nodes/test_parameter_docs.py` fails when this page differs from them. What the '
        'parameters do, how run-time changes are validated and applied: [nodes.md](nodes.md).',
        '',
        'Types are ROS parameter types. Constraints: `read-only` parameters are fixed once the '
        'node runs; `[a, b]` is an inclusive range; choices are separated by `|`. An array '
        'default `empty` means the optional array is left out. `joint_<i>.*` rows stand for '
        'every joint i = 1..`chain.n_joints`.',
        '',
        f'Every node also declares `{STRICT_PARAMETERS.name}` ({STRICT_PARAMETERS.type}, '
        f'default `{_default(STRICT_PARAMETERS)}`, read-only): {STRICT_PARAMETERS.description}.',
        '',
        'Nodes: ' + ', '.join(f'[`{t.node}`](#{t.node})' for t in tables) + '.',
        '',
    ]
    return '\n'.join(head) + '\n' + '\n'.join(render_table(t) for t in tables)


#: The flags that make a node executable print its usage instead of starting (before
#: ``--ros-args``; after it, the arguments are ROS's).
HELP_FLAGS = ('-h', '--help')


def asks_for_help(argv: Sequence[str]) -> bool:
    """Whether a node's command line ``argv`` (``sys.argv``: the program first) holds ``-h`` or
    ``--help`` before ``--ros-args``."""
    arguments = list(argv[1:])
    if '--ros-args' in arguments:
        arguments = arguments[:arguments.index('--ros-args')]
    return any(flag in arguments for flag in HELP_FLAGS)


def node_usage(node: str) -> str:
    """The ``--help`` text of the node executable ``node`` (a name of
    :func:`~tensegrity_stiffness.nodes.registry.node_tables`): what it is, how to start it
    with ROS arguments, and where its parameters, topics and services are documented."""
    from tensegrity_stiffness.config import packaged_config_path

    table = next((t for t in node_tables() if t.node == node), None)
    if table is None:
        raise ValueError(f'node {node!r} has no parameter table (known: '
                         f'{", ".join(t.node for t in node_tables())})')
    params = ''
    if table.config:
        config = Path(table.config).name
        params = f' --params-file {packaged_config_path(config)}'
    summary = table.summary[0].upper() + table.summary[1:] + '.' if table.summary else ''
    lines = [
        f'usage: {node} [-h] [--ros-args [--params-file FILE] [-p NAME:=VALUE ...] '
        "[-r '~/TOPIC:=/OTHER' ...] [-r __ns:=/NAMESPACE]]",
        '',
        f'{node}, a ROS 2 node of the tensegrity_stiffness package. {summary}',
        '',
        'Start it (ros2 run finds the same executable):',
        f'  ros2 run tensegrity_stiffness {node} --ros-args{params}',
        '  Quote a remap of a private name (~/...) so that the shell leaves the ~ alone.',
        '',
        'options:',
        '  -h, --help  print this text and exit, without starting the node',
        '',
        f'Parameters (names, types, defaults, ranges): docs/parameters.md#{node} of the '
        f'tensegrity_stiffness repository'
        + (f'; defaults as in config/{Path(table.config).name}' if table.config else '') + '.',
        f'Topics, services and QoS: {table.page or "docs/nodes.md"}.',
    ]
    return '\n'.join(lines) + '\n'


def check(path: Path, text: str | None = None) -> str:
    """An empty string when ``path`` holds the generated page, else what differs (a short
    unified diff, or that the file is missing)."""
    text = render() if text is None else text
    if not path.is_file():
        return f'{path} is missing'
    committed = path.read_text(encoding='utf-8')
    if committed == text:
        return ''
    diff = difflib.unified_diff(committed.splitlines(), text.splitlines(),
                                f'{path} (committed)', f'{path} (generated)', lineterm='', n=1)
    return '\n'.join(list(diff)[:40])


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog='python -m tensegrity_stiffness.nodes.parameter_docs',
        description='Generate docs/parameters.md from tensegrity_stiffness/parameters.py.')
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument('--write', action='store_true', help='write the page')
    mode.add_argument('--check', action='store_true',
                      help='exit 1 when the page differs from the generated one')
    parser.add_argument('--out', type=Path, default=DEFAULT_PAGE,
                        help=f'the page (default: {DEFAULT_PAGE}, from the repository root)')
    options = parser.parse_args(argv)
    text = render()
    if options.write:
        if not options.out.parent.is_dir():
            print(f'{options.out.parent}/ does not exist: run from the repository root or give '
                  '--out', file=sys.stderr)
            return 2
        options.out.write_text(text, encoding='utf-8')
        print(f'wrote {options.out}')
        return 0
    if options.check:
        problem = check(options.out, text)
        if problem:
            print(f'{problem}\n{options.out} is stale: run {COMMAND}', file=sys.stderr)
            return 1
        print(f'{options.out} is up to date')
        return 0
    sys.stdout.write(text)
    return 0


if __name__ == '__main__':
    sys.exit(main())
