"""The spine's recursive filter (tensegrity_stiffness.estimation.chain_filter) on the forward
model of the default 5-joint spine: its prediction against an integration of
ChainDynamics.acceleration, agreement with estimate_chain_state at rest, its trust rules (NIS,
a broken load cell named and held out, an unobservable set) and bad input."""

import numpy as np
import pytest
from scipy.integrate import solve_ivp
from support.estimation_trials import TENSION_STD

from tensegrity_stiffness.config import packaged_config_path
from tensegrity_stiffness.estimation.chain_filter import ChainFilter
from tensegrity_stiffness.estimation.estimators import (
    ChainEstimate,
    Measurements,
    estimate_chain_state,
)
from tensegrity_stiffness.mechanics.chain import (
    DEFAULT_SPINE_CONFIG,
    JointChain,
    solve_chain_equilibrium,
)
from tensegrity_stiffness.mechanics.dynamics import ChainDynamics


@pytest.fixture(scope='module')
def chain():
    return JointChain.from_yaml(packaged_config_path(DEFAULT_SPINE_CONFIG))


def readings(chain, xi, rng):
    st = chain.evaluate(xi)
    return [Measurements(tensions=st.tensions[i] + rng.normal(scale=TENSION_STD,
                                                               size=st.tensions[i].size),
                         tension_std=TENSION_STD) for i in range(chain.n_joints)]


@pytest.mark.slow
def test_prediction_follows_chain_dynamics(chain):
    """Released from rest off its equilibrium, 10 ms of the filter's prediction follow an
    RK45 integration of ChainDynamics.acceleration (whose velocity-product terms the filter
    leaves out: quadratic in the small rates). Slow: ChainDynamics.acceleration takes tens of
    milliseconds on a moving spine (about 25 s here)."""
    cd = ChainDynamics(chain, None, 0.5)
    rng = np.random.default_rng(1)
    n = chain.n_joints
    xi0 = chain.unloaded_screws() + rng.normal(scale=[2e-3] * 3 + [5e-5] * 3, size=(n, 6))
    horizon = 0.01

    def rhs(_, y):
        return np.concatenate([y[6 * n:], cd.acceleration(y[:6 * n].reshape(n, 6),
                                                          y[6 * n:].reshape(n, 6)).ravel()])

    sol = solve_ivp(rhs, (0.0, horizon), np.r_[xi0.ravel(), np.zeros(6 * n)], rtol=1e-7,
                    atol=1e-12)
    flt = ChainFilter(cd, load='known', stiffness_std=False)
    flt.reset(xi0)
    for k in range(11):
        flt.predict(k * 1e-3)
    travel = np.abs(sol.y[:6 * n, -1] - xi0.ravel()).max()
    assert travel > 1e-4
    np.testing.assert_allclose(flt.state[:6 * n], sol.y[:6 * n, -1], atol=1e-2 * travel)
    rates = sol.y[6 * n:, -1]
    np.testing.assert_allclose(flt.state[6 * n:12 * n], rates, atol=3e-2 * np.abs(rates).max())


def test_at_rest_the_chain_filter_agrees_with_the_static_estimator(chain):
    rng = np.random.default_rng(2)
    n = chain.n_joints
    for _ in range(3):
        W = rng.normal(scale=[0.02] * 3 + [5e-4] * 3)
        xi = solve_chain_equilibrium(chain, W).screws
        flt = ChainFilter(chain, string_damping=0.5, stiffness_std=False)
        for k in range(15):
            m = readings(chain, xi, rng)
            est = flt.step(k * 1e-3, m)
        assert isinstance(est, ChainEstimate) and est.success and est.consistent
        assert est.screw_rates.shape == (n, 6)
        static = estimate_chain_state(chain, m, stiffness_std=False)
        std = np.sqrt(np.diag(static.screw_covariance))
        d = (est.screws - static.screws).ravel()
        assert np.all(np.abs(d) <= 4.0 * std), np.abs(d / std).max()
        # without an IMU the tip load shows only through the motion it would cause: the
        # filter's is looser than the static estimator's (which assumes rest); within its std
        assert np.all(np.abs(est.tip_wrench - static.tip_wrench) <=
                      4.0 * np.sqrt(np.diag(est.tip_wrench_covariance)))


def test_clean_updates_consistent_and_a_broken_load_cell_named(chain):
    rng = np.random.default_rng(3)
    xi = chain.unloaded_screws()
    flt = ChainFilter(chain, string_damping=0.5, stiffness_std=False)
    flags = []
    for k in range(30):
        flags.append(flt.step(k * 1e-3, readings(chain, xi, rng)).consistent)
    assert np.mean([f is True for f in flags]) >= 0.95
    name = f'joint 2 tension[{chain.joints[1].string_names[4]}]'
    for k in range(30, 36):
        m = readings(chain, xi, rng)
        m[1].tensions[4] += 0.8
        est = flt.step(k * 1e-3, m)
        assert est.outliers == (name,), est.outlier_reasons
        assert est.consistent is True and not est.restarted


def test_unobservable_and_bad_input(chain):
    n = chain.n_joints
    flt = ChainFilter(chain)
    est = flt.step(0.0, [None] * n)
    assert not est.success and 'cannot determine' in est.message
    with pytest.raises(ValueError, match='one entry per joint'):
        flt.step(0.0, [None])
    with pytest.raises(ValueError, match='load must be one of'):
        ChainFilter(chain, load='perhaps')
    with pytest.raises(ValueError, match='restart_time_budget'):
        ChainFilter(chain, restart_time_budget=-0.1)
    with pytest.raises(ValueError, match='no state'):
        ChainFilter(chain).predict(0.0)
    with pytest.raises(ValueError, match='tip_pose_covariance'):
        flt.step(0.0, [None] * n, tip_pose=np.eye(4))
