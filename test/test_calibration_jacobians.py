"""Central-difference checks of the calibration's analytic Jacobians
(:mod:`tensegrity_stiffness.calibration`): tensions and wrench w.r.t. each string's stiffness and
rest length, and every whitened residual w.r.t. the screws and the scaled parameters."""

from __future__ import annotations

import numpy as np
import pytest

from tensegrity_stiffness import calibration as cal
from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.joint import JointModel
from tensegrity_stiffness.screw import exp_se3, exp_so3

STEP = 1e-7


def _model(force_law: str = 'hooke') -> JointModel:
    model = JointModel.from_yaml(packaged_config_path())
    if force_law == 'hooke':
        return model
    return JointModel(model.link1_nodes, model.connections, model.k, model.rest_lengths,
                      max_lengths=model.max_lengths, force_law=force_law,
                      initial_screw=model.initial_screw)


def _screws(model: JointModel, rng: np.random.Generator, count: int) -> np.ndarray:
    return model.initial_screw + rng.normal(0.0, [0.05] * 3 + [0.002] * 3, (count, 6))


@pytest.mark.parametrize('force_law', ['hooke', 'paper'])
def test_string_parameter_jacobians_match_central_differences(force_law):
    rng = np.random.default_rng(3)
    model = _model(force_law)
    n = model.n_strings
    xi = _screws(model, rng, 4)
    # Rest lengths that make some strings slack and, for the paper law, some saturated.
    rest = model.rest_lengths + rng.uniform(-4e-3, 4e-3, (4, n))
    rest[0, 0] = 0.08
    dphi_dk, dphi_dl0, dF_dk, dF_dl0 = cal.string_parameter_jacobians(model, xi, rest)
    for j in range(n):
        k_plus, k_minus = model.k.copy(), model.k.copy()
        h = STEP * model.k[j] * 1e3
        k_plus[j] += h
        k_minus[j] -= h
        plus = cal.model_with_parameters(model, k_plus).evaluate(xi, rest)
        minus = cal.model_with_parameters(model, k_minus).evaluate(xi, rest)
        np.testing.assert_allclose(dphi_dk[:, j], (plus.tensions - minus.tensions)[:, j] / (2 * h),
                                   rtol=1e-7, atol=1e-9)
        np.testing.assert_allclose(dF_dk[:, :, j], (plus.wrench - minus.wrench) / (2 * h),
                                   rtol=1e-7, atol=1e-9)
        r_plus, r_minus = rest.copy(), rest.copy()
        r_plus[:, j] += STEP
        r_minus[:, j] -= STEP
        plus = model.evaluate(xi, r_plus)
        minus = model.evaluate(xi, r_minus)
        np.testing.assert_allclose(dphi_dl0[:, j],
                                   (plus.tensions - minus.tensions)[:, j] / (2 * STEP),
                                   rtol=1e-6, atol=1e-6)
        np.testing.assert_allclose(dF_dl0[:, :, j], (plus.wrench - minus.wrench) / (2 * STEP),
                                   rtol=1e-6, atol=1e-6)
    assert np.all(dphi_dl0[0, 0] == 0.0)  # the slack string: no dependence


def _problem(rng: np.random.Generator, count: int = 3) -> tuple[cal._Problem, np.ndarray]:
    model = _model()
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
            rest_lengths=model.rest_lengths + rng.uniform(-2e-3, 2e-3, n), pose=T,
            tensions=tensions, lengths=lengths, external_wrench=rng.normal(0.0, 0.2, 6)))
    problem = cal._Problem(model, cal._samples_data(model, samples), cal.CalibrationNoise())
    return problem, xi


def test_residual_jacobians_match_central_differences():
    rng = np.random.default_rng(7)
    problem, xi = _problem(rng)
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
