"""The twin demo's live line (``scripts/run_twin.sh``): the stiffness and the latency are shown
only while input arrives, so a line at 0 Hz (the first seconds, before the subscriptions have
matched; a stopped twin) never shows a K_c or a latency of old or unrelated messages."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.ros.twin_demo import summary_line


@pytest.fixture(scope='module')
def state():
    model = JointModel.from_yaml(packaged_config_path())
    return model.evaluate(model.initial_screw)


@pytest.mark.parametrize('spine', [False, True])
def test_no_input_blanks_the_stiffness_and_the_latency(state, spine: bool) -> None:
    label = 'K_tip' if spine else 'K_c'
    line = summary_line(2.0, 0.0, state.transform, state.cartesian_stiffness, state.tensions,
                        [0.0012, 0.0030], spine=spine, n_strings=12)
    assert 'input      0 Hz' in line
    assert f'{label} -' in line and 'eig' not in line
    assert 'latency -' in line and 'median' not in line
    assert 'slack 0/12' in line and ('tip [' if spine else 'pose [') in line


def test_with_input_the_line_shows_the_eigenvalues_and_latency(state) -> None:
    K = state.cartesian_stiffness
    eig = np.linalg.eigvalsh(0.5 * (K + K.T))
    line = summary_line(4.0, 812.0, state.transform, K, state.tensions, [0.0012, 0.0030, 0.0016],
                        spine=False, n_strings=12)
    assert 'input    812 Hz' in line
    assert f'K_c eig {eig[0]:.4g} .. {eig[-1]:.4g}' in line
    assert 'latency median 1.60 ms max 3.00 ms' in line


def test_nothing_received_yet_is_blank_everywhere() -> None:
    line = summary_line(1.0, 0.0, None, None, None, [], spine=False, n_strings=12)
    assert line == ('t    1.0 s  input      0 Hz  pose -  K_c -  slack -/12  latency -')


def test_a_node_behind_its_input_is_named(state) -> None:
    """#39: an input that outruns the node is said, not shown as a growing latency."""
    K = state.cartesian_stiffness
    line = summary_line(4.0, 1000.0, state.transform, K, state.tensions, [0.05], spine=False,
                        n_strings=12, output_rate=400.0)
    assert 'answered    400 Hz (behind: the input outruns the node, inputs skipped)' in line
    line = summary_line(4.0, 200.0, state.transform, K, state.tensions, [0.001], spine=False,
                        n_strings=12, output_rate=199.0)
    assert 'answered    199 Hz' in line and 'behind' not in line


def test_control_demo_publishes_no_target_from_a_failed_design() -> None:
    """#39: a stiffness step whose design fails (tensions the joint cannot reach) gives no
    target, only the design's message; the default joint's design succeeds."""
    import warnings

    import numpy as np

    from tensegrity_stiffness import config
    from tensegrity_stiffness.ros.control_demo import pose_error, targets

    model = JointModel.from_yaml(packaged_config_path())
    _, stiffness, message = targets(model)
    assert stiffness is not None and message == ''
    assert np.all(np.isfinite(stiffness.data))
    section = dict(config.load_section(packaged_config_path(), 'joint'))
    section['max_lengths'] = [1.001 * r for r in section['rest_lengths']]  # strings barely give
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')  # its initial screw is no longer an equilibrium
        short = JointModel.from_dict(section)
    _, none, why = targets(short)
    assert none is None and 'no tension within the tension' in why
    T = np.eye(4)
    T[:3, 3] = [0.001, 0.0, 0.0]
    assert np.allclose(pose_error(np.eye(4), T), (0.001, 0.0))


@pytest.mark.parametrize('name', ['ring8_joint.yaml', 'ring16_joint.yaml'])
def test_control_demo_designs_a_stiffness_step_for_a_ring_and_the_design_for_a_vertebra(
        name: str) -> None:
    """#39: the stiffness step's design is the controller's QP at the stepped pose: on the
    default joint the optimum of ``design_rest_lengths`` (which holds all six directions), on a
    ring, where that design fails (its spin is not held by the strings), a finite K_c with
    every tension in the step's range."""
    from tensegrity_stiffness import config
    from tensegrity_stiffness.mechanics.design import design_rest_lengths
    from tensegrity_stiffness.ros.control_demo import (
        POSE_STEP,
        STIFFNESS_TENSIONS,
        stiffness_design,
        targets,
    )

    model = JointModel.from_yaml(packaged_config_path())
    xi = model.initial_screw + POSE_STEP
    reference = design_rest_lengths(model, xi, None, *STIFFNESS_TENSIONS)
    design = stiffness_design(model, xi)
    assert reference.success and design.feasible
    scale = np.abs(reference.cartesian_stiffness).max()
    np.testing.assert_allclose(design.predicted_cartesian_stiffness,
                               reference.cartesian_stiffness, rtol=0, atol=1e-9 * scale)
    ring = JointModel.from_yaml(config.example_config_path(name))
    xi = ring.initial_screw + POSE_STEP
    assert not design_rest_lengths(ring, xi, None, *STIFFNESS_TENSIONS).success
    _, stiffness, message = targets(ring)
    assert stiffness is not None and message == ''
    assert np.all(np.isfinite(stiffness.data))
    tensions = stiffness_design(ring, xi).tensions
    assert np.all(tensions >= STIFFNESS_TENSIONS[0] - 1e-12)
    assert np.all(tensions <= STIFFNESS_TENSIONS[1] + 1e-12)


def test_arguments_after_the_double_dash_reach_every_node_last() -> None:
    """#39 item 1: ``run_twin.sh --control --config FILE -- -p limits.tension_max:=3`` passes
    the ROS arguments after ``--`` to each of the three nodes, after the demo's own (a later
    ``-p`` of the same name wins in ROS 2), so they override the demo's settings."""
    from pathlib import Path

    from tensegrity_stiffness.ros.control_demo import node_command_lines
    from tensegrity_stiffness.ros.twin_demo import split_node_arguments

    argv = ['--control', '--config', 'lab.yaml', '--', '-p', 'limits.tension_max:=3.0',
            '-p', 'control.integral_gain:=1.0']
    own, extra = split_node_arguments(argv)
    assert own == ['--control', '--config', 'lab.yaml']
    assert extra == ['-p', 'limits.tension_max:=3.0', '-p', 'control.integral_gain:=1.0']
    assert split_node_arguments(['--control']) == (['--control'], [])
    lines = node_command_lines(Path('lab.yaml'), extra)
    assert [name for name, _ in lines] == ['sim_node', 'estimator_node', 'stiffness_controller']
    for _, args in lines:
        assert args[0] == '--ros-args' and args[-len(extra):] == extra
    controller = lines[2][1]
    # the demo's own integral gain comes first, the user's after it
    assert controller.index('control.integral_gain:=4.0') < controller.index(
        'control.integral_gain:=1.0')
