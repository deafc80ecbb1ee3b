"""Unit tests of tensegrity_stiffness.control.controller (no twin: the model itself is the
plant)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.control.controller import (
    ActuatorLimits,
    ChainStiffnessController,
    ControlTarget,
    StiffnessController,
    adjoint_twist,
    pose_terms,
    pose_terms_at,
    pose_terms_numpy,
    relative_stiffness_error,
    rest_from_tensions,
    solve_box_qp,
    tension_bounds,
    warm_face,
    warm_face_numpy,
)
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics import kernel
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.design import design_rest_lengths, rest_length_sensitivity
from tensegrity_stiffness.mechanics.joint import JointModel

#: The compiled kernel against the numpy path (relative to each quantity's largest entry).
KERNEL_TOLERANCE = 1e-12
needs_kernel = pytest.mark.skipif(not kernel.available(), reason=kernel.status())

DT = 0.002
RATE = 0.05
#: Relative slack on the rate limit (rounding of prev +- rate dt).
RATE_ROUNDING = 1e-9
FD_STEP = 1e-7


def joint(force_law: str = 'hooke') -> JointModel:
    section = dict(config.load_section(config.packaged_config_path(), 'joint'))
    section['force_law'] = force_law
    return JointModel.from_dict(section)


def limits(model: JointModel, rate: float = RATE, low: float = 0.5, high: float = 1.2
           ) -> ActuatorLimits:
    return ActuatorLimits(low * model.rest_lengths, high * model.rest_lengths, rate)


def near_screw(model: JointModel, rng: np.random.Generator) -> np.ndarray:
    return model.initial_screw + np.concatenate([rng.normal(0, 0.03, 3), rng.normal(0, 1e-3, 3)])


# ---------------------------------------------------------------------------------- inputs
@pytest.mark.parametrize('kwargs, match', [
    ({'rest_length_min': 0.05, 'rest_length_max': 0.04, 'max_rate': 1.0}, 'rest_length_max'),
    ({'rest_length_min': 0.04, 'rest_length_max': 0.04, 'max_rate': 1.0}, 'rest_length_max'),
    ({'rest_length_min': 0.01, 'rest_length_max': 0.04, 'max_rate': 0.0}, 'max_rate'),
    ({'rest_length_min': 0.01, 'rest_length_max': 0.04, 'max_rate': -1.0}, 'max_rate'),
    ({'rest_length_min': float('nan'), 'rest_length_max': 0.04, 'max_rate': 1.0},
     'rest_length_min'),
    ({'rest_length_min': 0.01, 'rest_length_max': 0.04, 'max_rate': float('nan')}, 'max_rate'),
    ({'rest_length_min': 0.0, 'rest_length_max': 0.04, 'max_rate': 1.0}, 'rest_length_min'),
    ({'rest_length_min': 0.01, 'rest_length_max': 0.04, 'max_rate': 1.0, 'tension_min': 2.0,
      'tension_max': 1.0}, 'tension_max'),
    ({'rest_length_min': 0.01, 'rest_length_max': 0.04, 'max_rate': 1.0, 'tension_min': 0.0},
     'tension_min'),
    ({'rest_length_min': [0.01, 0.02], 'rest_length_max': [0.04] * 3, 'max_rate': 1.0},
     'same length'),
])
def test_limits_reject_bad_fields(kwargs: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        ActuatorLimits(**kwargs)


def test_limits_per_string_and_scalar() -> None:
    lim = ActuatorLimits(0.01, np.linspace(0.04, 0.05, 12), 0.1)
    lo, hi, rate, tmin, tmax = lim.for_strings(12)
    assert lo.shape == hi.shape == rate.shape == tmin.shape == tmax.shape == (12,)
    assert hi[-1] == pytest.approx(0.05)
    with pytest.raises(ValueError, match='rest_length_max'):
        lim.for_strings(11)


def test_target_validation_and_forms() -> None:
    model = joint()
    T = exp_se3(model.initial_screw)
    from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
    seven = np.concatenate([T[:3, 3], rotation_to_quaternion(T[:3, :3])])
    np.testing.assert_allclose(ControlTarget(pose=seven).transform, T, atol=1e-12)
    np.testing.assert_allclose(ControlTarget(screw=model.initial_screw).transform, T,
                               atol=1e-12)
    with pytest.raises(ValueError, match='cartesian_stiffness'):
        ControlTarget(pose=T, cartesian_stiffness=np.eye(5))
    bad = np.eye(6)
    bad[1, 2] = np.nan
    with pytest.raises(ValueError, match='cartesian_stiffness'):
        ControlTarget(pose=T, cartesian_stiffness=bad)
    with pytest.raises(ValueError, match='pose'):
        ControlTarget()
    with pytest.raises(ValueError, match='pose'):
        ControlTarget(pose=T, screw=model.initial_screw)
    with pytest.raises(ValueError, match='pose'):
        ControlTarget(pose=np.eye(3))
    with pytest.raises(ValueError, match='stiffness_weight'):
        ControlTarget(pose=T, stiffness_weight=-np.ones(6))
    w = ControlTarget(pose=T, stiffness_weight=np.arange(1.0, 7.0)).stiffness_weight
    np.testing.assert_allclose(w, np.outer(np.arange(1.0, 7.0), np.arange(1.0, 7.0)))


# ---------------------------------------------------------------------------------- the pose
@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_pose_terms_match_the_model(force_law: str) -> None:
    """K_c(t) = K0 + sum t_j M_j and F = B t against the model at designed rest lengths, and
    M_j dt/dl0_j against the design's sensitivity and central differences of the model."""
    model = joint(force_law)
    rng = np.random.default_rng(1)
    for _ in range(4):
        xi = near_screw(model, rng)
        res = design_rest_lengths(model, xi, np.zeros(6))
        assert res.success
        terms = pose_terms(model, xi)
        state = model.evaluate(xi, res.rest_lengths)
        np.testing.assert_allclose(terms.K0 + np.einsum('j,jab->ab', res.tensions, terms.M),
                                   state.cartesian_stiffness, atol=1e-10)
        np.testing.assert_allclose(terms.B @ res.tensions, state.wrench, atol=1e-12)
        np.testing.assert_allclose(rest_from_tensions(model, terms.lengths, res.tensions),
                                   res.rest_lengths, atol=1e-14)
        sens = rest_length_sensitivity(model, xi, res.rest_lengths)
        dt_dl0 = -model.k if force_law == 'hooke' else -model.k / terms.lengths
        np.testing.assert_allclose(terms.M * dt_dl0[:, None, None], sens.cartesian_stiffness,
                                   atol=1e-9)
        j = int(rng.integers(12))
        plus, minus = res.rest_lengths.copy(), res.rest_lengths.copy()
        plus[j] += FD_STEP
        minus[j] -= FD_STEP
        fd = (model.evaluate(xi, plus).cartesian_stiffness
              - model.evaluate(xi, minus).cartesian_stiffness) / (2 * FD_STEP)
        np.testing.assert_allclose(terms.M[j] * dt_dl0[j], fd, atol=1e-5 * np.abs(fd).max())


@needs_kernel
@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_pose_terms_in_the_kernel_equal_the_numpy_path(force_law: str) -> None:
    """tsk_joint_pose_terms against pose_terms_numpy at poses near and far from the start."""
    model = joint(force_law)
    assert model.uses_kernel
    rng = np.random.default_rng(2)
    for k in range(20):
        xi = near_screw(model, rng) if k < 10 else np.r_[rng.normal(0, 1.0, 3),
                                                         rng.normal(0, 0.02, 3)]
        T = exp_se3(xi)
        new, ref = pose_terms_at(model, T), pose_terms_numpy(model, T)
        for name in ('lengths', 'B', 'K0', 'M', 'cap'):
            a, b = getattr(new, name), getattr(ref, name)
            assert a.shape == b.shape and a.dtype == b.dtype
            np.testing.assert_allclose(a, b, rtol=0.0, atol=KERNEL_TOLERANCE * np.abs(b).max(),
                                       err_msg=name)


def random_face_qps(rng: np.random.Generator) -> list[tuple]:
    """QPs of the controller's shape (n = 12, m = 6, P = G'G or I) with working sets of every
    kind: optimal faces, faces whose optimum leaves the box or has a negative multiplier, no
    free variable, an infeasible equality and a singular KKT system (two equal columns of A
    and P)."""
    cases = []
    for k in range(60):
        n, m = 12, 6
        G = rng.normal(size=(36, n))
        P = G.T @ G if k % 3 else np.eye(n)
        c = rng.normal(size=n) * 5.0
        A = rng.normal(size=(m, n))
        lo, hi = rng.uniform(0.1, 0.4, n), rng.uniform(0.8, 1.5, n)
        t0 = rng.uniform(lo, hi)
        b = A @ t0
        at_lo = rng.random(n) < 0.15 * (k % 4)
        at_hi = ~at_lo & (rng.random(n) < 0.1 * (k % 3))
        if k % 2 == 0:
            # An optimal face: t0 on its bounds, c = P t0 + A' nu - grad with the bound
            # multipliers positive (grad > 0 at lo, < 0 at hi).
            t0 = np.where(at_lo, lo, np.where(at_hi, hi, t0))
            b = A @ t0
            grad = np.where(at_lo, 1.0, np.where(at_hi, -1.0, 0.0)) * rng.uniform(0.1, 1.0, n)
            c = P @ t0 + A.T @ rng.normal(size=m) - grad
        if k == 7:
            at_lo[:] = True
        if k == 8:
            b = b + 10.0
        if k == 9:
            A[:, 1] = A[:, 0]
            P[:, 1], P[1, :] = P[:, 0], P[0, :]
        cases.append((P, c, A, b, lo, hi, t0, at_lo, at_hi))
    return cases


@needs_kernel
def test_warm_face_in_the_kernel_equals_the_numpy_path() -> None:
    """tsk_qp_warm_face decides as warm_face_numpy (optimal or not) and gives its tensions,
    on random faces and on the controller's own QPs; every outcome occurs."""
    rng = np.random.default_rng(3)
    outcomes = set()
    for case in random_face_qps(rng):
        new, ref = warm_face(*case), warm_face_numpy(*case)
        plain = warm_face(*case, use_kernel=False)
        assert (plain is None) == (ref is None)
        if ref is not None:
            np.testing.assert_array_equal(plain, ref)
        assert (new is None) == (ref is None)
        outcomes.add(ref is None)
        if ref is not None:
            np.testing.assert_allclose(new, ref, rtol=0.0,
                                       atol=KERNEL_TOLERANCE * np.abs(ref).max())
    assert outcomes == {True, False}
    model = joint()
    K = design_rest_lengths(model, model.initial_screw, np.zeros(6), 0.5, 1.5
                            ).cartesian_stiffness
    warm = 0
    for stiffness in (None, K, 3.0 * K):
        ctl = StiffnessController(model, limits(model), model.rest_lengths)
        for k in range(30):
            xi = model.initial_screw + 1e-3 * np.sin(0.3 * k + np.arange(6))
            cmd = ctl.update(DT, ControlTarget(screw=xi, cartesian_stiffness=stiffness),
                             screw=xi)
            warm += cmd.warm
    assert warm > 60


@needs_kernel
def test_the_controller_with_the_kernel_equals_the_numpy_path() -> None:
    """The same ticks (a moving target with and without K_c*, a measured pose) with the
    compiled pose terms and warm face and without them give the same commands."""
    model = joint()
    K = design_rest_lengths(model, model.initial_screw, np.zeros(6), 0.5, 1.5
                            ).cartesian_stiffness
    runs = []
    for use_kernel in (True, False):
        m = model if use_kernel else JointModel(
            model.link1_nodes, model.connections, model.k, model.rest_lengths,
            link2_nodes=model.link2_nodes, max_lengths=model.max_lengths,
            force_law=model.force_law, initial_screw=model.initial_screw, use_kernel=False)
        ctl = StiffnessController(m, limits(m), m.rest_lengths)
        out = []
        for k in range(200):
            d = np.array([0.02 * np.cos(0.03 * k), 0.02 * np.sin(0.03 * k), 0.0,
                          1e-3 * np.sin(0.03 * k), 0.0, 0.0])
            tgt = ControlTarget(screw=model.initial_screw + d,
                                cartesian_stiffness=K if k >= 100 else None)
            cmd = ctl.update(DT, tgt, screw=model.initial_screw + 0.9 * d)
            out.append((cmd.rest_lengths, cmd.tensions, cmd.warm))
        runs.append(out)
    for (r1, t1, w1), (r2, t2, w2) in zip(*runs, strict=True):
        np.testing.assert_allclose(r1, r2, rtol=0.0, atol=1e-12)
        np.testing.assert_allclose(t1, t2, rtol=0.0, atol=1e-9)
        assert w1 == w2


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_tension_bounds_are_the_rest_length_range(force_law: str) -> None:
    model = joint(force_law)
    terms = pose_terms(model, model.initial_screw)
    rmin, rmax = 0.6 * model.rest_lengths, 1.1 * model.rest_lengths
    lo, hi = tension_bounds(model, terms.lengths, rmin, rmax)
    np.testing.assert_allclose(rest_from_tensions(model, terms.lengths, lo), rmax, atol=1e-14)
    np.testing.assert_allclose(rest_from_tensions(model, terms.lengths, hi), rmin, atol=1e-14)
    for rest, t in ((rmax, lo), (rmin, hi)):
        state = model.evaluate(model.initial_screw, rest)
        taut = ~state.slack & ~state.saturated  # the affine law holds between the caps
        assert taut.sum() >= 8
        np.testing.assert_allclose(state.tensions[taut], t[taut], atol=1e-12)


# ---------------------------------------------------------------------------------- the QP
@pytest.mark.parametrize('with_target', [False, True])
def test_qp_cold_and_warm_equal_the_design(with_target: bool) -> None:
    """The controller's QP (cold, then warm from the previous request) gives the design's
    tensions when the rest-length range is wide (the design's problem)."""
    model = joint()
    rng = np.random.default_rng(2)
    L = float(np.linalg.norm(model.link1_nodes, axis=1).max())  # the design's default
    S = np.array([1, 1, 1, 1 / L, 1 / L, 1 / L])
    previous = None
    for _ in range(6):
        xi = near_screw(model, rng)
        W = np.concatenate([rng.normal(0, 0.03, 3), rng.normal(0, 1e-3, 3)])
        base = design_rest_lengths(model, xi, W)
        assert base.success
        target = (np.exp(rng.normal(0, 0.1, 6))[:, None] * base.cartesian_stiffness
                  if with_target else None)
        ref = design_rest_lengths(model, xi, W, target_stiffness=target)
        terms = pose_terms(model, xi)
        lo = np.full(12, 0.1)
        hi = np.minimum(1.5, terms.cap)
        if target is None:
            P, c = np.eye(12), 0.5 * (lo + hi)
        else:
            SS = S[:, None] * S[None, :]
            G = (terms.M * SS).reshape(12, 36).T
            g = ((target - terms.K0) * SS).ravel()
            P, c = G.T @ G, G.T @ g
        A, b = S[:, None] * terms.B, -S * W

        def same_optimum(t: np.ndarray, A: np.ndarray = A, b: np.ndarray = b,
                         lo: np.ndarray = lo, hi: np.ndarray = hi, terms: object = terms,
                         ref: object = ref, target: object = target) -> None:
            # The optimum's K_c (G t) is unique; t is when the objective is strictly convex.
            np.testing.assert_allclose(A @ t, b, atol=1e-9)
            assert np.all(t >= lo - 1e-12) and np.all(t <= hi + 1e-12)
            Kc = terms.K0 + np.einsum('j,jab->ab', t, terms.M)
            np.testing.assert_allclose(Kc, ref.cartesian_stiffness, atol=1e-6)
            if target is None:
                np.testing.assert_allclose(t, ref.tensions, atol=1e-9)

        cold = solve_box_qp(P, c, A, b, lo, hi, 0.5 * (lo + hi))
        assert cold.converged
        same_optimum(cold.t)
        if previous is not None:
            warm = solve_box_qp(P, c, A, b, lo, hi, previous.t, previous.at_lo, previous.at_hi)
            assert warm.converged
            same_optimum(warm.t)
            again = solve_box_qp(P, c, A, b, lo, hi, warm.t, warm.at_lo, warm.at_hi)
            assert again.warm and again.iterations == 1
            np.testing.assert_allclose(again.t, warm.t, atol=1e-12)
        previous = cold


def test_qp_reports_infeasible() -> None:
    model = joint()
    terms = pose_terms(model, model.initial_screw)
    lo, hi = np.full(12, 0.1), np.full(12, 1.5)
    W = np.array([0, 50.0, 0, 0, 0, 0])
    sol = solve_box_qp(np.eye(12), np.ones(12), terms.B, -W, lo, hi, np.ones(12))
    assert not sol.converged
    assert np.all(sol.t >= lo) and np.all(sol.t <= hi)


# ---------------------------------------------------------------------------------- controller
def test_settles_on_the_design_and_holds_limits() -> None:
    model = joint()
    ctl = StiffnessController(model, limits(model), model.rest_lengths)
    xi = model.initial_screw + [0.04, -0.02, 0.0, 0.0, 5e-4, 0.0]
    ref = design_rest_lengths(model, xi, np.zeros(6))
    target = ControlTarget(screw=xi)
    prev = model.rest_lengths
    for _ in range(400):
        cmd = ctl.update(DT, target, screw=xi)
        assert np.abs(cmd.rest_lengths - prev).max() <= RATE * DT * (1 + RATE_ROUNDING)
        prev = cmd.rest_lengths
    np.testing.assert_allclose(cmd.rest_lengths, ref.rest_lengths, atol=1e-12)
    assert cmd.feasible and cmd.message == 'ok' and not cmd.saturated.any() and cmd.warm
    np.testing.assert_allclose(cmd.tensions, ref.tensions, atol=1e-9)


def test_rate_and_range_limits_are_never_exceeded() -> None:
    """Random targets and loads with a narrow range: every tick within rate and range."""
    model = joint()
    lim = limits(model, rate=0.02, low=0.85, high=1.05)
    rmin, rmax = 0.85 * model.rest_lengths, 1.05 * model.rest_lengths
    ctl = StiffnessController(model, lim, model.rest_lengths)
    rng = np.random.default_rng(3)
    prev = model.rest_lengths
    infeasible = 0
    for k in range(600):
        if k % 50 == 0:
            xi = near_screw(model, rng)
            W = np.concatenate([rng.normal(0, 0.05, 3), rng.normal(0, 1e-3, 3)])
            base = design_rest_lengths(model, xi, W)
            K = None if not base.success or k % 100 else 1.3 * base.cartesian_stiffness
            target = ControlTarget(screw=xi, cartesian_stiffness=K)
        measured = xi + rng.normal(0, 1e-4, 6)
        cmd = ctl.update(DT, target, screw=measured, external_wrench=W)
        infeasible += not cmd.feasible
        assert np.abs(cmd.rest_lengths - prev).max() <= 0.02 * DT * (1 + RATE_ROUNDING)
        assert np.all(cmd.rest_lengths >= rmin * (1 - 1e-12))
        assert np.all(cmd.rest_lengths <= rmax * (1 + 1e-12))
        if cmd.saturated.any():
            assert 'rate or range' in cmd.message
        prev = cmd.rest_lengths
    assert infeasible < 600


def test_start_outside_the_range_moves_in_at_the_rate() -> None:
    model = joint()
    start = 1.3 * model.rest_lengths  # above rest_length_max = 1.2 l0
    ctl = StiffnessController(model, limits(model), start)
    cmd = ctl.update(DT, ControlTarget(screw=model.initial_screw))
    np.testing.assert_allclose(start - cmd.rest_lengths, RATE * DT, rtol=1e-9)
    assert cmd.saturated.all()


def test_target_change_is_followed_without_a_jump_and_integral_waits() -> None:
    model = joint()
    ctl = StiffnessController(model, limits(model), model.rest_lengths)
    xi0 = model.initial_screw
    for _ in range(300):
        ctl.update(DT, ControlTarget(screw=xi0), screw=xi0 + 1e-4)
    z = ctl.integral
    assert np.linalg.norm(z) > 0
    before = ctl.rest_lengths
    cmd = ctl.update(DT, ControlTarget(screw=xi0 + [0.2, 0, 0, 0, 0, 0]), screw=xi0 + 1e-4)
    assert cmd.saturated.any()
    assert np.abs(cmd.rest_lengths - before).max() <= RATE * DT * (1 + RATE_ROUNDING)
    np.testing.assert_array_equal(ctl.integral, z)  # anti-windup: frozen while saturated


def test_reset_forgets_integral_and_sets_positions() -> None:
    model = joint()
    ctl = StiffnessController(model, limits(model), model.rest_lengths)
    for _ in range(20):
        ctl.update(DT, ControlTarget(screw=model.initial_screw),
                   screw=model.initial_screw + 1e-3)
    new = 0.98 * model.rest_lengths
    ctl.reset(new)
    np.testing.assert_array_equal(ctl.integral, np.zeros(6))
    np.testing.assert_array_equal(ctl.rest_lengths, new)
    with pytest.raises(ValueError, match='rest_lengths'):
        ctl.reset(new[:5])
    with pytest.raises(ValueError, match='rest_lengths'):
        ctl.reset(np.full(12, np.nan))


@pytest.mark.parametrize('kwargs, match', [
    ({'dt': 0.0}, 'dt'), ({'dt': -1e-3}, 'dt'), ({'dt': float('nan')}, 'dt'),
    ({'pose': np.full((4, 4), np.nan)}, 'pose'),
    ({'screw': [0, 0, 0, np.inf, 0, 0]}, 'screw'),
    ({'external_wrench': [0, 0, np.nan, 0, 0, 0]}, 'external_wrench'),
    ({'external_wrench': [0, 0, 0]}, 'external_wrench'),
    ({'target': 'pose'}, 'target'),
])
def test_bad_input_raises_and_keeps_state(kwargs: dict, match: str) -> None:
    model = joint()
    a = StiffnessController(model, limits(model), model.rest_lengths)
    b = StiffnessController(model, limits(model), model.rest_lengths)
    target = ControlTarget(screw=model.initial_screw + [0.02, 0, 0, 0, 0, 0])
    measured = model.initial_screw + 1e-4
    for ctl in (a, b):
        for _ in range(5):
            ctl.update(DT, target, screw=measured)
    call = {'dt': DT, 'target': target, 'screw': measured}
    call.update(kwargs)
    if 'pose' in kwargs:
        del call['screw']
    with pytest.raises(ValueError, match=match):
        a.update(**call)
    np.testing.assert_array_equal(a.rest_lengths, b.rest_lengths)
    np.testing.assert_array_equal(a.integral, b.integral)
    ca, cb = a.update(DT, target, screw=measured), b.update(DT, target, screw=measured)
    np.testing.assert_array_equal(ca.rest_lengths, cb.rest_lengths)


def test_constructor_validation() -> None:
    model = joint()
    with pytest.raises(ValueError, match='integral_gain'):
        StiffnessController(model, limits(model), model.rest_lengths, integral_gain=-1.0)
    with pytest.raises(ValueError, match='proportional_gain'):
        StiffnessController(model, limits(model), model.rest_lengths, proportional_gain=1.5)
    with pytest.raises(ValueError, match='rest_length_offsets'):
        StiffnessController(model, limits(model), model.rest_lengths,
                            rest_length_offsets=np.zeros(3))
    with pytest.raises(ValueError, match='limits'):
        StiffnessController(model, (0.01, 0.05, 1.0), model.rest_lengths)


def test_unreachable_stiffness_is_reported_with_safe_commands() -> None:
    model = joint()
    lim = limits(model)
    ctl = StiffnessController(model, lim, model.rest_lengths)
    xi = model.initial_screw
    base = design_rest_lengths(model, xi, np.zeros(6))
    target = ControlTarget(screw=xi, cartesian_stiffness=3.0 * base.cartesian_stiffness)
    for _ in range(600):
        cmd = ctl.update(DT, target, screw=xi)
    assert cmd.feasible
    assert cmd.stiffness_error > 0.1
    assert 'not reachable' in cmd.message
    closest = design_rest_lengths(model, xi, np.zeros(6),
                                  target_stiffness=target.cartesian_stiffness)
    assert cmd.stiffness_error == pytest.approx(closest.stiffness_error, rel=1e-6)
    assert np.all(cmd.tensions >= 0.1 - 1e-12) and np.all(cmd.tensions <= 1.5 + 1e-12)
    state = model.evaluate(xi, cmd.rest_lengths)
    assert not state.slack.any()
    assert np.linalg.norm(state.wrench) < 1e-9


def test_unholdable_pose_keeps_the_last_command() -> None:
    model = joint()
    ctl = StiffnessController(model, limits(model), model.rest_lengths)
    xi = model.initial_screw
    for _ in range(100):
        ctl.update(DT, ControlTarget(screw=xi), screw=xi)
    last, z = ctl.rest_lengths, ctl.integral
    cmd = ctl.update(DT, ControlTarget(screw=xi), screw=xi + 1e-3,
                     external_wrench=[0, 30.0, 0, 0, 0, 0])
    assert not cmd.feasible and 'infeasible' in cmd.message and 'kept' in cmd.message
    np.testing.assert_array_equal(cmd.rest_lengths, last)
    np.testing.assert_array_equal(ctl.integral, z)
    assert np.isnan(cmd.stiffness_error)


def test_rest_length_offsets_shift_the_commands() -> None:
    model = joint()
    d = np.linspace(-1e-3, 1e-3, 12)
    ctl = StiffnessController(model, limits(model), model.rest_lengths - d,
                              rest_length_offsets=d)
    xi = model.initial_screw
    ref = design_rest_lengths(model, xi, np.zeros(6))
    for _ in range(300):
        cmd = ctl.update(DT, ControlTarget(screw=xi), screw=xi)
    np.testing.assert_allclose(cmd.rest_lengths, ref.rest_lengths - d, atol=1e-12)


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_integral_removes_a_model_error_on_the_model_plant(force_law: str) -> None:
    """Plant: the model with every k_j off by up to 10 %, solved to equilibrium each tick
    (quasi-static): the integral drives the true pose to the target."""
    from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
    model = joint(force_law)
    rng = np.random.default_rng(4)
    section = dict(config.load_section(config.packaged_config_path(), 'joint'))
    section['force_law'] = force_law
    section['stiffness'] = (model.k * rng.uniform(0.9, 1.1, 12)).tolist()
    plant = JointModel.from_dict(section)
    ctl = StiffnessController(model, limits(model, rate=1.0), model.rest_lengths,
                              integral_gain=50.0)
    xi_t = model.initial_screw + [0.02, 0.0, -0.01, 0.0, 3e-4, 0.0]
    target = ControlTarget(screw=xi_t)
    xi = model.initial_screw
    for _ in range(200):
        cmd = ctl.update(DT, target, screw=xi)
        res = solve_equilibrium(plant, np.zeros(6), cmd.rest_lengths, xi)
        assert res.success
        xi = res.screw
    T, Ts = exp_se3(xi), exp_se3(xi_t)
    assert np.linalg.norm(T[:3, 3] - Ts[:3, 3]) < 1e-8
    assert np.linalg.norm(T[:3, :3] - Ts[:3, :3]) < 1e-7


def test_relative_stiffness_error_matches_the_design() -> None:
    model = joint()
    xi = model.initial_screw
    K = design_rest_lengths(model, xi, np.zeros(6)).cartesian_stiffness
    res = design_rest_lengths(model, xi, np.zeros(6), target_stiffness=2.0 * K)
    L = float(np.linalg.norm(model.link1_nodes, axis=1).max())
    assert relative_stiffness_error(res.cartesian_stiffness, 2.0 * K, L) == \
        pytest.approx(res.stiffness_error, rel=1e-9)


# ---------------------------------------------------------------------------------- spine
def spine_chain() -> JointChain:
    return JointChain.from_yaml(Path(config.packaged_config_path()).with_name(
        'default_spine.yaml'))


def spine_tip_stiffness(chain: JointChain, screws: np.ndarray, tmin: float, tmax: float
                        ) -> tuple[np.ndarray, list[np.ndarray]]:
    model = chain.joints[0]
    rest = [design_rest_lengths(model, x, np.zeros(6), tmin, tmax).rest_lengths for x in screws]
    return chain.tip_stiffness(screws, rest_lengths=rest), rest


def test_series_compliance_is_the_chain_formula_without_load() -> None:
    """The spine's stiffness objective, C_tip = sum Ad_i K_i^-1 Ad_i^T, against the library's
    exact tip stiffness at zero load (no weights in the default spine)."""
    chain = spine_chain()
    xi = chain.unloaded_screws()
    K_tip, rest = spine_tip_stiffness(chain, xi, 0.1, 1.5)
    state = chain.evaluate(xi, rest)
    C = sum(adjoint_twist(P) @ np.linalg.inv(K) @ adjoint_twist(P).T
            for P, K in zip(state.joint_frames, state.cartesian_stiffness, strict=True))
    np.testing.assert_allclose(np.linalg.inv(C), K_tip, rtol=1e-7, atol=1e-9 * np.abs(K_tip).max())


def test_spine_meets_a_reachable_tip_stiffness_and_reports_an_unreachable_one() -> None:
    chain = spine_chain()
    model = chain.joints[0]
    xi = chain.unloaded_screws()
    T0 = chain.tip_transform(xi)
    L = float(np.linalg.norm(model.link1_nodes, axis=1).max())
    lim = ActuatorLimits(0.5 * model.rest_lengths, 1.2 * model.rest_lengths, 10.0)
    K_mid, _ = spine_tip_stiffness(chain, xi, 0.1, 1.5)
    for tmin, tmax in ((0.5, 1.5), (0.1, 0.5)):
        K_star, _ = spine_tip_stiffness(chain, xi, tmin, tmax)
        assert relative_stiffness_error(K_mid, K_star, L) > 0.1  # a real step
        ctl = ChainStiffnessController(chain, lim, [model.rest_lengths] * chain.n_joints)
        target = ControlTarget(pose=T0, cartesian_stiffness=K_star)
        for _ in range(20):
            cmd = ctl.update(DT, target, tip_pose=T0)
        assert cmd.feasible and cmd.stiffness_error < 1e-3, cmd.stiffness_error
        exact = chain.tip_stiffness(cmd.design_screws, rest_lengths=[
            c.rest_lengths for c in cmd.joint_commands])
        assert relative_stiffness_error(exact, K_star, L) < 1e-3
    ctl = ChainStiffnessController(chain, lim, [model.rest_lengths] * chain.n_joints)
    target = ControlTarget(pose=T0, cartesian_stiffness=3.0 * K_mid)
    for _ in range(10):
        cmd = ctl.update(DT, target, tip_pose=T0)
    assert cmd.feasible and cmd.stiffness_error > 0.1
    assert 'not met' in cmd.message
    for c in cmd.joint_commands:
        assert np.all(c.rest_lengths >= 0.5 * model.rest_lengths * (1 - 1e-12))
        assert np.all(c.rest_lengths <= 1.2 * model.rest_lengths * (1 + 1e-12))
        assert np.all(c.tensions >= 0.1 - 1e-9)
