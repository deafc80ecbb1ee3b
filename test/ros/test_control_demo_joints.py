"""#39 item 1, the demo side, across processes: ``twin_demo --control`` (what
``scripts/run_twin.sh --control`` runs) holds the pose on both templates of ``new-config`` and
on the worked joint examples: once the pose step is on, the controller's ticks are feasible and
the twin's own pose (the true error, beside the estimate's) stays within a bound. The test
reads the live lines as they come and stops the demo as soon as the condition holds."""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path

import pytest

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
from support import REPO

pytestmark = [pytest.mark.ros, pytest.mark.slow]

#: Consecutive live lines of the pose step (or later) that must be feasible and within bound.
HELD_LINES = 3
#: The bound of the true pose error (position m, rotation deg) while held.
TRUE_ERROR_BOUND = (2e-3, 2.0)
DEADLINE_S = 150.0
TRUE = re.compile(r'\(true ([0-9.]+) mm ([0-9.]+) deg\)')


def _demo() -> str:
    from ament_index_python.packages import get_package_prefix

    return str(Path(get_package_prefix('tensegrity_stiffness')) / 'lib' / 'tensegrity_stiffness'
               / 'twin_demo')


def _config(tmp_path: Path, which: str) -> Path:
    if which.startswith('template '):
        out = tmp_path / f'{which.split()[1]}.yaml'
        done = subprocess.run(['tensegrity-stiffness', 'new-config', '--template',
                               which.split()[1], '--out', str(out)], capture_output=True,
                              text=True, check=False, cwd=tmp_path)
        assert done.returncode == 0, done.stderr
        return out
    return REPO / 'config' / 'examples' / which


@pytest.mark.parametrize('which', [
    'template vertebra', 'template ring', 'ring8_joint.yaml', 'ring16_joint.yaml'])
def test_the_control_demo_holds_the_pose_on_any_joint(tmp_path: Path, which: str) -> None:
    config = _config(tmp_path, which)
    proc = subprocess.Popen([_demo(), '--control', '--config', str(config), '--duration', '40'],
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=os.environ.copy(), start_new_session=True)
    lines: list[str] = []
    held = 0
    deadline = time.monotonic() + DEADLINE_S
    try:
        for line in proc.stdout:
            lines.append(line.rstrip())
            assert time.monotonic() < deadline, '\n'.join(lines)
            assert 'exited; see' not in line, '\n'.join(lines)
            if not line.startswith('t ') or ' hold ' in line:
                continue
            true = TRUE.search(line)
            ok = ('feasible true' in line and true is not None
                  and float(true.group(1)) * 1e-3 <= TRUE_ERROR_BOUND[0]
                  and float(true.group(2)) <= TRUE_ERROR_BOUND[1])
            held = held + 1 if ok else 0
            if held >= HELD_LINES:
                break
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGINT)
        out, _ = proc.communicate(timeout=60)
        lines += out.splitlines()
    assert held >= HELD_LINES, '\n'.join(lines)
    assert any('control_demo: stopped' in line for line in lines), '\n'.join(lines)
    assert not any(line.startswith('control_demo: no stiffness step') for line in lines), \
        '\n'.join(lines)
