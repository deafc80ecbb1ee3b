"""The output tables of the streaming nodes (``nodes/layouts.OutputRow``: one row of name, layout
and value per output): the names are the rows' in order, each value's array fills its layout, and
the node modules' ``output_arrays`` are the tables' values. No ROS."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from support import JOINT_CONFIG, SPINE_CONFIG

from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes import (
    layouts,
    spine_node,
    stiffness_node,
    structure_estimator_node,
    structure_node,
)
from tensegrity_stiffness.nodes.parameter_specs import defaults
from tensegrity_stiffness.structures.structure import Structure
from tensegrity_stiffness.structures.templates import six_bar_document


def check_table(rows, names, layouts_by_name, arrays, expected) -> None:
    """The table's names are ``names`` in row order, its arrays the ``expected`` objects, each
    filling its layout."""
    assert names == tuple(row.name for row in rows) == tuple(layouts_by_name)
    assert all(a is b for a, b in zip(arrays, expected, strict=True))
    for (name, layout), values in zip(layouts_by_name.items(), arrays, strict=True):
        assert np.asarray(values).size == layout.size, name


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
