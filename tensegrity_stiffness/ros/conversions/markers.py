"""RViz ``visualization_msgs/MarkerArray`` of a tensegrity joint: nodes and coloured strings.

Markers (all ``action=ADD``, ``id=0``, in ``frame_id`` {1}, poses identity):

- ns ``'link1_nodes'``: SPHERE_LIST of the link-1 nodes;
- ns ``'link2_nodes'``: SPHERE_LIST of the link-2 nodes (already transformed into {1});
- ns ``'strings'``: LINE_LIST of the taut strings, per-vertex colours by tension, blue (0) to red
  (``max_tension``);
- ns ``'slack_strings'``: LINE_LIST of the slack strings, grey and thinner.

The two LINE_LIST markers are always sent (possibly with no points), so a string that turns
slack moves from one to the other without stale lines left in RViz.
"""

from __future__ import annotations

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from numpy.typing import ArrayLike, NDArray
from std_msgs.msg import ColorRGBA
from visualization_msgs.msg import Marker, MarkerArray

from tensegrity_stiffness.geometry.validation import finite_array_of_shape

__all__ = [
    'HIGH_TENSION_COLOR',
    'LINK1_COLOR',
    'LINK2_COLOR',
    'LOW_TENSION_COLOR',
    'NODE_DIAMETER',
    'SLACK_COLOR',
    'SLACK_STRING_WIDTH',
    'STRING_WIDTH',
    'marker_array',
    'tension_color',
]

#: RGBA colours (0..1).
LINK1_COLOR = (0.15, 0.15, 0.15, 1.0)
LINK2_COLOR = (0.95, 0.6, 0.1, 1.0)
SLACK_COLOR = (0.6, 0.6, 0.6, 0.8)
LOW_TENSION_COLOR = (0.0, 0.2, 1.0, 1.0)
HIGH_TENSION_COLOR = (1.0, 0.0, 0.0, 1.0)

#: Default sizes in m (node spacing of the default joint is about 3 cm).
NODE_DIAMETER = 0.004
STRING_WIDTH = 0.001
SLACK_STRING_WIDTH = 0.0004


def _points(value: ArrayLike, name: str) -> NDArray[np.float64]:
    arr = np.asarray(value, dtype=np.float64)
    if arr.ndim != 2 or arr.shape[1] != 3:
        raise ValueError(f'{name} must have shape (n, 3), got {arr.shape}')
    return finite_array_of_shape(name, arr, None)


def _color(rgba: tuple[float, float, float, float] | NDArray[np.float64]) -> ColorRGBA:
    r, g, b, a = (float(c) for c in rgba)
    return ColorRGBA(r=r, g=g, b=b, a=a)


def tension_color(ratio: float) -> ColorRGBA:
    """Colour of a tension ratio ``t / max_tension``, clipped to [0, 1]: blue -> red, linear."""
    s = float(np.clip(ratio, 0.0, 1.0))
    low = np.asarray(LOW_TENSION_COLOR)
    high = np.asarray(HIGH_TENSION_COLOR)
    return _color((1.0 - s) * low + s * high)


def _marker(ns: str, marker_type: int, frame_id: str, stamp: Time, width: float,
            height: float | None = None) -> Marker:
    m = Marker()
    m.header.frame_id = frame_id
    m.header.stamp = stamp
    m.ns = ns
    m.id = 0
    m.type = marker_type
    m.action = Marker.ADD
    m.pose.orientation.w = 1.0
    m.scale.x = float(width)
    m.scale.y = float(width if height is None else height)
    m.scale.z = float(width if height is None else height)
    return m


def marker_array(p1: ArrayLike, p2: ArrayLike, connections: ArrayLike, tensions: ArrayLike,
                 slack: ArrayLike, frame_id: str, stamp: Time, *,
                 max_tension: float | None = None, node_diameter: float = NODE_DIAMETER,
                 string_width: float = STRING_WIDTH,
                 slack_string_width: float = SLACK_STRING_WIDTH) -> MarkerArray:
    """MarkerArray of the joint for RViz (see the module docstring for the markers).

    Parameters
    ----------
    p1 : (n1, 3) link-1 node positions in {1}, m.
    p2 : (n2, 3) link-2 node positions transformed into {1}, m.
    connections : (n, 2) int, string j joins ``p1[connections[j, 0]]`` to
        ``p2[connections[j, 1]]``.
    tensions : (n,) string tensions, N (finite, >= 0).
    slack : (n,) bool, True for slack strings (drawn grey and thinner, whatever their tension).
    frame_id : frame of link 1, e.g. ``'link1'``.
    stamp : header stamp of every marker.
    max_tension : tension drawn full red, N; default: the largest taut tension (1 N if none).
    node_diameter, string_width, slack_string_width : sizes in m.

    Raises
    ------
    ValueError
        On wrong shapes, non-finite values, negative tensions or out-of-range node indices.
    """
    a = _points(p1, 'p1')
    b = _points(p2, 'p2')
    conn = np.asarray(connections)
    if conn.ndim != 2 or conn.shape[1] != 2:
        raise ValueError(f'connections must have shape (n, 2), got {conn.shape}')
    if conn.size and not np.issubdtype(conn.dtype, np.integer):
        raise ValueError(f'connections must be integer node indices, got dtype {conn.dtype}')
    conn = conn.astype(np.intp)
    n = conn.shape[0]
    if n and (conn[:, 0].min() < 0 or conn[:, 0].max() >= a.shape[0]):
        raise ValueError(f'connections[:, 0] must index p1 (0..{a.shape[0] - 1})')
    if n and (conn[:, 1].min() < 0 or conn[:, 1].max() >= b.shape[0]):
        raise ValueError(f'connections[:, 1] must index p2 (0..{b.shape[0] - 1})')
    t = finite_array_of_shape('tensions', tensions, (n,))
    if np.any(t < 0.0):
        raise ValueError('tensions must be >= 0')
    is_slack = np.asarray(slack)
    if is_slack.shape != (n,):
        raise ValueError(f'slack must have shape ({n},), got {is_slack.shape}')
    is_slack = is_slack.astype(bool)
    taut = ~is_slack
    if max_tension is None:
        top = float(t[taut].max()) if np.any(taut) else 0.0
        max_tension = top if top > 0.0 else 1.0
    elif not (np.isfinite(max_tension) and max_tension > 0.0):
        raise ValueError(f'max_tension must be finite and > 0, got {max_tension}')

    nodes1 = _marker('link1_nodes', Marker.SPHERE_LIST, frame_id, stamp, node_diameter)
    nodes1.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in a]
    nodes1.color = _color(LINK1_COLOR)
    nodes2 = _marker('link2_nodes', Marker.SPHERE_LIST, frame_id, stamp, node_diameter)
    nodes2.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in b]
    nodes2.color = _color(LINK2_COLOR)

    strings = _marker('strings', Marker.LINE_LIST, frame_id, stamp, string_width, 0.0)
    strings.color = _color(HIGH_TENSION_COLOR)  # fallback; per-vertex colours take precedence
    slack_strings = _marker('slack_strings', Marker.LINE_LIST, frame_id, stamp,
                            slack_string_width, 0.0)
    slack_strings.color = _color(SLACK_COLOR)
    for j in range(n):
        start = a[conn[j, 0]]
        end = b[conn[j, 1]]
        segment = [Point(x=float(start[0]), y=float(start[1]), z=float(start[2])),
                   Point(x=float(end[0]), y=float(end[1]), z=float(end[2]))]
        if is_slack[j]:
            slack_strings.points.extend(segment)
        else:
            color = tension_color(t[j] / max_tension)
            strings.points.extend(segment)
            strings.colors.extend([color, color])
    return MarkerArray(markers=[nodes1, nodes2, strings, slack_strings])
