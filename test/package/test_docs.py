"""The documentation holds together: README.md is a short front page, every relative link of
README.md and docs/*.md names a file (and heading) of the repository, and no file of the
project points to a path outside the repository."""

from __future__ import annotations

import re
from pathlib import Path

import pytest
from support import REPO

REPO = REPO
PAGES = [REPO / 'README.md', *sorted((REPO / 'docs').glob('*.md'))]
#: Front page length the docs promise (the rest lives in docs/).
MAX_README_LINES = 250
#: Folders that are not the project's files (environment, build products, VCS).
SKIPPED_DIRS = {'.git', '.venv', 'build', 'install', 'log', '__pycache__', '.pytest_cache',
                '.ruff_cache', 'figures'}
TEXT_SUFFIXES = {'.py', '.md', '.sh', '.txt', '.yaml', '.yml', '.xml', '.cfg', '.toml', '.cpp',
                 '.hpp', '.h', '.srv', '.msg', '.in', ''}
#: Paths of the machine this project was written on, outside the repository, and the files
#: there that docs/errata.md and docs/install.md replace (built from pieces so that this file
#: does not match itself).
OUTSIDE = [re.compile(p) for p in ('/' + 'work/', r'\.\./' + 'shared', 'shared/' + 'papers',
                                   'shared/' + 'ros2-from-pypi', 'shared/' + 'STYLE',
                                   r'\bERRATA' + r'\.md', r'\bNOTES' + r'\.md')]
LINK = re.compile(r'!?\[[^\]]*\]\(([^)\s]+)\)')
FENCE = re.compile(r'^```.*?^```', re.S | re.M)


def _slug(heading: str) -> str:
    """GitHub's anchor of a heading."""
    text = heading.strip().lower()
    text = re.sub(r'[^\w\- ]', '', text)
    return text.replace(' ', '-')


def _anchors(page: Path) -> set[str]:
    seen: dict[str, int] = {}
    out = set()
    for line in FENCE.sub('', page.read_text(encoding='utf-8')).splitlines():
        match = re.match(r'^#{1,6} (.+)$', line)
        if not match:
            continue
        slug = _slug(match[1])
        n = seen.get(slug, 0)
        seen[slug] = n + 1
        out.add(slug if n == 0 else f'{slug}-{n}')
    return out


def test_readme_is_a_front_page():
    lines = (REPO / 'README.md').read_text(encoding='utf-8').splitlines()
    assert len(lines) <= MAX_README_LINES, len(lines)


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_relative_links_resolve(page: Path):
    text = FENCE.sub('', page.read_text(encoding='utf-8'))
    for target in LINK.findall(text):
        if re.match(r'^[a-z]+:', target):  # https:, mailto:
            continue
        path_part, _, anchor = target.partition('#')
        file = (page.parent / path_part).resolve() if path_part else page
        assert REPO in file.parents or file == REPO, f'{page.name}: {target} leaves the repository'
        assert file.exists(), f'{page.name}: {target} does not exist'
        if anchor and file.suffix == '.md':
            assert anchor in _anchors(file), f'{page.name}: no heading #{anchor} in {file.name}'


def _project_files() -> list[Path]:
    files = []
    for path in REPO.rglob('*'):
        if any(part in SKIPPED_DIRS for part in path.relative_to(REPO).parts):
            continue
        if path.is_file() and path.suffix in TEXT_SUFFIXES and path.stat().st_size < 2_000_000:
            files.append(path)
    return files


def test_no_file_points_outside_the_repository():
    found = []
    for path in _project_files():
        try:
            text = path.read_text(encoding='utf-8')
        except UnicodeDecodeError:
            continue
        for number, line in enumerate(text.splitlines(), 1):
            if any(p.search(line) for p in OUTSIDE):
                found.append(f'{path.relative_to(REPO)}:{number}: {line.strip()[:100]}')
    assert not found, 'paths outside the repository:\n' + '\n'.join(found)


def test_errata_page_names_tests_that_exist():
    """Every test docs/errata.md cites as showing an erratum exists."""
    text = (REPO / 'docs' / 'errata.md').read_text(encoding='utf-8')
    cited = re.findall(r'`(test_\w+\.py)::(test_\w+)`', text)
    assert len(cited) >= 15
    module = None
    for row in text.splitlines():
        for name in re.findall(r'`(?:(test_\w+\.py)::)?(test_\w+)`', row):
            module = name[0] or module
            source = next((REPO / 'test').rglob(module)).read_text(encoding='utf-8')
            assert f'def {name[1]}(' in source, f'{module}::{name[1]}'


#: A path into the repository's own folders as the pages write it (in text or code).
REPO_PATH = re.compile(r'(?<![\w/.~-])((?:test|bench|scripts|config|launch|examples|docs|'
                       r'tensegrity_stiffness)/[\w./-]*\w\.(?:py|sh|yaml|md|launch\.py|json|rviz))')


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_repository_paths_named_by_the_pages_exist(page: Path):
    """Every repository file a page names (``test/...py``, ``bench/...``, ``config/...``) is
    there: a page that survives a move of the files it cites is not true."""
    missing = sorted({m for m in REPO_PATH.findall(page.read_text(encoding='utf-8'))
                      if '*' not in m and not (REPO / m).exists()
                      and not (page.parent / m).exists()})
    assert not missing, f'{page.name} names files that do not exist: {missing}'


#: A dotted name in the package as the pages write it (``tensegrity_stiffness.mechanics.joint``).
DOTTED_NAME = re.compile(r'(?<![\w/])tensegrity_stiffness(?:\.\w+)+')


def _resolves(dotted: str) -> bool:
    """The longest importable module prefix of ``dotted``, then attributes for the rest."""
    import importlib

    parts = dotted.split('.')
    for i in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module('.'.join(parts[:i]))
        except ImportError:
            continue
        for name in parts[i:]:
            if not hasattr(obj, name):
                return False
            obj = getattr(obj, name)
        return True
    return False


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_dotted_names_named_by_the_pages_import(page: Path):
    """Every ``tensegrity_stiffness.<module>[.<name>]`` a page names imports (ROS modules
    included: the tests run with the built package on the path)."""
    names = set(DOTTED_NAME.findall(page.read_text(encoding='utf-8')))
    missing = sorted(n for n in names if not _resolves(n))
    assert not missing, f'{page.name} names what does not import: {missing}'


def _cells(row: str) -> int:
    return len(re.split(r'(?<!\\)\|', row.strip().strip('|')))


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_table_rows_have_the_header_s_cells(page: Path):
    """A pipe inside a table cell (even in code, e.g. |omega|) must be escaped as \\|, else it
    splits the cell."""
    header = None
    text = FENCE.sub(lambda m: '\n' * m[0].count('\n'), page.read_text(encoding='utf-8'))
    for number, line in enumerate(text.splitlines(), 1):
        if not line.startswith('|'):
            header = None
            continue
        if header is None:
            header = _cells(line)
            continue
        assert _cells(line) == header, f'{page.name}:{number}: {line[:80]}'


LIBRARY_EXAMPLES = [(page, i, code) for page in PAGES
                    for i, code in enumerate(re.findall(r'```python\n(.*?)```',
                                                        page.read_text(encoding='utf-8'), re.S))
                    if 'rclpy' not in code]


@pytest.mark.parametrize('page, index, code', LIBRARY_EXAMPLES,
                         ids=[f'{p.name}-{i}' for p, i, _ in LIBRARY_EXAMPLES])
def test_library_examples_run(page: Path, index: int, code: str, tmp_path: Path, monkeypatch,
                              capsys):
    """Every Python example of the docs that needs no ROS graph runs as printed from a
    directory outside the repository (the examples find the configs through
    ``config.packaged_config_path``, not through paths relative to the repository root)."""
    assert REPO not in tmp_path.resolve().parents
    monkeypatch.chdir(tmp_path)
    exec(compile(code, f'{page.name} example {index}', 'exec'), {})
    capsys.readouterr()


def test_install_layout_names_every_launch_file_and_subpackage():
    """docs/install.md's layout and docs/architecture.md stay complete as files are added."""
    install = (REPO / 'docs' / 'install.md').read_text(encoding='utf-8')
    layout = install[install.index('## Layout'):]
    for path in sorted((REPO / 'launch').glob('*.launch.py')):
        name = path.name
        preset = re.match(r'stiffness_bridge_(\w+)\.launch\.py', name)
        assert name in layout or (preset and preset[1] in layout), name
    architecture = (REPO / 'docs' / 'architecture.md').read_text(encoding='utf-8')
    for init in sorted((REPO / 'tensegrity_stiffness').glob('*/__init__.py')):
        if init.parent.name != 'srv':
            assert f'`{init.parent.name}/`' in architecture, init.parent.name
    for init in sorted((REPO / 'tensegrity_stiffness' / 'ros').glob('*/__init__.py')):
        assert f'ros/{init.parent.name}/' in architecture, init.parent.name


#: Fenced blocks of the pages that are not shell (their ``~/`` is no shell word).
NOT_SHELL = {'python', 'yaml', 'json', 'xml', 'cpp', 'c++', 'cmake', 'text', 'msg', 'srv'}
#: A word that starts with ``~/`` and is a ROS remap or parameter (``~/name:=...``) with the
#: tilde unquoted: bash expands it to ``$HOME/name:=...`` before the node sees it.
UNQUOTED_TILDE_REMAP = re.compile(r'''(?:^|[\s=`(])~/[^\s'"`]*:=''')


def _shell_texts(page: Path) -> list[tuple[int, str]]:
    """(line number, text) of every line of a shell block (a fence whose language is not
    ``NOT_SHELL``) and of every inline code span of the prose of ``page``."""
    out, language = [], None
    for number, line in enumerate(page.read_text(encoding='utf-8').splitlines(), 1):
        fence = re.match(r'^\s*```(\S*)', line)
        if fence:
            language = fence[1].lower() if language is None else None
            continue
        if language is None:
            out += [(number, span) for span in re.findall(r'`([^`]+)`', line)]
        elif language not in NOT_SHELL:
            out.append((number, line))
    return out


@pytest.mark.parametrize('page', PAGES, ids=lambda p: p.name)
def test_tilde_remaps_are_quoted(page: Path):
    """A ``~/`` remap in a shell command is quoted (``-r '~/input_stiffness:=/x'``): unquoted,
    bash turns it into ``/root/input_stiffness:=/x`` and the node waits on a topic nobody
    publishes."""
    found = [f'{page.name}:{number}: {text.strip()}' for number, text in _shell_texts(page)
             if UNQUOTED_TILDE_REMAP.search(text)]
    assert not found, 'unquoted ~/ remaps:\n' + '\n'.join(found)


def test_the_tilde_check_finds_an_unquoted_remap(tmp_path: Path):
    """The check above catches the form docs/controllers.md once had, in a block and inline,
    and passes the quoted form and a home path."""
    page = tmp_path / 'page.md'
    page.write_text('```\nros2 run p n --ros-args -r ~/input_stiffness:=/j1/k\n```\n'
                    "Or `-r ~/output_stiffness:=/c/t`, not `-r '~/output_stiffness:=/c/t'`.\n"
                    '```bash\ncd ~/ws && x -r "~/a:=/b"\n```\n', encoding='utf-8')
    hits = [n for n, text in _shell_texts(page) if UNQUOTED_TILDE_REMAP.search(text)]
    assert hits == [2, 4]


def test_command_line_table_names_every_command():
    """docs/command_line.md's table has a row for every subcommand the parser has (read from
    ``cli.parser.COMMANDS``, the commands of ``build_parser``, so a new command needs its row),
    and no row for a command the parser does not have."""
    import argparse

    from tensegrity_stiffness.cli.parser import COMMANDS

    commands = argparse.ArgumentParser().add_subparsers()
    for add_parser in COMMANDS:  # as build_parser does
        add_parser(commands)
    text = (REPO / 'docs' / 'command_line.md').read_text(encoding='utf-8')
    table = text[text.index('| command | what it prints |'):].split('\n\n')[0]
    rows = {re.match(r'\| `([\w-]+)', row)[1] for row in table.splitlines()[2:]}
    assert rows == set(commands.choices), (sorted(set(commands.choices) - rows),
                                           sorted(rows - set(commands.choices)))


def installed_executables() -> set[str]:
    """Every executable the package installs: the ``name=module:function`` entries of
    CMakeLists.txt (where ``ros2 run`` looks, and the command line) and setup.py's console
    scripts."""
    cmake = (REPO / 'CMakeLists.txt').read_text(encoding='utf-8')
    names = set(re.findall(r'"([\w-]+)=tensegrity_stiffness[\w.]*:\w+"', cmake))
    setup = (REPO / 'setup.py').read_text(encoding='utf-8')
    names |= set(re.findall(r"'([\w-]+) = tensegrity_stiffness[\w.]*:\w+'", setup))
    return names


def test_readme_names_every_executable_with_one_line():
    """The README's table of executables has one row for each executable installed (and no
    other)."""
    text = (REPO / 'README.md').read_text(encoding='utf-8')
    section = text.split('## Executables', 1)[1].split('\n## ', 1)[0]
    rows = re.findall(r'^\| `([\w-]+)` \| .+ \|$', section, re.M)
    assert len(rows) == len(set(rows)), rows
    expected = installed_executables()
    assert {'stiffness_node', 'control_loop', 'structure_node', 'tensegrity-stiffness'} <= expected
    assert set(rows) == expected
