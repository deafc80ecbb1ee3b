"""``bash scripts/run_twin.sh --structure ...`` (``structure_twin_demo``): the nodes' command
lines (the estimator's inputs remapped onto the twin's, the gait, the markers), the structure's
name resolved or refused, and the live line across processes: the twin's line and, with
``--estimate``, the estimate's error against the twin's truth."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from tensegrity_stiffness.ros import structure_twin_demo as demo


def test_the_command_lines_wire_the_estimator_to_the_twin() -> None:
    args = demo.build_parser().parse_args(['--structure', 'three_bar', '--roll', '2',
                                           '--estimate', '--markers', '--method', 'static'])
    lines = demo.commands(args, ['-p', 'qos.depth:=10'])
    twin, estimator = lines[demo.TWIN], lines[demo.ESTIMATOR]
    assert 'structure.config:=three_bar.yaml' in twin and 'gait.steps:=2' in twin
    assert 'markers.enabled:=true' in twin and 'noise.lengths:=0.001' in twin
    assert 'estimation.method:=static' in estimator
    remaps = {estimator[k + 1] for k, a in enumerate(estimator) if a == '-r'}
    for name in ('measured_lengths', 'measured_rest_lengths', 'measured_contacts',
                 'measured_markers', 'imu/bar0', 'imu/bar1', 'imu/bar2'):
        assert f'~/{name}:={demo.TWIN}/{name}' in remaps
    assert twin[-2:] == estimator[-2:] == ['-p', 'qos.depth:=10']


def test_a_structure_is_a_file_or_a_packaged_example() -> None:
    assert demo.structure_config('six_bar') == 'six_bar.yaml'
    with pytest.raises(SystemExit, match='--structure nine_bar'):
        demo.structure_config('nine_bar')


@pytest.mark.slow
@pytest.mark.ros
def test_the_live_line_shows_the_estimate_s_error() -> None:
    """The 3-bar twin with the static estimator for 20 s (the demo's clock starts with its
    nodes, whose start took 9 s beside the suite's colcon build): a line with the twin's state
    and the estimate's error (waited for by the demo's own --duration; its exit status 0)."""
    done = subprocess.run([sys.executable, '-m', 'tensegrity_stiffness.ros.structure_twin_demo',
                           '--structure', 'three_bar', '--estimate', '--method', 'static',
                           '--duration', '20'], capture_output=True, text=True, timeout=120,
                          env=os.environ.copy())
    assert done.returncode == 0, done.stdout[-3000:] + done.stderr[-3000:]
    errors = [(float(mm), float(deg)) for mm, deg in re.findall(
        r'contacts bar0\.a,bar1\.a,bar2\.a .* est err ([\d.]+) mm ([\d.]+) deg', done.stdout)]
    assert errors, done.stdout[-3000:]
    assert min(mm for mm, _ in errors) < 5.0 and min(deg for _, deg in errors) < 3.0, errors
