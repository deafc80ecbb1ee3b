"""The registry of the package's nodes (:func:`node_tables`: every node's parameter table, in
the order of ``docs/parameters.md``) and the rules that need it: an unknown parameter of a
node's own sections is one that no node of the package has (:func:`unknown_parameter_messages`,
:func:`refuse_unknown_parameters`; a whole config file:
:func:`unknown_config_parameters`), and :func:`values_from_config` reads a config file as a node
reads its parameter file. The node modules are imported when :func:`node_tables` is first
called (and only by the unknown-parameter rules when a name is not in the node's own table), so
that importing this module loads no node. No ROS import.
"""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from typing import Any

from tensegrity_stiffness import config
from tensegrity_stiffness.nodes.parameter_specs import (
    STRICT_PARAMETERS,
    NodeTable,
    ParameterSpec,
    by_name,
    defaults,
    flatten,
    generic_name,
)


def node_tables() -> tuple[NodeTable, ...]:
    """Every node's parameter table, in the order of ``docs/parameters.md``: the one registry
    the page is generated from (:mod:`tensegrity_stiffness.nodes.parameter_docs`). A node's table
    is listed here once; after a change run ``python -m tensegrity_stiffness.nodes.parameter_docs
    --write`` (``test/nodes/test_parameter_docs.py`` fails while the committed page differs). A
    function that imports the node modules when called (each node module imports only what
    its node uses)."""
    from tensegrity_stiffness.nodes.estimator_node import ESTIMATOR_NODE_PARAMETERS
    from tensegrity_stiffness.nodes.sim_node import sim_node_parameters
    from tensegrity_stiffness.nodes.spine_estimator_node import spine_estimator_node_parameters
    from tensegrity_stiffness.nodes.spine_node import SPINE_NODE_PARAMETERS
    from tensegrity_stiffness.nodes.stiffness_bridge import BRIDGE_PARAMETERS
    from tensegrity_stiffness.nodes.stiffness_controller import CONTROLLER_PARAMETERS
    from tensegrity_stiffness.nodes.stiffness_node import STIFFNESS_NODE_PARAMETERS
    from tensegrity_stiffness.nodes.structure_estimator_node import (
        STRUCTURE_ESTIMATOR_PARAMETERS,
    )
    from tensegrity_stiffness.nodes.structure_node import STRUCTURE_NODE_PARAMETERS
    from tensegrity_stiffness.nodes.structure_sim_node import STRUCTURE_SIM_PARAMETERS

    return (
        NodeTable('stiffness_node', STIFFNESS_NODE_PARAMETERS, 'config/default_joint.yaml',
                  'one joint: wrench, K, K_c per screw or pose; equilibrium, design and planar '
                  'services', 'docs/nodes.md'),
        NodeTable('spine_node', SPINE_NODE_PARAMETERS, 'config/default_spine.yaml',
                  'a spine of chain.n_joints joints (the table for the default N = 5): '
                  'per-joint outputs, tip pose, tip wrench and tip stiffness; chain '
                  'equilibrium service', 'docs/nodes.md'),
        NodeTable('sim_node', sim_node_parameters(), 'config/default_joint.yaml',
                  'the MuJoCo twin of the joint (with sim.spine true and a spine config, of the '
                  'spine): truth in the nodes\' input formats and simulated sensors',
                  'docs/simulation.md'),
        NodeTable('stiffness_bridge', BRIDGE_PARAMETERS, '',
                  'the stiffness in the form an impedance or admittance controller takes: '
                  'frame change, symmetric positive definite projection, clamps, low-pass, rate '
                  'limit; published or set as the controller\'s parameters',
                  'docs/controllers.md'),
        NodeTable('estimator_node', ESTIMATOR_NODE_PARAMETERS, 'config/default_joint.yaml',
                  'pose, load and stiffness with their uncertainty from measured tensions, '
                  'lengths, an IMU, motion capture or a force-torque sensor',
                  'docs/estimation.md'),
        NodeTable('spine_estimator_node', spine_estimator_node_parameters(),
                  'config/default_spine.yaml',
                  'the estimator of a spine (the table for the default N = 5): every screw, the '
                  'tip load, tip pose and tip stiffness with their covariances',
                  'docs/estimation.md'),
        NodeTable('stiffness_controller', CONTROLLER_PARAMETERS, 'config/default_joint.yaml',
                  'rest-length commands that hold a target pose with a target K_c in closed '
                  'loop, within the actuators\' range and rate', 'docs/control.md'),
        NodeTable('structure_node', STRUCTURE_NODE_PARAMETERS, '',
                  'a structure of rigid bodies and strings (the 3-bar, the 6-bar): per-body '
                  'wrenches, the 6N x 6N stiffness, tensions, bar and contact forces; '
                  'equilibrium and analysis-report services', 'docs/structures.md'),
        NodeTable('structure_sim_node', STRUCTURE_SIM_PARAMETERS, '',
                  'the MuJoCo twin of a structure on the ground: body poses, string lengths, '
                  'tensions, encoders, one IMU per bar; rest-length commands, loads, pushes and '
                  'the scripted roll', 'docs/structures.md'),
        NodeTable('structure_estimator_node', STRUCTURE_ESTIMATOR_PARAMETERS, '',
                  "every body's pose of a structure with its covariance from string lengths, "
                  'load cells, encoders, per-bar IMUs and markers; the trust, the structure '
                  "node's outputs at the estimate", 'docs/structures.md'),
    )



def unknown_parameter_messages(given: Iterable[str], table: Iterable[ParameterSpec]
                               ) -> list[str]:
    """One message per name of ``given`` (the parameters a node's parameter file and overrides
    set) that lies under one of the node's own sections (the first part of a dotted name of
    ``table``: ``joint``, ``joint_<i>``, ``estimation``, ``control``, ...) and is a parameter of
    none of the package's nodes, in the one format of :func:`config.unknown_key_messages`:
    ``joint.stifness: unknown key (did you mean joint.stiffness?)``. Such a value would be left
    out and the default used instead. A parameter of another node (a shared file) is no
    mistake; names outside the node's sections (``use_sim_time``, ``qos_overrides.*``, another
    package's) are not judged."""
    own = sorted({generic_name(spec.name) for spec in table})
    sections = {name.split('.', 1)[0] for name in own if '.' in name}
    candidates = sorted(name for name in set(given) if '.' in name
                        and generic_name(name).split('.', 1)[0] in sections
                        and generic_name(name) not in own)
    if not candidates:  # the common case: the other nodes' tables are not needed (not loaded)
        return []
    known = {generic_name(spec.name) for t in node_tables() for spec in t.parameters}
    lines = []
    for name in candidates:
        generic = generic_name(name)
        if generic in known:
            continue
        section, key = name.split('.', 1)
        generic_section = generic.split('.', 1)[0]
        keys = [n.split('.', 1)[1] for n in own if n.startswith(generic_section + '.')]
        lines += config.unknown_key_messages({key: None}, keys, section)
    return lines


def unknown_config_parameters(document: Any) -> tuple[list[str], bool]:
    """The unknown parameters of every node section of a config document (a ROS parameter file
    or a plain config), judged with every node's table at once (:func:`node_tables`; a file
    shared by several nodes holds each one's parameters), in the one format of
    :func:`unknown_parameter_messages`; and whether the file is strict (its
    ``strict_parameters``, default true: a node refuses to start on them, else warns and
    runs). ValueError when ``strict_parameters`` is not a bool."""
    given = flatten(config.parameters(document))
    strict = bool(STRICT_PARAMETERS.check(given.get(STRICT_PARAMETERS.name, True)))
    table = [spec for t in node_tables() for spec in t.parameters]
    return unknown_parameter_messages(given, table), strict


def refuse_unknown_parameters(given: Iterable[str], table: Iterable[ParameterSpec],
                              strict: bool = True) -> list[str]:
    """Refuse (ValueError, every message of :func:`unknown_parameter_messages` and the opt-out)
    the unknown parameters of the node's own sections in ``given``; with ``strict=False``
    (``strict_parameters: false``) return them as warnings (``...: ignored``) instead."""
    lines = unknown_parameter_messages(given, table)
    if lines and strict:
        raise ValueError('; '.join(lines) + f' ({STRICT_PARAMETERS.name}:=false to warn and '
                         'run with the defaults instead)')
    return [f'{line}: ignored' for line in lines]


def values_from_config(path: Any, table: Iterable[ParameterSpec], strict: bool | None = None
                       ) -> dict[str, Any]:
    """The table's defaults overridden by the parameters of a config file (a ROS parameter file
    or a plain config of the same sections); ValueError names a mistyped one, and an unknown one
    of the table's own sections (:func:`refuse_unknown_parameters`, as a node refuses it)
    unless ``strict`` is False (None: the file's ``strict_parameters``, default true; the
    unknown names are then warned about, :class:`config.UnknownKeyWarning`). Names that are not
    in the table are left out, as a node leaves out the undeclared parameters of its
    ``--params-file`` (``use_sim_time``, ``qos_overrides``, another node's)."""
    specs = by_name(table)
    values = defaults(specs.values())
    given = flatten(config.parameters(config.load_yaml(path)))
    if strict is None:
        strict = bool(STRICT_PARAMETERS.check(given.get(STRICT_PARAMETERS.name, True)))
    for line in refuse_unknown_parameters(given, specs.values(), strict):
        warnings.warn(f'{path}: {line}', config.UnknownKeyWarning, stacklevel=2)
    for name, value in given.items():
        if name in specs:
            values[name] = specs[name].check(value)
    return values

