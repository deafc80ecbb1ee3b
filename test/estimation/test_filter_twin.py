"""The recursive filter on the MuJoCo twin (slow): rest lengths swept +-2 mm at 1-5 Hz and a
swinging load, 12 load cells and an IMU every millisecond (support/filter_trials.py). The pose
and twist NEES lie in the chi-square 95 % band over more than 200 windows of seeded runs,
``consistent`` holds on at least 95 % of the clean updates, a broken load cell (-0.3 N, 0.8 N
off) or a flipped IMU is named within 0.1 s, and the static estimator's figures on a resting
twin are those of test_estimation_twin.py (unchanged: that file runs as before). Under the
controller's own steps (StiffnessController in the loop on the filter's estimate: a pose step, a
stiffness step) the NEES is in the band too, with the same defaults: the accelerations' process
noise follows the rate of the commanded rest lengths (ProcessNoise.motion_scale; a constant one
fitted one motion or the other, never both). The spine's filter: its screw NEES in the band on
the moving 5-joint twin."""

import math

import numpy as np
import pytest
from support import REPO
from support.estimation_trials import TENSION_STD, nees_band
from support.filter_trials import (
    BURN_IN,
    SAMPLE_SPACING,
    TIMESTEP,
    Run,
    Sample,
    drive,
    nees,
    readings,
    twin_twist,
)

from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.control.controller import (
    ActuatorLimits,
    ControlTarget,
    StiffnessController,
)
from tensegrity_stiffness.estimation import sensor_models as sm
from tensegrity_stiffness.estimation.chain_filter import ChainFilter
from tensegrity_stiffness.estimation.estimators import Measurements
from tensegrity_stiffness.estimation.joint_filter import JointFilter
from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG, JointChain
from tensegrity_stiffness.mechanics.design import design_rest_lengths
from tensegrity_stiffness.mechanics.joint import JointModel

pytest.importorskip('mujoco')
from tensegrity_stiffness.simulation.twin import (
    DEFAULT_TENDON_DAMPING,
    ChainSimulation,
    JointSimulation,
)

CONFIG = REPO / 'config' / 'default_joint.yaml'
#: Seeded runs and their length (s): 6 x (2.0 - 0.3) s / 0.05 s = 204 windows.
RUNS = 6
DURATION = 2.0
#: Issue 37: clean updates pass the NIS test at least this often.
CONSISTENT_RATE = 0.95
#: A broken sensor is named within this long (s) after it broke.
NAMED_WITHIN = 0.1
FAULTS = ('load cell at -0.3 N', 'load cell 0.8 N off', 'IMU flipped')


@pytest.fixture(scope='module')
def model():
    return JointModel.from_yaml(CONFIG)


@pytest.fixture(scope='module')
def runs(model):
    return [drive(model, seed, DURATION) for seed in range(RUNS)]


@pytest.mark.slow
def test_twin_pose_and_twist_nees_in_band(runs, record_property):
    pose = np.array([s.pose_nees for r in runs for s in r.samples])
    twist = np.array([s.twist_nees for r in runs for s in r.samples])
    assert pose.size >= 200
    low, high = nees_band(pose.size)
    record_property('windows', pose.size)
    record_property('pose NEES', pose.mean())
    record_property('twist NEES', twist.mean())
    print(f'\nfilter on the moving twin: {pose.size} windows, pose NEES {pose.mean():.2f}, '
          f'twist NEES {twist.mean():.2f}, band [{low:.2f}, {high:.2f}]')
    assert low <= pose.mean() <= high
    assert low <= twist.mean() <= high
    assert sum(r.restarts for r in runs) == 0


@pytest.mark.slow
def test_twin_clean_updates_are_consistent(runs, record_property):
    flags = [c for r in runs for c in r.consistent]
    rate = np.mean([c is True for c in flags])
    left_out = sum(bool(o) for r in runs for _, o in r.outliers)
    record_property('consistent rate', rate)
    print(f'\nclean updates consistent: {rate:.2%} of {len(flags)}; a reading left out in '
          f'{left_out}')
    assert rate >= CONSISTENT_RATE


@pytest.mark.slow
@pytest.mark.parametrize('fault', FAULTS)
def test_twin_broken_sensor_named_within_a_tenth_of_a_second(model, fault):
    names = model.string_names
    for seed, cell in ((100, 2), (101, 7), (102, 11)):
        broke = 0.6
        run = drive(model, seed, broke + 0.3, fault, broke, cell)
        name = 'imu' if fault == 'IMU flipped' else f'tension[{names[cell]}]'
        named = [t for t, o in run.outliers if t >= broke and name in o]
        assert named and named[0] - broke <= NAMED_WITHIN, (fault, named[:3])
        # and it stays named (held out) to the end
        after = [o for t, o in run.outliers if t >= named[0]]
        assert np.mean([name in o for o in after]) >= 0.95, fault
        assert run.restarts == 0


# ------------------------------------------------------------------ the controller's own steps
#: The controller in the loop (issue 37, item 5: "the controller's own steps"): seeded runs of
#: this length (s), the controller at 500 Hz on the filter's estimate, a pose step at
#: :data:`POSE_STEP_AT` and a stiffness step at :data:`STIFFNESS_STEP_AT` (s); 6 x (2.0 - 0.3) s
#: / 0.05 s = 204 windows.
CONTROL_RUNS = 6
CONTROL_DURATION = 2.0
CONTROL_TICK = 2  # twin steps (1 ms) per controller tick: 500 Hz
POSE_STEP_AT = 0.3
STIFFNESS_STEP_AT = 1.1
#: The pose step: a turn of this angle (rad) about a seeded axis and a shift of this length (m)
#: along a seeded direction (the control demo's step is 0.4 mrad and 22 mm of screw; the twin
#: test's 2 deg and 1.35 mm).
STEP_ANGLE = 0.025
STEP_SHIFT = 1e-3
#: The controller's rest-length rate limit (m/s), as test_control_twin.py's.
CONTROL_MAX_RATE = 0.05


def controlled_run(model: JointModel, seed: int) -> Run:
    """One seeded run: the twin at rest, then :class:`StiffnessController` (the ROS-free library
    the controller node runs) commanding the rest lengths at 500 Hz from the filter's pose
    estimate, the filter given the rest lengths in force; the target holds the rest pose, steps
    the pose, then the stiffness (the design of tensions in [0.5, 1.5] N at the stepped pose).
    The NEES samples as :func:`support.filter_trials.drive`'s."""
    rng = np.random.default_rng(1000 + seed)
    sim = JointSimulation(model)
    assert sim.settle(1e-9, max_time=20.0)
    T0 = sim.pose()
    axis = rng.normal(size=3)
    shift = rng.normal(size=3)
    T1 = exp_se3(np.r_[STEP_ANGLE * axis / np.linalg.norm(axis), np.zeros(3)]) @ T0
    T1[:3, 3] += STEP_SHIFT * shift / np.linalg.norm(shift)
    design = design_rest_lengths(model, log_se3(T1, reference=model.initial_screw), np.zeros(6),
                                 0.5, 1.5)
    assert design.success, design.message
    phases = ((0.0, ControlTarget(pose=T0)), (POSE_STEP_AT, ControlTarget(pose=T1)),
              (STIFFNESS_STEP_AT, ControlTarget(pose=T1,
                                                cartesian_stiffness=design.cartesian_stiffness)))
    limits = ActuatorLimits(0.5 * model.rest_lengths, 1.2 * model.rest_lengths, CONTROL_MAX_RATE)
    ctl = StiffnessController(model, limits, sim.rest_lengths)
    flt = JointFilter(model, string_damping=DEFAULT_TENDON_DAMPING, stiffness_std=False)
    rest = sim.rest_lengths.copy()
    est = None
    run = Run()
    every = round(SAMPLE_SPACING / TIMESTEP)
    first = round(BURN_IN / TIMESTEP)
    for k in range(round(CONTROL_DURATION / TIMESTEP)):
        t0 = k * TIMESTEP
        if est is not None and k % CONTROL_TICK == 0:
            target = [p for start, p in phases if t0 >= start - 1e-12][-1]
            cmd = ctl.update(CONTROL_TICK * TIMESTEP, target, pose=est.transform)
            rest = cmd.rest_lengths
        sim.set_rest_lengths(rest)
        sim.step(1)
        t = (k + 1) * TIMESTEP
        est = flt.step(t, readings(sim, rng), rest)
        assert est.success, est.message
        run.restarts += est.restarted
        run.consistent.append(est.consistent)
        if k >= first and (k - first) % every == 0:
            e = sm.pose_error(est.transform, sim.pose())
            d = est.twist - twin_twist(sim)
            run.samples.append(Sample(t, nees(e, est.covariance), nees(d, est.twist_covariance)))
    # the steps moved the joint: the twin ends near the stepped pose, far from the rest pose
    moved = np.linalg.norm(sim.pose()[:3, 3] - T0[:3, 3])
    assert moved > 0.5 * STEP_SHIFT, moved
    return run


@pytest.fixture(scope='module')
def controlled_runs(model):
    return [controlled_run(model, seed) for seed in range(CONTROL_RUNS)]


def controlled_nees(runs: list[Run]) -> tuple[np.ndarray, np.ndarray]:
    return (np.array([s.pose_nees for r in runs for s in r.samples]),
            np.array([s.twist_nees for r in runs for s in r.samples]))


@pytest.mark.slow
def test_twin_under_the_controllers_steps_is_not_overconfident(controlled_runs,
                                                               record_property):
    """Issue 37, item 5, "the controller's own steps": over >= 200 windows of seeded runs with
    the controller in the loop the pose and twist NEES are not above the 95 % band (the
    covariance never claims more than the filter knows), ``consistent`` holds on >= 95 % of
    the updates and no track restarts."""
    pose, twist = controlled_nees(controlled_runs)
    rate = float(np.mean([c is True for r in controlled_runs for c in r.consistent]))
    assert pose.size >= 200
    low, high = nees_band(pose.size)
    record_property('controlled pose NEES', pose.mean())
    record_property('controlled twist NEES', twist.mean())
    print(f'\nfilter under the controller\'s steps: {pose.size} windows, pose NEES '
          f'{pose.mean():.2f}, twist NEES {twist.mean():.2f}, band [{low:.2f}, {high:.2f}], '
          f'consistent {rate:.1%}')
    assert pose.mean() <= high
    assert twist.mean() <= high
    assert rate >= CONSISTENT_RATE
    assert sum(r.restarts for r in controlled_runs) == 0


@pytest.mark.slow
def test_twin_nees_in_band_under_the_controllers_steps(controlled_runs, record_property):
    """Issue 37, item 5: the pose and twist NEES in the 95 % band under the controller's own
    steps, with the defaults that put the sweeps' in it (test_twin_pose_and_twist_nees_in_band):
    the accelerations' process noise follows the rest lengths' rate (ProcessNoise.motion_scale).
    With constant densities (rest_rate = 0) the steps gave pose 3.78 and twist 3.47 here
    (pessimistic), and densities that fitted them gave 15-49 on the sweeps."""
    pose, twist = controlled_nees(controlled_runs)
    assert pose.size >= 200
    low, high = nees_band(pose.size)
    record_property('controlled pose NEES', pose.mean())
    record_property('controlled twist NEES', twist.mean())
    assert low <= pose.mean() <= high
    assert low <= twist.mean() <= high


# ------------------------------------------------------------------------------------ spine
#: The spine on the twin: seeded runs of this length (s), every rest length swept as the
#: joint's, 12 load cells per joint; samples every 50 ms after 0.3 s (2 x 18 = 36 samples of
#: the 30 screw coordinates).
SPINE_RUNS = 2
SPINE_DURATION = 1.2


@pytest.mark.slow
def test_twin_spine_screw_nees_in_band(record_property):
    chain = JointChain.from_yaml(packaged_config_path(DEFAULT_SPINE_CONFIG))
    n = chain.n_joints
    values, flags, restarts = [], [], 0
    for seed in range(SPINE_RUNS):
        rng = np.random.default_rng(seed)
        sim = ChainSimulation(chain)
        rest0 = [r.copy() for r in sim.rest_lengths]
        freq = [rng.uniform(1.0, 5.0, size=r.size) for r in rest0]
        amp = [rng.uniform(0.3, 1.0, size=r.size) * 2e-3 * rng.choice([-1.0, 1.0], size=r.size)
               for r in rest0]
        assert sim.settle(1e-9, max_time=30.0)
        flt = ChainFilter(chain, string_damping=DEFAULT_TENDON_DAMPING, stiffness_std=False)
        for k in range(round(SPINE_DURATION / 1e-3)):
            rest = [r0 + a * np.sin(2.0 * math.pi * f * k * 1e-3)
                    for r0, a, f in zip(rest0, amp, freq, strict=True)]
            sim.set_rest_lengths(rest)
            sim.step(1)
            tensions = sim.tensions()
            est = flt.step((k + 1) * 1e-3, [
                Measurements(tensions=tensions[i] + rng.normal(scale=TENSION_STD,
                                                               size=tensions[i].size),
                             tension_std=TENSION_STD) for i in range(n)], rest)
            assert est.success, est.message
            flags.append(est.consistent)
            restarts += est.restarted
            if k >= 300 and k % 50 == 0:
                d = (est.screws - sim.screws()).ravel()
                values.append(float(d @ np.linalg.solve(est.screw_covariance, d)))
    low, high = nees_band(len(values), 6 * n)
    mean = float(np.mean(values))
    rate = float(np.mean([f is True for f in flags]))
    record_property('spine screw NEES', mean)
    print(f'\nspine filter on the moving twin: {len(values)} samples, screw NEES {mean:.1f} '
          f'(band [{low:.1f}, {high:.1f}] for {6 * n} dof), consistent {rate:.1%}')
    assert low <= mean <= high
    assert rate >= CONSISTENT_RATE
    assert restarts == 0
