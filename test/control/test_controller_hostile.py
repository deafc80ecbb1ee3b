"""The controller's library side under hostile input (issue #42; #39 item 1): the settings'
start, default limits and refusals, the stiffness target's layout, the integral's restart."""

from __future__ import annotations

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness.control.controller import (
    MIN_QP_ITERATIONS,
    OUT_OF_TIME,
    ControlCommand,
    ControlTarget,
    StiffnessController,
    solve_box_qp,
)
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.design import DEFAULT_TENSION_MAX, DEFAULT_TENSION_MIN
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.mechanics.plausibility import check_target_stiffness
from tensegrity_stiffness.nodes.stiffness_controller import (
    CONTROLLER_PARAMETERS,
    PRETENSION_RANGE,
    controller_settings,
    default_tension_limits,
    stiffness_target,
)

CONFIG = REPO / 'config' / 'default_joint.yaml'


def defaults() -> dict:
    return {spec.name: spec.default for spec in CONTROLLER_PARAMETERS}


def test_a_start_outside_the_range_is_moved_in_with_a_warning() -> None:
    values = defaults()
    values['joint.rest_length_offsets'] = [0.05]  # the config's rest lengths less it: < 0
    settings = controller_settings(values)
    low, high, *_ = settings.limits.for_strings(settings.model.n_strings)
    assert np.all(settings.start >= low) and np.all(settings.start <= high)
    assert 'moved into the range' in settings.start_warning
    values = defaults()
    values['limits.rest_length_min'], values['limits.rest_length_max'] = [0.04], [0.05]
    settings = controller_settings(values)
    assert np.all(settings.start >= 0.04) and 'cross_AA' in settings.start_warning
    assert controller_settings(defaults()).start_warning == ''


def test_refused_settings_name_the_field() -> None:
    values = defaults()
    values['frames.link1'] = ''
    with pytest.raises(ValueError, match=r'frames\.link1 must not be empty'):
        controller_settings(values)
    values = defaults()
    values['joint.rest_length_offsets'] = [-1.0]
    with pytest.raises(ValueError, match=r'true rest length .* must be > 0'):
        controller_settings(values)


def test_default_tension_limits_come_from_the_joint() -> None:
    model = JointModel.from_yaml(CONFIG)
    tensions = model.evaluate(model.initial_screw).tensions
    low, high = default_tension_limits(model)
    assert low == min(DEFAULT_TENSION_MIN, PRETENSION_RANGE[0] * tensions.min())
    assert high == max(DEFAULT_TENSION_MAX, PRETENSION_RANGE[1] * tensions.max())
    # a joint pretensioned at 4x: the range follows its design tensions
    strong = model.with_rest_lengths(model.rest_lengths * 0.9)
    t = strong.evaluate(strong.initial_screw).tensions
    assert default_tension_limits(strong)[1] >= PRETENSION_RANGE[1] * t.max()
    settings = controller_settings(defaults())
    assert settings.limits.tension_max == high
    values = defaults()
    values['limits.tension_max'] = 3.0
    assert controller_settings(values).limits.tension_max == 3.0


def test_stiffness_targets_refused_with_the_reason() -> None:
    with pytest.raises(ValueError, match='layout 3 x 12'):
        stiffness_target(np.ones(36), (3, 12))
    assert stiffness_target(np.ones(36), (6, 6)).shape == (6, 6)
    model = JointModel.from_yaml(CONFIG)
    rng = np.random.default_rng(3)
    A = rng.standard_normal((6, 6))
    for K, reason in ((np.diag([1e12] * 6), 'outside the range'),
                      (np.full((6, 6), 1e308), 'too large'),
                      (-100.0 * np.eye(6), 'not positive semidefinite'),
                      (np.zeros((6, 6)), 'zero'), (A - A.T, 'antisymmetric')):
        with pytest.raises(ValueError, match=reason):
            check_target_stiffness(model, K)


def _turned(angle: float) -> np.ndarray:
    """A turn by ``angle`` about link 2's y axis (the joint's), as a 4x4 on the right."""
    c, s = np.cos(angle), np.sin(angle)
    return np.array([[c, 0.0, s, 0.0], [0.0, 1.0, 0.0, 0.0], [-s, 0.0, c, 0.0],
                     [0.0, 0.0, 0.0, 1.0]])


DT = 0.002


def _run(ctl: StiffnessController, T0: np.ndarray, angles: list[float],
         integrals: list[float] | None = None) -> list[ControlCommand]:
    """Ticks of ``ctl`` at the targets ``T0 @ _turned(a)``, the estimate at ``T0`` throughout
    (the issue's open loop); the commands, and each tick's integral rotation (rad) appended to
    ``integrals``."""
    out = []
    for a in angles:
        out.append(ctl.update(DT, ControlTarget(pose=T0 @ _turned(a)), pose=T0))
        if integrals is not None:
            integrals.append(float(np.linalg.norm(ctl.integral[:3])))
    return out


def _at_first_target() -> tuple[StiffnessController, StiffnessController, np.ndarray]:
    """Two controllers of the default settings held at the unloaded pose T0 with a good
    estimate: the one the test drives and the reference that stays there."""
    settings = controller_settings(defaults())
    model = settings.model
    T0 = exp_se3(model.initial_screw)
    ctl = StiffnessController(model, settings.limits, settings.start)
    reference = StiffnessController(model, settings.limits, settings.start)
    for c in (ctl, reference):
        _run(c, T0, [0.0] * 300)
    return ctl, reference, T0


def test_the_integral_does_not_wind_up_at_a_turned_target() -> None:
    """The issue's: a target turned by 180 deg about the joint's axis needs the same rest
    lengths, so no limit binds; the integral ran to its clamp and sat there. Now the error,
    beyond the clamp, is not integrated, and back at the first target the commands are the
    first target's."""
    ctl, reference, T0 = _at_first_target()
    commands = _run(ctl, T0, [np.pi] * 200)
    assert not commands[-1].saturated.any()
    assert np.linalg.norm(ctl.integral[:3]) < 1e-3 * ctl.integral_limit[0]
    back = _run(ctl, T0, [0.0] * 300)[-1]
    expected = _run(reference, T0, [0.0] * 500)[-1]
    np.testing.assert_allclose(back.rest_lengths, expected.rest_lengths, rtol=0, atol=1e-6)


def test_the_integral_does_not_sit_at_its_clamp_under_a_ramped_target() -> None:
    """A target ramped away by 0.3 rad in steps of 1 mrad (each well below the clamp, so the
    one-tick restart never fires; no limit binds) and back, the estimate at the first target:
    the integral reaches its clamp, rests within 1 / k_i and decays, and back at the first
    target the commands are the first target's (3.3 mm off before the rule)."""
    ctl, reference, T0 = _at_first_target()
    ramp = list(np.linspace(0.0, 0.3, 300))
    integrals: list[float] = []
    commands = _run(ctl, T0, ramp + [0.3] * 300 + ramp[::-1] + [0.0] * 600, integrals)
    assert not any(c.saturated.any() or not c.feasible for c in commands)
    clamp = ctl.integral_limit[0]
    runs = ''.join('x' if z >= clamp * (1 - 1e-9) else ' ' for z in integrals).split()
    assert runs and max(map(len, runs)) <= 1.0 / (ctl.integral_gain * DT) + 1
    assert any('integral correction at its clamp' in c.message for c in commands)
    assert 'integral correction at rest' in commands[-1].message
    expected = _run(reference, T0, [0.0] * 1500)[-1]
    np.testing.assert_allclose(commands[-1].rest_lengths, expected.rest_lengths, rtol=0,
                               atol=1e-6)
    # a target farther than the clamp from where it came to rest (about 0.06 rad, on the way
    # back) with an error within the clamp: the integral runs again
    moved = _run(ctl, T0, list(np.linspace(0.0, -0.19, 190)))
    assert 'at rest' not in moved[-1].message
    assert np.linalg.norm(ctl.integral[:3]) > 1e-3



def test_the_qp_stops_at_its_iteration_limit_and_says_so() -> None:
    """issue #42 item 2: every phase of the tick's QP (the active set, SLSQP's last resort) is
    bounded by ``max_iterations``; a solve that hits the bound is unconverged and its reason
    names the limit (with 1 iteration), where the same QP converges under the default."""
    rng = np.random.default_rng(42)
    n = 12
    G = rng.normal(size=(20, n))
    P, c = G.T @ G, 10.0 * G.T @ rng.normal(size=20)
    A, b = rng.normal(size=(3, n)), rng.normal(size=3)
    lo, hi = np.zeros(n), np.ones(n)
    middle = 0.5 * (lo + hi)
    b = A @ middle  # feasible at the middle: every phase up to SLSQP runs
    full = solve_box_qp(P, c, A, b, lo, hi, middle)
    assert full.converged and full.reason == ''
    assert full.iterations > 2  # the optimum is not the start's face
    capped = solve_box_qp(P, c, A, b, lo, hi, middle, max_iterations=1)
    assert capped.iterations <= 4  # one per phase (SLSQP's feasible point is kept)
    assert capped.reason.startswith('the active-set method stopped at its limit of 1 '
                                    'iterations, then SLSQP stopped after 1 of at most 1 '
                                    'iterations: '), capped.reason
    b_far = A @ rng.uniform(0.2, 0.8, size=n)  # the middle infeasible: the box least squares
    capped = solve_box_qp(P, c, A, b_far, lo, hi, middle, max_iterations=1)
    assert not capped.converged
    assert capped.reason == 'the active-set method stopped at its limit of 1 iterations'
    assert solve_box_qp(P, c, A, b_far, lo, hi, middle).converged


def test_the_qp_stops_at_its_deadline_and_says_so() -> None:
    """issue #42 item 2: a deadline that has passed stops the QP after ``min_iterations``
    (unconverged, ``out_of_time``, the reason :data:`OUT_OF_TIME`); the same QP converges
    without one, and within ``min_iterations`` the deadline is not looked at."""
    rng = np.random.default_rng(42)
    n = 12
    G = rng.normal(size=(20, n))
    P, c = G.T @ G, 10.0 * G.T @ rng.normal(size=20)
    A = rng.normal(size=(3, n))
    lo, hi = np.zeros(n), np.ones(n)
    middle = 0.5 * (lo + hi)
    b = A @ middle
    full = solve_box_qp(P, c, A, b, lo, hi, middle)
    assert full.converged and not full.out_of_time
    late = solve_box_qp(P, c, A, b, lo, hi, middle, deadline=0.0, min_iterations=0)
    assert late.out_of_time and not late.converged and late.iterations == 0
    assert late.reason == f'{OUT_OF_TIME}: the QP passed its deadline after 0 iterations'
    exempt = solve_box_qp(P, c, A, b, lo, hi, middle, deadline=0.0,
                          min_iterations=full.iterations)
    assert exempt.converged and not exempt.out_of_time
    np.testing.assert_allclose(exempt.t, full.t, rtol=0.0, atol=1e-12)


def test_a_tick_past_its_deadline_is_held_and_keeps_the_state() -> None:
    """A reachable stiffness target after an unreachable one: the warm start stalls on a
    degenerate face (more than MIN_QP_ITERATIONS iterations, SLSQP ends it). With a time budget
    of 0 s the tick is held with the named reason, the command and the integral unchanged; the
    next tick starts cold and is held no longer (not a tick held for ever). A tick within
    MIN_QP_ITERATIONS is not judged by the clock."""
    settings = controller_settings(defaults())
    model = settings.model
    T0 = exp_se3(model.initial_screw)
    K = model.evaluate(model.initial_screw).cartesian_stiffness
    off = T0 @ _turned(0.01)  # a pose error (the integral is frozen: a rate limit binds)
    reference = StiffnessController(model, settings.limits, settings.start)
    ctl = StiffnessController(model, settings.limits, settings.start, time_budget=0.0)
    for c in (reference, ctl):
        first = c.update(DT, ControlTarget(pose=T0, cartesian_stiffness=3.0 * K), pose=off)
        assert first.feasible and first.iterations <= MIN_QP_ITERATIONS
    stalled = reference.update(DT, ControlTarget(pose=T0, cartesian_stiffness=K), pose=off)
    assert stalled.feasible and stalled.iterations > MIN_QP_ITERATIONS  # the case exists
    command, integral = ctl.rest_lengths, ctl.integral
    assert not np.allclose(stalled.rest_lengths, command)  # the tick would move the motors
    held = ctl.update(DT, ControlTarget(pose=T0, cartesian_stiffness=K), pose=off)
    assert held.out_of_time and not held.feasible
    assert held.iterations == MIN_QP_ITERATIONS
    assert held.message.startswith(f"{OUT_OF_TIME}: the QP passed the tick's deadline of 0 s "
                                   f'after {MIN_QP_ITERATIONS} iterations'), held.message
    np.testing.assert_array_equal(held.rest_lengths, command)
    np.testing.assert_array_equal(ctl.rest_lengths, command)
    np.testing.assert_array_equal(ctl.integral, integral)
    again = ctl.update(DT, ControlTarget(pose=T0, cartesian_stiffness=K), pose=off)
    assert again.feasible and not again.out_of_time
    assert again.iterations <= MIN_QP_ITERATIONS
    with pytest.raises(ValueError, match='time_budget must be >= 0'):
        StiffnessController(model, settings.limits, settings.start, time_budget=-1.0)
