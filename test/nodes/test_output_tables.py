"""The output tables of the streaming nodes (``nodes/layouts.OutputRow``: one row of name, layout
and value per output), the estimators' included: the names are the rows' in order, each value's
arrays fill its layout (an estimated pose: its transform and covariance), and the node modules'
``output_arrays`` are the tables' values. No ROS."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace
from typing import Any

import numpy as np
import pytest
from support import JOINT_CONFIG, SPINE_CONFIG
from support.estimation_trials import truth_from_model

from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import (
    estimator_node,
    layouts,
    spine_estimator_node,
    spine_node,
    stiffness_node,
    structure_estimator_node,
    structure_node,
)
from tensegrity_stiffness.nodes.estimator_node import EstimatorInput, Reading
from tensegrity_stiffness.nodes.parameter_specs import defaults
from tensegrity_stiffness.structures.structure import Structure
from tensegrity_stiffness.structures.templates import six_bar_document


def check_table(rows, names, layouts_by_name, arrays, expected) -> None:
    """The table's names are ``names`` in row order, its arrays the ``expected`` objects, each
    filling its layout."""
    assert names == tuple(row.name for row in rows) == tuple(layouts_by_name)
    assert all(a is b for a, b in zip(flattened(arrays), flattened(expected), strict=True))
    for (name, layout), values in zip(layouts_by_name.items(), arrays, strict=True):
        parts = values if isinstance(values, tuple) else (values,)
        assert sum(np.asarray(part).size for part in parts) == layout.size, name


def flattened(arrays: Sequence[Any]) -> tuple[Any, ...]:
    """A table's arrays with a pose's (transform, covariance) as two."""
    return tuple(a for values in arrays
                 for a in (values if isinstance(values, tuple) else (values,)))


def test_the_joints_table_names_its_outputs_and_fills_their_layouts() -> None:
    model = JointModel.from_yaml(JOINT_CONFIG)
    outputs = stiffness_node.joint_outputs(model, model.initial_screw)
    state = outputs.state
    check_table(layouts.JOINT_OUTPUT_TABLE, layouts.JOINT_OUTPUTS,
                layouts.joint_array_layouts(model.string_names),
                stiffness_node.output_arrays(outputs),
                (state.wrench, state.stiffness, state.cartesian_stiffness, state.tensions,
                 outputs.interpretation))


def test_the_spines_table_names_its_outputs_and_fills_their_layouts() -> None:
    chain = JointChain.from_yaml(SPINE_CONFIG)
    outputs = spine_node.spine_outputs(chain, np.array([m.initial_screw for m in chain.joints]))
    state = outputs.state
    check_table(layouts.SPINE_OUTPUT_TABLE, layouts.SPINE_OUTPUTS,
                layouts.spine_array_layouts(chain.n_joints), spine_node.output_arrays(outputs),
                (state.wrenches, state.stiffness, state.cartesian_stiffness,
                 state.tip_transform, outputs.tip_wrench, outputs.tip_stiffness_tool,
                 outputs.tip_stiffness_base))


def test_the_controllers_table_names_its_outputs_and_fills_their_layouts() -> None:
    from tensegrity_stiffness.nodes.parameter_specs import defaults
    from tensegrity_stiffness.nodes.stiffness_controller import (
        CONTROLLER_PARAMETERS,
        ControllerTicks,
        controller_settings,
        new_controller,
    )

    settings = controller_settings(defaults(CONTROLLER_PARAMETERS))
    model = settings.model
    ticker = ControllerTicks(settings, new_controller(settings), 0.002)
    pose = model.evaluate(model.initial_screw).transform
    ticker.target_pose = pose
    ticker.take_state(pose, received=0.0, stamp_ns=0)
    cmd = ticker.tick(0.0, 0).command
    assert layouts.CONTROLLER_OUTPUTS == ('rest_lengths', 'predicted_stiffness')
    table = layouts.controller_output_layouts(model.n_strings)
    check_table(layouts.CONTROLLER_OUTPUT_TABLE, layouts.CONTROLLER_OUTPUTS, table,
                layouts.table_arrays(layouts.CONTROLLER_OUTPUT_TABLE, cmd),
                (cmd.rest_lengths, cmd.predicted_cartesian_stiffness))
    assert table['rest_lengths'].dims[0][0] == layouts.REST_LENGTHS_LABEL
    # the controller's first command is published by the same row
    np.testing.assert_array_equal(layouts.CONTROLLER_OUTPUT_TABLE[0].of(ticker.controller),
                                  ticker.controller.rest_lengths)


@pytest.mark.parametrize('ground', [True, False])
def test_the_structures_tables_name_their_outputs_and_fill_their_layouts(ground: bool) -> None:
    """structure_node's table and the structure estimator's (the covariance, then the structure
    node's rows): the contact forces only with a ground."""
    structure = Structure.from_dict(six_bar_document(ground=ground))
    settings = replace(structure_node.structure_node_settings(
        defaults(structure_node.STRUCTURE_NODE_PARAMETERS)), structure=structure,
        rest_lengths=structure.rest_lengths)
    outputs = structure_node.structure_outputs(settings, structure.start_poses())
    state = outputs.state
    names = structure_node.STRUCTURE_OUTPUTS[:5 if ground else 4]
    expected = (state.wrenches, state.stiffness, state.tensions, state.bar_forces,
                *((outputs.contact_forces,) if ground else ()))
    table = structure_node.STRUCTURE_OUTPUT_TABLE
    assert structure_node.STRUCTURE_OUTPUTS == tuple(row.name for row in table)
    check_table(table[:len(names)], names, structure_node.structure_output_layouts(structure),
                structure_node.output_arrays(outputs), expected)

    n6 = 6 * structure.n_bodies
    estimate = structure_estimator_node.StructureEstimatorOutputs(
        state.poses, np.eye(n6), None, 0, 0.0, (), (), (), (), 'static', (), {}, outputs)
    table = structure_estimator_node.STRUCTURE_ESTIMATOR_OUTPUT_TABLE
    names = ('pose_covariance', *names)
    assert structure_estimator_node.STRUCTURE_ESTIMATOR_OUTPUT_NAMES == (
        'poses', *(row.name for row in table))
    check_table(table[:len(names)], names,
                structure_estimator_node.estimator_array_layouts(structure),
                structure_estimator_node.estimator_output_arrays(estimate)[1:],
                (estimate.covariance, *expected))


def test_the_estimators_table_names_its_outputs_and_fills_their_layouts() -> None:
    """estimator_node's table: the pose and its covariance in one row, K, K_c and the tensions
    on stiffness_node's names and rows; its processing checks the same arrays; the stamped K
    and K_c follow, as stiffness_node's."""
    settings = estimator_node.estimator_node_settings(
        defaults(estimator_node.ESTIMATOR_NODE_PARAMETERS))
    model = settings.model
    truth = truth_from_model(model, model.initial_screw)
    outputs = estimator_node.estimator_outputs(settings, EstimatorInput(
        {'measured_tensions': Reading(truth.tensions, 1.0), 'imu': Reading(truth.gravity, 1.0)},
        1.0, truth.screw))
    est = outputs.estimate
    table = layouts.ESTIMATOR_OUTPUT_TABLE
    arrays = layouts.table_arrays(table, outputs)
    check_table(table, layouts.ESTIMATOR_OUTPUTS,
                layouts.table_layouts(table, model.string_names), arrays,
                ((est.transform, est.covariance), est.external_wrench, est.screw,
                 est.state.stiffness, est.state.cartesian_stiffness, est.state.tensions,
                 est.cartesian_stiffness_std))
    assert [row for row in table if row.name in layouts.JOINT_OUTPUTS] == [
        row for row in layouts.JOINT_OUTPUT_TABLE if row.name in layouts.ESTIMATOR_OUTPUTS]
    assert layouts.ESTIMATOR_STD_OUTPUT in layouts.ESTIMATOR_OUTPUTS
    assert all(a is b for a, b in zip(estimator_node.output_arrays(outputs), flattened(arrays),
                                      strict=True))
    assert tuple(layouts.estimator_output_layouts(model.string_names)) == (
        *layouts.ESTIMATOR_OUTPUTS, *layouts.JOINT_STAMPED_OUTPUTS)
    # the checked arrays' names: the table's, the pose's covariance after the pose
    assert estimator_node.OUTPUT_NAMES == (
        'pose_estimate', 'pose covariance', 'wrench_estimate', 'screw_estimate', 'stiffness',
        'cartesian_stiffness', 'string_tensions', 'cartesian_stiffness_std')
    assert len(estimator_node.OUTPUT_NAMES) == len(estimator_node.output_arrays(outputs))


def test_the_spine_estimators_table_names_its_outputs_and_fills_their_layouts() -> None:
    """spine_estimator_node's table (the tip stiffness on spine_node's name and layout), its
    processing's arrays, then the stamped tip stiffness in the base frame."""
    values = defaults(spine_estimator_node.spine_estimator_node_parameters(3))
    values['chain.n_joints'] = 3
    settings = spine_estimator_node.spine_estimator_node_settings(values)
    screws = settings.chain.unloaded_screws()
    tensions = np.concatenate(list(settings.chain.evaluate(screws).tensions))
    outputs = spine_estimator_node.spine_estimator_outputs(settings, EstimatorInput(
        {'measured_tensions': Reading(tensions, 1.0)}, 1.0, (screws, np.zeros(6))))
    est = outputs.estimate
    table = layouts.SPINE_ESTIMATOR_OUTPUT_TABLE
    arrays = layouts.table_arrays(table, outputs)
    found = layouts.table_layouts(table, 3)
    check_table(table, layouts.SPINE_ESTIMATOR_OUTPUTS, found, arrays,
                (est.screws, (est.tip_transform, est.tip_pose_covariance), est.tip_wrench,
                 est.tip_stiffness, est.tip_stiffness_std))
    assert found['tip_stiffness_base'] == layouts.spine_output_layouts(3)['tip_stiffness_base']
    assert layouts.SPINE_ESTIMATOR_STD_OUTPUT in layouts.SPINE_ESTIMATOR_OUTPUTS
    assert all(a is b for a, b in zip(spine_estimator_node.spine_output_arrays(outputs),
                                      flattened(arrays), strict=True))
    assert tuple(layouts.spine_estimator_output_layouts(3)) == (
        *layouts.SPINE_ESTIMATOR_OUTPUTS, 'tip_stiffness_base_stamped')
    assert spine_estimator_node.SPINE_OUTPUT_NAMES == (
        'screws_estimate', 'tip_pose_estimate', 'tip pose covariance', 'tip_wrench_estimate',
        'tip_stiffness_base', 'tip_stiffness_base_std')
    assert len(spine_estimator_node.SPINE_OUTPUT_NAMES) == len(
        spine_estimator_node.spine_output_arrays(outputs))


def test_the_estimators_pose_and_load_rows_carry_their_message_types() -> None:
    """The rows stiffness_controller subscribes to, looked up by name: the pose with its
    covariance and the load."""
    found = layouts.estimator_output_layouts(())
    assert found[layouts.ESTIMATOR_POSE_OUTPUT].msgtype == layouts.POSE_WITH_COVARIANCE_STAMPED
    assert found[layouts.ESTIMATOR_WRENCH_OUTPUT].msgtype == layouts.WRENCH_STAMPED


def test_a_row_of_several_values_names_each_array() -> None:
    """A row whose message carries several arrays names each (the finite check says which is
    not); a row of one value names none (its array has the row's name)."""
    def layout(sizes):
        return None

    with pytest.raises(ValueError, match='1 array names for 2 values'):
        layouts.OutputRow('pose', layout, ('a', 'b'), array_names=('pose',))
    with pytest.raises(ValueError, match='2 array names for 1 values'):
        layouts.OutputRow('wrench', layout, 'a', array_names=('wrench', 'other'))
    row = layouts.OutputRow('pose', layout, ('a', 'b'), array_names=('pose', 'covariance'))
    assert layouts.table_array_names((row, layouts.OutputRow('w', layout, 'c'))) == (
        'pose', 'covariance', 'w')


def test_the_estimators_finite_check_names_the_array_and_skips_a_std_not_computed() -> None:
    """The first non-finite array is named by the table (the pose's covariance by its own
    name); the std, when not computed (NaN), is left out by name, wherever its row is."""
    names = estimator_node.OUTPUT_NAMES
    arrays = [np.zeros(2) for _ in names]
    arrays[names.index('pose covariance')] = np.array([0.0, np.inf])
    with pytest.raises(ValueError, match=r'^pose covariance contains NaN or inf'):
        estimator_node.require_finite_outputs(names, arrays, None)
    arrays = [np.zeros(2) for _ in names]
    std = names.index(layouts.ESTIMATOR_STD_OUTPUT)
    arrays[std] = np.full(2, np.nan)
    estimator_node.require_finite_outputs(names, arrays, layouts.ESTIMATOR_STD_OUTPUT)
    reordered = (names[std], *names[:std], *names[std + 1:])
    estimator_node.require_finite_outputs(
        reordered, [arrays[std], *arrays[:std], *arrays[std + 1:]], layouts.ESTIMATOR_STD_OUTPUT)
    with pytest.raises(ValueError, match=layouts.ESTIMATOR_STD_OUTPUT):
        estimator_node.require_finite_outputs(names, arrays, None)
