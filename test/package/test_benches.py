"""The benchmark scripts stay runnable: each answers ``--help`` (its imports resolve), and every
test helper one imports, also inside a function, is a ``support`` module that defines the
names it takes (benches never import a test module)."""

from __future__ import annotations

import ast
import subprocess
import sys

import pytest
from support import REPO

BENCHES = sorted((REPO / 'bench').glob('*.py'))


def support_imports(path) -> list[tuple[str, list[str]]]:
    """(module, names) of every ``from <module> import ...`` of a test helper in ``path``."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module and (
                node.module.split('.')[0] in ('support', 'test') or
                node.module.startswith('test_')):
            found.append((node.module, [a.name for a in node.names]))
    return found


@pytest.mark.parametrize('path', BENCHES, ids=lambda p: p.name)
def test_bench_answers_help(path) -> None:
    result = subprocess.run([sys.executable, str(path), '--help'], capture_output=True,
                            text=True, timeout=120, cwd=REPO)
    assert result.returncode == 0, result.stderr[-2000:]
    assert 'usage' in result.stdout.lower()


@pytest.mark.parametrize('path', BENCHES, ids=lambda p: p.name)
def test_bench_imports_only_support_modules_that_define_the_names(path) -> None:
    for module, names in support_imports(path):
        assert module.split('.')[0] == 'support', f'{path.name} imports test module {module}'
        source = REPO / 'test' / (module.replace('.', '/') + '.py')
        if not source.exists():
            source = REPO / 'test' / module.replace('.', '/') / '__init__.py'
        assert source.exists(), f'{path.name}: no module {module}'
        tree = ast.parse(source.read_text())
        defined = {n.name for n in tree.body if isinstance(n, (ast.FunctionDef, ast.ClassDef))}
        defined |= {t.id for n in tree.body if isinstance(n, ast.Assign)
                    for t in n.targets if isinstance(t, ast.Name)}
        defined |= {(a.asname or a.name) for n in tree.body
                    if isinstance(n, (ast.Import, ast.ImportFrom)) for a in n.names}
        submodules = {m.stem for m in source.parent.glob('*.py')} if \
            source.name == '__init__.py' else set()
        missing = sorted(set(names) - defined - submodules)
        assert not missing, f'{path.name}: {module} defines none of {missing}'
