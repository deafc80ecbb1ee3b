"""What the bag command reads, for each node it replays (:data:`NODE_TOPICS`): the input and
output topics, the node's settings from its parameter file, the rosbags typestore, one
message's reading (:class:`MessageReading`) and the command's errors (:class:`BagError`).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.chain import DEFAULT_SPINE_CONFIG
from tensegrity_stiffness.nodes import layouts, structure_node
from tensegrity_stiffness.nodes.layouts import FLOAT64_MULTIARRAY
from tensegrity_stiffness.nodes.messages import (
    MessageTypes,
)
from tensegrity_stiffness.nodes.parameter_specs import defaults
from tensegrity_stiffness.nodes.registry import values_from_config
from tensegrity_stiffness.nodes.shared_parameters import CHAIN_PARAMETERS
from tensegrity_stiffness.nodes.spine_node import (
    SpineNodeSettings,
    spine_node_parameters,
    spine_node_settings,
)
from tensegrity_stiffness.nodes.stiffness_node import (
    STIFFNESS_NODE_PARAMETERS,
    JointNodeSettings,
    joint_node_settings,
)
from tensegrity_stiffness.structures.schema import is_structure_document

FloatArray = NDArray[np.float64]

POSE_STAMPED = layouts.POSE_STAMPED
POSE_ARRAY = 'geometry_msgs/msg/PoseArray'
DEFAULT_NAMESPACE = '/stiffness_node'
#: Output storages (rosbag2 storage identifiers).
STORAGES = ('mcap', 'sqlite3')
#: Answers computed per batched evaluation.
CHUNK_SIZE = 2048
#: Seconds between progress reports.
PROGRESS_PERIOD = 0.2


@dataclass(frozen=True)
class NodeTopics:
    """Input and output topics (names relative to the node, message types) of one node kind:
    ``stiffness`` is ``stiffness_node`` (:class:`StiffnessProcessor`), ``spine`` is
    ``spine_node`` (:class:`SpineProcessor`)."""

    inputs: Mapping[str, str]
    outputs: Mapping[str, str]


NODE_TOPICS: dict[str, NodeTopics] = {
    # The outputs' types (from the node's layouts) do not depend on the string names or the
    # joint count.
    'stiffness': NodeTopics(
        inputs={'screw': FLOAT64_MULTIARRAY, 'pose': POSE_STAMPED,
                'rest_lengths': FLOAT64_MULTIARRAY},
        outputs={name: layout.msgtype for name, layout in
                 layouts.joint_output_layouts(()).items()}),
    # spine_node's per-input outputs, in the order of spine_node.OUTPUT_NAMES.
    'spine': NodeTopics(
        inputs={'screws': FLOAT64_MULTIARRAY, 'poses': POSE_ARRAY,
                'rest_lengths': FLOAT64_MULTIARRAY},
        outputs={name: layout.msgtype for name, layout in
                 layouts.spine_output_layouts(1).items()}),
    # structure_node's, in the order of structure_node.STRUCTURE_OUTPUTS (contact_forces only
    # for a structure with a ground: the structure kind's writer skips it otherwise).
    'structure': NodeTopics(
        inputs={'poses': POSE_ARRAY, 'pose_values': FLOAT64_MULTIARRAY,
                'rest_lengths': FLOAT64_MULTIARRAY},
        outputs=dict.fromkeys(structure_node.STRUCTURE_OUTPUTS, FLOAT64_MULTIARRAY)),
}


OUTPUT_NAMES = tuple(NODE_TOPICS['stiffness'].outputs)
#: Default namespace (the node's name in the root namespace) of each node kind.
DEFAULT_NAMESPACES = {'stiffness': DEFAULT_NAMESPACE, 'spine': '/spine_node',
                      'structure': '/structure_node'}


class BagError(ValueError):
    """A problem with the command's files or options (the CLI's exit 2, one line)."""


class DamagedBagError(BagError):
    """A recording whose storage stops being readable part way (flipped bytes, a truncated
    file): what was read is said; the reader that raises it takes ``allow_damaged`` to go on
    with what was read."""


@dataclass
class MessageReading:
    """The messages of a rosbag2 reader with damage caught: :meth:`messages` yields
    ``reader.messages(connections=...)`` until the storage ends or stops being readable, then
    ``damage`` says why (empty: read to the end) and ``read`` how many of ``total`` came."""

    total: int
    read: int = 0
    damage: str = ''

    def messages(self, reader: Any, connections: Sequence[Any]) -> Iterable[Any]:
        """``(connection, log_time, raw)`` of ``connections`` in log-time order."""
        stream = iter(reader.messages(connections=connections))
        while True:
            try:
                item = next(stream)
            except StopIteration:
                return
            except Exception as exc:  # rosbags raises many types on corrupt storage
                self.damage = f'{type(exc).__name__}: {exc}'
                return
            self.read += 1
            yield item

    def check(self, source: Any, allow_damaged: bool) -> None:
        """:class:`DamagedBagError` saying how much was read, unless ``allow_damaged`` or the
        storage was read to its end."""
        if self.damage and not allow_damaged:
            raise DamagedBagError(f'{source}: {self.summary()}; nothing kept (allow damaged '
                                  'input to go on with what was read: --allow-damaged)')

    def summary(self) -> str:
        """``damaged: 271 of 600 messages read (OverflowError: ...)``, or empty when whole."""
        if not self.damage:
            return ''
        return f'damaged: {self.read} of {self.total} messages read ({self.damage})'


# ------------------------------------------------------------------------------ configuration
def node_settings(path: str | Path | None = None) -> JointNodeSettings:
    """The settings ``stiffness_node`` runs with for ``--params-file path`` (model, frames,
    limits): the parameter table's defaults, overridden by the file's parameters
    (:func:`~tensegrity_stiffness.nodes.registry.values_from_config`); BagError names the file
    and the field."""
    try:
        values = (defaults(STIFFNESS_NODE_PARAMETERS) if path is None
                  else values_from_config(path, STIFFNESS_NODE_PARAMETERS))
        return joint_node_settings(values)
    except ValueError as exc:
        text = str(exc)
        raise BagError(text if path is None or str(path) in text else f'config {path}: {text}'
                       ) from None


def spine_settings(path: str | Path | None = None) -> SpineNodeSettings:
    """The settings ``spine_node`` runs with for ``--params-file path`` (default: the packaged
    ``config/default_spine.yaml``): the parameter table of the file's ``chain.n_joints``,
    overridden by the file's parameters; BagError names the file and the field."""
    path = config.packaged_config_path(DEFAULT_SPINE_CONFIG) if path is None else path
    try:
        n = values_from_config(path, CHAIN_PARAMETERS)['chain.n_joints']
        values = values_from_config(path, spine_node_parameters(n))
        return spine_node_settings(values)
    except ValueError as exc:
        text = str(exc)
        raise BagError(text if str(path) in text else f'config {path}: {text}') from None


def structure_settings(path: str | Path | None = None) -> structure_node.StructureNodeSettings:
    """The settings ``structure_node`` runs with for ``--params-file path`` (default: the
    parameter table's defaults, the packaged 6-bar); a structure file itself (a ``structure``
    section with ``bodies``) is taken as ``structure.config``. BagError names the file and the
    field."""
    table = structure_node.STRUCTURE_NODE_PARAMETERS
    try:
        if path is None:
            return structure_node.structure_node_settings(defaults(table))
        if is_structure_document(config.load_yaml(path)):  # the structure itself
            values = {**defaults(table), 'structure.config': str(path)}
        else:
            values = values_from_config(path, table)
        return structure_node.structure_node_settings(values)
    except ValueError as exc:
        text = str(exc)
        raise BagError(text if path is None or str(path) in text else f'config {path}: {text}'
                       ) from None


def single_threaded_blas() -> Any:
    """A context manager holding BLAS to one thread inside its block (restored after):
    ``threadpoolctl.threadpool_limits(limits=1, user_api='blas')``. The batched evaluation's
    GEMMs are large enough for OpenBLAS to start its threads, whose busy waiting on a shared
    machine costs more than it saves; the bag command runs one process that is already busy."""
    from threadpoolctl import threadpool_limits

    return threadpool_limits(limits=1, user_api='blas')


def jazzy_typestore() -> Any:
    """rosbags' type store of ROS 2 Jazzy's messages (decodes and encodes recordings), with
    the package's own ``StampedMatrix`` registered from its definition (``msg/``)."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)
    definition = config.packaged_path(layouts.STAMPED_MATRIX_DEFINITION).read_text('utf-8')
    typestore.register(get_types_from_msg(definition, layouts.STAMPED_MATRIX))
    return typestore


def rosbags_types(typestore: Any) -> MessageTypes:
    """rosbags' message classes of ``typestore`` for :mod:`tensegrity_stiffness.nodes.messages`
    (``float64[]`` fields as float64 arrays)."""
    return MessageTypes(classes=typestore.types,
                        payload=lambda values: np.array(values, dtype=np.float64).reshape(-1))
