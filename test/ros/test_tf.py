"""The nodes' frames on ``/tf`` and ``/tf_static`` (``tf.enabled``): ``tf2_msgs`` is not on
PyPI, so the package's setup builds it from its definition (``cmake/tf2_msgs/``, into
``install/tf2_msgs``; ``support/tf2_standin.py`` builds the same in the test's workspace where
neither the setup nor a ROS install provides it), then ``support/tf_check.py`` runs in a process
that imports it: ``stiffness_node``, ``spine_node``, ``estimator_node``, ``sim_node`` (joint
and spine) and ``structure_node`` broadcast frames whose poses are the library's to 1e-12, the
spine's tool frame is latched on ``/tf_static``, and ``tf.enabled: false`` stops the broadcast at
run time (the frames go out only while someone subscribes)."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from support import REPO

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from support.tf2_standin import build_tf2_msgs, environment_with, installed

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture(scope='module')
def tf2_msgs_prefix(tmp_path_factory: pytest.TempPathFactory) -> Path | None:
    """None where this process imports tf2_msgs (the setup's, or a ROS install's), else the
    prefix of one built from the same definition in a workspace of the test's."""
    return None if installed() else build_tf2_msgs(tmp_path_factory.mktemp('tf2_ws'))


def test_the_setup_provides_tf2_msgs() -> None:
    """Every node publishes its frames in the package's own setup (scripts/setup_env.sh builds
    tf2_msgs from cmake/tf2_msgs/ where no ROS install has it)."""
    assert installed(), 'tf2_msgs is not importable: run bash scripts/setup_env.sh'


def test_tf_frames_are_the_library_poses(tf2_msgs_prefix: Path | None) -> None:
    env = dict(os.environ) if tf2_msgs_prefix is None else environment_with(tf2_msgs_prefix)
    env['PYTHONPATH'] = f'{REPO / "test"}:{env.get("PYTHONPATH", "")}'
    ran = subprocess.run([sys.executable, str(REPO / 'test' / 'support' / 'tf_check.py')],
                         env=env, capture_output=True, text=True, timeout=600)
    output = ran.stdout + ran.stderr
    assert ran.returncode == 0, output[-8000:]
    assert 'TF OK' in ran.stdout, output[-8000:]
    lines = re.findall(r'^TF (.+): (\d+) frames, largest difference (\S+)$', ran.stdout, re.M)
    assert {name for name, _, _ in lines} == {
        'stiffness_node', 'spine_node', 'estimator_node', 'sim_node', 'sim_node (spine)',
        'structure_node'}, lines
    for name, count, worst in lines:
        assert int(count) > 0 and float(worst) < 1e-12, (name, count, worst)
