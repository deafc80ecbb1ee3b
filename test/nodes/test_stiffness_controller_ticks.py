"""The controller's tick rule without ROS (:class:`~tensegrity_stiffness.nodes.
stiffness_controller.ControllerTicks`): no target or a stale state holds the last command, the
time step after a pause is capped, the latency counts once per reading within its window, the
load fed forward follows ``control.use_wrench_estimate``. No rclpy, no threads: time is passed
in."""

from __future__ import annotations

import numpy as np
import pytest

from tensegrity_stiffness.control.controller import ControlTarget
from tensegrity_stiffness.nodes.parameter_specs import defaults
from tensegrity_stiffness.nodes.stiffness_controller import (
    CONTROLLER_PARAMETERS,
    MAX_STEP_PERIODS,
    STAMP_WINDOW,
    ControllerTicks,
    controller_settings,
    new_controller,
    tick_time_budget,
)

PERIOD = 0.002


@pytest.fixture(scope='module')
def settings():
    return controller_settings(defaults(CONTROLLER_PARAMETERS))


@pytest.fixture()
def ticker(settings) -> ControllerTicks:
    return ControllerTicks(settings, new_controller(settings), PERIOD)


def pose_of(settings) -> np.ndarray:
    """The joint's unloaded pose (a target the default controller holds)."""
    model = settings.model
    return model.evaluate(model.initial_screw).transform


def test_no_target_holds_and_says_so(ticker):
    outcome = ticker.tick(1.0, 0)
    assert outcome.command is None and not outcome.error
    assert ticker.hold_reason == 'no target yet' and ticker.ticks == ticker.held == 0


def test_no_state_or_a_stale_one_holds_the_last_command(settings, ticker):
    ticker.target_pose = pose_of(settings)
    assert ticker.tick(1.0, 0).command is None
    assert ticker.held == 1 and 'control.max_state_age' in ticker.hold_reason
    max_age = settings.values['control.max_state_age']
    ticker.take_state(pose_of(settings), received=1.0, stamp_ns=0)
    before = ticker.controller.rest_lengths.copy()
    assert ticker.tick(1.0 + 1.5 * max_age, 0).command is None  # stale
    assert ticker.held == 2 and ticker.ticks == 0
    assert ticker.state_age == pytest.approx(1.5 * max_age)
    np.testing.assert_array_equal(ticker.controller.rest_lengths, before)
    ticker.take_state(pose_of(settings), received=1.2, stamp_ns=0)  # fresh again
    outcome = ticker.tick(1.2, 0)
    assert outcome.command is not None and outcome.command.feasible
    assert ticker.ticks == 1 and ticker.hold_reason == '' and ticker.last is outcome.command


def test_the_time_step_is_one_period_first_and_capped_after_a_pause(settings, ticker):
    """The commands equal those of a controller stepped with dt = one period, then with
    MAX_STEP_PERIODS periods (a pause of 100 periods: missed ticks do not make the integral
    jump)."""
    target = pose_of(settings).copy()
    target[:3, 3] += [0.001, 0.0, 0.0]  # a pose error for the integral to act on
    reference = new_controller(settings)
    ticker.target_pose = target
    ticker.take_state(pose_of(settings), received=0.0, stamp_ns=0)
    first = ticker.tick(0.0, 0).command
    expected = reference.update(PERIOD, ControlTarget(pose=target), pose=pose_of(settings))
    np.testing.assert_array_equal(first.rest_lengths, expected.rest_lengths)
    ticker.take_state(pose_of(settings), received=100 * PERIOD, stamp_ns=0)
    second = ticker.tick(100 * PERIOD, 0).command
    expected = reference.update(MAX_STEP_PERIODS * PERIOD, ControlTarget(pose=target),
                                pose=pose_of(settings))
    np.testing.assert_array_equal(second.rest_lengths, expected.rest_lengths)


def test_the_latency_counts_once_per_reading_within_its_window(settings, ticker):
    ticker.target_pose = pose_of(settings)
    stamp = 5_000_000_000
    ticker.take_state(pose_of(settings), received=1.0, stamp_ns=stamp)
    ticker.tick(1.0, stamp + 2_000_000)
    ticker.tick(1.0 + PERIOD / 2, stamp + 4_000_000)  # the same reading: no second latency
    assert list(ticker.latencies) == [pytest.approx(0.002)]
    assert ticker.ticks == 2 and ticker.old_state_ticks == 0
    ticker.take_state(pose_of(settings), received=2.0,
                      stamp_ns=stamp - int(2 * STAMP_WINDOW[1] * 1e9))  # far in the past
    ticker.tick(2.0 + 3 * PERIOD, stamp)  # a state three periods old
    assert ticker.stamps_out_of_window == 1 and len(ticker.latencies) == 1
    assert ticker.old_state_ticks == 1
    ticker.take_state(pose_of(settings), received=3.0, stamp_ns=0)  # unstamped: no latency
    ticker.tick(3.0, stamp)
    assert ticker.stamps_out_of_window == 1 and len(ticker.latencies) == 1


def test_the_load_follows_use_wrench_estimate(settings):
    known, estimate = np.full(6, 0.01), np.full(6, 0.02)
    ticker = ControllerTicks(settings, new_controller(settings), PERIOD)
    assert ticker.load() is None
    ticker.known_wrench = known
    ticker.take_state(pose_of(settings), received=0.0, stamp_ns=0, wrench=estimate)
    assert ticker.load() is known  # default: the estimate is not fed forward
    values = dict(settings.values, **{'control.use_wrench_estimate': True})
    on = controller_settings(values)
    ticker.reconfigure(on, new_controller(on))
    assert ticker.load() is estimate and ticker.state is not None  # the state is kept


def test_a_refused_update_is_an_error_not_a_command(settings, ticker):
    ticker.target_pose = pose_of(settings)
    ticker.take_state(np.full((4, 4), np.nan), received=0.0, stamp_ns=0)
    outcome = ticker.tick(0.0, 0)
    assert outcome.command is None and outcome.error
    assert ticker.ticks == 0


def test_a_period_must_be_positive(settings):
    with pytest.raises(ValueError, match='period'):
        ControllerTicks(settings, new_controller(settings), 0.0)


def test_a_tick_past_control_time_budget_is_held_and_named(settings):
    """``control.time_budget`` (0: half a period) reaches the controller; a tick whose QP runs
    past it is held, counted, and its message names the parameter. The stalling tick: a
    reachable stiffness target after an unreachable one (test_controller_hostile)."""
    assert tick_time_budget(settings.values) == 0.5 / settings.values['control.rate']
    assert new_controller(settings).time_budget == tick_time_budget(settings.values)
    tight = controller_settings(dict(settings.values, **{'control.time_budget': 1e-9}))
    ticker = ControllerTicks(tight, new_controller(tight), PERIOD)
    model = tight.model
    K = model.evaluate(model.initial_screw).cartesian_stiffness
    ticker.target_pose = pose_of(tight)
    outcomes = []
    for now, stiffness in ((0.0, 3.0 * K), (PERIOD, K)):
        ticker.target_stiffness = stiffness
        ticker.take_state(pose_of(tight), received=now, stamp_ns=0)
        outcomes.append(ticker.tick(now, 0).command)
    first, held = outcomes
    assert first.feasible and not first.out_of_time and ticker.out_of_time == 1
    assert held.out_of_time and not held.feasible
    assert 'time budget exhausted' in held.message
    assert held.message.endswith('(control.time_budget = 1e-09 s)'), held.message
    np.testing.assert_array_equal(held.rest_lengths, first.rest_lengths)


def test_the_target_is_built_once_per_target_set_with_the_same_commands(settings):
    """The ``ControlTarget`` is validated once per target set (issue 37: not every tick); the
    commands are bitwise those of a ticker that builds it every tick (the targets set anew,
    as copies, before each tick), through a pose step, a stiffness target and a bad target."""
    cached, anew = (ControllerTicks(settings, new_controller(settings), PERIOD)
                    for _ in range(2))
    pose = pose_of(settings)
    moved = pose.copy()
    moved[:3, 3] += [0.002, -0.001, 0.001]
    stiffness = None
    rng = np.random.default_rng(4)
    for i in range(60):
        if i == 20:
            pose = moved
        if i == 35:
            stiffness = np.asarray(new_controller(settings).update(  # a probe's controller
                PERIOD, ControlTarget(pose=pose), pose=pose).predicted_cartesian_stiffness)
        if i in (0, 20, 35):
            cached.target_pose, cached.target_stiffness = pose, stiffness
        anew.target_pose = pose.copy()
        anew.target_stiffness = None if stiffness is None else stiffness.copy()
        built = cached.control_target()
        assert (cached.control_target() is built) and (anew.control_target() is not built)
        state = pose_of(settings)
        state[:3, 3] += 1e-4 * rng.standard_normal(3)
        for ticker in (cached, anew):
            ticker.take_state(state, received=1.0 + i * PERIOD, stamp_ns=0)
        a, b = (ticker.tick(1.0 + i * PERIOD, 0) for ticker in (cached, anew))
        assert a.error == b.error and (a.command is None) == (b.command is None), i
        if a.command is not None:
            for name in ('rest_lengths', 'tensions', 'predicted_cartesian_stiffness'):
                assert np.array_equal(getattr(a.command, name), getattr(b.command, name),
                                      equal_nan=True), (i, name)
    cached.target_pose = np.full((4, 4), np.nan)
    with pytest.raises(ValueError):
        cached.control_target()
    for t in (2.0, 2.0 + PERIOD):  # a bad target is refused at every tick, not cached
        cached.take_state(pose_of(settings), received=t, stamp_ns=0)
        assert cached.tick(t, 0).error
