"""The kernel's C++ unit tests (gtest through ament_cmake_gtest, closed forms of its math) in the
pytest suite: ``scripts/setup_env.sh`` builds them with the kernel (BUILD_TESTING on); this runs
the binary and fails when any of them fails (or when it was not built)."""

import os
import re
import subprocess
from pathlib import Path

import pytest
from support import REPO

from tensegrity_stiffness.mechanics import kernel

ROOT = REPO
#: Name of the gtest executable (``ament_add_gtest`` in CMakeLists.txt).
GTEST = 'test_kernel_math'
#: Where colcon builds it (the package's build folder).
BUILD_DIR = ROOT / 'build' / 'tensegrity_stiffness'


def gtest_binary() -> Path:
    path = BUILD_DIR / GTEST
    if path.is_file() and os.access(path, os.X_OK):
        return path
    pytest.fail(f'{path} not built: run bash scripts/setup_env.sh (it builds with '
                'BUILD_TESTING=ON)')


@pytest.mark.skipif(os.environ.get(kernel.KERNEL_ENV, '').lower() in kernel.OFF_VALUES,
                    reason=f'{kernel.KERNEL_ENV} selects the numpy path')
def test_kernel_gtests_pass(tmp_path):
    binary = gtest_binary()
    report = tmp_path / 'gtest.xml'
    done = subprocess.run([str(binary), f'--gtest_output=xml:{report}'], capture_output=True,
                          text=True, timeout=120, check=False)
    output = done.stdout[-4000:] + done.stderr[-2000:]
    assert done.returncode == 0, output
    ran = re.search(r'\[==========\] (\d+) tests? from \d+ test suites? ran', done.stdout)
    assert ran and int(ran.group(1)) >= 10, output
    assert '[  PASSED  ]' in done.stdout and 'FAILED' not in done.stdout, output
    assert report.is_file() and 'failures="0"' in report.read_text()
