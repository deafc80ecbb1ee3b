"""The library, the command line and the bag command run where no ROS is installed.

Each check runs in a subprocess whose ``sitecustomize`` (first on ``PYTHONPATH``) puts a meta-path
finder in front of every other: importing rclpy, a ROS message package, the project's interfaces,
``tensegrity_stiffness.ros.conversions`` or ``tensegrity_stiffness.ros`` raises ImportError there
(and is reported on stderr, so an import that some code catches is seen too). The outputs are
checked against the library in this process: every module of the library imports, two CLI commands
print what they print here, and the bag command writes the answers of ``test_bag``'s and
``test_bag_spine``'s scenarios (mcap and sqlite3), checked message by message.
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from support import REPO

from tensegrity_stiffness import cli

pytest.importorskip('rosbags')

REPO = REPO

#: Top-level names (and their submodules) the subprocess cannot import.
BLOCKED = ('rclpy', 'std_msgs', 'geometry_msgs', 'sensor_msgs', 'diagnostic_msgs',
           'visualization_msgs', 'builtin_interfaces', 'rcl_interfaces',
           'tensegrity_stiffness.ros', 'tensegrity_stiffness.srv',
           'ament_index_python', 'rosidl_runtime_py', 'launch', 'launch_ros')
BLOCKED_MARK = 'blocked import (no ROS here):'

SITECUSTOMIZE = f'''
import importlib.abc
import sys

BLOCKED = {BLOCKED!r}


class NoRos(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if any(name == b or name.startswith(b + '.') for b in BLOCKED):
            sys.stderr.write({BLOCKED_MARK!r} + ' ' + name + '\\n')
            raise ImportError({BLOCKED_MARK!r} + ' ' + name, name=name)
        return None


sys.meta_path.insert(0, NoRos())
'''


@pytest.fixture(scope='module')
def no_ros_env(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """The environment of a subprocess that cannot import ROS (see the module docstring)."""
    site = tmp_path_factory.mktemp('no_ros')
    (site / 'sitecustomize.py').write_text(SITECUSTOMIZE)
    path = [str(site), str(REPO), *filter(None, os.environ.get('PYTHONPATH', '').split(
        os.pathsep))]
    return dict(os.environ, PYTHONPATH=os.pathsep.join(path))


def run_without_ros(env: dict[str, str], *args: str | Path) -> subprocess.CompletedProcess:
    """``python args`` in the no-ROS environment; fails the test on a blocked import."""
    result = subprocess.run([sys.executable, *map(str, args)], capture_output=True, text=True,
                            env=env, timeout=180, check=False)
    assert BLOCKED_MARK not in result.stderr, result.stderr
    return result


def run_cli_here(*args: str | Path) -> tuple[int, str]:
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = cli.main([str(a) for a in args])
    return code, out.getvalue()


def test_the_subprocess_cannot_import_ros(no_ros_env: dict[str, str]) -> None:
    """The guard works (else the other tests here prove nothing)."""
    for name in ('rclpy', 'std_msgs.msg', 'tensegrity_stiffness.ros.conversions',
                 'tensegrity_stiffness.ros.runtime.node_base'):
        result = subprocess.run([sys.executable, '-c', f'import {name}'], capture_output=True,
                                text=True, env=no_ros_env, timeout=60, check=False)
        assert result.returncode == 1 and f'{BLOCKED_MARK} {name.split(".")[0]}' in (
            result.stderr), (name, result.stderr)


def test_every_library_module_imports_and_computes_without_ros(
        no_ros_env: dict[str, str]) -> None:
    code = '''
import importlib, json, pkgutil
import numpy as np
import tensegrity_stiffness
from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import processing

# iter_modules does not import; each subpackage is imported to list its modules. Left out: the
# ROS layer (ros), what the colcon build generates into the installed package (the service
# types srv and their C type-support extensions) and the command line's __main__ (it runs).
SKIP = ('tensegrity_stiffness.ros', 'tensegrity_stiffness.srv')


def walk(path, prefix):
    for m in pkgutil.iter_modules(path, prefix):
        if m.name in SKIP or '__rosidl_typesupport' in m.name or m.name.endswith('.__main__'):
            continue
        yield m.name
        if m.ispkg:
            yield from walk(importlib.import_module(m.name).__path__, m.name + '.')


names = sorted(walk(tensegrity_stiffness.__path__, 'tensegrity_stiffness.'))
for name in names:
    importlib.import_module(name)
model = JointModel.from_yaml(config.packaged_config_path())
out = processing.joint_outputs(model, model.initial_screw + 0.01)
print(json.dumps({'modules': names, 'stiffness': out.state.stiffness.tolist()}))
'''
    result = run_without_ros(no_ros_env, '-c', code)
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    for name in ('recordings.bag', 'cli', 'cli.parser', 'nodes.layouts', 'nodes.messages',
                 'nodes.processing', 'nodes.spine_processing', 'joint', 'mechanics.chain',
                 'estimation.calibration', 'simulation.twin', 'geometry.screw'):
        assert f'tensegrity_stiffness.{name}' in report['modules']
    from tensegrity_stiffness import config
    from tensegrity_stiffness.mechanics.joint import JointModel
    from tensegrity_stiffness.nodes import processing

    model = JointModel.from_yaml(config.packaged_config_path())
    here = processing.joint_outputs(model, model.initial_screw + 0.01).state.stiffness
    assert report['stiffness'] == here.tolist()


@pytest.mark.parametrize('argv', [['joint', '--screw', '0.1', '0', '0', '0', '0', '0.03'],
                                  ['chain']])
def test_cli_commands_print_what_they_print_with_ros(no_ros_env: dict[str, str],
                                                     argv: list[str]) -> None:
    code, here = run_cli_here(*argv, '--json')
    assert code == 0
    result = run_without_ros(no_ros_env, '-m', 'tensegrity_stiffness.cli', *argv, '--json')
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout) == json.loads(here)


@pytest.mark.parametrize('storage', ['mcap', 'sqlite3'])
def test_bag_command_answers_like_the_node_without_ros(no_ros_env: dict[str, str],
                                                       tmp_path: Path, storage: str) -> None:
    from support import bag_recordings as test_bag

    msgs, expected, rejected = test_bag.scenario()
    src = test_bag.write_bag(tmp_path / 'in', msgs, storage)
    result = run_without_ros(no_ros_env, '-m', 'tensegrity_stiffness.cli', 'bag', src,
                             '--out', tmp_path / 'out', '--json')
    assert result.returncode == 0, result.stderr
    report = json.loads(result.stdout)
    assert report['storage'] == storage and report['rejected'] == rejected
    test_bag.check_output(tmp_path / 'out', expected)


def test_spine_bag_command_answers_like_the_node_without_ros(no_ros_env: dict[str, str],
                                                             tmp_path: Path) -> None:
    from support import spine_bag_recordings as test_bag_spine

    msgs, expected, rejected = test_bag_spine.scenario()
    src = test_bag_spine.write_bag(tmp_path / 'in', msgs, 'mcap')
    result = run_without_ros(no_ros_env, '-m', 'tensegrity_stiffness.cli', 'bag', src,
                             '--out', tmp_path / 'out', '--node', 'spine', '--json')
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)['rejected'] == rejected
    test_bag_spine.check_output(tmp_path / 'out', expected)
