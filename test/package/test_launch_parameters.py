"""Single parameters on the ``ros2 launch`` command line
(:mod:`tensegrity_stiffness.ros.launch_parameters`) and the launch files that take them.

``launch`` is not on PyPI, so the launch files are read, not run: each compiles, declares
``namespace`` and ``params_file``, starts only executables with a parameter table, sets in its
fixed parameters only names of the started node's table, and the example command of its
docstring sets only declared arguments or the nodes' parameters, with values the table takes.
The rule that turns ``name:=value`` into typed parameters is tested here directly.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from support import REPO

from tensegrity_stiffness.nodes.parameters import by_name
from tensegrity_stiffness.ros.launch_parameters import (
    PARAMS_FILE,
    node_parameter_list,
    node_parameters,
    parse_value,
    single_parameters,
)

LAUNCH_FILES = sorted((REPO / 'launch').glob('*.launch.py'))


def test_single_parameters_are_typed_by_the_node_s_table() -> None:
    given = single_parameters('stiffness_controller', {
        'limits.tension_max': '3', 'control.rate': '200', 'namespace': '/control',
        'params_file': '/x.yaml', 'control_rate': '500.0', 'use_sim_time': 'true',
        'not.a.parameter': '1'})
    assert given == {'limits.tension_max': 3.0, 'control.rate': 200.0, 'use_sim_time': True}
    assert all(type(given[name]) is float for name in ('limits.tension_max', 'control.rate'))
    assert single_parameters('stiffness_node', {'qos.depth': '5', 'tf.enabled': 'false'}) == {
        'qos.depth': 5, 'tf.enabled': False}


def test_a_string_parameter_takes_the_text_as_it_is() -> None:
    specs = by_name(node_parameters('stiffness_node'))
    string = next(spec for spec in specs.values() if spec.type == 'string' and not spec.choices)
    assert parse_value(string, 'true') == 'true'
    assert parse_value(string, '3') == '3'


def test_an_array_parameter_takes_a_yaml_list() -> None:
    specs = by_name(node_parameters('stiffness_node'))
    array = next(spec for spec in specs.values() if spec.type == 'double_array')
    assert parse_value(array, '[1, 2.5]') == [1.0, 2.5]
    with pytest.raises(ValueError, match=re.escape(array.name)):
        parse_value(array, '1.0')


@pytest.mark.parametrize(('name', 'text', 'says'), [
    ('qos.depth', 'abc', 'must be an integer'),
    ('qos.depth', '2.5', 'must be an integer'),
    ('tf.enabled', 'maybe', 'must be true or false'),
    ('planar.L', '[1', 'not a value'),
    ('planar.L', '.nan', 'must be finite'),
    ('planar.L', 'one', 'must be a number'),
])
def test_a_bad_value_is_refused_naming_the_argument(name: str, text: str, says: str) -> None:
    with pytest.raises(ValueError, match=rf'launch argument {re.escape(name)}:=.*{says}'):
        single_parameters('stiffness_node', {name: text})


def test_out_of_range_is_refused() -> None:
    specs = by_name(node_parameters('stiffness_node'))
    ranged = next(spec for spec in specs.values() if spec.range is not None and spec.type in
                  ('int', 'double'))
    too_big = ranged.range[1] + 1
    with pytest.raises(ValueError, match=rf'{re.escape(ranged.name)}.*outside'):
        single_parameters('stiffness_node', {ranged.name: str(too_big)})


def test_an_executable_without_a_table_is_named() -> None:
    with pytest.raises(ValueError, match="no parameter table for the executable 'twin_demo'"):
        node_parameters('twin_demo')


def test_the_parameters_come_file_first_then_fixed_then_single() -> None:
    fixed = [{'sim.spine': False}]
    configurations = {PARAMS_FILE: '/lab.yaml', 'sim.rate': '100', 'swing_amplitude': '0.1'}
    assert node_parameter_list('sim_node', configurations, fixed) == [
        '/lab.yaml', {'sim.spine': False}, {'sim.rate': 100.0}]
    # an empty params_file (structure_node's default) is no file; no single parameter: no dict
    assert node_parameter_list('structure_node', {PARAMS_FILE: ''}, fixed) == fixed


def module_constants(tree: ast.Module) -> dict:
    """The module-level names bound to literals."""
    constants = {}
    for node in tree.body:
        if isinstance(node, ast.Assign) and isinstance(node.targets[0], ast.Name):
            try:
                constants[node.targets[0].id] = ast.literal_eval(node.value)
            except ValueError:
                continue
    return constants


def started_nodes(tree: ast.Module, constants: dict) -> list[tuple[str, list[str]]]:
    """(executable, keys of its fixed parameter dicts) of every ``launch_node`` call; a name that
    is no module constant (``partner`` of twin.launch.py) stands for every partner of TWINS."""
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, 'id', '') == 'launch_node':
            first = node.args[0]
            if isinstance(first, ast.Constant):
                executables = [first.value]
            elif first.id in constants:
                executables = [constants[first.id]]
            else:
                executables = [partner for partner, *_ in constants['TWINS'].values()]
            keys = [key.value for keyword in node.keywords if keyword.arg == 'fixed'
                    for entry in keyword.value.elts for key in entry.keys]
            found += [(executable, keys) for executable in executables]
    return found


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_a_launch_file_sets_only_parameters_of_the_nodes_it_starts(path: Path) -> None:
    source = path.read_text(encoding='utf-8')
    tree = ast.parse(source)
    compile(tree, str(path), 'exec')
    constants = module_constants(tree)
    nodes = started_nodes(tree, constants)
    if 'IncludeLaunchDescription' in source or 'twin_description(KIND)' in source:
        return  # the per-preset bridge files and the spine twin: the included file's nodes
    if path.name == 'stiffness_bridge.launch.py':
        assert 'single_parameters(EXECUTABLE, context.launch_configurations)' in source
        nodes = [(constants['EXECUTABLE'], ['preset', 'target.node'])]
    assert nodes, f'{path.name} starts no node through launch_parameters'
    for argument in ('namespace', 'params_file'):
        assert f"DeclareLaunchArgument('{argument}'" in source or f"'{argument}': (" in source
    for executable, keys in nodes:
        table = by_name(node_parameters(executable))
        assert set(keys) <= set(table), (path.name, executable, set(keys) - set(table))


@pytest.mark.parametrize('path', LAUNCH_FILES, ids=lambda p: p.name)
def test_the_example_command_sets_arguments_the_file_takes(path: Path) -> None:
    """Every ``name:=value`` of the docstring's ``ros2 launch`` example is a declared argument or
    a parameter of a node the file starts, with a value its table takes."""
    source = path.read_text(encoding='utf-8')
    tree = ast.parse(source)
    doc = ast.get_docstring(tree) or ''
    command = re.search(r'ros2 launch \S+ \S+((?:[^\n]|\\\n)*)', doc.replace('\\\\\n', '\\\n'))
    assert command, f'{path.name}: no example command'
    declared = set(re.findall(r"DeclareLaunchArgument\('([\w.]+)'", source)) | set(
        re.findall(r"^    '(\w+)': \(", source, re.M))
    constants = module_constants(tree)
    executables = {executable for executable, _ in started_nodes(tree, constants)}
    if 'twin_description(KIND)' in source:
        executables = {'sim_node', 'spine_node'}
        declared |= {'namespace', 'params_file', 'swing_amplitude', 'swing_period'}
    if 'EXECUTABLE' in constants and 'stiffness_bridge' in constants['EXECUTABLE']:
        executables.add('stiffness_bridge')
    for name, text in re.findall(r'([\w.]+):=(\S+)', command[1]):
        if name in declared:
            continue
        takers = [e for e in executables if name in by_name(node_parameters(e))]
        assert takers, f'{path.name}: {name}:={text} is neither an argument nor a parameter'
        for executable in takers:
            single_parameters(executable, {name: text})
