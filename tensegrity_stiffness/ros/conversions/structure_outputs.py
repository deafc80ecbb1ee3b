"""The messages of ``structure_node``'s per-input outputs (``~/body_wrenches``, ``~/stiffness``,
``~/string_tensions``, ``~/bar_forces``, ``~/contact_forces`` with a ground) and its markers.

The messages are :class:`tensegrity_stiffness.nodes.structure_node.StructureOutputMessages` with
rclpy's classes (one preallocated message per topic, labelled once; per input only the data is
refilled, after one finite check of every output).
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray

from tensegrity_stiffness.nodes import structure_node
from tensegrity_stiffness.nodes.structure_node import StructureOutputs
from tensegrity_stiffness.ros.conversions.markers import marker_array
from tensegrity_stiffness.ros.conversions.outputs import RCLPY_TYPES
from tensegrity_stiffness.structures.structure import Structure

__all__ = ['BAR_COLOR', 'CONTACT_COLOR', 'StructureOutputMessages', 'structure_markers']

#: RGBA of the bars and of the contact-force arrows.
BAR_COLOR = (0.2, 0.2, 0.2, 1.0)
CONTACT_COLOR = (0.1, 0.7, 0.1, 1.0)
#: Contact-force arrows: m per N.
CONTACT_ARROW_SCALE = 0.05


class StructureOutputMessages(structure_node.StructureOutputMessages):
    """The per-input output messages of ``structure`` (rclpy), refilled by :meth:`fill`."""

    def __init__(self, structure: Structure) -> None:
        super().__init__(structure, RCLPY_TYPES)


def _point(x: np.ndarray) -> Point:
    return Point(x=float(x[0]), y=float(x[1]), z=float(x[2]))


def _set_color(marker: Marker, rgba: tuple[float, float, float, float]) -> None:
    marker.color.r, marker.color.g, marker.color.b, marker.color.a = (float(c) for c in rgba)


def structure_markers(structure: Structure, outputs: StructureOutputs, frame_id: str,
                      stamp: Time) -> MarkerArray:
    """Markers of a configuration in the world frame: the nodes (ns ``nodes``), the strings
    coloured blue -> red by tension up to the largest (``strings``, ``slack_strings``: those of
    :func:`marker_array`), the bars as thick lines (``bars``) and, with a ground, one arrow per
    contact force (``contact_forces``, :data:`CONTACT_ARROW_SCALE` m per N; a DELETEALL first
    clears the arrows of the last configuration)."""
    state = outputs.state
    x = structure.node_positions(state.poses)
    span = float(np.ptp(x, axis=0).max()) if x.shape[0] > 1 else 1.0
    base = marker_array(x, x, structure.string_nodes, state.tensions, state.slack, frame_id,
                        stamp, node_diameter=0.02 * span, string_width=0.005 * span,
                        slack_string_width=0.002 * span)
    nodes, _, strings, slack = base.markers
    nodes.ns = 'nodes'
    bars = Marker()
    bars.header.frame_id, bars.header.stamp = frame_id, stamp
    bars.ns, bars.type, bars.action = 'bars', Marker.LINE_LIST, Marker.ADD
    bars.pose.orientation.w = 1.0
    bars.scale.x = 0.015 * span
    _set_color(bars, BAR_COLOR)
    bars.points = [_point(x[j]) for pair in structure.bar_nodes for j in pair]
    markers = [nodes, strings, slack, bars]
    if outputs.contact_forces is not None:
        clear = Marker()
        clear.header.frame_id, clear.header.stamp = frame_id, stamp
        clear.ns, clear.action = 'contact_forces', Marker.DELETEALL
        markers.append(clear)
        rows = np.flatnonzero(structure.node_bodies >= 0)
        forces = dict(zip(rows.tolist(), outputs.contact_forces, strict=True))
        for m, j in enumerate(outputs.contacts):
            arrow = Marker()
            arrow.header.frame_id, arrow.header.stamp = frame_id, stamp
            arrow.ns, arrow.id, arrow.type, arrow.action = ('contact_forces', m, Marker.ARROW,
                                                            Marker.ADD)
            arrow.pose.orientation.w = 1.0
            arrow.scale.x, arrow.scale.y, arrow.scale.z = 0.005 * span, 0.01 * span, 0.0
            _set_color(arrow, CONTACT_COLOR)
            arrow.points = [_point(x[j]), _point(x[j] + CONTACT_ARROW_SCALE * forces[j])]
            markers.append(arrow)
    return MarkerArray(markers=markers)
