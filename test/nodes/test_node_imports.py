"""Each node's ROS-free module imports only what its node uses: in a fresh interpreter, importing
it does not load the planar mechanism (``mechanics.planar``), the MuJoCo twin
(``simulation.twin``) or MuJoCo unless that node needs them (issue #40)."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

PLANAR = 'tensegrity_stiffness.mechanics.planar'
TWIN = 'tensegrity_stiffness.simulation.twin'
HEAVY = (PLANAR, TWIN, 'mujoco', 'rclpy')

#: The heavy modules each node's module may load (every other one of HEAVY it must not).
NEEDS = {
    'stiffness_node': {PLANAR},  # the planar services
    'spine_node': set(),
    'sim_node': {TWIN, 'mujoco'},
    'estimator_node': set(),
    'spine_estimator_node': set(),
    'stiffness_controller': set(),
    'stiffness_bridge': set(),
    'structure_node': set(),
    'structure_sim_node': {TWIN, 'mujoco'},
    'structure_estimator_node': set(),
    # the machinery, the shared sections and the registry load no node
    'parameter_specs': set(),
    'shared_parameters': set(),
    'registry': set(),
    'control_demo_line': set(),  # the control demo's live line, ROS-free
}

SCRIPT = """
import importlib, json, sys
importlib.import_module(sys.argv[1])
print(json.dumps(sorted(m for m in {heavy!r} if m in sys.modules)))
"""


def loaded_after_import(module: str) -> set[str]:
    """The modules of HEAVY in ``sys.modules`` after importing ``module`` in a fresh
    interpreter."""
    out = subprocess.run([sys.executable, '-c', SCRIPT.format(heavy=HEAVY), module],
                         capture_output=True, text=True, check=True, timeout=120)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


@pytest.mark.parametrize('node', sorted(NEEDS))
def test_a_nodes_module_loads_only_what_the_node_uses(node: str) -> None:
    loaded = loaded_after_import(f'tensegrity_stiffness.nodes.{node}')
    assert loaded <= NEEDS[node], f'{node} loads {sorted(loaded - NEEDS[node])}'


def test_the_registry_lists_every_node_module() -> None:
    """The registry's tables are the node modules' own (one home per table)."""
    from tensegrity_stiffness.nodes import (
        estimator_node,
        registry,
        spine_estimator_node,
        spine_node,
        stiffness_bridge,
        stiffness_controller,
        stiffness_node,
    )

    tables = {t.node: t.parameters for t in registry.node_tables()}
    assert tables['stiffness_node'] is stiffness_node.STIFFNESS_NODE_PARAMETERS
    assert tables['spine_node'] is spine_node.SPINE_NODE_PARAMETERS
    assert tables['estimator_node'] is estimator_node.ESTIMATOR_NODE_PARAMETERS
    assert tables['spine_estimator_node'] == \
        spine_estimator_node.spine_estimator_node_parameters()
    assert tables['stiffness_bridge'] is stiffness_bridge.BRIDGE_PARAMETERS
    assert tables['stiffness_controller'] is stiffness_controller.CONTROLLER_PARAMETERS


def test_the_old_module_names_are_faces_of_the_new_homes() -> None:
    """``nodes.parameters``, ``processing``, ``spine_processing`` and ``control_processing``
    re-export the very objects of the new homes."""
    from tensegrity_stiffness.nodes import (
        control_processing,
        parameter_specs,
        parameters,
        processing,
        registry,
        shared_parameters,
        spine_node,
        spine_processing,
        stiffness_controller,
        stiffness_node,
    )

    assert parameters.ParameterSpec is parameter_specs.ParameterSpec
    assert parameters.JOINT_PARAMETERS is shared_parameters.JOINT_PARAMETERS
    assert parameters.node_tables is registry.node_tables
    assert parameters.JointNodeSettings is stiffness_node.JointNodeSettings
    assert processing.joint_outputs is stiffness_node.joint_outputs
    assert spine_processing.spine_outputs is spine_node.spine_outputs
    assert control_processing.controller_settings is stiffness_controller.controller_settings
    for face in (parameters, processing, spine_processing, control_processing):
        assert all(hasattr(face, name) for name in face.__all__)
