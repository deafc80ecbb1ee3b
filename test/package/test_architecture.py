"""The import rule of docs/architecture.md, read from the code: no module imports from a layer
above its own, only ``tensegrity_stiffness.ros`` imports rclpy or a ROS message package, and no
module uses another module's private names."""

from __future__ import annotations

import ast
import functools
from dataclasses import dataclass
from pathlib import Path

import pytest
from support import REPO


@dataclass(frozen=True)
class Layer:
    """A layer of docs/architecture.md: its modules (packages or modules by dotted name) and its
    rank; a module may import only from layers of a lower rank (and from its own layer).
    ``alias``: the documented import paths at the top level, which only re-export."""

    name: str
    rank: float
    packages: tuple[str, ...]
    alias: bool = False


T = 'tensegrity_stiffness.'
LAYERS = (
    Layer('config', 0, (T + 'config',)),
    Layer('geometry', 0, (T + 'geometry',)),
    # The deprecated paths' warnings: imports nothing of the package.
    Layer('deprecation', 0, (T + 'deprecation',)),
    Layer('mechanics', 1, (T + 'mechanics',)),
    # Between mechanics and the rank-2 concerns, which will build on it (a structure twin, a
    # structure estimator).
    Layer('structures', 1.5, (T + 'structures',)),
    Layer('estimation', 2, (T + 'estimation',)),
    Layer('simulation', 2, (T + 'simulation',)),
    Layer('control', 2, (T + 'control',)),
    Layer('nodes', 3, (T + 'nodes',)),
    Layer('recordings', 4, (T + 'recordings',)),
    Layer('cli', 5, (T + 'cli',)),
    Layer('ros', 6, (T + 'ros', T + 'srv', T + 'msg')),
    Layer('documented paths', 7, ('tensegrity_stiffness',), alias=True),
)
#: Imported only under tensegrity_stiffness.ros.
ROS_ONLY_IMPORTS = ('rclpy', 'std_msgs', 'geometry_msgs', 'sensor_msgs', 'diagnostic_msgs',
                    'visualization_msgs', 'builtin_interfaces', 'rcl_interfaces', 'tf2_msgs',
                    'std_srvs', 'rosidl_runtime_py', 'launch', 'launch_ros',
                    'ament_index_python', T + 'srv', T + 'msg', T + 'ros')


def layer_of(module: str) -> Layer | None:
    """The layer of a dotted module name (the longest matching package), None outside."""
    best = None
    for layer in LAYERS:
        for package in layer.packages:
            if module == package or module.startswith(package + '.'):
                if best is None or len(package) > len(best[0]):
                    best = (package, layer)
    return best[1] if best else None

PACKAGE = REPO / 'tensegrity_stiffness'
MODULES = sorted(p for p in PACKAGE.rglob('*.py') if '__pycache__' not in p.parts)


@functools.cache
def parsed(path: Path) -> ast.Module:
    """A module's syntax tree, parsed once for every test of this file (none changes it)."""
    return ast.parse(path.read_text(encoding='utf-8'))


@functools.cache
def walked(path: Path) -> tuple[ast.AST, ...]:
    """Every node of :func:`parsed`'s tree, in ``ast.walk`` order, listed once."""
    return tuple(ast.walk(parsed(path)))


def dotted(path: Path) -> str:
    parts = path.relative_to(REPO).with_suffix('').parts
    return '.'.join(parts[:-1] if parts[-1] == '__init__' else parts)


def imported_modules(tree: ast.AST, module: str, is_package: bool) -> list[tuple[int, str]]:
    """(line, absolute module) of every import statement, function-local ones too."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = module.split('.')
                base = base[:len(base) - node.level + (1 if is_package else 0)]
                target = '.'.join(base + ([node.module] if node.module else []))
            else:
                target = node.module or ''
            if target != 'tensegrity_stiffness':
                found.append((node.lineno, target))
            # `from package import module` imports the module
            found += [(node.lineno, f'{target}.{a.name}') for a in node.names]
    return found


def test_every_library_module_has_a_layer() -> None:
    for path in MODULES:
        assert layer_of(dotted(path)) is not None, f'{dotted(path)} has no layer in LAYERS'


def test_no_module_imports_from_a_layer_above_or_a_sibling() -> None:
    """Within one rank, the concerns are siblings that do not import each other."""
    wrong = []
    for path in MODULES:
        module = dotted(path)
        mine = layer_of(module)
        tree = parsed(path)
        for line, target in imported_modules(tree, module, path.name == '__init__.py'):
            theirs = layer_of(target)
            if theirs is None or mine is None or theirs.name == mine.name:
                continue
            if mine.alias:
                continue
            if theirs.rank >= mine.rank:
                wrong.append(f'{path.relative_to(REPO)}:{line} ({mine.name}) imports {target} '
                             f'({theirs.name})')
    assert not wrong, '\n'.join(wrong)


#: The modules split along their seams that keep their names as faces re-exporting their parts
#: (docs/architecture.md, "Import paths"): code inside the package imports the parts.
FACES = tuple(T + name for name in (
    'nodes.parameters', 'nodes.processing', 'nodes.spine_processing', 'nodes.control_processing',
    'nodes.estimation_processing', 'estimation.estimators', 'estimation.calibration',
    'simulation.twin', 'recordings.bag'))


def face_imports(tree: ast.AST, faces: dict[str, ast.Module]) -> list[tuple[int, str]]:
    """(line, what) of each import through a face: a name it re-exports (``from face import
    name``), or the face itself when it defines no function or class of its own
    (``from package import face``)."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.ImportFrom) or not node.module:
            continue
        for alias in node.names:
            face = faces.get(node.module)
            if face is not None and alias.name in reexported_names(face):
                found.append((node.lineno, f'{node.module}.{alias.name}'))
            whole = faces.get(f'{node.module}.{alias.name}')
            if whole is not None and not any(isinstance(n, (ast.FunctionDef, ast.ClassDef))
                                             for n in whole.body):
                found.append((node.lineno, f'{node.module}.{alias.name}'))
    return found


def reexported_names(face: ast.Module) -> set[str]:
    """The names a module binds by importing them from the package (at its top level)."""
    return {a.asname or a.name for n in face.body if isinstance(n, ast.ImportFrom)
            and (n.module or '').startswith('tensegrity_stiffness') for a in n.names}


def test_code_inside_the_package_imports_the_parts_not_the_faces() -> None:
    faces = {face: ast.parse((REPO / (face.replace('.', '/') + '.py')).read_text(
        encoding='utf-8')) for face in FACES}
    wrong = []
    for path in MODULES:
        module = dotted(path)
        if module in faces or layer_of(module).alias:  # a face's own imports; the old paths
            continue
        wrong += [f'{path.relative_to(REPO)}:{line} imports {what} through its face'
                  for line, what in face_imports(parsed(path),
                                                 faces)]
    assert not wrong, '\n'.join(wrong)


def test_face_imports_are_found() -> None:
    faces = {T + 'nodes.processing': ast.parse(
        'from tensegrity_stiffness.nodes.stiffness_node import joint_outputs\n')}
    code = ('from tensegrity_stiffness.nodes.processing import joint_outputs\n'
            'from tensegrity_stiffness.nodes import processing\n'
            'from tensegrity_stiffness.nodes.stiffness_node import joint_outputs\n')
    assert face_imports(ast.parse(code), faces) == [
        (1, T + 'nodes.processing.joint_outputs'), (2, T + 'nodes.processing')]


def test_only_the_ros_layer_imports_rclpy_or_message_packages() -> None:
    wrong = []
    for path in MODULES:
        module = dotted(path)
        if module.startswith('tensegrity_stiffness.ros'):
            continue
        tree = parsed(path)
        for line, target in imported_modules(tree, module, path.name == '__init__.py'):
            if any(target == name or target.startswith(name + '.') for name in ROS_ONLY_IMPORTS):
                wrong.append(f'{path.relative_to(REPO)}:{line} imports {target}')
    assert not wrong, '\n'.join(wrong)


def own_member(value: ast.expr) -> bool:
    """``self``, ``cls`` or ``super()``: the receiver of a class's own members."""
    if isinstance(value, ast.Name):
        return value.id in ('self', 'cls')
    return isinstance(value, ast.Call) and isinstance(value.func, ast.Name) and \
        value.func.id == 'super'


def private_uses(tree: ast.AST) -> list[tuple[int, str]]:
    """Private names this module uses that it does not define: ``from m import _x`` and
    ``something._x`` where ``_x`` is neither defined nor assigned here, or where ``something``
    is an imported name (a method copied from another module's class); ``self._x``, ``cls._x``
    and ``super()._x`` are a class's own (inherited) members."""
    defined: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            defined.add(node.name)
        elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store):
            defined.add(node.attr)
        elif isinstance(node, ast.Name) and isinstance(node.ctx, ast.Store):
            defined.add(node.id)
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            defined.add(node.target.id)
        elif isinstance(node, ast.arg):
            defined.add(node.arg)
        elif isinstance(node, ast.alias):
            defined.add(node.asname or node.name.split('.')[0])
        elif isinstance(node, ast.keyword) and node.arg:
            defined.add(node.arg)
    imported = {a.asname or a.name.split('.')[0] for node in ast.walk(tree)
                if isinstance(node, (ast.Import, ast.ImportFrom)) for a in node.names}
    uses = []
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.module != '__future__':
            uses += [(node.lineno, a.name) for a in node.names
                     if a.name.startswith('_') and not a.name.startswith('__')]
        elif isinstance(node, ast.Attribute) and node.attr.startswith('_') and \
                not node.attr.startswith('__') and not own_member(node.value) and (
                    node.attr not in defined or (isinstance(node.value, ast.Name)
                                                 and node.value.id in imported)):
            uses.append((node.lineno, node.attr))
    return uses


# Private names of dependencies that their public documentation tells users to use.
DOCUMENTED_PRIVATE_NAMES = {
    '_asdict', '_replace', '_fields',  # collections.namedtuple's public API
}


def test_no_module_uses_another_module_s_private_names() -> None:
    wrong = []
    for path in MODULES:
        tree = parsed(path)
        for line, name in private_uses(tree):
            if name not in DOCUMENTED_PRIVATE_NAMES:
                wrong.append(f'{path.relative_to(REPO)}:{line} uses {name}')
    assert not wrong, '\n'.join(wrong)


@pytest.mark.parametrize('layer', LAYERS, ids=lambda layer: layer.name)
def test_every_subpackage_says_what_it_may_import(layer) -> None:
    for package in layer.packages:
        init = REPO.joinpath(*package.split('.'), '__init__.py')
        if init.is_file():
            doc = ast.get_docstring(ast.parse(init.read_text(encoding='utf-8'))) or ''
            assert doc, f'{package}/__init__.py has no docstring'


def test_output_names_and_order_have_one_home() -> None:
    """stiffness_node's and spine_node's outputs are named and ordered once, in
    ``nodes/layouts.py``: no other module writes a topic ``'~/<output>'`` or a sequence of
    three or more output names (the node, the bag command, the message builders and the
    processing read the table; a mapping such as the command line's JSON keys is no order)."""
    from tensegrity_stiffness.nodes.layouts import (
        ESTIMATOR_OUTPUTS,
        JOINT_OUTPUTS,
        SPINE_ESTIMATOR_OUTPUTS,
        SPINE_OUTPUTS,
    )

    home = PACKAGE / 'nodes' / 'layouts.py'
    tables = [(frozenset(names), frozenset(f'~/{n}' for n in names))
              for names in (JOINT_OUTPUTS, SPINE_OUTPUTS, ESTIMATOR_OUTPUTS,
                            SPINE_ESTIMATOR_OUTPUTS)]
    wrong = []
    for names, topics in tables:
        for path in MODULES:
            if path == home:
                continue
            for node in walked(path):
                if isinstance(node, ast.Constant) and isinstance(node.value, str) and \
                        node.value in topics:
                    wrong.append(f'{path.relative_to(REPO)}:{node.lineno} {node.value!r}')
                elif isinstance(node, (ast.Tuple, ast.List, ast.Set)):
                    values = [i.value for i in node.elts if isinstance(i, ast.Constant)]
                    if len(names.intersection(values)) >= 3:
                        wrong.append(f'{path.relative_to(REPO)}:{node.lineno} {values}')
    assert not wrong, '\n'.join(wrong)


def test_rclpy_internals_are_used_in_one_module_only() -> None:
    """rclpy's implementation internals appear in ``ros/runtime/rclpy_internals.py`` alone
    (``test/ros/test_rclpy_internals.py`` exercises them there)."""
    home = PACKAGE / 'ros' / 'runtime' / 'rclpy_internals.py'
    internals = ('rclpy_implementation', 'implementation_singleton', 'take_message', '_rclpy')
    wrong = []
    for path in MODULES:
        if path == home:
            continue
        for node in walked(path):
            names = []
            if isinstance(node, ast.ImportFrom):
                names = [node.module or '', *(a.name for a in node.names)]
            elif isinstance(node, ast.Attribute):
                names = [node.attr]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            if any(part in internals for name in names for part in name.split('.')) or (
                    isinstance(node, ast.Attribute) and node.attr == 'pointer'):
                wrong.append(f'{path.relative_to(REPO)}:{node.lineno}')
    assert not wrong, '\n'.join(wrong)


#: A function longer than this says why in its docstring, with the marker below.
LONG_FUNCTION_LINES = 80
LONG_FUNCTION_MARKER = '(Long:'


def test_long_functions_say_why() -> None:
    """No function of the package over :data:`LONG_FUNCTION_LINES` lines unless its docstring
    gives the reason, as ``(Long: ...)``."""
    unexplained = []
    for path in MODULES:
        for node in walked(path):
            if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                continue
            length = node.end_lineno - node.lineno + 1
            if length > LONG_FUNCTION_LINES and \
                    LONG_FUNCTION_MARKER not in (ast.get_docstring(node) or ''):
                unexplained.append(f'{path.relative_to(REPO)}:{node.lineno} {node.name} '
                                   f'({length} lines)')
    assert not unexplained, 'split these or say why in the docstring:\n' + '\n'.join(unexplained)


def runtime_import_targets(tree: ast.AST, module: str, is_package: bool,
                           modules: set[str]) -> set[str]:
    """The package modules an import statement of ``tree`` loads when it runs, function-level
    ones too, not those under ``if TYPE_CHECKING:``: ``import a.b`` loads ``a.b``;
    ``from a import b, c`` loads the modules ``a.b``, ``a.c`` and, when a name is not a module,
    ``a`` itself (a package's ``__init__`` that every import of its modules loads first is no
    edge of its own)."""
    skipped = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and 'TYPE_CHECKING' in ast.unparse(node.test):
            skipped |= {id(n) for part in node.body for n in ast.walk(part)}
    targets = set()
    for node in ast.walk(tree):
        if id(node) in skipped or not isinstance(node, (ast.Import, ast.ImportFrom)):
            continue
        statement = ast.Module(body=[node], type_ignores=[])
        found = {target for _, target in imported_modules(statement, module, is_package)}
        if isinstance(node, ast.ImportFrom):
            base = {target for target in found
                    if not any(target == f'{other}.{a.name}' for other in found
                               for a in node.names)}
            names = found - base
            if names <= modules:  # only modules imported from the package
                found = names
        targets |= found & modules
    return targets


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports when it runs, function-level imports included
    (the top-level documented paths, which only re-export, are left out)."""
    names = {dotted(path): path for path in MODULES}
    aliases = {name for name in names if layer_of(name).alias}
    modules = set(names) - aliases
    graph: dict[str, set[str]] = {}
    for name in sorted(modules):
        path = names[name]
        tree = parsed(path)
        graph[name] = runtime_import_targets(tree, name, path.name == '__init__.py',
                                             modules) - {name}
    return graph


def import_circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    circles = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                circles.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return circles


def test_no_import_circle() -> None:
    """No module imports itself through others, deferred (function-level) imports counted:
    every import of the package is a path down the layers or within one, never back."""
    circles = import_circles(import_graph())
    assert not circles, 'import circles:\n' + '\n'.join(' <-> '.join(c) for c in circles)


def test_import_circles_are_found() -> None:
    graph = {'a': {'b'}, 'b': {'c'}, 'c': {'a'}, 'd': {'a'}, 'e': {'e'}}
    assert import_circles(graph) == [['a', 'b', 'c']]


def dynamic_imports(tree: ast.AST) -> list[tuple[int, ast.expr | None]]:
    """(line, argument) of every ``importlib.import_module(...)``, ``import_module(...)`` and
    ``__import__(...)`` call (argument None when there is none)."""
    found = []
    for node in ast.walk(tree):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        name = f.attr if isinstance(f, ast.Attribute) else f.id if isinstance(f, ast.Name) \
            else ''
        if name in ('import_module', '__import__'):
            found.append((node.lineno, node.args[0] if node.args else None))
    return found


#: Modules below ``ros`` that import by a name built at run time, and why that keeps the rule.
RUNTIME_NAME_IMPORTS = {
    # MovedNames imports, on first use of an old name, a module of the subpackage that made it:
    # ``MovedNames(__name__, {relative: ...})`` in that subpackage's ``__init__``, whose
    # relative names test_moved_names_name_their_own_modules holds to its own modules.
    T + 'deprecation': 'the modules a subpackage names for its old names',
}


def test_dynamic_imports_keep_the_import_rule() -> None:
    """A module imports by name (``importlib.import_module``, ``__import__``) only what it may
    import by statement: below the ``ros`` layer the name is a constant string, held to the
    layer and ROS rules (or the module is in :data:`RUNTIME_NAME_IMPORTS`, which says why);
    the ``ros`` layer (which may import anything) may build it."""
    wrong = []
    for path in MODULES:
        module = dotted(path)
        mine = layer_of(module)
        for line, arg in dynamic_imports(parsed(path)):
            where = f'{path.relative_to(REPO)}:{line}'
            if mine.name == 'ros' or module in RUNTIME_NAME_IMPORTS:
                continue
            if not (isinstance(arg, ast.Constant) and isinstance(arg.value, str)):
                wrong.append(f'{where} imports a module by a name built at run time')
                continue
            target = arg.value
            theirs = layer_of(target)
            if any(target == name or target.startswith(name + '.') for name in ROS_ONLY_IMPORTS):
                wrong.append(f'{where} imports {target} (ROS only)')
            elif theirs is not None and theirs.name != mine.name and not mine.alias and \
                    theirs.rank >= mine.rank:
                wrong.append(f'{where} ({mine.name}) imports {target} ({theirs.name})')
    assert not wrong, '\n'.join(wrong)


def test_dynamic_imports_are_found() -> None:
    tree = ast.parse("import importlib\nimportlib.import_module('x.y')\n__import__(name)\n")
    found = dynamic_imports(tree)
    assert [line for line, _ in found] == [2, 3]
    assert found[0][1].value == 'x.y' and isinstance(found[1][1], ast.Name)


def test_moved_names_name_their_own_modules() -> None:
    """Every ``MovedNames(__name__, {relative: ...})`` (the lazy old names of a subpackage)
    names modules of its own subpackage, so the run-time imports of :data:`RUNTIME_NAME_IMPORTS`
    stay inside the subpackage that asks for them."""
    names = {dotted(path) for path in MODULES}
    wrong = []
    for path in MODULES:
        package = dotted(path) if path.name == '__init__.py' else dotted(path).rpartition('.')[0]
        for node in walked(path):
            if not (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                    and node.func.id == 'MovedNames'):
                continue
            table = node.args[1] if len(node.args) > 1 else None
            if not (isinstance(node.args[0], ast.Name) and node.args[0].id == '__name__'
                    and isinstance(table, ast.Dict)):
                wrong.append(f'{path.relative_to(REPO)}:{node.lineno} is not '
                             'MovedNames(__name__, {...})')
                continue
            for key in table.keys:
                if not (isinstance(key, ast.Constant) and f'{package}.{key.value}' in names):
                    wrong.append(f'{path.relative_to(REPO)}:{node.lineno} names '
                                 f'{ast.unparse(key)}, not a module of {package}')
    assert not wrong, '\n'.join(wrong)
