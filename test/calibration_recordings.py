"""Synthetic calibration recordings for the tests and the bench: a joint whose true parameters
are drawn away from the nominal (each ``k_j`` within +-20 %, each rest-length offset within
+-1 mm), driven through commanded rest lengths and loads, measured with noise.

The true configurations come from the MuJoCo twin (:mod:`tensegrity_stiffness.simulation`)
when it is installed, else from the library's equilibrium solver (``backend='library'``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tensegrity_stiffness.calibration import (
    CalibrationNoise,
    CalibrationSample,
    model_with_parameters,
)
from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.equilibrium import solve_equilibrium
from tensegrity_stiffness.joint import JointModel
from tensegrity_stiffness.screw import exp_so3

#: Spread of the commanded rest lengths around the nominal (m, uniform) and of the loads
#: (force N, moment N m, normal): loads of the order of the pretension excite the offsets.
REST_SPREAD = 3e-3
FORCE_SPREAD = 0.6
MOMENT_SPREAD = 0.01


@dataclass
class Recording:
    """Samples with the truth behind them."""

    nominal: JointModel
    true_stiffness: np.ndarray
    true_offsets: np.ndarray
    true_screws: np.ndarray
    true_loads: np.ndarray
    samples: list[CalibrationSample]


def nominal_model() -> JointModel:
    return JointModel.from_yaml(packaged_config_path())


def true_parameters(model: JointModel, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    n = model.n_strings
    return model.k * (1.0 + rng.uniform(-0.2, 0.2, n)), rng.uniform(-1e-3, 1e-3, n)


def configurations(model: JointModel, k: np.ndarray, d: np.ndarray, count: int, seed: int,
                   force: float = FORCE_SPREAD, moment: float = MOMENT_SPREAD,
                   rest_spread: float = REST_SPREAD
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(commanded rest lengths (count, n), loads (count, 6), true screws (count, 6)): stable
    equilibria of the true joint (library solver) under random loads of std ``force`` (N) and
    ``moment`` (N m)."""
    rng = np.random.default_rng(seed + 1000)
    true = model_with_parameters(model, k, model.rest_lengths + d)
    n = model.n_strings
    rest, loads, screws = [], [], []
    previous = solve_equilibrium(true, np.zeros(6)).screw
    while len(rest) < count:
        command = model.rest_lengths + rng.uniform(-rest_spread, rest_spread, n)
        W = np.concatenate([rng.normal(0.0, force, 3), rng.normal(0.0, moment, 3)])
        eq = solve_equilibrium(true, W, command + d, initial_screw=previous)
        if not (eq.success and eq.stable):
            continue
        previous = eq.screw
        rest.append(command)
        loads.append(W)
        screws.append(eq.screw)
    return np.array(rest), np.array(loads), np.array(screws)


def measure(model: JointModel, k: np.ndarray, d: np.ndarray, rest: np.ndarray,
            loads: np.ndarray, screws: np.ndarray, seed: int, noise: CalibrationNoise,
            pose: bool = True, wrench: bool = True, tensions: tuple[int, ...] = (),
            unloaded_disturbance: bool = False) -> list[CalibrationSample]:
    """Noisy samples of the true states. ``unloaded_disturbance``: the recorded wrench is zero
    while the joint carried small random loads of the wrench noise (an "unloaded" joint)."""
    rng = np.random.default_rng(seed + 2000)
    true = model_with_parameters(model, k, model.rest_lengths + d)
    states = true.evaluate(screws, rest + d)
    samples = []
    for i in range(len(rest)):
        T = states.transform[i].copy()
        T[:3, :3] = exp_so3(rng.normal(0.0, noise.rotation, 3)) @ T[:3, :3]
        T[:3, 3] += rng.normal(0.0, noise.position, 3)
        W = loads[i] + np.concatenate([rng.normal(0.0, noise.force, 3),
                                       rng.normal(0.0, noise.moment, 3)])
        t = np.full(model.n_strings, np.nan)
        idx = list(tensions)
        t[idx] = states.tensions[i, idx] + rng.normal(0.0, noise.tension, len(idx))
        samples.append(CalibrationSample(
            rest_lengths=rest[i], pose=T if pose else None,
            tensions=t if idx else None,
            external_wrench=(np.zeros(6) if unloaded_disturbance else W) if wrench else None))
    return samples
