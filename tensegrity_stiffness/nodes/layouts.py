"""Labels and shapes of the arrays that tensegrity_stiffness publishes: one home for the node,
the bag command, the command line and :mod:`tensegrity_stiffness.ros.conversions`.

No ROS import: the labels are plain strings, used to build ``std_msgs/Float64MultiArray``
layouts with rclpy messages (:mod:`tensegrity_stiffness.ros.conversions`) or with any other
message implementation
(rosbags types in the bag command). Layout convention (row-major, ``std_msgs/MultiArrayLayout``):
a matrix of shape (rows, cols) has ``dim[0] = (row_label, rows, rows*cols)`` and
``dim[1] = (col_label, cols, cols)``; a vector ``dim[0] = (label, n, n)``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from operator import attrgetter
from typing import Any

from tensegrity_stiffness.geometry.components import (
    BLOCK_NAMES,
    SCREW_NAMES,
    TWIST_NAMES,
    WRENCH_NAMES,
)

WRENCH_LABEL = 'wrench [' + ' '.join(WRENCH_NAMES) + ']'
SCREW_LABEL = 'screw [' + ' '.join(SCREW_NAMES) + ']'
TWIST_LABEL = 'spatial twist in {1} [' + ' '.join(TWIST_NAMES) + '] (linear first, as ROS)'

#: Row label of K and K_c; column labels of K (screw) and of K_c (spatial twist).
STIFFNESS_ROW_LABEL = 'rows: ' + WRENCH_LABEL
STIFFNESS_COL_LABEL = 'cols: ' + SCREW_LABEL
CARTESIAN_STIFFNESS_COL_LABEL = 'cols: ' + TWIST_LABEL

#: Label of ``~/natural_frequencies`` (``dynamics.enabled``): the undamped natural frequencies
#: of the joint's 6 modes (or a spine's 6N), ascending.
NATURAL_FREQUENCIES_LABEL = 'natural frequencies [Hz], modes in ascending order'


def natural_frequencies_label(stable: bool, overdamped: list[int]) -> str:
    """The label of one ``~/natural_frequencies`` message (issue #42): the
    :data:`NATURAL_FREQUENCIES_LABEL`, then ``; stable: yes`` or ``; stable: no`` (an unstable
    pose's frequencies are not those of a vibration about it) and, when some modes are
    overdamped (they do not oscillate: published as 0 Hz), ``; overdamped (0 Hz): modes i, j``
    (0-based positions)."""
    label = f'{NATURAL_FREQUENCIES_LABEL}; stable: {"yes" if stable else "no"}'
    if overdamped:
        label += '; overdamped (0 Hz): modes ' + ', '.join(map(str, overdamped))
    return label
#: Label of ``~/stiffness_eigenvalues`` (a spine's ``~/tip_stiffness_eigenvalues``): the
#: principal stiffnesses of K_c (the tip stiffness in the tool frame),
#: :func:`~tensegrity_stiffness.mechanics.interpretation.principal_stiffnesses`.
STIFFNESS_EIGENVALUES_LABEL = ('principal stiffnesses: eigenvalues of the symmetric part of the '
                               'translational block [N/m] x3, then of the rotational block '
                               '[N m/rad] x3, each ascending')

#: Label of ``~/string_tensions``: this prefix, then the string names in config order.
TENSIONS_LABEL_PREFIX = 'tensions [N], strings in config order: '

#: Label of ``~/stiffness_interpretation`` (16 values, :func:`interpretation_vector`).
INTERPRETATION_LABEL = (
    'stiffness interpretation of K: block Frobenius norms [' + ' '.join(BLOCK_NAMES) + '] (4), '
    'column norms [' + ' '.join(SCREW_NAMES) + '] (6), '
    'row norms [' + ' '.join(WRENCH_NAMES) + '] (6)')
INTERPRETATION_SIZE = len(BLOCK_NAMES) + len(SCREW_NAMES) + len(WRENCH_NAMES)


def tensions_label(string_names: Sequence[str]) -> str:
    """Label of the tensions vector for these string names (config order)."""
    return TENSIONS_LABEL_PREFIX + ' '.join(string_names)


def matrix_dims(rows: int, cols: int, row_label: str, col_label: str
                ) -> list[tuple[str, int, int]]:
    """``(label, size, stride)`` of the two dimensions of a dense row-major matrix."""
    return [(row_label, rows, rows * cols), (col_label, cols, cols)]


def vector_dims(n: int, label: str) -> list[tuple[str, int, int]]:
    """``(label, size, stride)`` of the one dimension of a vector."""
    return [(label, n, n)]


# ------------------------------------------------------------------------------------ spines
#: First dimension of the spine's per-joint arrays (joint-major: joint 1 first).
JOINTS_LABEL = 'joints'
#: Tip stiffness K_tip = dW/d(delta) of a spine: rows the tip wrench, cols a small twist of the
#: tool frame (linear first, as ROS), both in the tool frame (``~/tip_stiffness``) or in the
#: base frame, wrench about its origin (``~/tip_stiffness_base``).
TIP_STIFFNESS_LABELS = {
    frame: ('rows: tip wrench in the ' + frame + ' frame [' + ' '.join(WRENCH_NAMES) + ']',
            'cols: tip twist in the ' + frame + ' frame [' + ' '.join(TWIST_NAMES)
            + '] (linear first, as ROS)')
    for frame in ('tool', 'base')}


def stacked_matrix_dims(n: int, rows: int, cols: int, stack_label: str, row_label: str,
                        col_label: str) -> list[tuple[str, int, int]]:
    """``(label, size, stride)`` of ``n`` dense row-major (rows, cols) matrices, one after
    the other (shape (n, rows, cols))."""
    return [(stack_label, n, n * rows * cols), *matrix_dims(rows, cols, row_label, col_label)]


# ------------------------------------------------------------------------------ output messages
#: ROS 2 type names of the nodes' output messages (``package/msg/Name``, as rosbag2 records them).
FLOAT64_MULTIARRAY = 'std_msgs/msg/Float64MultiArray'
WRENCH_STAMPED = 'geometry_msgs/msg/WrenchStamped'
POSE_STAMPED = 'geometry_msgs/msg/PoseStamped'
#: The estimators' poses: a (4, 4) transform and the (6, 6) covariance of ``[dp; dtheta]``
#: (ROS's ``PoseWithCovariance`` convention, row-major, both in the header's frame).
POSE_WITH_COVARIANCE_STAMPED = 'geometry_msgs/msg/PoseWithCovarianceStamped'
#: The package's stamped matrix (``msg/StampedMatrix.msg``: header with the input's stamp and
#: the frame, row and column labels and counts, row-major data).
STAMPED_MATRIX = 'tensegrity_stiffness/msg/StampedMatrix'
#: Its definition, relative to the package's share folder (read by the bag command, which
#: registers it with rosbags).
STAMPED_MATRIX_DEFINITION = 'msg/StampedMatrix.msg'


@dataclass(frozen=True)
class OutputLayout:
    """One output message of a node: its type and, for a ``Float64MultiArray``, its layout
    ``dims`` ((label, size, stride) each; the payload holds ``dims[0][2]`` values). A stamped
    message (``WrenchStamped``, ``PoseStamped``, ``PoseWithCovarianceStamped``) carries the
    frame id the node is configured with (``link1_frame`` of ``stiffness_node``,
    ``base_frame`` of ``spine_node``), given when it is filled."""

    msgtype: str
    dims: tuple[tuple[str, int, int], ...] = ()
    #: The output whose array this one carries too (a :data:`STAMPED_MATRIX` beside the
    #: ``Float64MultiArray`` of the same matrix); None: its own array.
    source: str | None = None

    @property
    def size(self) -> int:
        """Values in the payload (6 for a wrench, 16 for a pose's (4, 4) transform, 16 + 36
        with its (6, 6) covariance)."""
        if self.msgtype in (FLOAT64_MULTIARRAY, STAMPED_MATRIX):
            return self.dims[0][2]
        return {WRENCH_STAMPED: 6, POSE_STAMPED: 16, POSE_WITH_COVARIANCE_STAMPED: 16 + 36}[
            self.msgtype]

    @property
    def stamped(self) -> bool:
        """Whether the message has a header (stamp and frame id)."""
        return self.msgtype != FLOAT64_MULTIARRAY


def _array(dims: Sequence[tuple[str, int, int]]) -> OutputLayout:
    return OutputLayout(FLOAT64_MULTIARRAY, tuple(dims))


def with_stamped_matrices(arrays: dict[str, OutputLayout], stamped: Mapping[str, str]
                          ) -> dict[str, OutputLayout]:
    """``arrays`` followed by a :data:`STAMPED_MATRIX` for each ``stamped`` name -> the name
    of the matrix output of ``arrays`` it carries (same labels and data, with a header)."""
    return {**arrays, **{name: OutputLayout(STAMPED_MATRIX, arrays[of].dims, source=of)
                         for name, of in stamped.items()}}


@dataclass(frozen=True)
class OutputRow:
    """One per-input output of a streaming node, one row of its output table: the topic
    ``name`` (relative to the node), its ``layout`` (a function of the node's sizes: the
    joint's string names, the spine's joint count) and ``value``, the dotted attribute of the
    node's outputs object that holds its array (``'state.wrench'`` of
    :class:`~tensegrity_stiffness.nodes.stiffness_node.JointOutputs`), or a tuple of them for a
    message that carries several arrays (an estimated pose and its covariance: its value the
    tuple of their arrays)."""

    name: str
    layout: Callable[[Any], OutputLayout | None]
    value: str | tuple[str, ...]
    #: An output that only some nodes publish (a structure's contact forces: only with a
    #: ground): where it is absent, its layout is None and its value is None.
    optional: bool = False
    #: The names of the arrays of a row of several values, in their order (the finite check
    #: names the one that is not); none for a row of one value: its array has the row's name.
    array_names: tuple[str, ...] = ()
    of: Callable[[Any], Any] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        values = (self.value,) if isinstance(self.value, str) else self.value
        if len(self.array_names) != (len(values) if len(values) > 1 else 0):
            raise ValueError(f'output {self.name!r}: {len(self.array_names)} array names for '
                             f'{len(values)} values (a row of several values names each)')
        object.__setattr__(self, 'of', attrgetter(*values))

    @property
    def arrays(self) -> tuple[str, ...]:
        """The names of this row's arrays, in the order of its values."""
        return self.array_names or (self.name,)

    def within(self, attribute: str) -> OutputRow:
        """This row for outputs that hold this row's outputs as ``attribute`` (the structure
        estimator's ``structure``: its value ``'<attribute>.<value>'``)."""
        if isinstance(self.value, str):
            return replace(self, value=f'{attribute}.{self.value}')
        return replace(self, value=tuple(f'{attribute}.{value}' for value in self.value))


def table_arrays(table: Sequence[OutputRow], outputs: Any) -> tuple[Any, ...]:
    """The arrays of ``outputs`` in the order of ``table`` (one per row; none for an absent
    optional row)."""
    arrays = ((row, row.of(outputs)) for row in table)
    return tuple(value for row, value in arrays if not (row.optional and value is None))


def table_array_names(table: Sequence[OutputRow]) -> tuple[str, ...]:
    """The names of the arrays of ``table``'s rows, in :func:`flat_table_arrays` order (a row
    of several values: :attr:`OutputRow.array_names`)."""
    return tuple(name for row in table for name in row.arrays)


def flat_table_arrays(table: Sequence[OutputRow], outputs: Any) -> tuple[Any, ...]:
    """:func:`table_arrays` with the arrays of a row of several values (an estimated pose's
    transform and covariance) one by one, in :func:`table_array_names` order."""
    arrays = ((row, row.of(outputs)) for row in table)
    return tuple(array for row, values in arrays if not (row.optional and values is None)
                 for array in (values if len(row.arrays) > 1 else (values,)))


def table_layouts(table: Sequence[OutputRow], sizes: Any) -> dict[str, OutputLayout]:
    """The layouts of ``table``'s outputs by name, in its order, for a node of ``sizes``
    (none for an absent optional row)."""
    layouts = {row.name: row.layout(sizes) for row in table}
    return {name: layout for name, layout in layouts.items() if layout is not None}


def _joint_matrix(col_label: str) -> Callable[[Any], OutputLayout]:
    return lambda names: _array(matrix_dims(6, 6, STIFFNESS_ROW_LABEL, col_label))


def _spine_stack(col_label: str) -> Callable[[int], OutputLayout]:
    return lambda n: _array(stacked_matrix_dims(n, 6, 6, JOINTS_LABEL, STIFFNESS_ROW_LABEL,
                                                col_label))


#: K, K_c and the tensions of a joint's state (``state.*``), published by ``stiffness_node``
#: and, on the same names so that one remap serves both, by ``estimator_node``.
_JOINT_STATE_ROWS = (
    OutputRow('stiffness', _joint_matrix(STIFFNESS_COL_LABEL), 'state.stiffness'),
    OutputRow('cartesian_stiffness', _joint_matrix(CARTESIAN_STIFFNESS_COL_LABEL),
              'state.cartesian_stiffness'),
    OutputRow('string_tensions',
              lambda names: _array(vector_dims(len(names), tensions_label(names))),
              'state.tensions'),
)


def _tip_stiffness_base(n_joints: int) -> OutputLayout:
    """The layout of a spine's tip stiffness in the base frame (``spine_node``'s and the
    spine estimator's ``~/tip_stiffness_base``, and its std)."""
    return _array(matrix_dims(6, 6, *TIP_STIFFNESS_LABELS['base']))


#: ``stiffness_node``'s per-input outputs (topic names relative to the node), in the order they
#: are computed, filled and published: one row each (name, layout of the string names, value of
#: :class:`~tensegrity_stiffness.nodes.stiffness_node.JointOutputs`). Adding or reordering an
#: output is one row here; the node, the bag command and the message builders read it.
JOINT_OUTPUT_TABLE: tuple[OutputRow, ...] = (
    OutputRow('wrench', lambda names: OutputLayout(WRENCH_STAMPED), 'state.wrench'),
    *_JOINT_STATE_ROWS,
    OutputRow('stiffness_interpretation',
              lambda names: _array(vector_dims(INTERPRETATION_SIZE, INTERPRETATION_LABEL)),
              'interpretation'),
)
#: The names of :data:`JOINT_OUTPUT_TABLE`, in its order: the one home of the joint's output
#: names and order.
JOINT_OUTPUTS = tuple(row.name for row in JOINT_OUTPUT_TABLE)
#: ``spine_node``'s per-input outputs, likewise (layouts of the joint count N, values of
#: :class:`~tensegrity_stiffness.nodes.spine_node.SpineOutputs`).
SPINE_OUTPUT_TABLE: tuple[OutputRow, ...] = (
    OutputRow('joint_wrenches', lambda n: _array(matrix_dims(n, 6, JOINTS_LABEL, WRENCH_LABEL)),
              'state.wrenches'),
    OutputRow('joint_stiffness', _spine_stack(STIFFNESS_COL_LABEL),
              'state.stiffness'),
    OutputRow('joint_cartesian_stiffness',
              _spine_stack(CARTESIAN_STIFFNESS_COL_LABEL),
              'state.cartesian_stiffness'),
    OutputRow('tip_pose', lambda n: OutputLayout(POSE_STAMPED), 'state.tip_transform'),
    OutputRow('tip_wrench', lambda n: OutputLayout(WRENCH_STAMPED), 'tip_wrench'),
    OutputRow('tip_stiffness', lambda n: _array(matrix_dims(6, 6, *TIP_STIFFNESS_LABELS['tool'])),
              'tip_stiffness_tool'),
    OutputRow('tip_stiffness_base', _tip_stiffness_base, 'tip_stiffness_base'),
)
#: The names of :data:`SPINE_OUTPUT_TABLE`, in its order.
SPINE_OUTPUTS = tuple(row.name for row in SPINE_OUTPUT_TABLE)

#: Label of ``stiffness_controller``'s ``~/rest_lengths`` (motor commands, ``true - offset``).
REST_LENGTHS_LABEL = 'rest lengths [m] (motor commands), string order of the config'
#: ``stiffness_controller``'s outputs, likewise (layouts of the string count n, values of a
#: :class:`~tensegrity_stiffness.control.controller.ControlCommand`; ``rest_lengths`` also of
#: the controller itself, its first command).
CONTROLLER_OUTPUT_TABLE: tuple[OutputRow, ...] = (
    OutputRow('rest_lengths', lambda n: _array(vector_dims(n, REST_LENGTHS_LABEL)),
              'rest_lengths'),
    OutputRow('predicted_stiffness', _joint_matrix(CARTESIAN_STIFFNESS_COL_LABEL),
              'predicted_cartesian_stiffness'),
)
#: The names of :data:`CONTROLLER_OUTPUT_TABLE`, in its order.
CONTROLLER_OUTPUTS = tuple(row.name for row in CONTROLLER_OUTPUT_TABLE)
#: The stamped matrices published beside ``stiffness_node``'s arrays (name -> the array it
#: carries), after :data:`JOINT_OUTPUTS`: a subscriber pairs each with its input by stamp.
JOINT_STAMPED_OUTPUTS = {'stiffness_stamped': 'stiffness',
                         'cartesian_stiffness_stamped': 'cartesian_stiffness'}
#: ``spine_node``'s, likewise (the tip stiffness in the tool and in the base frame).
SPINE_STAMPED_OUTPUTS = {'tip_stiffness_stamped': 'tip_stiffness',
                         'tip_stiffness_base_stamped': 'tip_stiffness_base'}

#: The output ``estimator_node`` computes only while someone subscribes to it (the std of
#: K_c, labelled as K_c); ``spine_estimator_node``'s (the std of the tip stiffness).
ESTIMATOR_STD_OUTPUT = 'cartesian_stiffness_std'
SPINE_ESTIMATOR_STD_OUTPUT = 'tip_stiffness_base_std'
#: ``estimator_node``'s estimated pose (with its covariance) and load: ``stiffness_controller``
#: subscribes to its state on these names, so that one remap each wires it to the estimator.
ESTIMATOR_POSE_OUTPUT = 'pose_estimate'
ESTIMATOR_WRENCH_OUTPUT = 'wrench_estimate'
#: ``estimator_node``'s per-estimate outputs, likewise (layouts of the string names, values of
#: :class:`~tensegrity_stiffness.nodes.estimator_node.EstimatorOutputs`): the pose with its
#: covariance, the load, the screw, then K, K_c and the tensions on the names of
#: ``stiffness_node``'s (so that one remap serves both), the std of K_c.
ESTIMATOR_OUTPUT_TABLE: tuple[OutputRow, ...] = (
    OutputRow(ESTIMATOR_POSE_OUTPUT, lambda names: OutputLayout(POSE_WITH_COVARIANCE_STAMPED),
              ('estimate.transform', 'estimate.covariance'),
              array_names=(ESTIMATOR_POSE_OUTPUT, 'pose covariance')),
    OutputRow(ESTIMATOR_WRENCH_OUTPUT, lambda names: OutputLayout(WRENCH_STAMPED),
              'estimate.external_wrench'),
    OutputRow('screw_estimate', lambda names: _array(vector_dims(6, SCREW_LABEL)),
              'estimate.screw'),
    *_JOINT_STATE_ROWS,
    OutputRow(ESTIMATOR_STD_OUTPUT, _joint_matrix(CARTESIAN_STIFFNESS_COL_LABEL),
              'estimate.cartesian_stiffness_std'),
)
#: The names of :data:`ESTIMATOR_OUTPUT_TABLE`, in its order.
ESTIMATOR_OUTPUTS = tuple(row.name for row in ESTIMATOR_OUTPUT_TABLE)
#: ``spine_estimator_node``'s, likewise (layouts of the joint count N, values of
#: :class:`~tensegrity_stiffness.nodes.spine_estimator_node.SpineEstimatorOutputs`): the
#: screws (joint-major), the tip pose (the tool frame in the base) with its covariance, the
#: tip load (base, about its origin), the tip stiffness in the base (on ``spine_node``'s name)
#: and its std (labelled as it).
SPINE_ESTIMATOR_OUTPUT_TABLE: tuple[OutputRow, ...] = (
    OutputRow('screws_estimate', lambda n: _array(matrix_dims(n, 6, JOINTS_LABEL, SCREW_LABEL)),
              'estimate.screws'),
    OutputRow('tip_pose_estimate', lambda n: OutputLayout(POSE_WITH_COVARIANCE_STAMPED),
              ('estimate.tip_transform', 'estimate.tip_pose_covariance'),
              array_names=('tip_pose_estimate', 'tip pose covariance')),
    OutputRow('tip_wrench_estimate', lambda n: OutputLayout(WRENCH_STAMPED),
              'estimate.tip_wrench'),
    OutputRow('tip_stiffness_base', _tip_stiffness_base, 'estimate.tip_stiffness'),
    OutputRow(SPINE_ESTIMATOR_STD_OUTPUT, _tip_stiffness_base, 'estimate.tip_stiffness_std'),
)
#: The names of :data:`SPINE_ESTIMATOR_OUTPUT_TABLE`, in its order.
SPINE_ESTIMATOR_OUTPUTS = tuple(row.name for row in SPINE_ESTIMATOR_OUTPUT_TABLE)
#: The stamped matrices published after the estimators' outputs: ``stiffness_node``'s (K and
#: K_c) and those of ``spine_node``'s that the spine estimator publishes (the tip stiffness in
#: the base frame), stamped with the estimate's stamp and frame.
ESTIMATOR_STAMPED_OUTPUTS = JOINT_STAMPED_OUTPUTS
SPINE_ESTIMATOR_STAMPED_OUTPUTS = {name: of for name, of in SPINE_STAMPED_OUTPUTS.items()
                                   if of in SPINE_ESTIMATOR_OUTPUTS}


def joint_output_layouts(string_names: Sequence[str]) -> dict[str, OutputLayout]:
    """``stiffness_node``'s per-input outputs by topic, in :data:`JOINT_OUTPUTS` order (wrench,
    K, K_c, tensions, interpretation), then :data:`JOINT_STAMPED_OUTPUTS`."""
    return with_stamped_matrices(joint_array_layouts(string_names), JOINT_STAMPED_OUTPUTS)


def joint_array_layouts(string_names: Sequence[str]) -> dict[str, OutputLayout]:
    """The outputs of :data:`JOINT_OUTPUT_TABLE` alone (one array each)."""
    return table_layouts(JOINT_OUTPUT_TABLE, string_names)


def spine_output_layouts(n_joints: int) -> dict[str, OutputLayout]:
    """``spine_node``'s per-input outputs by topic, in :data:`SPINE_OUTPUTS` order, then
    :data:`SPINE_STAMPED_OUTPUTS`."""
    return with_stamped_matrices(spine_array_layouts(n_joints), SPINE_STAMPED_OUTPUTS)


def spine_array_layouts(n_joints: int) -> dict[str, OutputLayout]:
    """The outputs of :data:`SPINE_OUTPUT_TABLE` alone (one array each)."""
    return table_layouts(SPINE_OUTPUT_TABLE, n_joints)


def controller_output_layouts(n_strings: int) -> dict[str, OutputLayout]:
    """``stiffness_controller``'s outputs by topic, in :data:`CONTROLLER_OUTPUT_TABLE` order."""
    return table_layouts(CONTROLLER_OUTPUT_TABLE, n_strings)


def estimator_output_layouts(string_names: Sequence[str]) -> dict[str, OutputLayout]:
    """``estimator_node``'s per-estimate outputs by topic, in :data:`ESTIMATOR_OUTPUTS` order,
    then :data:`ESTIMATOR_STAMPED_OUTPUTS`."""
    return with_stamped_matrices(table_layouts(ESTIMATOR_OUTPUT_TABLE, string_names),
                                 ESTIMATOR_STAMPED_OUTPUTS)


def spine_estimator_output_layouts(n_joints: int) -> dict[str, OutputLayout]:
    """``spine_estimator_node``'s per-estimate outputs by topic, in
    :data:`SPINE_ESTIMATOR_OUTPUTS` order, then :data:`SPINE_ESTIMATOR_STAMPED_OUTPUTS`."""
    return with_stamped_matrices(table_layouts(SPINE_ESTIMATOR_OUTPUT_TABLE, n_joints),
                                 SPINE_ESTIMATOR_STAMPED_OUTPUTS)
