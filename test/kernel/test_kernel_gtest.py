"""The kernel's C++ unit tests (gtest through ament_cmake_gtest) in the pytest suite: the closed
forms of its math (``test_kernel_math``) and the C++ header over its ABI
(``test_joint_kernel_hpp``). ``scripts/setup_env.sh`` builds them with the kernel (BUILD_TESTING
on); this runs each binary and fails when any of its tests fails (or when it was not built), and
checks that the installed ``kernel_defaults.h`` is the one the Python package writes now."""

import os
import re
import subprocess
from pathlib import Path

import pytest
from support import REPO

from tensegrity_stiffness.mechanics import kernel

ROOT = REPO
#: The gtest executables (``ament_add_gtest`` in CMakeLists.txt) and the fewest tests each runs.
GTESTS = {'test_kernel_math': 10, 'test_joint_kernel_hpp': 5}
#: Where colcon builds them (the package's build folder).
BUILD_DIR = ROOT / 'build' / 'tensegrity_stiffness'


def gtest_binary(name: str) -> Path:
    path = BUILD_DIR / name
    if path.is_file() and os.access(path, os.X_OK):
        return path
    pytest.fail(f'{path} not built: run bash scripts/setup_env.sh (it builds with '
                'BUILD_TESTING=ON)')


@pytest.mark.skipif(os.environ.get(kernel.KERNEL_ENV, '').lower() in kernel.OFF_VALUES,
                    reason=f'{kernel.KERNEL_ENV} selects the numpy path')
@pytest.mark.parametrize('name', sorted(GTESTS))
def test_kernel_gtests_pass(tmp_path, name):
    binary = gtest_binary(name)
    report = tmp_path / 'gtest.xml'
    done = subprocess.run([str(binary), f'--gtest_output=xml:{report}'], capture_output=True,
                          text=True, timeout=120, check=False)
    output = done.stdout[-4000:] + done.stderr[-2000:]
    assert done.returncode == 0, output
    ran = re.search(r'\[==========\] (\d+) tests? from \d+ test suites? ran', done.stdout)
    assert ran and int(ran.group(1)) >= GTESTS[name], output
    assert '[  PASSED  ]' in done.stdout and 'FAILED' not in done.stdout, output
    assert report.is_file() and 'failures="0"' in report.read_text()


def test_installed_defaults_header_is_the_python_packages():
    installed = ROOT / 'install' / 'tensegrity_stiffness' / 'include' / 'tensegrity_stiffness' / \
        'tensegrity_stiffness' / kernel.DEFAULTS_HEADER
    if not installed.is_file():
        pytest.fail(f'{installed} not installed: run bash scripts/setup_env.sh')
    assert installed.read_text() == kernel.defaults_header(), (
        f'{installed} is stale: rebuild (TENSEGRITY_FORCE=1 bash scripts/setup_env.sh)')
