"""Every executable the package installs where ``ros2 run`` looks answers ``--help`` with its
usage and exit status 0, without starting a node.

The executables run as installed (``<prefix>/lib/tensegrity_stiffness/<name>``, the files
CMakeLists.txt generates from cmake/entry_point.py.in) with a ``ROS_DOMAIN_ID`` that is not a
number: ``rclpy.init`` (the first step of a node, before any DDS participant) fails on it, so an
exit status of 0 proves that no context and no participant was created. The same executable
without ``--help`` fails in that environment, which shows that the check would see a start.
"""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import pytest
from support import REPO

from tensegrity_stiffness.nodes.parameter_docs import asks_for_help, node_usage
from tensegrity_stiffness.nodes.registry import node_tables

PACKAGE = 'tensegrity_stiffness'
#: A domain id rcl refuses: any rclpy.init fails on it (importing rclpy does not).
NO_MIDDLEWARE = {'ROS_DOMAIN_ID': 'not_a_domain'}
#: Generous for a loaded 2-core machine (an import of rclpy and the node module).
TIMEOUT_S = 120.0


def _lib_dir() -> Path:
    try:
        from ament_index_python.packages import PackageNotFoundError, get_package_prefix
    except ImportError as exc:
        pytest.skip(f'ament_index_python not importable: {exc} (source scripts/env.sh)')
    try:
        return Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE
    except (PackageNotFoundError, OSError):
        if os.environ.get('TENSEGRITY_ENV_SOURCED'):
            pytest.fail(f'{PACKAGE} not in the ament index although scripts/env.sh was sourced')
        pytest.skip(f'{PACKAGE} is not built (source scripts/env.sh)')
    raise AssertionError('unreachable')


def _executables() -> list[str]:
    """The node executables of the parameter tables (their usage is checked word by word) and
    every other installed program (twin_demo, the command line), so that a new one is covered."""
    nodes = [t.node for t in node_tables()]
    try:
        from ament_index_python.packages import get_package_prefix

        lib = Path(get_package_prefix(PACKAGE)) / 'lib' / PACKAGE
        installed = sorted(p.name for p in lib.iterdir() if os.access(p, os.X_OK))
    except Exception:  # not built: the tests of the nodes' names skip or fail in _lib_dir
        installed = []
    return nodes + [name for name in installed if name not in nodes]


def _run(exe: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=TIMEOUT_S,
                          env={**os.environ, **NO_MIDDLEWARE}, stdin=subprocess.DEVNULL,
                          check=False)


@pytest.mark.parametrize('name', _executables())
def test_help_prints_the_usage_and_starts_nothing(name: str) -> None:
    exe = _lib_dir() / name
    assert exe.is_file(), f'{exe} is not installed'
    done = _run(exe, '--help')
    assert done.returncode == 0, (done.returncode, done.stdout[-2000:], done.stderr[-2000:])
    assert done.stdout.startswith('usage:'), done.stdout[:500]
    assert 'RCLError' not in done.stderr, done.stderr[-2000:]
    if name in {t.node for t in node_tables()}:
        assert done.stdout == node_usage(name)
        assert f'ros2 run tensegrity_stiffness {name} --ros-args' in done.stdout
        assert f'docs/parameters.md#{name}' in done.stdout


def test_without_help_the_same_environment_fails_to_start_a_node() -> None:
    """The control: rclpy.init fails on that domain id, so ``--help``'s exit 0 above is not a
    node that started and stopped."""
    done = _run(_lib_dir() / 'stiffness_node')
    assert done.returncode != 0, done.stdout[-2000:]
    assert 'ROS_DOMAIN_ID is not an integral number' in done.stderr, done.stderr[-2000:]


def test_help_after_ros_args_is_ros_s() -> None:
    """``-h`` before ``--ros-args`` asks for the usage; after it, it is a ROS argument."""
    assert asks_for_help(['stiffness_node', '--help'])
    assert asks_for_help(['stiffness_node', '-h', '--ros-args', '-p', 'a:=1'])
    assert not asks_for_help(['stiffness_node', '--ros-args', '--help'])
    assert not asks_for_help(['stiffness_node'])


@pytest.mark.parametrize('table', node_tables(), ids=lambda t: t.node)
def test_usage_names_the_packaged_config_and_the_docs_that_exist(table) -> None:
    text = node_usage(table.node)
    assert table.page and (REPO / table.page).is_file(), table.page
    assert f'`{table.node}`' in (REPO / table.page).read_text(encoding='utf-8')
    assert f'## `{table.node}`' in (REPO / 'docs' / 'parameters.md').read_text(encoding='utf-8')
    if table.config:
        run = next(line for line in text.splitlines() if 'ros2 run tensegrity_stiffness' in line)
        config = Path(run.split('--params-file ')[1].split()[0])
        assert config.is_absolute() and config.is_file(), config
        assert config.name == Path(table.config).name
