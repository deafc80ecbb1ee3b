"""The spine node's pure parts without a node: its parameter table against
config/default_spine.yaml and the chain library, the per-input checks and outputs
(:mod:`tensegrity_stiffness.nodes.spine_processing`) and the service validation
(:mod:`tensegrity_stiffness.ros.services.spine_services`, with stand-in request objects)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest
from support import REPO

from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.chain import JointChain, solve_chain_equilibrium
from tensegrity_stiffness.nodes import parameters as params
from tensegrity_stiffness.nodes.spine_node import (
    joint_health_in_chain,
    poses_input,
    rest_lengths_input,
    screws_input,
    spine_outputs,
)

SPINE_CONFIG = REPO / 'config' / 'default_spine.yaml'
#: A tip load the default spine holds (forces ~0.1 N, moments ~2 mN m; see test_chain).
TIP_WRENCH = np.array([0.05, -0.1, 0.02, 0.001, 0.0, -0.002])


@pytest.fixture(scope='module')
def settings() -> params.SpineNodeSettings:
    return params.spine_node_settings(
        params.values_from_config(SPINE_CONFIG, params.SPINE_NODE_PARAMETERS))


@pytest.fixture(scope='module')
def loaded(settings):
    res = solve_chain_equilibrium(settings.chain, TIP_WRENCH, np.zeros(3))
    assert res.success, res.message
    return res


def test_default_spine_yaml_agrees_with_the_table():
    """Every key of the file is in the table with its type, and the table's defaults are the
    file's values."""
    from_file = params.values_from_config(SPINE_CONFIG, params.SPINE_NODE_PARAMETERS)
    defaults = params.defaults(params.SPINE_NODE_PARAMETERS)
    assert from_file.keys() == defaults.keys()
    for name, value in defaults.items():
        if name == 'joint.initial_screw':  # empty in the table: solved (mechanics.unloaded)
            assert value == []
            continue
        if isinstance(value, list) and value and isinstance(value[0], float):
            np.testing.assert_allclose(from_file[name], value, rtol=1e-15, err_msg=name)
        else:
            assert from_file[name] == value, name


def test_settings_build_the_chain_of_the_library(settings):
    reference = JointChain.from_yaml(SPINE_CONFIG)
    chain = settings.chain
    assert chain.n_joints == reference.n_joints == 5
    np.testing.assert_array_equal(chain.link_offsets, reference.link_offsets)
    np.testing.assert_array_equal(chain.tool, reference.tool)
    np.testing.assert_array_equal(chain.gravity, reference.gravity)
    assert (chain.base_frame, chain.tool_frame) == (settings.base_frame, settings.tool_frame) \
        == ('spine_base', 'spine_tool')
    assert settings.equilibrium_time_budget == 0.1
    xi = reference.unloaded_screws() + 0.01
    np.testing.assert_array_equal(chain.evaluate(xi).stiffness, reference.evaluate(xi).stiffness)


def test_per_joint_overrides_as_the_library_reads_them():
    values = params.defaults(params.SPINE_NODE_PARAMETERS)
    values['joint_3.stiffness'] = [90.0] * 12
    values['joint_2.force_law'] = 'paper'
    chain = params.spine_node_settings(values).chain
    assert chain.joints[0] is chain.joints[3]  # the shared vertebra
    np.testing.assert_array_equal(chain.joints[2].k, 90.0)
    assert chain.joints[1].force_law == 'paper' and chain.joints[0].force_law == 'hooke'
    document = params.chain_document(values)
    assert sorted(k for k in document if k.startswith('joint_')) == ['joint_2', 'joint_3']


@pytest.mark.parametrize('name, value, match', [
    ('chain.link_offsets', [0.0] * 5, 'chain.link_offsets must have 7'),
    ('chain.tool', [0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0], 'chain: tool'),
    ('chain.link_masses', [0.1, 0.2], 'chain.link_masses must have 5'),
    ('chain.gravity', [0.0, 9.81], 'gravity'),
    ('frames.base', ' ', 'frames.base must not be empty'),
    ('joint_2.rest_lengths', [0.03] * 3, 'joint_2: '),
    ('joint_1.force_law', 'cubic', 'joint_1.force_law must be one of'),
    ('limits.max_array_length', 20, 'below the longest input'),
    ('chain.n_joints', 0, 'chain.n_joints'),
])
def test_whole_set_validation_names_the_field(name, value, match):
    values = params.defaults(params.SPINE_NODE_PARAMETERS)
    values[name] = value
    with pytest.raises(ValueError, match=match):
        params.spine_node_settings(values)


def test_the_table_follows_the_joint_count():
    table = params.by_name(params.spine_node_parameters(2))
    assert 'joint_2.stiffness' in table and 'joint_3.stiffness' not in table
    values = params.defaults(table.values())
    values['chain.n_joints'] = 2
    assert params.spine_node_settings(values).n_joints == 2


# ------------------------------------------------------------------------ inputs and outputs
def test_screws_input_checks_length_and_chart(settings):
    xi = np.zeros(30)
    assert screws_input(xi, 5).shape == (5, 6)
    with pytest.raises(ValueError, match=r'expected 6 N = 30 values .* got 29'):
        screws_input(np.zeros(29), 5)
    xi[12] = 7.0
    with pytest.raises(ValueError, match='joint 3 screw'):
        screws_input(xi, 5)


def test_poses_input_recovers_the_screws_on_the_nearest_branch(settings, loaded):
    xi = loaded.screws
    T = exp_se3(xi)
    got = poses_input('', list(T), 'spine_base', xi)
    np.testing.assert_allclose(got, xi, atol=1e-9)
    assert poses_input('spine_base', list(T), 'spine_base', xi).shape == (5, 6)
    with pytest.raises(ValueError, match="not the base frame 'spine_base'"):
        poses_input('world', list(T), 'spine_base', xi)
    with pytest.raises(ValueError, match='expected N = 5 poses'):
        poses_input('', list(T[:4]), 'spine_base', xi)
    bad = T.copy()
    bad[3, :3, :3] *= 2.0
    with pytest.raises(ValueError, match='joint 4 pose'):
        poses_input('', list(bad), 'spine_base', xi)


def test_rest_lengths_input_splits_and_names_the_joint(settings):
    rest = np.concatenate([m.rest_lengths for m in settings.chain.joints])
    got = rest_lengths_input(rest, settings.chain)
    assert len(got) == 5 and all(r.shape == (12,) for r in got)
    with pytest.raises(ValueError, match='expected 60 values'):
        rest_lengths_input(rest[:-1], settings.chain)
    rest[30] = -0.01
    with pytest.raises(ValueError, match='joint 3: '):
        rest_lengths_input(rest, settings.chain)


def test_outputs_against_the_library(settings, loaded):
    """The implied tip wrench of a configuration solved under a known tip wrench is that
    wrench; the tip stiffness is the library's in both frames."""
    chain, xi = settings.chain, loaded.screws
    out = spine_outputs(chain, xi)
    np.testing.assert_allclose(out.tip_wrench, TIP_WRENCH, atol=1e-9)
    np.testing.assert_allclose(out.tip_wrench, chain.implied_tip_wrench(xi), rtol=0, atol=1e-15)
    np.testing.assert_allclose(out.tip_stiffness_base,
                               chain.tip_stiffness(xi, out.tip_wrench), rtol=1e-12)
    np.testing.assert_allclose(out.tip_stiffness_tool,
                               chain.tip_stiffness(xi, out.tip_wrench, frame='tool'),
                               rtol=1e-12, atol=1e-12 * np.abs(out.tip_stiffness_tool).max())
    np.testing.assert_allclose(out.tip_stiffness_base, loaded.tip_stiffness, rtol=1e-8,
                               atol=1e-8 * np.abs(loaded.tip_stiffness).max())
    rest = tuple(m.rest_lengths * 1.01 for m in chain.joints)
    np.testing.assert_array_equal(spine_outputs(chain, xi, rest).state.stiffness,
                                  chain.evaluate(xi, list(rest)).stiffness)


def test_joint_health_in_chain(settings, loaded):
    state = settings.chain.evaluate(loaded.screws)
    model = settings.chain.joints[0]
    health = joint_health_in_chain(state, 2, model.string_names)
    assert health.stable and not health.slack
    assert math.isclose(health.chart_margin,
                        2 * math.pi - np.linalg.norm(loaded.screws[2, :3]))


# ------------------------------------------------------------------------ services
def _request(**fields):
    wrench = SimpleNamespace(force=SimpleNamespace(x=0.05, y=-0.1, z=0.02),
                             torque=SimpleNamespace(x=0.001, y=0.0, z=-0.002))
    base = {'tip_wrench': wrench, 'use_gravity': False, 'rest_lengths': [],
            'initial_screws': []}
    return SimpleNamespace(**{**base, **fields})


def test_service_job_and_response(settings, loaded):
    spine_services = pytest.importorskip('tensegrity_stiffness.ros.services.spine_services',
                                         exc_type=ImportError)
    job = spine_services.chain_equilibrium_job(_request(), settings, None)
    np.testing.assert_array_equal(job.tip_wrench, TIP_WRENCH)
    assert job.gravity is not None and not job.gravity.any()
    assert job.initial_screws is None and job.rest_lengths is None
    assert job.time_budget == settings.equilibrium_time_budget
    assert spine_services.chain_equilibrium_job(_request(use_gravity=True), settings,
                                                loaded.screws).gravity is None
    for fields, match in (({'initial_screws': [0.0] * 29}, 'initial_screws: expected 6 N'),
                          ({'initial_screws': [math.nan] * 30}, 'finite'),
                          ({'rest_lengths': [0.03] * 59}, 'rest_lengths: expected 60'),
                          ({'rest_lengths': [0.0] * 2000}, 'too many elements')):
        with pytest.raises(ValueError, match=match):
            spine_services.chain_equilibrium_job(_request(**fields), settings, None)
    result = solve_chain_equilibrium(settings.chain, *job.args(), **job.kwargs())
    response = SimpleNamespace()
    assert spine_services.fill_chain_equilibrium(response, result)
    np.testing.assert_allclose(response.screws, loaded.screws.ravel(), atol=1e-12)
    np.testing.assert_array_equal(response.tip_stiffness_base, result.tip_stiffness.ravel())
    np.testing.assert_array_equal(response.tip_stiffness, result.tip_stiffness_tool.ravel())
    assert len(response.joint_wrenches) == 30 and response.stable


def test_require_finite_names_the_output(settings, loaded):
    from dataclasses import replace

    from tensegrity_stiffness.nodes.spine_node import require_finite

    out = spine_outputs(settings.chain, loaded.screws)
    require_finite(out)
    bad = out.tip_stiffness_tool.copy()
    bad[2, 3] = math.inf
    with pytest.raises(ValueError, match='tip_stiffness contains NaN or inf'):
        require_finite(replace(out, tip_stiffness_tool=bad))
    # Far out the chain's outputs overflow: refused as singular or not finite, never published.
    with pytest.raises(ValueError, match=r'singular|contains NaN or inf'):
        require_finite(spine_outputs(settings.chain, loaded.screws + np.r_[0, 0, 0, 1e200, 0, 0]))
