"""The old import paths (:mod:`tensegrity_stiffness.deprecation`): each still works and warns with
the path to use; importing a subpackage imports none of its modules; and nothing of the
repository (the package, the tests, benches, examples, scripts, docs) uses an old path. setup.cfg
makes the deprecation warnings errors in the test run."""

from __future__ import annotations

import ast
import importlib
import re
import subprocess
import sys
import warnings
from pathlib import Path

import pytest
from support import REPO

T = 'tensegrity_stiffness'
#: The 14 top-level modules of the old flat layout and the module each is now.
MOVED_MODULES = {
    'calibration': 'estimation.calibration',
    'chain': 'mechanics.chain',
    'controller_stiffness': 'mechanics.controller_stiffness',
    'design': 'mechanics.design',
    'dynamics': 'mechanics.dynamics',
    'equilibrium': 'mechanics.equilibrium',
    'interpretation': 'mechanics.interpretation',
    'joint': 'mechanics.joint',
    'kernel': 'mechanics.kernel',
    'planar': 'mechanics.planar',
    'planar_workspace': 'mechanics.planar_workspace',
    'quaternion': 'geometry.quaternion',
    'screw': 'geometry.screw',
    'sweeps': 'mechanics.sweeps',
}
#: The top-level modules that are no old path.
TOP_LEVEL_MODULES = {'__init__', 'config', 'deprecation'}
#: The subpackages whose ``__init__`` re-exported their modules' names, and those modules.
MOVED_NAMES = {
    'estimation': ('estimators', 'joint_filter', 'chain_filter'),
    'simulation': ('twin',),
    'control': ('controller',),
}

#: A moved name beside the modules' ``__all__`` (test_the_old_from_imports_keep_working checks
#: it).
EXTRA_MOVED_NAMES = {'estimation': {'estimate_structure_poses'}}


def warning_of(old: str, new: str) -> str:
    return f'^{re.escape(old)} is deprecated: use {re.escape(new)}$'


def test_every_top_level_module_is_known() -> None:
    found = {p.stem for p in (REPO / T).glob('*.py')}
    assert found == set(MOVED_MODULES) | TOP_LEVEL_MODULES


@pytest.mark.parametrize('old', sorted(MOVED_MODULES))
def test_an_old_module_path_is_the_module_itself_and_warns_once(old: str) -> None:
    alias, real = f'{T}.{old}', f'{T}.{MOVED_MODULES[old]}'
    moved = importlib.import_module(real)
    sys.modules.pop(alias, None)
    with pytest.warns(DeprecationWarning, match=warning_of(alias, real)) as caught:
        module = importlib.import_module(alias)
    assert module is moved
    assert dir(module) == dir(moved)
    assert len(caught) == 1
    # once a process: the next import finds the module
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        assert importlib.import_module(alias) is moved


def test_the_warning_points_at_the_importing_line() -> None:
    sys.modules.pop(f'{T}.joint', None)
    with pytest.warns(DeprecationWarning) as caught:
        exec(compile(f'from {T}.joint import JointModel', __file__, 'exec'), {})
    assert [w.filename for w in caught] == [__file__]


@pytest.mark.parametrize('package', sorted(MOVED_NAMES))
def test_an_old_name_of_a_subpackage_is_the_module_s_name_with_a_warning(package: str) -> None:
    subpackage = importlib.import_module(f'{T}.{package}')
    names = []
    for relative in MOVED_NAMES[package]:
        module = importlib.import_module(f'{T}.{package}.{relative}')
        names += module.__all__
        for name in module.__all__:
            old, new = f'{T}.{package}.{name}', f'{T}.{package}.{relative}.{name}'
            with pytest.warns(DeprecationWarning, match=warning_of(old, new)):
                assert getattr(subpackage, name) is getattr(module, name)
    assert subpackage.__all__ == names + sorted(EXTRA_MOVED_NAMES.get(package, ()))


def test_the_old_from_imports_keep_working() -> None:
    from tensegrity_stiffness.control.controller import StiffnessController
    from tensegrity_stiffness.estimation.joint_filter import JointFilter
    from tensegrity_stiffness.estimation.structure_estimator import estimate_structure_poses
    from tensegrity_stiffness.simulation.twin import JointSimulation

    for statement, value in (
            (f'from {T}.estimation import JointFilter', JointFilter),
            (f'from {T}.estimation import estimate_structure_poses', estimate_structure_poses),
            (f'from {T}.simulation import JointSimulation', JointSimulation),
            (f'from {T}.control import StiffnessController', StiffnessController)):
        scope: dict = {}
        with pytest.warns(DeprecationWarning, match='is deprecated: use'):
            exec(statement, scope)
        assert scope[statement.split()[-1]] is value, statement
    with pytest.warns(DeprecationWarning):
        scope = {}
        exec(f'from {T}.estimation import *', scope)
    assert scope['JointFilter'] is JointFilter
    # a submodule is no moved name: no warning
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        from tensegrity_stiffness.estimation import sensor_models  # noqa: F401
    with pytest.raises(ImportError, match='no_such_name'):
        exec(f'from {T}.estimation import no_such_name', {})


def test_importing_a_subpackage_imports_none_of_its_modules() -> None:
    """docs/architecture.md: the subpackages' ``__init__`` files import nothing heavy."""
    code = (f'import sys, {T}.estimation, {T}.simulation, {T}.control, {T}.mechanics, '
            f'{T}.geometry, {T}.structures\n'
            f'print(sorted(m for m in sys.modules if m.startswith("{T}.")))')
    result = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True,
                            cwd=REPO, timeout=60, check=True)
    loaded = set(ast.literal_eval(result.stdout.strip()))
    assert loaded == {f'{T}.{name}' for name in ('estimation', 'simulation', 'control',
                                                  'mechanics', 'geometry', 'structures',
                                                  'deprecation')}, loaded


#: Where the repository's own code and docs live.
SEARCHED = ('tensegrity_stiffness', 'test', 'bench', 'examples', 'scripts', 'docs', 'launch',
            'src', 'include', 'README.md', 'CMakeLists.txt', 'setup.py', 'msg', 'srv')
#: The files that name the old paths on purpose.
OLD_PATHS_ON_PURPOSE = {'tensegrity_stiffness/deprecation.py', 'docs/architecture.md',
                        Path(__file__).resolve().relative_to(REPO).as_posix()} | {
    f'tensegrity_stiffness/{old}.py' for old in MOVED_MODULES} | {
    f'tensegrity_stiffness/{package}/__init__.py' for package in MOVED_NAMES}



def old_path_uses(text: str) -> list[str]:
    """The old paths ``text`` names: ``tensegrity_stiffness.joint`` (also as ``from
    tensegrity_stiffness import joint``) and ``tensegrity_stiffness.estimation.JointFilter`` (also
    as ``from tensegrity_stiffness.estimation import (..., JointFilter)``)."""
    moved = '|'.join(MOVED_MODULES)
    found = re.findall(rf'\b{T}\.(?:{moved})\b', text)
    for group in re.findall(rf'from {T} import (\([^)]*\)|[^\n]*)', text):
        found += [f'from {T} import {name}' for name in re.findall(r'\w+', group.split('#')[0])
                  if name in MOVED_MODULES]
    for package, modules in MOVED_NAMES.items():
        names = {name for relative in modules
                 for name in importlib.import_module(f'{T}.{package}.{relative}').__all__}
        names |= EXTRA_MOVED_NAMES.get(package, set())
        found += [f'{T}.{package}.{name}'
                  for name in re.findall(rf'\b{T}\.{package}\.(\w+)', text) if name in names]
        for group in re.findall(rf'from {T}\.{package} import (\([^)]*\)|[^\n]*)', text):
            found += [f'from {T}.{package} import {name}'
                      for name in re.findall(r'\w+', group.split('#')[0]) if name in names]
    return found


def test_nothing_here_uses_an_old_path() -> None:
    wrong = []
    for top in SEARCHED:
        root = REPO / top
        for path in ([root] if root.is_file() else sorted(root.rglob('*'))):
            relative = path.relative_to(REPO).as_posix()
            if not path.is_file() or '__pycache__' in path.parts or \
                    relative in OLD_PATHS_ON_PURPOSE or path.suffix in ('.png', '.svg', '.so'):
                continue
            text = path.read_text(encoding='utf-8', errors='replace')
            wrong += [f'{relative}: {use}' for use in old_path_uses(text)]
    assert not wrong, '\n'.join(wrong)


#: Modules that import a sibling through their subpackage (``from tensegrity_stiffness.estimation
#: import sensor_models``): the package is asked for the name before the submodule is imported.
SUBMODULE_IMPORTERS = sorted(
    '.'.join(path.relative_to(REPO).with_suffix('').parts)
    for path in (REPO / T).rglob('*/*.py')  # not the top-level old paths, which warn
    if re.search(rf'^from {T}\.(estimation|simulation|control) import \w+ as ',
                 path.read_text(encoding='utf-8'), re.M))


def test_submodule_importers_are_found() -> None:
    assert f'{T}.estimation.chain_estimator' in SUBMODULE_IMPORTERS


@pytest.mark.parametrize('module', SUBMODULE_IMPORTERS)
def test_a_module_that_imports_a_sibling_through_its_subpackage_imports_alone(module: str
                                                                              ) -> None:
    """In a fresh interpreter, first thing: the subpackage's ``__getattr__`` must answer a
    submodule's name without importing its moved names' modules (``estimators``, which imports
    ``chain_estimator`` part-way through its own import: an ImportError of a circle)."""
    done = subprocess.run([sys.executable, '-W', 'error::DeprecationWarning', '-c',
                           f'import {module}'], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
