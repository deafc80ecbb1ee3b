"""A stand-in for the ``tf2_msgs`` interface package, which is not on PyPI: the package's one
message the nodes use, ``tf2_msgs/msg/TFMessage`` (``geometry_msgs/TransformStamped[]
transforms``, as in ros2/geometry2's ``tf2_msgs/msg/TFMessage.msg``), built in a test's workspace
with the machine's cmake and g++ by colcon, as ``scripts/setup_env.sh`` builds the package's own
interfaces (rosidl from the pinned wheels, the wheels' missing include directories dropped by
``cmake/include_directory_fixes.cmake``). A stock ROS install brings the real package; the nodes
import ``tf2_msgs.msg.TFMessage`` either way, as the controller stand-ins
(``controller_standins.py``) stand in for real controllers.

:func:`build_tf2_msgs` builds it once into a folder; :func:`environment_with` is the environment
in which a process (a node, a client) imports it: its install prefix on ``AMENT_PREFIX_PATH``,
``PYTHONPATH`` and ``LD_LIBRARY_PATH`` (no RPATH in rosidl's libraries: the loader reads
``LD_LIBRARY_PATH`` at a process's start, so the stand-in is for child processes only).
"""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from support import REPO

PACKAGE = 'tf2_msgs'
#: ros2/geometry2, tf2_msgs/msg/TFMessage.msg.
TF_MESSAGE = 'geometry_msgs/TransformStamped[] transforms\n'
PACKAGE_XML = """<?xml version="1.0"?>
<package format="3">
  <name>tf2_msgs</name>
  <version>0.36.0</version>
  <description>Test stand-in of tf2_msgs: TFMessage only.</description>
  <maintainer email="nobody@example.invalid">nobody</maintainer>
  <license>BSD-3-Clause</license>
  <buildtool_depend>ament_cmake</buildtool_depend>
  <buildtool_depend>rosidl_default_generators</buildtool_depend>
  <depend>geometry_msgs</depend>
  <exec_depend>rosidl_default_runtime</exec_depend>
  <member_of_group>rosidl_interface_packages</member_of_group>
  <export><build_type>ament_cmake</build_type></export>
</package>
"""
CMAKE_LISTS = f"""cmake_minimum_required(VERSION 3.20)
project(tf2_msgs)
find_package(ament_cmake REQUIRED)
find_package(rosidl_default_generators REQUIRED)
find_package(geometry_msgs REQUIRED)
include("{REPO / 'cmake' / 'include_directory_fixes.cmake'}")
tsk_drop_missing_include_dirs()
rosidl_generate_interfaces(${{PROJECT_NAME}} "msg/TFMessage.msg" DEPENDENCIES geometry_msgs)
tsk_drop_missing_include_dirs()
ament_export_dependencies(rosidl_default_runtime)
ament_package()
"""


def build_tf2_msgs(workspace: Path) -> Path:
    """Build the stand-in in ``workspace`` (``src/tf2_msgs``, ``build/``, ``install/``) with
    colcon; returns its install prefix (``install/tf2_msgs``). Raises with colcon's output on
    failure."""
    package = workspace / 'src' / PACKAGE
    (package / 'msg').mkdir(parents=True, exist_ok=True)
    (package / 'msg' / 'TFMessage.msg').write_text(TF_MESSAGE)
    (package / 'package.xml').write_text(PACKAGE_XML)
    (package / 'CMakeLists.txt').write_text(CMAKE_LISTS)
    venv = Path(sys.prefix)
    env = os.environ.copy()
    env['PATH'] = f'{venv / "bin"}{os.pathsep}{env.get("PATH", "")}'
    env['CMAKE_PREFIX_PATH'] = os.pathsep.join(filter(None, [str(venv),
                                                             env.get('CMAKE_PREFIX_PATH')]))
    env.pop('PYTHONPATH', None)  # as setup_env.sh builds: the venv's interpreter alone
    python = str(venv / 'bin' / 'python')
    ran = subprocess.run(
        ['colcon', 'build', '--base-paths', 'src', '--event-handlers', 'console_cohesion+',
         'status-', '--cmake-args', '-DBUILD_TESTING=OFF', f'-DPython3_EXECUTABLE={python}',
         f'-DPYTHON_EXECUTABLE={python}'],
        cwd=workspace, env=env, capture_output=True, text=True, timeout=900)
    if ran.returncode != 0:
        raise RuntimeError(f'building the tf2_msgs stand-in failed:\n{ran.stdout[-6000:]}'
                           f'\n{ran.stderr[-3000:]}')
    prefix = workspace / 'install' / PACKAGE
    if not (prefix / 'share' / PACKAGE / 'msg' / 'TFMessage.msg').is_file():
        raise RuntimeError(f'no TFMessage in {prefix}:\n{ran.stdout[-3000:]}')
    return prefix


def environment_with(prefix: Path, env: dict[str, str] | None = None) -> dict[str, str]:
    """``env`` (default: this process's) with the stand-in at ``prefix`` importable."""
    env = dict(os.environ if env is None else env)
    site = prefix / 'lib' / f'python{sys.version_info[0]}.{sys.version_info[1]}' / \
        'site-packages'
    for name, path in (('AMENT_PREFIX_PATH', prefix), ('PYTHONPATH', site),
                       ('LD_LIBRARY_PATH', prefix / 'lib')):
        env[name] = os.pathsep.join(filter(None, [str(path), env.get(name)]))
    return env
