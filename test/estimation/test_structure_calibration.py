"""The structure calibration: each string's stiffness and rest-length offset recovered from a
recording made by the MuJoCo twin (tensegrity_stiffness.estimation.structure_calibration)."""

from __future__ import annotations

import numpy as np
import pytest
from support.structure_recordings import perturbed_strings

from tensegrity_stiffness.estimation.calibration import CalibrationNoise
from tensegrity_stiffness.estimation.structure_calibration import (
    StructureCalibrationSample,
    calibrate_structure,
    tension_parameter_jacobians,
)
from tensegrity_stiffness.structures.equilibrium import solve_structure_equilibrium
from tensegrity_stiffness.structures.structure import Structure

NOISE = CalibrationNoise(length=1e-4, tension=5e-3)


def three_bar() -> Structure:
    return Structure.from_yaml('config/examples/three_bar.yaml')


def test_tension_jacobians_match_central_differences() -> None:
    s = three_bar()
    rng = np.random.default_rng(0)
    lengths = s.evaluate().lengths * (1 + 0.01 * rng.standard_normal(s.n_strings))
    rest, k = s.rest_lengths, s.k * 1.1
    _, dl, dk, dr = tension_parameter_jacobians(s, lengths, rest, k)
    h = 1e-7
    for analytic, args in ((dl, 0), (dk, 2), (dr, 1)):
        plus = [lengths, rest, k]
        minus = [lengths, rest, k]
        plus[args] = plus[args] + h
        minus[args] = minus[args] - h
        numeric = (tension_parameter_jacobians(s, *plus)[0]
                   - tension_parameter_jacobians(s, *minus)[0]) / (2 * h)
        np.testing.assert_allclose(analytic, numeric, rtol=1e-6, atol=1e-6)


def twin_recording(truth: Structure, offsets: np.ndarray, rng: np.random.Generator,
                   n_commands: int = 12, steps: int = 40
                   ) -> list[StructureCalibrationSample]:
    """The twin of ``truth`` (its stiffnesses and rest lengths the truth) driven through random
    rest-length commands; the encoders read the truth's rest lengths minus ``offsets``."""
    from tensegrity_stiffness.simulation.structure_twin import (
        StructureSimulation,
        measure_structure,
    )
    from tensegrity_stiffness.simulation.twin import SensorNoise

    eq = solve_structure_equilibrium(truth)
    sim = StructureSimulation(truth, poses=eq.poses)
    noise = SensorNoise(lengths=NOISE.length, tensions=NOISE.tension)
    samples = []
    for _ in range(n_commands):
        command = truth.rest_lengths * (1 + 0.03 * rng.uniform(-1, 1, truth.n_strings))
        sim.set_rest_lengths(command)
        for _ in range(3):
            sim.step(steps)
            z = measure_structure(sim, noise, rng)
            samples.append(StructureCalibrationSample(z.lengths, z.tensions,
                                                      z.encoders - offsets))
    return samples


@pytest.mark.slow
def test_recovers_the_twins_stiffness_and_offsets() -> None:
    nominal = three_bar()
    rng = np.random.default_rng(1)
    truth, k_true, offsets = perturbed_strings(nominal, rng)
    samples = twin_recording(truth, offsets, rng)
    cal = calibrate_structure(nominal, samples, NOISE)
    assert cal.unidentifiable == ()
    zk = (cal.stiffness - k_true) / cal.stiffness_std
    zd = (cal.offsets - offsets) / cal.offset_std
    # measured: stiffness within 2.1 % (std <= 1.3 %), offsets within 0.05 mm, chi2/dof 0.80
    assert np.all(np.abs(zk) < 4.0) and np.all(np.abs(zd) < 4.0)
    assert np.max(cal.stiffness_std / k_true) < 0.02
    assert np.max(np.abs(cal.offsets - offsets)) < 2e-4
    assert 0.7 < cal.chi2 / cal.dof < 1.3


def test_a_string_never_taut_is_named_unidentifiable() -> None:
    s = three_bar()
    rng = np.random.default_rng(2)
    state = s.evaluate(solve_structure_equilibrium(s).poses)
    samples = []
    for _ in range(20):
        enc = s.rest_lengths * (1 + 0.02 * rng.uniform(-1, 1, s.n_strings))
        enc[0] = state.lengths[0] + 0.05  # slack: no tension, whatever k and d
        lengths = state.lengths + 1e-4 * rng.standard_normal(s.n_strings)
        tensions, _, _, _ = tension_parameter_jacobians(s, state.lengths, enc, s.k)
        samples.append(StructureCalibrationSample(lengths, tensions + 5e-3 *
                                                  rng.standard_normal(s.n_strings), enc))
    cal = calibrate_structure(s, samples, NOISE)
    assert any(s.string_names[0] in words for words in cal.unidentifiable), cal.unidentifiable
    assert np.isnan(cal.stiffness_std[0]) and np.isnan(cal.offset_std[0])
    assert np.all(np.isfinite(cal.stiffness_std[1:]))


def test_bad_samples_are_named() -> None:
    s = three_bar()
    with pytest.raises(ValueError, match=r'samples\[0\].tensions'):
        calibrate_structure(s, [StructureCalibrationSample(np.ones(9), np.ones(3), np.ones(9))])
    with pytest.raises(ValueError, match='at least one sample'):
        calibrate_structure(s, [])
