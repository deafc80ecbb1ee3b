"""Central-difference checks of the calibration's analytic Jacobians
(:mod:`tensegrity_stiffness.estimation.calibration`): tensions and wrench w.r.t. each string's
stiffness and rest length, and every whitened residual w.r.t. the screws and the scaled
parameters."""

from __future__ import annotations

import numpy as np
import pytest

from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.estimation import calibration as cal
from tensegrity_stiffness.estimation import sensor_models
from tensegrity_stiffness.estimation.calibration_model import CalibrationProblem
from tensegrity_stiffness.estimation.calibration_samples import samples_data
from tensegrity_stiffness.geometry.screw import exp_se3, exp_so3
from tensegrity_stiffness.mechanics.joint import JointModel

STEP = 1e-7


def _model(force_law: str = 'hooke') -> JointModel:
    model = JointModel.from_yaml(packaged_config_path())
    if force_law == 'hooke':
        return model
    return JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                      max_lengths=model.max_lengths, force_law=force_law,
                      initial_screw=model.initial_screw)


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_residual_jacobians_match_central_differences(force_law):
    rng = np.random.default_rng(7)
    problem, xi = _problem(rng, force_law=force_law)
    n = problem.n
    z = rng.normal(0.0, 0.2, 2 * n)
    ev = problem.evaluate(z, xi)
    h = 1e-7
    for c in range(6):
        plus, minus = xi.copy(), xi.copy()
        plus[:, c] += h
        minus[:, c] -= h
        numeric = (problem.evaluate(z, plus, False).residuals
                   - problem.evaluate(z, minus, False).residuals) / (2 * h)
        np.testing.assert_allclose(ev.jac_screw[:, :, c], numeric, rtol=1e-5,
                                   atol=1e-5 * np.abs(numeric).max())
    for c in range(2 * n):
        plus, minus = z.copy(), z.copy()
        plus[c] += h
        minus[c] -= h
        numeric = (problem.evaluate(plus, xi, False).residuals
                   - problem.evaluate(minus, xi, False).residuals) / (2 * h)
        np.testing.assert_allclose(ev.jac_parameters[:, :, c], numeric, rtol=1e-5,
                                   atol=1e-6 * max(np.abs(numeric).max(), 1.0))


def _screws(model: JointModel, rng: np.random.Generator, count: int) -> np.ndarray:
    return model.initial_screw + rng.normal(0.0, [0.05] * 3 + [0.002] * 3, (count, 6))


def test_batched_models_equal_sensor_models_sample_by_sample():
    """The calibration's batched residuals and Jacobians are sensor_models' per screw."""
    rng = np.random.default_rng(5)
    problem, xi = _problem(rng, count=4)
    n = problem.n
    z = rng.normal(0.0, 0.2, 2 * n)
    ev = problem.evaluate(z, xi)
    k, d = problem.parameters(z)
    model = cal.model_with_parameters(problem.model, k)
    data = problem.data
    std = problem.std
    for i in range(len(xi)):
        rest = data.rest[i] + d
        r, jr = sensor_models.pose_residual(xi[i], data.poses[i])
        e, je = sensor_models.equilibrium_residual(model, xi[i], data.wrench[i], rest)
        pred = sensor_models.string_predictions(model, xi[i], rest)
        par = sensor_models.string_parameter_jacobians(model, xi[i], rest)
        raw = np.concatenate([r, e, pred.tensions - data.tensions[i],
                              pred.lengths - data.lengths[i]])
        jx = np.vstack([jr, je[:, :6], pred.tension_jacobian, pred.length_jacobian])
        jk = np.vstack([np.zeros((6, n)), par.wrench_stiffness, np.diag(par.tension_stiffness),
                        np.zeros((n, n))])
        jd = np.vstack([np.zeros((6, n)), par.wrench_rest_length,
                        np.diag(par.tension_rest_length), np.zeros((n, n))])
        m = problem.mask[i]
        np.testing.assert_allclose(ev.residuals[i][m], (raw / std)[m], rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(ev.jac_screw[i][m], (jx / std[:, None])[m], rtol=1e-8,
                                   atol=1e-8)
        jp = np.hstack([jk, jd]) * problem.unit / std[:, None]
        np.testing.assert_allclose(ev.jac_parameters[i][m], jp[m], rtol=1e-8, atol=1e-8)


def _problem(rng: np.random.Generator, count: int = 3, force_law: str = 'hooke'
             ) -> tuple[CalibrationProblem, np.ndarray]:
    """Samples with every kind of measurement (some strings slack, some tensions and lengths
    missing) around the nominal unloaded equilibrium."""
    model = _model(force_law)
    n = model.n_strings
    xi = _screws(model, rng, count)
    samples = []
    for x in xi:
        T = exp_se3(x + rng.normal(0.0, 1e-3, 6))
        T[:3, :3] = exp_so3(rng.normal(0.0, 0.02, 3)) @ T[:3, :3]
        tensions = rng.normal(0.4, 0.1, n)
        tensions[rng.random(n) < 0.5] = np.nan
        lengths = rng.normal(0.03, 0.005, n)
        lengths[rng.random(n) < 0.5] = np.nan
        samples.append(cal.CalibrationSample(
            rest_lengths=model.rest_lengths + rng.uniform(-4e-3, 4e-3, n), pose=T,
            tensions=tensions, lengths=lengths, external_wrench=rng.normal(0.0, 0.2, 6)))
    problem = CalibrationProblem(model, samples_data(model, samples), cal.CalibrationNoise())
    return problem, xi


def test_identifiability_separates_dead_parameters_combinations_and_weak_directions():
    """A synthetic information (scaled units): parameter 0 no measurement sees, the combination
    (p1 - p2) / sqrt(2) determined to std 10 (unidentifiable: above one unit), and p3 ... p5
    well determined; the held direction p5 is removed."""
    names = [f'stiffness[{j}]' for j in range(6)]
    v = np.array([0.0, 1.0, -1.0, 0.0, 0.0, 0.0]) / np.sqrt(2.0)
    w = np.array([0.0, 1.0, 1.0, 0.0, 0.0, 0.0]) / np.sqrt(2.0)
    S = 1e-2 * np.outer(v, v) + 400.0 * np.outer(w, w)
    S[3, 3] = S[4, 4] = S[5, 5] = 900.0
    ident = cal.identifiability(S, names)
    assert ident.zero_columns.tolist() == [0]
    assert ident.basis.shape == (6, 4) and ident.null.shape == (6, 2)
    assert 'stiffness[0]' in ident.descriptions[0]
    assert '+0.71 stiffness[1]' in ident.descriptions[1] or '-0.71 stiffness[1]' in \
        ident.descriptions[1]
    assert np.allclose(np.abs(ident.null[:, 1]), np.abs(v))
    held = np.zeros((6, 1))
    held[5, 0] = 1.0
    ident = cal.identifiability(S, names, held=held)
    assert ident.basis.shape == (6, 3)
    assert np.allclose(ident.basis[5], 0.0)


def test_batched_logs_equal_log_se3_on_every_branch():
    """Rotations near 0, near pi (the default joint's equilibria) and between; each screw on
    the branch nearest the previous one, as log_se3 with that reference."""
    from tensegrity_stiffness.geometry.screw import log_se3, log_se3_sequence

    rng = np.random.default_rng(9)
    axes = rng.normal(size=(300, 3))
    axes /= np.linalg.norm(axes, axis=1)[:, None]
    angles = np.concatenate([rng.uniform(0, 1e-3, 50), rng.uniform(0, np.pi, 150),
                             np.pi - rng.uniform(0, 1e-6, 50), rng.uniform(np.pi, 2 * np.pi, 50)])
    screws = np.hstack([axes * angles[:, None], rng.normal(0, 0.02, (300, 3))])
    poses = exp_se3(screws)
    got = log_se3_sequence(poses, screws[0])
    previous = screws[0]
    for T, x in zip(poses, got, strict=True):
        want = log_se3(T, reference=previous)
        np.testing.assert_allclose(x, want, atol=1e-9)
        previous = want
