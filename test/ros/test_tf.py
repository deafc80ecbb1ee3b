"""The nodes' frames on ``/tf`` and ``/tf_static`` (``tf.enabled``): built against a stand-in
``tf2_msgs`` (``support/tf2_standin.py``: ``TFMessage.msg`` built in the test's workspace with
cmake and g++, as the package's own interfaces are; ``tf2_msgs`` is not on PyPI), then
``support/tf_check.py`` runs in a process that imports it: ``stiffness_node``, ``spine_node``,
``estimator_node``, ``sim_node`` (joint and spine) and ``structure_node`` broadcast frames whose
poses are the library's to 1e-12, the spine's tool frame is latched on ``/tf_static``, and
``tf.enabled: false`` stops the broadcast at run time. Without ``tf2_msgs`` (every other test
here) the nodes run as before."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
from support import REPO

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from support.tf2_standin import build_tf2_msgs, environment_with

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture(scope='module')
def tf2_msgs_prefix(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_tf2_msgs(tmp_path_factory.mktemp('tf2_ws'))


def test_tf_frames_are_the_library_poses(tf2_msgs_prefix: Path) -> None:
    env = environment_with(tf2_msgs_prefix)
    env['PYTHONPATH'] = f'{REPO / "test"}:{env["PYTHONPATH"]}'
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
