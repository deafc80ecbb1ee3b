"""The config written by ``tensegrity-stiffness calibrate`` loads in ``stiffness_node`` as it is:
the installed node, started with ``--params-file calibrated.yaml`` over the real middleware,
publishes the calibrated model's wrench and tensions."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
pytestmark = pytest.mark.ros

from geometry_msgs.msg import WrenchStamped  # noqa: E402
from std_msgs.msg import Float64MultiArray  # noqa: E402
from support.calibration_recordings import (  # noqa: E402
    configurations,
    measure,
    nominal_model,
    true_parameters,
)
from support.ros_harness import NodeProcess, RosClient, repeat_until, unique_namespace  # noqa: E402

from tensegrity_stiffness.cli import calibration_report  # noqa: E402
from tensegrity_stiffness.config import load_yaml, packaged_config_path  # noqa: E402
from tensegrity_stiffness.estimation import calibration as cal  # noqa: E402
from tensegrity_stiffness.mechanics.joint import JointModel  # noqa: E402


def test_calibrated_config_runs_in_stiffness_node(tmp_path: Path):
    model = nominal_model()
    k, d = true_parameters(model, 31)
    states = configurations(model, k, d, 60, 31, backend='library')
    result = cal.calibrate_joint(model, measure(model, states, 31, cal.CalibrationNoise()))
    out = calibration_report.write_config(tmp_path / 'calibrated.yaml',
                                          load_yaml(packaged_config_path()), result, 'test')
    calibrated = JointModel.from_yaml(out)
    ns = unique_namespace('calibrated')
    proc = NodeProcess(ns, out)
    ros = RosClient('calibration_test')
    try:
        base = f'{ns}/stiffness_node'
        wrench = ros.subscribe(WrenchStamped, f'{base}/wrench')
        tensions = ros.subscribe(Float64MultiArray, f'{base}/string_tensions')
        screw = ros.publisher(Float64MultiArray, f'{base}/screw')
        ros.wait_for_subscribers(screw)
        ros.wait_for_publishers(f'{base}/wrench')
        xi = calibrated.initial_screw + np.array([0.05, -0.02, 0.03, 1e-3, 0.0, -5e-4])
        state = calibrated.evaluate(xi)
        # until both outputs answered (the node fills a topic only once it sees the subscriber)
        repeat_until(lambda: screw.publish(Float64MultiArray(data=xi.tolist())),
                     lambda: True if len(tensions) and len(wrench) else None)
        got = np.asarray(tensions.messages[0].data)
        np.testing.assert_allclose(got, state.tensions, rtol=0, atol=1e-12)
        w = wrench.messages[0].wrench
        np.testing.assert_allclose([w.force.x, w.force.y, w.force.z, w.torque.x, w.torque.y,
                                    w.torque.z], state.wrench, rtol=0, atol=1e-12)
        # ... and they are not the nominal model's.
        assert np.max(np.abs(model.evaluate(xi).tensions - got)) > 0.01
    finally:
        ros.close()
        code = proc.stop()
    assert code == 0, proc.log()
