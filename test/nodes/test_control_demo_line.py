"""The control demo's live line without ROS (issue #39): an infeasible tick says why (the
controller's diagnostic message), a feasible one does not, the twin's true pose error stands
beside the estimate's, and nothing but the head shows before the controller has a state."""

from __future__ import annotations

import math

import numpy as np

from tensegrity_stiffness.nodes.control_demo_line import control_line, pose_error

HEAD = 't   5.0 s  pose step      '
REASON = ('the pose cannot be held under this load within the limits (tension 2 N above '
          'limits.tension_max 1.5 N); the last command is kept')
VALUES = {'pose error [m, rad]': '[0.001, 0.0, 0.0, 0.0, 0.0, 0.01]', 'feasible': 'false',
          'saturated strings': '0', 'tick time [ms]': '0.8', 'achieved tick rate [Hz]': '499',
          'tick rate [Hz]': '500', 'missed ticks': '0', 'stiffness target': 'none',
          'latency from the reading median [ms]': '1.2',
          'latency from the reading p99 [ms]': '3.4'}


def test_an_infeasible_tick_shows_the_controller_s_reason():
    line = control_line(HEAD, VALUES, REASON, {'consistent share': '0.97'}, (2e-3, 0.02))
    assert line.startswith(HEAD)
    assert f'feasible false ({REASON})  tick 0.8 ms' in line
    assert 'pose error 1.000 mm 0.573 deg (true 2.000 mm 1.146 deg)' in line
    assert 'consistent 97.0%' in line and 'K_c error -' in line


def test_a_feasible_tick_shows_no_reason_and_no_state_shows_the_head_alone():
    line = control_line(HEAD, {**VALUES, 'feasible': 'true'}, 'ok', {}, None)
    assert 'feasible true  tick' in line and '(ok)' not in line
    assert '(true -)' in line and 'consistent -' in line
    assert control_line(HEAD, {}, REASON, {}, None) == HEAD
    assert control_line(HEAD, {**VALUES, 'feasible': 'false'}, '', {}, None).count(
        'feasible false  tick') == 1


def test_pose_error_is_the_distance_and_the_angle():
    T = np.eye(4)
    T[:3, 3] = [0.0, 0.003, 0.004]
    c, s = math.cos(0.1), math.sin(0.1)
    T[:3, :3] = [[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]
    np.testing.assert_allclose(pose_error(np.eye(4), T), (0.005, 0.1), rtol=1e-12)
