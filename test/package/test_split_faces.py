"""The modules split along their seams (#40) keep every public name they had before the split
(commit a3fb32b), as the faces that re-export their parts: every documented import path
keeps working, and a name read from the face is the object of its new home."""

from __future__ import annotations

import importlib

import pytest

#: The public names of each split module before the split.
PUBLIC_NAMES_BEFORE = {
    'tensegrity_stiffness.estimation.estimators': (
        'AMBIGUITY', 'CHAIN_EQUILIBRIUM_TOLERANCE', 'CONSISTENCY_PROBABILITY', 'ChainEstimate',
        'DAMPING_GROWTH', 'DECREMENT_TOLERANCE', 'IMPOSSIBLE_STD', 'INITIAL_DAMPING',
        'JointEstimate', 'MAX_CONTRADICTED', 'MAX_DAMPING', 'MAX_ITERATIONS',
        'MAX_RESTORATION_STEPS', 'MIN_LENGTH_SCALE', 'Measurements', 'NEAR_SINGULAR_TOLERANCE',
        'POSE_AXES', 'PreparedMeasurements', 'RANK_TOLERANCE', 'SINGULAR_NORMAL_MATRIX',
        'STALL_TOLERANCE', 'STIFFNESS_JACOBIAN_REUSE', 'STIFFNESS_STEP',
        'cartesian_stiffness_jacobian', 'consistency_threshold', 'entry_std',
        'estimate_chain_state', 'estimate_joint_state', 'missing_message',
        'stiffness_jacobian_near', 'suspect_reading', 'tip_pose_jacobian', 'tip_stiffness_std',
        'wilson_hilferty'
    ),
    'tensegrity_stiffness.estimation.calibration': (
        'CalibrationNoise', 'CalibrationResult', 'CalibrationSample', 'ChainCalibrationSample',
        'DAMPING', 'EQUILIBRIUM_ITERATIONS', 'EQUILIBRIUM_TOLERANCE', 'FIT_KINDS',
        'FIT_TOLERANCE', 'HOLD_PASSES', 'Identifiability', 'LOSSES', 'MAX_ITERATIONS',
        'OFFSET_UNIT', 'OUTLIER_PROBABILITY', 'PARAMETER_NAMES', 'PARAMETER_UNITS',
        'RANK_TOLERANCE', 'RECORDED_ROTATION_TOLERANCE', 'RESIDUAL_KINDS', 'RESIDUAL_UNITS',
        'ROBUST_SCALE', 'ROBUST_TOLERANCE', 'SCALE_TEST_PROBABILITY', 'SCREW_ITERATIONS',
        'SCREW_TOLERANCE', 'SLACK_MARGIN', 'STIFFNESS_UNIT', 'SUM_BLOCK_ROWS', 'WARM_DAMPING',
        'calibrate_chain', 'calibrate_joint', 'cramer_rao_std', 'identifiability',
        'initial_screws', 'measures_force', 'model_with_parameters', 'residual_block'
    ),
    'tensegrity_stiffness.simulation.twin': (
        'ChainSimulation', 'DEFAULT_JOINT_DAMPING', 'DEFAULT_JOINT_GRAVITY', 'DEFAULT_MAX_FORCE',
        'DEFAULT_MAX_MOMENT', 'DEFAULT_TENDON_DAMPING', 'DEFAULT_TIMESTEP', 'INTEGRATORS',
        'ImuReading', 'JointSimulation', 'MAX_LENGTH_MODES', 'MIN_REST_LENGTH_FRACTION',
        'Measurements', 'REST_LENGTH_MARGIN', 'REST_SPEED_FACTOR', 'SensorNoise',
        'SimulationOptions', 'chain_mjcf', 'checked_wrench', 'export_mjcf', 'import_mujoco',
        'joint_mjcf', 'measure', 'rate_limited', 'rest_length_bounds'
    ),
    'tensegrity_stiffness.recordings.bag': (
        'Answers', 'BagError', 'BagSummary', 'CHUNK_SIZE', 'DEFAULT_NAMESPACE',
        'DEFAULT_NAMESPACES', 'DamagedBagError', 'FLOAT64_MULTIARRAY', 'MessageReading',
        'NODE_TOPICS', 'NodeTopics', 'OUTPUT_NAMES', 'PLAIN_SCREW_SIZE', 'POSE_ARRAY',
        'POSE_STAMPED', 'PROGRESS_PERIOD', 'Processor', 'STORAGES', 'SpineAnswer',
        'SpineProcessor', 'StiffnessProcessor', 'StructureAnswer', 'StructureProcessor',
        'check_input', 'clear_output', 'jazzy_typestore', 'namespace_prefix', 'node_settings',
        'plain_screw_values', 'process_bag', 'publisher_prefix', 'rosbags_types',
        'single_threaded_blas', 'spine_settings', 'structure_settings', 'write_blocks'
    ),
    'tensegrity_stiffness.mechanics.dynamics': (
        'ChainDynamics', 'ComplexArray', 'DEFAULT_LINK_MASS', 'DEFAULT_STRING_DAMPING',
        'EQUILIBRIUM_TOLERANCE', 'JointDynamics', 'JointModes', 'LinkInertia',
        'MIN_GYRATION_SQUARED', 'REAL_TOLERANCE', 'SCREW_LABELS', 'SYMMETRY_TOLERANCE',
        'body_jacobian', 'body_jacobian_rate', 'chain_inertias_from_config',
        'chain_link_inertias', 'default_inertia_moments', 'format_modes', 'jacobian_derivatives',
        'modes_from_config', 'modes_report', 'state_matrix_modes', 'twin_link_inertias'
    ),
    'tensegrity_stiffness.structures.joints': (
        'JOINT_BODIES', 'link_name', 'structure_from_chain', 'structure_from_joint'
    ),
    'tensegrity_stiffness.mechanics.joint': (
        'BATCH_CHUNK', 'FORCE_LAWS', 'JOINT_KEYS', 'JOINT_SECTION_KEYS', 'JointModel',
        'JointState', 'MAX_STRINGS', 'MIN_STRING_LENGTH', 'NUMERICAL_STEP', 'string_forces'
    ),
}


@pytest.mark.parametrize('module', sorted(PUBLIC_NAMES_BEFORE))
def test_a_split_module_keeps_its_public_names(module: str) -> None:
    face = importlib.import_module(module)
    missing = [name for name in PUBLIC_NAMES_BEFORE[module] if not hasattr(face, name)]
    assert not missing, f'{module} lost {missing}'


@pytest.mark.parametrize('module', sorted(PUBLIC_NAMES_BEFORE))
def test_a_face_s_names_are_their_homes_objects(module: str) -> None:
    """A class or function read from the face is the one its defining module holds (no copy)."""
    face = importlib.import_module(module)
    for name in PUBLIC_NAMES_BEFORE[module]:
        value = getattr(face, name)
        home = getattr(value, '__module__', None)
        if callable(value) and home and home.startswith('tensegrity_stiffness.'):
            assert getattr(importlib.import_module(home), name, None) is value, (module, name)
