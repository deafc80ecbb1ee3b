"""``tf2_msgs`` for the tests, which is not on PyPI: the package's setup builds the one message
the nodes use, ``tf2_msgs/msg/TFMessage`` (``geometry_msgs/TransformStamped[] transforms``, as in
ros2/geometry2's ``tf2_msgs/msg/TFMessage.msg``), from ``cmake/tf2_msgs/`` into
``install/tf2_msgs`` (:func:`installed`); :func:`build_tf2_msgs` builds the same definition in a
test's workspace with the machine's cmake and g++ by colcon where neither that nor a ROS install
is there, as ``scripts/setup_env.sh`` builds the package's own interfaces (rosidl from the
pinned wheels, the wheels' missing include directories dropped by
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
#: The definition the package's setup builds (scripts/setup_env.sh): one home for both.
DEFINITION = REPO / 'cmake' / 'tf2_msgs'
TF_MESSAGE = (DEFINITION / 'msg' / 'TFMessage.msg').read_text()
PACKAGE_XML = (DEFINITION / 'package.xml.in').read_text()
CMAKE_LISTS = (DEFINITION / 'CMakeLists.txt.in').read_text().replace(
    '@FIXES@', str(REPO / 'cmake' / 'include_directory_fixes.cmake'))


def installed() -> bool:
    """Whether this process imports ``tf2_msgs`` (a stock ROS install, or the package's setup,
    which builds it from :data:`DEFINITION` into ``install/tf2_msgs``)."""
    try:
        import tf2_msgs.msg  # noqa: F401
    except ImportError:
        return False
    return True


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
