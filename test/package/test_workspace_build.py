"""The repository builds in a colcon workspace as a ROS user builds it.

``git clone <checkout> ws/src/tensegrity_stiffness`` next to another package that depends on it
(a C++ package: ``find_package(tensegrity_stiffness)``, ``target_link_libraries(...
tensegrity_stiffness::kernel)`` and ``joint_kernel.hpp``), ``cd ws && colcon build`` in this
environment, ``source install/setup.bash``, then ``test/support/workspace_check.py`` runs
the consumer's program (the default joint's K_c equal to the Python library's to 1e-12) and starts
the installed ``stiffness_node`` from ``ws/install`` (through the ament index, as ``ros2 run``
does) for a correct K and an equilibrium. Nothing of the checkout's own build (its install/) is
on any path of the workspace's environment.

The build passes ``--cmake-args -DBUILD_TESTING=OFF``, its one option, which reuses what the
setup proved: scripts/setup_env.sh builds the same CMakeLists.txt with ``BUILD_TESTING=ON`` (in CI
from a fresh clone too) and test_kernel_gtest.py runs those gtests, while compiling googletest
and the two gtests again here was a third of this build (CPU 57 s against 37 s without them,
side by side on the 2-core machine). Everything this test proves beyond that (the clone holds
every file the build needs, the workspace layout, the consumer's ``find_package`` and link, the
ament index of ``ws/install``) is built and checked as before.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path

import pytest
from support import REPO

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

pytestmark = [pytest.mark.ros, pytest.mark.slow]

REPO = REPO
PATH_VARIABLES = ('AMENT_PREFIX_PATH', 'CMAKE_PREFIX_PATH', 'COLCON_PREFIX_PATH', 'PYTHONPATH',
                  'LD_LIBRARY_PATH', 'PATH')

CONSUMER_PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>tensegrity_consumer</name>
  <version>0.0.1</version>
  <description>Beside tensegrity_stiffness in the workspace, depends on it.</description>
  <maintainer email="nobody@example.invalid">nobody</maintainer>
  <license>Apache-2.0</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <depend>tensegrity_stiffness</depend>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
CONSUMER_CMAKE = """cmake_minimum_required(VERSION 3.8)
project(tensegrity_consumer CXX)
find_package(ament_cmake REQUIRED)
find_package(tensegrity_stiffness REQUIRED)
add_executable(joint_stiffness src/joint_stiffness.cpp)
target_compile_options(joint_stiffness PRIVATE -Wall -Wextra -Wpedantic -Werror)
target_link_libraries(joint_stiffness tensegrity_stiffness::kernel)
install(TARGETS joint_stiffness DESTINATION lib/${PROJECT_NAME})
ament_package()
"""
#: The consumer's C++ program (joint_kernel.hpp over the kernel): F, K, K_c of a joint.
CONSUMER_SOURCE = REPO / 'test' / 'kernel' / 'consumer_joint_stiffness.cpp'


def _without_checkout_build(env: dict[str, str]) -> dict[str, str]:
    """The environment less every path entry inside the checkout's install/ or build/."""
    own = (str(REPO / 'install'), str(REPO / 'build'))
    clean = dict(env)
    for name in PATH_VARIABLES:
        if name in clean:
            kept = [p for p in clean[name].split(os.pathsep) if p and not p.startswith(own)]
            clean[name] = os.pathsep.join(kept)
    return clean


def test_clone_build_and_run_in_a_workspace(tmp_path: Path) -> None:
    if shutil.which('git') is None or shutil.which('colcon') is None:
        pytest.fail('git and colcon are needed (scripts/setup_env.sh installs colcon)')
    ws = tmp_path / 'ws'
    src = ws / 'src'
    src.mkdir(parents=True)
    subprocess.run(['git', 'clone', '--quiet', str(REPO), str(src / 'tensegrity_stiffness')],
                   check=True)
    consumer = src / 'tensegrity_consumer'
    consumer.mkdir()
    (consumer / 'package.xml').write_text(CONSUMER_PACKAGE_XML)
    (consumer / 'CMakeLists.txt').write_text(CONSUMER_CMAKE)
    (consumer / 'src').mkdir()
    shutil.copy(CONSUMER_SOURCE, consumer / 'src' / 'joint_stiffness.cpp')

    env = _without_checkout_build(os.environ.copy())
    script = f"""
set -e
cd {ws}
colcon list --names-only
colcon build --event-handlers console_cohesion- status- --cmake-args -DBUILD_TESTING=OFF
set +u
source install/setup.bash
set -u
python {src / 'tensegrity_stiffness' / 'test' / 'support' / 'workspace_check.py'} {ws / 'install'}
"""
    env['PYTHONPATH'] = os.pathsep.join(
        filter(None, [str(src / 'tensegrity_stiffness' / 'test'), env.get('PYTHONPATH', '')]))
    result = subprocess.run(['bash', '-c', script], env=env, cwd=ws, capture_output=True,
                            text=True, timeout=900)
    output = result.stdout + result.stderr
    assert result.returncode == 0, output[-6000:]
    listed = result.stdout.split()
    assert 'tensegrity_stiffness' in listed and 'tensegrity_consumer' in listed, output[-3000:]
    assert 'C++ consumer: F, K, K_c relative error' in result.stdout, output[-6000:]
    assert 'WORKSPACE OK' in result.stdout, output[-6000:]
