"""The spine estimator names what its sensors leave undetermined (issue #39, observability named):
each joint's part of an undetermined direction in the joint estimator's words, and the tip
load's; a fit stopped by a singular normal matrix names the weak direction instead."""

from __future__ import annotations

import pytest

from tensegrity_stiffness import config
from tensegrity_stiffness.estimation import chain_estimator
from tensegrity_stiffness.estimation.estimators import Measurements, estimate_chain_state
from tensegrity_stiffness.estimation.least_squares import SINGULAR_NORMAL_MATRIX
from tensegrity_stiffness.mechanics.chain import JointChain

#: The ring's spin about its own axis (+z of each joint's {1}), which neither its tensions nor
#: its lengths determine, and the tip load's moment about that axis which turns it.
SPIN = 'rotation about (0.00, 0.00, 1.00)'
MOMENT = 'the tip load (moment about (0.00, 0.00, 1.00))'


@pytest.fixture(scope='module')
def ring_spine():
    chain = JointChain.from_yaml(config.example_config_path('ring8_spine.yaml'))
    return chain, chain.evaluate(chain.unloaded_screws())


def readings(chain, state, kind):
    if kind == 'tensions':
        return [Measurements(tensions=state.tensions[i], tension_std=1e-3)
                for i in range(chain.n_joints)]
    return [Measurements(lengths=state.lengths[i], length_std=1e-4)
            for i in range(chain.n_joints)]


@pytest.mark.parametrize('kind', ['tensions', 'lengths'])
def test_each_joint_s_undetermined_direction_is_named(ring_spine, kind):
    chain, state = ring_spine
    estimate = estimate_chain_state(chain, readings(chain, state, kind))
    assert not estimate.success and not estimate.observable and estimate.rank == 5
    message = estimate.message
    assert 'undetermined: ' + ' with '.join(
        [f'joint {i + 1} {SPIN}' for i in range(chain.n_joints)] + [MOMENT]) in message
    assert '-0.00' not in message


def test_a_weakly_determined_direction_is_named_not_a_singular_matrix(ring_spine,
                                                                      monkeypatch):
    """With a rank tolerance below the spin's singular value the fit's rank is 6; when its
    normal matrix then proves singular, the failure names the direction (as the joint
    estimator's does), not 'singular normal matrix'."""
    chain, state = ring_spine
    solve = chain_estimator._constrained_gauss_newton

    def stopped_singular(*args, **kwargs):
        z, ev, iterations, _, _ = solve(*args, **kwargs)
        return z, ev, iterations, False, SINGULAR_NORMAL_MATRIX

    monkeypatch.setattr(chain_estimator, '_constrained_gauss_newton', stopped_singular)
    estimate = estimate_chain_state(chain, readings(chain, state, 'lengths'),
                                    rank_tolerance=1e-16)
    assert not estimate.success and not estimate.observable
    assert SINGULAR_NORMAL_MATRIX not in estimate.message
    assert f'undetermined: joint 1 {SPIN}' in estimate.message and MOMENT in estimate.message
