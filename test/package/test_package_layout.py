"""The colcon install layout is what ``ros2 run`` and ``ros2 launch`` expect.

``ros2 run tensegrity_stiffness stiffness_node`` resolves ``<prefix>/lib/tensegrity_stiffness/
stiffness_node`` through the ament index (``AMENT_PREFIX_PATH``, set by scripts/env.sh); the
parameter files are looked up under ``share/tensegrity_stiffness/config``; the service
definitions are generated into the same package (types ``tensegrity_stiffness/srv/<Name>``,
Python ``tensegrity_stiffness.srv``), and so is the compiled kernel (``lib/``).

Outside the set-up environment (plain ``pytest`` without ``source scripts/env.sh``) these tests
skip with a reason; inside it (``TENSEGRITY_ENV_SOURCED`` set by env.sh, as in scripts/test.sh)
a missing piece is a failure.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path
from typing import Any

import pytest

PACKAGE = 'tensegrity_stiffness'
REPO = Path(__file__).resolve().parents[2]
INTERFACES = 'tensegrity_stiffness.srv'
EXECUTABLE = 'stiffness_node'
SPINE_EXECUTABLE = 'spine_node'
ENV_REQUIRED = bool(os.environ.get('TENSEGRITY_ENV_SOURCED'))


def _unavailable(reason: str) -> None:
    """Fail inside the set-up environment, skip outside it."""
    if ENV_REQUIRED:
        pytest.fail(reason + ' (scripts/env.sh was sourced: the build is incomplete)')
    pytest.skip(reason + ' (not in the set-up environment: source scripts/env.sh)')


@pytest.fixture(scope='module')
def ament() -> Any:
    try:
        import ament_index_python.packages as module
    except ImportError as exc:
        _unavailable(f'ament_index_python not importable: {exc}')
    return module


@pytest.fixture(scope='module')
def prefix(ament: Any) -> Path:
    try:
        return Path(ament.get_package_prefix(PACKAGE))
    except (ament.PackageNotFoundError, OSError):
        _unavailable(f'package {PACKAGE!r} not in the ament index '
                     f'(AMENT_PREFIX_PATH={os.environ.get("AMENT_PREFIX_PATH", "")!r})')
    raise AssertionError('unreachable')


@pytest.fixture(scope='module')
def srv() -> Any:
    try:
        import tensegrity_stiffness.srv as module
    except ImportError as exc:
        _unavailable(f'{INTERFACES} not importable: {exc}')
    return module


def test_executable_where_ros2_run_looks(prefix: Path) -> None:
    exe = prefix / 'lib' / PACKAGE / EXECUTABLE
    assert exe.is_file(), f'{exe} missing'
    assert os.access(exe, os.X_OK), f'{exe} is not executable'


def test_spine_node_executable_where_ros2_run_looks(prefix: Path) -> None:
    exe = prefix / 'lib' / PACKAGE / SPINE_EXECUTABLE
    assert exe.is_file(), f'{exe} missing'
    assert os.access(exe, os.X_OK), f'{exe} is not executable'
    assert (prefix / 'share' / PACKAGE / 'config' / 'default_spine.yaml').is_file()


def test_package_xml_and_marker_installed(prefix: Path) -> None:
    assert (prefix / 'share' / PACKAGE / 'package.xml').is_file()
    marker = prefix / 'share' / 'ament_index' / 'resource_index' / 'packages' / PACKAGE
    assert marker.is_file(), f'ament index marker {marker} missing'


def test_config_files_installed(prefix: Path) -> None:
    configs = sorted((prefix / 'share' / PACKAGE / 'config').glob('*.yaml'))
    assert configs, 'no share/tensegrity_stiffness/config/*.yaml installed'
    assert any(p.name == 'default_joint.yaml' for p in configs)
    for path in configs:
        assert path.resolve().is_file(), f'{path} is a dangling link'
    # The worked examples of docs/your_joint.md, where config.example_config_path finds them.
    examples = sorted((prefix / 'share' / PACKAGE / 'config' / 'examples').glob('*.yaml'))
    assert [p.name for p in examples] == sorted(
        p.name for p in (REPO / 'config' / 'examples').glob('*.yaml'))
    assert all(p.resolve().is_file() for p in examples)


def test_interfaces_kernel_and_command_line_in_the_one_package(prefix: Path) -> None:
    share = prefix / 'share' / PACKAGE
    assert (share / 'srv' / 'SolveEquilibrium.srv').is_file()
    assert (prefix / 'lib' / 'libtensegrity_stiffness_kernel.so').is_file()
    command = prefix / 'bin' / 'tensegrity-stiffness'
    assert command.is_file() and os.access(command, os.X_OK), f'{command} missing'


def test_interfaces_and_library_are_one_python_package(srv: Any) -> None:
    """The generated ``srv`` module sits in the installed folder of the library itself."""
    import tensegrity_stiffness
    import tensegrity_stiffness.mechanics.joint
    installed = Path(os.path.abspath(srv.__file__)).parents[1]
    assert installed.name == PACKAGE
    assert str(installed) in [os.path.abspath(p) for p in tensegrity_stiffness.__path__]
    assert (installed / 'joint.py').exists()


EXPECTED_FIELDS = {
    'SolveEquilibrium': (
        {'external_wrench': 'geometry_msgs/Wrench', 'rest_lengths': 'sequence<double>',
         'initial_screw': 'sequence<double>'},
        {'success': 'boolean', 'message': 'string', 'screw': 'double[6]',
         'pose': 'geometry_msgs/Pose', 'string_wrench': 'geometry_msgs/Wrench',
         'stiffness': 'double[36]', 'cartesian_stiffness': 'double[36]',
         'tensions': 'sequence<double>', 'energy': 'double', 'stable': 'boolean',
         'residual': 'double', 'iterations': 'int32'},
    ),
    'PlanarForwardKinematics': (
        {'actuator_length': 'double', 'actuator_angle': 'double'},
        {'success': 'boolean', 'message': 'string', 'x': 'double', 'y': 'double',
         'platform_angle': 'double', 'stiffness': 'double', 'energy': 'double',
         'stable': 'boolean', 'in_range': 'boolean', 'jacobian': 'double[4]',
         'jacobian_determinant': 'double', 'singularities': 'sequence<string>'},
    ),
    'DesignRestLengths': (
        {'target_screw': 'sequence<double>', 'target_pose': 'geometry_msgs/Pose',
         'external_wrench': 'geometry_msgs/Wrench', 'tension_min': 'double',
         'tension_max': 'double', 'target_cartesian_stiffness': 'sequence<double>'},
        {'success': 'boolean', 'message': 'string', 'rest_lengths': 'sequence<double>',
         'tensions': 'sequence<double>', 'cartesian_stiffness': 'double[36]',
         'stiffness': 'double[36]', 'stiffness_error': 'double', 'stable': 'boolean'},
    ),
    'SolveChainEquilibrium': (
        {'tip_wrench': 'geometry_msgs/Wrench', 'use_gravity': 'boolean',
         'rest_lengths': 'sequence<double>', 'initial_screws': 'sequence<double>'},
        {'success': 'boolean', 'message': 'string', 'screws': 'sequence<double>',
         'tip_pose': 'geometry_msgs/Pose', 'tip_stiffness': 'double[36]',
         'tip_stiffness_base': 'double[36]', 'joint_wrenches': 'sequence<double>',
         'residual': 'double', 'iterations': 'int32', 'stable': 'boolean'},
    ),
    'PlanarInverseKinematics': (
        {'x': 'double', 'y': 'double'},
        {'success': 'boolean', 'message': 'string', 'actuator_length': 'sequence<double>',
         'actuator_angle': 'sequence<double>', 'platform_angle': 'sequence<double>',
         'stiffness': 'sequence<double>', 'stable': 'sequence<boolean>'},
    ),
}


@pytest.mark.parametrize('name', sorted(EXPECTED_FIELDS))
def test_service_fields(srv: Any, name: str) -> None:
    service = getattr(srv, name)
    request_fields, response_fields = EXPECTED_FIELDS[name]
    assert service.Request.get_fields_and_field_types() == request_fields
    assert service.Response.get_fields_and_field_types() == response_fields
    # the type support library loads (fails here if LD_LIBRARY_PATH misses install/.../lib)
    service.Request()
    service.Response()


def test_solve_equilibrium_defaults(srv: Any) -> None:
    response = srv.SolveEquilibrium.Response()
    assert response.stiffness.shape == (36,)
    assert response.cartesian_stiffness.shape == (36,)
    assert response.screw.shape == (6,)
    assert len(response.tensions) == 0
    assert response.pose.orientation.w == 1.0


def test_interface_loaded_once(srv: Any) -> None:
    """The interfaces live in install/ only, never also in the venv (two copies of the C
    libraries would load in random order: docs/install.md, "The ROS 2 wheels from PyPI")."""
    module_file = Path(srv.__file__).resolve()
    venv = Path(sys.prefix).resolve()
    if ENV_REQUIRED:
        assert venv not in module_file.parents, f'{INTERFACES} imported from the venv'
    copies = list(venv.glob(f'lib/python*/site-packages/{PACKAGE}/srv'))
    assert not copies, f'second copy of {INTERFACES} in the venv: {copies}'


@pytest.mark.parametrize('launch_file', ['stiffness_node.launch.py', 'spine_node.launch.py',
                                         'structure_node.launch.py',
                                         'structure_estimator.launch.py'])
def test_launch_file_compiles_and_names_the_installed_executable_and_config(
        prefix: Path, launch_file: str) -> None:
    """``launch`` is not on PyPI: the launch file is compiled and read, not run. It must name an
    executable and a config file that the install has."""
    import ast

    installed = prefix / 'share' / PACKAGE / 'launch' / launch_file
    assert installed.resolve().is_file(), f'{installed} not installed'
    source = installed.read_text()
    tree = ast.parse(source)
    compile(tree, str(installed), 'exec')
    constants = {node.targets[0].id: node.value.value for node in tree.body
                 if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)}
    assert constants['PACKAGE'] == PACKAGE
    assert (prefix / 'lib' / PACKAGE / constants['EXECUTABLE']).is_file()
    assert (prefix / 'share' / PACKAGE / 'config' / constants['CONFIG']).is_file()
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert 'generate_launch_description' in functions
    for argument in ('namespace', 'params_file'):
        assert f"DeclareLaunchArgument('{argument}'" in source


def test_command_line_on_path_after_sourcing(prefix: Path) -> None:
    """``source scripts/env.sh`` (and a workspace's ``install/setup.bash``) put
    ``tensegrity-stiffness`` on PATH: colcon adds the package's ``bin/``."""
    import shutil

    found = shutil.which('tensegrity-stiffness')
    if found is None:
        _unavailable('tensegrity-stiffness not on PATH')
    assert Path(found).parent == prefix / 'bin', found


def _launch_tree(prefix: Path, launch_file: str) -> tuple[str, Any, dict[str, Any]]:
    """The installed launch file's source, syntax tree (compiled) and module-level constants."""
    import ast

    installed = prefix / 'share' / PACKAGE / 'launch' / launch_file
    assert installed.resolve().is_file(), f'{installed} not installed'
    source = installed.read_text()
    tree = ast.parse(source)
    compile(tree, str(installed), 'exec')
    constants = {node.targets[0].id: node.value.value for node in tree.body
                 if isinstance(node, ast.Assign) and isinstance(node.value, ast.Constant)}
    functions = {node.name for node in tree.body if isinstance(node, ast.FunctionDef)}
    assert 'generate_launch_description' in functions
    return source, tree, constants


def test_bridge_launch_file_names_the_executable_and_its_arguments(prefix: Path) -> None:
    """``stiffness_bridge.launch.py``: the installed executable, a default preset the bridge
    knows, every argument the per-preset files and docs/controllers.md use."""
    import ast

    from tensegrity_stiffness.nodes.stiffness_bridge import BRIDGE_PRESETS

    source, tree, constants = _launch_tree(prefix, 'stiffness_bridge.launch.py')
    assert constants['PACKAGE'] == PACKAGE
    assert (prefix / 'lib' / PACKAGE / constants['EXECUTABLE']).is_file()
    arguments = next(ast.literal_eval(node.value) for node in tree.body
                     if isinstance(node, ast.Assign) and node.targets[0].id == 'ARGUMENTS')
    assert set(arguments) == {'preset', 'namespace', 'input_topic', 'output_topic',
                              'target_node', 'params_file'}
    assert arguments['preset'][0] in BRIDGE_PRESETS
    for topic in ('~/input_stiffness', '~/output_stiffness'):
        assert topic in source


def _bridge_presets() -> list[str]:
    try:
        from tensegrity_stiffness.nodes.stiffness_bridge import BRIDGE_PRESETS
    except ImportError:  # outside the set-up environment: the tests below skip anyway
        return []
    return sorted(BRIDGE_PRESETS)


@pytest.mark.parametrize('preset', _bridge_presets())
def test_a_launch_file_per_bridge_preset(prefix: Path, preset: str) -> None:
    """``stiffness_bridge_<preset>.launch.py`` includes the bridge's launch file with its
    preset."""
    source, _, constants = _launch_tree(prefix, f'stiffness_bridge_{preset}.launch.py')
    assert constants['PACKAGE'] == PACKAGE
    assert constants['PRESET'] == preset
    assert (prefix / 'lib' / PACKAGE / constants['EXECUTABLE']).is_file()
    assert (prefix / 'share' / PACKAGE / 'launch' / constants['INCLUDED']).resolve().is_file()
    assert "launch_arguments={'preset': PRESET}" in source
