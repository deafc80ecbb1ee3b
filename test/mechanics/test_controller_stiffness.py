"""tensegrity_stiffness.mechanics.controller_stiffness: the frame change against central
differences of the joint's wrench under small twists of the controller's frame, the projection
against a numerical optimiser (no symmetric matrix with the eigenvalue floor is closer), clamps,
layouts, low-pass."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.optimize import minimize
from support import REPO
from support.eigenvalues import (
    assert_eigenvalues_at_floor,
    assert_eigenvalues_at_least,
    eigenvalue_rounding,
)

from tensegrity_stiffness.geometry.screw import exp_se3, log_se3
from tensegrity_stiffness.geometry.transforms import adjoint
from tensegrity_stiffness.geometry.transforms import pose_vector_to_transform as pose_to_transform
from tensegrity_stiffness.mechanics.controller_stiffness import (
    EIGENVALUE_MARGIN,
    LAYOUTS,
    Conditioner,
    LowPass,
    clamp,
    diagonal,
    from_layout,
    moved_beyond,
    nearest_positive_definite,
    symmetric_part,
    to_layout,
    transform_cartesian_stiffness,
)
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel

CONFIG = REPO / 'config' / 'default_joint.yaml'
CD_STEP = 1e-6


@pytest.fixture(scope='module')
def model() -> JointModel:
    return JointModel.from_yaml(CONFIG)


def random_pose(rng: np.random.Generator) -> np.ndarray:
    q = rng.normal(size=4)
    return np.r_[rng.normal(scale=0.05, size=3), q / np.linalg.norm(q)]


def twist_exp(delta: np.ndarray) -> np.ndarray:
    """exp of a twist [dv; dw] (the library's exp_se3 takes [omega; v])."""
    return exp_se3(np.r_[delta[3:], delta[:3]])


def rel(a, b) -> float:
    return float(np.linalg.norm(a - b) / np.linalg.norm(b))


# --------------------------------------------------------------------------- frame change
def test_transform_against_central_differences_of_the_wrench_in_frame_c(model):
    """K_C = -dW_C/d(eps): W_C the joint's wrench expressed in C (about C's origin), eps a small
    twist of C in C's coordinates moving link 2 (T2 -> P exp(eps) P^-1 T2, P = pose of C in {1}),
    at loaded configurations (K_c not symmetric) and at a loaded equilibrium."""
    rng = np.random.default_rng(11)
    loaded = solve_equilibrium(model, np.array([0.3, -0.2, 0.5, 0.004, 0.002, -0.003]),
                               initial_screw=model.initial_screw)
    assert loaded.success, loaded.message
    screws = [loaded.screw] + [model.initial_screw + rng.normal(scale=[0.1] * 3 + [0.003] * 3)
                               for _ in range(8)]
    for xi in screws:
        K_c = model.evaluate(xi).cartesian_stiffness
        T2 = exp_se3(xi)
        pose = random_pose(rng)
        P = pose_to_transform(pose)
        P_inv = np.linalg.inv(P)
        Ad = adjoint(P)

        def wrench_in_c(eps, T2=T2, P=P, P_inv=P_inv, Ad=Ad, xi=xi):
            moved = P @ twist_exp(eps) @ P_inv @ T2
            return Ad.T @ model.wrench(log_se3(moved, reference=xi))

        numeric = np.zeros((6, 6))
        for i in range(6):
            e = np.zeros(6)
            e[i] = CD_STEP
            numeric[:, i] = -(wrench_in_c(e) - wrench_in_c(-e)) / (2 * CD_STEP)
        analytic = transform_cartesian_stiffness(K_c, pose)
        assert rel(analytic, numeric) < 1e-6, rel(analytic, numeric)
        # the 4x4 form gives the same; the identity changes nothing
        np.testing.assert_allclose(transform_cartesian_stiffness(K_c, P), analytic, rtol=1e-12,
                                   atol=1e-12 * np.abs(analytic).max())
        np.testing.assert_allclose(
            transform_cartesian_stiffness(K_c, [0, 0, 0, 0, 0, 0, 1]), K_c, rtol=0, atol=0)


def test_transform_keeps_symmetry_and_inertia_and_composes(model):
    rng = np.random.default_rng(12)
    K = model.evaluate(model.initial_screw).cartesian_stiffness  # symmetric PD (unloaded)
    for _ in range(20):
        P1, P2 = pose_to_transform(random_pose(rng)), pose_to_transform(random_pose(rng))
        K1 = transform_cartesian_stiffness(K, P1)
        assert np.abs(K1 - K1.T).max() <= 1e-9 * np.abs(K1).max()
        assert np.linalg.eigvalsh(symmetric_part(K1)).min() > 0
        # C2 given in C1 after C1 given in A = C2 given in A
        np.testing.assert_allclose(transform_cartesian_stiffness(K1, P2),
                                   transform_cartesian_stiffness(K, P1 @ P2),
                                   rtol=1e-9, atol=1e-9 * np.abs(K1).max())


@pytest.mark.parametrize('pose, match', [
    ([0, 0, 0, 0, 0, 0, 2], 'not a unit quaternion'),
    ([0, 0, 0, 0, 0, 0, 0], 'zero norm'),
    ([0, 0, 0, 1], '7 values|transform'),
    (np.diag([1.0, 1.0, -1.0, 1.0]), 'rigid transform'),
    ([0, 0, math.nan, 0, 0, 0, 1], 'finite'),
])
def test_bad_pose_raises_naming_it(pose, match):
    with pytest.raises(ValueError, match=match) as info:
        transform_cartesian_stiffness(np.eye(6), pose)
    assert 'pose' in str(info.value)


@pytest.mark.parametrize('K, match', [
    (np.eye(5), '6x6'), (np.ones(36), '6x6'), (np.full((6, 6), math.inf), 'finite'),
    ('a', 'numeric'),
])
def test_bad_matrix_raises_naming_it(K, match):
    for fn in (symmetric_part, diagonal, lambda k: nearest_positive_definite(k, 0.0),
               lambda k: to_layout(k, 'row_major_36'), lambda k: clamp(k, (0, 1))):
        with pytest.raises(ValueError, match=match):
            fn(K)
    with pytest.raises(ValueError, match='K_c'):
        transform_cartesian_stiffness(K, [0, 0, 0, 0, 0, 0, 1])


@pytest.mark.parametrize('K', [np.full((6, 6), 1e308), np.eye(6) * 1e308, -np.eye(6) * 1e308,
                               np.full((6, 6), 1e200)])
def test_a_matrix_whose_conditioning_overflows_is_refused(K):
    """Finite but absurd entries (a hostile input): a ValueError naming the size, not numpy's
    LinAlgError or a NaN output; a tiny (denormal) matrix is conditioned to the floor."""
    conditioner = Conditioner(pose=[0.02, 0, 0.01, 0, 0, math.sin(0.3), math.cos(0.3)],
                              min_eigenvalue=1e-3)
    with pytest.raises(ValueError, match='too large to condition'):
        conditioner.apply(K)
    with pytest.raises(ValueError, match='too large to condition'):
        Conditioner(min_eigenvalue=1e-3, scale=1e12).apply(np.eye(6) * 1e300)
    tiny = conditioner.apply(np.full((6, 6), 5e-324))
    np.testing.assert_allclose(np.linalg.eigvalsh(tiny.matrix), 1e-3)
    assert_eigenvalues_at_floor(tiny.matrix, 1e-3)


# --------------------------------------------------------------------------- projection
def _optimised_distance(K: np.ndarray, floor: float, rng: np.random.Generator) -> float:
    """min |X - K|_F over X = floor I + L L^T (every symmetric X with eigenvalues >= floor),
    L lower triangular: BFGS from several starts."""
    rows, cols = np.tril_indices(6)

    def build(theta):
        L = np.zeros((6, 6))
        L[rows, cols] = theta
        return floor * np.eye(6) + L @ L.T

    def cost(theta):
        L = np.zeros((6, 6))
        L[rows, cols] = theta
        D = floor * np.eye(6) + L @ L.T - K
        grad_X = 2.0 * D
        grad_L = (grad_X + grad_X.T) @ L
        return float(np.sum(D * D)), grad_L[rows, cols]

    best = math.inf
    scale = math.sqrt(np.abs(K).max())
    for _ in range(3):
        theta0 = rng.normal(scale=scale, size=rows.size)
        res = minimize(cost, theta0, jac=True, method='BFGS',
                       options={'gtol': 1e-12, 'maxiter': 5000})
        best = min(best, float(np.linalg.norm(build(res.x) - K)))
    return best


def test_projection_is_the_nearest_against_an_optimiser():
    rng = np.random.default_rng(13)
    for case in range(9):
        K = rng.normal(size=(6, 6)) * rng.uniform(0.5, 20.0)  # indefinite, not symmetric
        floor = [0.0, 0.1, 1.0][case % 3]
        X, distance = nearest_positive_definite(K, floor)
        assert np.array_equal(X, X.T)
        assert_eigenvalues_at_floor(X, floor)
        assert distance == pytest.approx(np.linalg.norm(X - K), rel=1e-12)
        optimised = _optimised_distance(K, floor, rng)
        # nothing feasible is closer; the optimiser gets there too (the check is not vacuous)
        assert distance <= optimised * (1 + 1e-9), (case, distance, optimised)
        assert optimised <= distance * (1 + 1e-5), (case, distance, optimised)
        # random feasible matrices near X are all farther
        for _ in range(50):
            E = rng.normal(scale=1e-3, size=(6, 6))
            Y, _ = nearest_positive_definite(X + E + E.T, floor)
            assert np.linalg.norm(Y - K) >= distance * (1 - 1e-12)


def test_projection_is_idempotent_and_keeps_a_valid_matrix(model):
    rng = np.random.default_rng(14)
    for _ in range(20):
        K = rng.normal(size=(6, 6))
        X, _ = nearest_positive_definite(K, 0.2)
        X2, d2 = nearest_positive_definite(X, 0.2)
        np.testing.assert_allclose(X2, X, rtol=0, atol=1e-12)
        assert d2 <= 1e-12
    K = model.evaluate(model.initial_screw).cartesian_stiffness
    S = symmetric_part(K)
    X, d = nearest_positive_definite(K, 0.0)
    assert np.array_equal(X, S)
    assert d == pytest.approx(np.linalg.norm(K - S), abs=1e-15)
    with pytest.raises(ValueError, match='min_eigenvalue'):
        nearest_positive_definite(K, -1.0)


def test_conditioner_reports_an_unstable_joint_and_outputs_spd(model):
    """An unstable unloaded equilibrium: the output is SPD, the report says the input was not."""
    rng = np.random.default_rng(15)
    unstable = None
    for _ in range(60):
        axis = rng.normal(size=3)
        x0 = np.r_[axis / np.linalg.norm(axis) * rng.uniform(0, math.pi),
                   rng.normal(size=3) * 0.02]
        res = solve_equilibrium(model, np.zeros(6), initial_screw=x0)
        if res.success and not res.stable:
            unstable = res
            break
    assert unstable is not None, 'no unstable equilibrium found'
    out = Conditioner(pose=random_pose(rng), min_eigenvalue=0.5).apply(
        unstable.cartesian_stiffness)
    assert not out.input_positive_definite
    assert out.input_min_eigenvalue < 0
    assert out.projection_distance > 0 and out.relative_projection > 0
    assert_eigenvalues_at_floor(out.matrix, 0.5)
    assert np.array_equal(out.matrix, out.matrix.T)


def test_projection_floor_holds_as_a_subscriber_checks_it():
    """Over 3,000 seeded matrices of sizes 1e-3 .. 1e6 (indefinite; the smallest eigenvalue above,
    at or just below the floor; large ones beside a small floor, where eps |K| is well above
    1e-9 of the floor): eigvalsh of the result is >= the floor with no tolerance, within the
    margin and rounding of it where it clipped, and a second pass returns the result unchanged."""
    rng = np.random.default_rng(43)
    clipped = 0
    for case in range(3000):
        scale = 10.0 ** rng.uniform(-3.0, 6.0)
        floor = [0.0, 1e-3, 1.0][case % 3]
        Q, _ = np.linalg.qr(rng.normal(size=(6, 6)))
        eigenvalues = rng.normal(scale=scale, size=6)
        if case % 2:  # the smallest eigenvalue within rounding of the floor
            eigenvalues[0] = floor + rng.normal(scale=eigenvalue_rounding(np.diag(eigenvalues)))
        K = (Q * eigenvalues) @ Q.T
        X, _ = nearest_positive_definite(K, floor)
        assert np.array_equal(X, X.T)
        assert_eigenvalues_at_least(X, floor)
        if np.linalg.eigvalsh(symmetric_part(K)).min() < floor:
            assert_eigenvalues_at_floor(X, floor)
            clipped += 1
        again, moved = nearest_positive_definite(X, floor)
        assert np.array_equal(again, X) and moved == 0.0, case
        out = Conditioner(pose=[0.02, 0, 0.01, 0, 0, math.sin(0.3), math.cos(0.3)],
                          min_eigenvalue=floor).apply(K)
        assert_eigenvalues_at_least(out.matrix, floor)
    assert clipped > 1500  # the floor is what is judged, not only matrices far above it
    assert EIGENVALUE_MARGIN < 1e-13


# --------------------------------------------------------------------------- clamps, layouts
def test_clamp_bounds_block_eigenvalues_and_keeps_positive_definite():
    rng = np.random.default_rng(16)
    for _ in range(50):
        M = rng.normal(size=(6, 6))
        K = M @ M.T + 0.01 * np.eye(6)
        K[:3, :3] *= 100.0
        out, hit = clamp(K, translational=(20.0, 80.0), rotational=(0.5, 1.5))
        assert np.array_equal(out, out.T)
        for block, (lo, hi) in ((out[:3, :3], (20.0, 80.0)), (out[3:, 3:], (0.5, 1.5))):
            ev = np.linalg.eigvalsh(block)
            assert ev.min() >= lo - 1e-9 and ev.max() <= hi + 1e-9
            assert np.all((np.diag(block) >= lo - 1e-9) & (np.diag(block) <= hi + 1e-9))
        assert np.linalg.eigvalsh(out).min() > 0
        assert hit['translational'] or hit['rotational']
    K = np.diag([100.0, 100, 100, 1, 1, 1])
    same, hit = clamp(K, (10.0, 1000.0), (0.1, 10.0))
    assert np.array_equal(same, K) and not any(hit.values())
    with pytest.raises(ValueError, match='translational'):
        clamp(K, translational=(5.0, 1.0))


def test_layouts_round_trip():
    rng = np.random.default_rng(17)
    K = rng.normal(size=(6, 6))
    for layout in ('row_major_36', 'column_major_36'):
        np.testing.assert_array_equal(from_layout(to_layout(K, layout), layout), K)
    assert to_layout(K, 'row_major_36')[1] == K[0, 1]
    assert to_layout(K, 'column_major_36')[1] == K[1, 0]
    np.testing.assert_array_equal(to_layout(K, 'diagonal_6'), np.diag(K))
    d = rng.uniform(1, 2, size=6)
    np.testing.assert_array_equal(to_layout(from_layout(d, 'diagonal_6'), 'diagonal_6'), d)
    np.testing.assert_array_equal(diagonal(K), np.diag(K))
    assert set(LAYOUTS) == {'row_major_36', 'column_major_36', 'diagonal_6'}
    with pytest.raises(ValueError, match='layout'):
        to_layout(K, 'row_major')
    with pytest.raises(ValueError, match='takes 36 values'):
        from_layout(np.ones(6), 'row_major_36')


# --------------------------------------------------------------------------- filter, deadband
def test_low_pass_step_response_and_positive_definiteness():
    tau = 0.1
    lp = LowPass(tau)
    A, B = np.diag([1.0, 2, 3, 4, 5, 6]), np.diag([10.0, 20, 30, 40, 50, 60])
    np.testing.assert_array_equal(lp.update(A, 0.0), A)
    np.testing.assert_array_equal(lp.update(B, 0.05), A)  # A held until now, then B
    y = lp.update(None, 0.1)
    np.testing.assert_allclose(y, B + (A - B) * math.exp(-0.5), rtol=1e-14)
    y = lp.update(None, 0.15)
    np.testing.assert_allclose(y, B + (A - B) * math.exp(-1.0), rtol=1e-14)
    for k in range(1, 6):  # PD all along the way
        assert np.linalg.eigvalsh(lp.update(None, 0.15 + 0.01 * k)).min() > 0
    assert not lp.settled()
    lp.update(None, 10.0)
    assert lp.settled()
    off = LowPass(0.0)
    off.update(A, 0.0)
    np.testing.assert_array_equal(off.update(B, 1e-3), B)
    with pytest.raises(ValueError, match='time_constant'):
        LowPass(-1.0)


def test_deadband():
    assert moved_beyond([1.0, 2.0], None, 0.1)
    assert not moved_beyond([1.05, 2.0], [1.0, 2.0], 0.1)
    assert moved_beyond([1.2, 2.0], [1.0, 2.0], 0.1)
    assert not moved_beyond([1.0], [1.0], 0.0)
