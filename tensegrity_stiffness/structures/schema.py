"""The schema of a structure config: the ``structure`` section (top level, or under
``<node>: ros__parameters:`` as the joint's) read into the elements of
:mod:`~tensegrity_stiffness.structures.elements` and written back.

::

    structure:
      force_law: hooke                 # or paper (the joint's laws)
      gravity: [0, 0, -9.81]           # m/s^2, optional
      ground: {normal: [0, 0, 1], height: 0, friction: 0.8}   # optional
      bodies:
        - {name: bar0, type: bar, length: 1.0, pose: [x, y, z, qx, qy, qz, qw], mass: 0.1}
        - {name: hub, type: body, nodes: {A: [0.1, 0, 0], B: [0, 0.1, 0]}, mass: 0.2,
           com: [0, 0, 0], inertia: [1e-3, 1e-3, 1e-3], fixed: false}
      world_nodes: {anchor: [0, 0, 0]}   # optional
      strings:
        - {name: s0, from: bar0.a, to: hub.A, stiffness: 100, rest_length: 0.5,
           max_length: 0.9, damping: 0.1}

Errors are ValueErrors that name the entry (``structure.strings[3].to: no node 'c' on body
'bar1'``); an unknown key is a :class:`StructureConfigWarning` with the nearest known name.
"""

from __future__ import annotations

import difflib
import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.joint import FORCE_LAWS
from tensegrity_stiffness.structures.elements import (
    BAR,
    BODY,
    BODY_KINDS,
    IDENTITY_POSE,
    WORLD,
    Body,
    Ground,
    StringSpec,
)

#: The section of a config document that holds a structure.
SECTION = 'structure'
STRUCTURE_KEYS = ('force_law', 'gravity', 'ground', 'bodies', 'world_nodes', 'strings')
BODY_KEYS = ('name', 'type', 'length', 'radius', 'nodes', 'pose', 'mass', 'com', 'inertia',
             'fixed')
STRING_KEYS = ('name', 'from', 'to', 'stiffness', 'rest_length', 'max_length', 'damping')
GROUND_KEYS = ('normal', 'height', 'friction')
#: Similarity (difflib ratio) above which an unknown key is told its nearest known name (the
#: nodes' unknown-parameter warnings use the same cutoff).
NEAREST_NAME_CUTOFF = 0.75


def nearest_name(name: str, known: Sequence[str]) -> str | None:
    """The known name nearest to ``name`` (difflib), or None when none is close."""
    close = difflib.get_close_matches(name, list(known), n=1, cutoff=NEAREST_NAME_CUTOFF)
    return close[0] if close else None


def unknown_keys(entry: Mapping[str, Any], known: Sequence[str], where: str,
                 found: list[str] | None) -> None:
    """The unknown keys of ``entry`` in the one format of every reader
    (:func:`tensegrity_stiffness.config.unknown_key_messages`), appended to ``found``; with
    ``found`` None, refused at once (ValueError)."""
    lines = config.unknown_key_messages(entry, known, where)
    if found is None:
        if lines:
            raise ValueError('; '.join(lines))
    else:
        found.extend(lines)


def _mapping(value: Any, where: str) -> Mapping[str, Any]:
    if not isinstance(value, Mapping):
        raise ValueError(f'{where} must be a mapping, got {type(value).__name__}')
    return value


def _entries(section: Mapping[str, Any], key: str, required: bool) -> list[Mapping[str, Any]]:
    value = section.get(key)
    if value is None:
        if required:
            raise ValueError(f'{SECTION}.{key} is missing')
        return []
    if isinstance(value, (str, Mapping)) or not isinstance(value, Sequence):
        raise ValueError(f'{SECTION}.{key} must be a list of mappings')
    return [_mapping(v, f'{SECTION}.{key}[{i}]') for i, v in enumerate(value)]


def _named(error: ValueError, where: str) -> ValueError:
    return ValueError(f'{where}.{error}')


def parse_body(entry: Mapping[str, Any], where: str, found: list[str] | None = None) -> Body:
    """One entry of ``structure.bodies`` (ValueErrors name ``where``)."""
    unknown_keys(entry, BODY_KEYS, where, found)
    name = entry.get('name')
    if not isinstance(name, str) or not name or '.' in name or name == WORLD:
        raise ValueError(f'{where}.name must be a non-empty string without "." and not '
                         f'"{WORLD}", got {name!r}')
    kind = entry.get('type', BODY)
    if kind not in BODY_KINDS:
        raise ValueError(f'{where}.type must be one of {BODY_KINDS}, got {kind!r}')
    common: dict[str, Any] = {'pose': entry.get('pose', IDENTITY_POSE),
                              'fixed': entry.get('fixed', False)}
    for key in ('mass', 'inertia'):
        if entry.get(key) is not None:
            common[key] = entry[key]
    if not isinstance(common['fixed'], bool):
        raise ValueError(f'{where}.fixed must be true or false, got {common["fixed"]!r}')
    try:
        if kind == BAR:
            if 'nodes' in entry or 'com' in entry:
                raise ValueError(f'{"nodes" if "nodes" in entry else "com"}: a bar has the '
                                 'nodes a, b and its centre of mass at the middle')
            if entry.get('length') is None:
                raise ValueError('length is missing')
            return Body.bar(name, entry['length'], radius=entry.get('radius'), **common)
        if 'length' in entry or 'radius' in entry:
            raise ValueError('length: only a bar has a length (type: bar)')
        if entry.get('com') is not None:
            common['com'] = entry['com']
        return Body.rigid(name, _mapping(entry.get('nodes'), 'nodes'), **common)
    except ValueError as exc:
        raise _named(exc, where) from None


def _node_reference(value: Any, bodies: Mapping[str, Body], world: Mapping[str, Any],
                    where: str) -> str:
    """A checked node reference ``body.node`` / ``world.node``."""
    if not isinstance(value, str) or value.count('.') != 1:
        raise ValueError(f'{where} must be "body.node" or "{WORLD}.node", got {value!r}')
    body, node = value.split('.')
    if body == WORLD:
        if node not in world:
            raise ValueError(f'{where}: no world node {node!r}')
    elif body not in bodies:
        near = nearest_name(body, list(bodies))
        raise ValueError(f'{where}: no body {body!r}' + (f' (did you mean {near!r}?)'
                                                         if near else ''))
    elif node not in bodies[body].nodes:
        raise ValueError(f'{where}: no node {node!r} on body {body!r} (its nodes: '
                         f'{", ".join(bodies[body].node_names)})')
    return value


def parse_string(entry: Mapping[str, Any], index: int, bodies: Mapping[str, Body],
                 world: Mapping[str, Any], where: str, found: list[str] | None = None
                 ) -> StringSpec:
    """One entry of ``structure.strings``."""
    unknown_keys(entry, STRING_KEYS, where, found)
    start = _node_reference(entry.get('from'), bodies, world, f'{where}.from')
    end = _node_reference(entry.get('to'), bodies, world, f'{where}.to')
    if start == end:
        raise ValueError(f'{where}: from and to are the same node {start!r}')
    name = entry.get('name', f'{start}-{end}')
    values: dict[str, Any] = {}
    for key in ('stiffness', 'rest_length'):
        if entry.get(key) is None:
            raise ValueError(f'{where}.{key} is missing')
        values[key] = entry[key]
    for key in ('max_length', 'damping'):
        if entry.get(key) is not None:
            values[key] = entry[key]
    for key, value in values.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f'{where}.{key} must be a number, got {value!r}')
    try:
        return StringSpec(str(name), start, end, **{k: float(v) for k, v in values.items()})
    except ValueError as exc:
        raise _named(exc, where) from None


def parse_ground(value: Any, found: list[str] | None = None) -> Ground | None:
    """``structure.ground`` (None: no ground)."""
    if value is None:
        return None
    where = f'{SECTION}.ground'
    entry = _mapping(value, where)
    unknown_keys(entry, GROUND_KEYS, where, found)
    try:
        return Ground(**{k: entry[k] for k in GROUND_KEYS if entry.get(k) is not None})
    except ValueError as exc:
        raise _named(exc, where) from None


def is_structure_document(document: Any) -> bool:
    """Whether ``document`` describes a structure (a ``structure`` section with ``bodies``, at
    the top level or under ``ros__parameters``), not a node's parameter file that names one."""
    try:
        section = config.parameters(document).get(SECTION)
    except ValueError:
        return False
    return isinstance(section, Mapping) and 'bodies' in section


def parse_structure(document: Any, strict: bool = True) -> dict[str, Any]:
    """The keyword arguments of :class:`~tensegrity_stiffness.structures.structure.Structure`
    from a config document (plain or ROS parameter file) or its ``structure`` section. Unknown
    keys are refused, all named at once with the nearest name (``strict=False``: warned about,
    :class:`~tensegrity_stiffness.config.UnknownKeyWarning`, and ignored)."""
    params = config.parameters(document)
    if SECTION in params:
        section = _mapping(params[SECTION], SECTION)
    elif 'bodies' in params:
        section = params
    else:
        raise ValueError(f'config has no "{SECTION}" section (top level or under '
                         f'{config.ROS_PARAMETERS})')
    found: list[str] = []
    unknown_keys(section, STRUCTURE_KEYS, SECTION, found)
    bodies: dict[str, Body] = {}
    for i, entry in enumerate(_entries(section, 'bodies', True)):
        body = parse_body(entry, f'{SECTION}.bodies[{i}]', found)
        if body.name in bodies:
            raise ValueError(f'{SECTION}.bodies[{i}].name: {body.name!r} is taken')
        bodies[body.name] = body
    if not bodies:
        raise ValueError(f'{SECTION}.bodies is empty')
    world = {}
    raw_world = section.get('world_nodes') or {}
    for key, value in _mapping(raw_world, f'{SECTION}.world_nodes').items():
        p = np.asarray(value, dtype=float).ravel() if isinstance(value, Sequence) else None
        if p is None or p.shape != (3,) or not np.all(np.isfinite(p)):
            raise ValueError(f'{SECTION}.world_nodes.{key} must be 3 finite values [x, y, z]')
        world[str(key)] = p
    strings = [parse_string(entry, i, bodies, world, f'{SECTION}.strings[{i}]', found)
               for i, entry in enumerate(_entries(section, 'strings', True))]
    if len({s.name for s in strings}) != len(strings):
        raise ValueError(f'{SECTION}.strings: names must be unique')
    force_law = section.get('force_law', 'hooke')
    if force_law not in FORCE_LAWS:
        raise ValueError(f'{SECTION}.force_law must be one of {FORCE_LAWS}, got {force_law!r}')
    gravity = section.get('gravity')
    if gravity is not None:
        g = np.asarray(gravity, dtype=float).ravel() if isinstance(gravity, Sequence) else None
        if g is None or g.shape != (3,) or not np.all(np.isfinite(g)):
            raise ValueError(f'{SECTION}.gravity must be 3 finite values [gx, gy, gz] (m/s^2)')
        gravity = g
    ground = parse_ground(section.get('ground'), found)
    if found:
        if strict:
            raise ValueError('; '.join(found))
        for line in found:
            warnings.warn(f'{line}: ignored', config.UnknownKeyWarning, stacklevel=3)
    return {'bodies': list(bodies.values()), 'strings': strings, 'world_nodes': world,
            'gravity': gravity, 'ground': ground, 'force_law': str(force_law)}


def _floats(values: Any) -> list[float]:
    return [float(x) for x in np.asarray(values, dtype=float).ravel()]


def _pose_vector(T: np.ndarray) -> list[float]:
    from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion

    return _floats(T[:3, 3]) + _floats(rotation_to_quaternion(T[:3, :3]))


def body_entry(body: Body) -> dict[str, Any]:
    """The config entry of a body (what :func:`parse_body` reads back to the same body)."""
    entry: dict[str, Any] = {'name': body.name, 'type': body.kind}
    if body.kind == BAR:
        entry.update(length=float(body.length), radius=float(body.radius))
    else:
        entry['nodes'] = {k: _floats(v) for k, v in body.nodes.items()}
    entry.update(pose=_pose_vector(body.pose), mass=float(body.mass))
    if body.kind != BAR:
        entry['com'] = _floats(body.com)
    entry['inertia'] = _floats(body.inertia)
    entry['fixed'] = bool(body.fixed)
    return entry


def structure_document(bodies: Sequence[Body], strings: Sequence[StringSpec],
                       world_nodes: Mapping[str, np.ndarray], gravity: np.ndarray | None,
                       ground: Ground | None, force_law: str) -> dict[str, Any]:
    """The ``{'structure': ...}`` document of a structure's elements."""
    section: dict[str, Any] = {'force_law': force_law}
    if gravity is not None:
        section['gravity'] = _floats(gravity)
    if ground is not None:
        section['ground'] = {'normal': _floats(ground.normal), 'height': float(ground.height),
                             'friction': float(ground.friction)}
    section['bodies'] = [body_entry(b) for b in bodies]
    if world_nodes:
        section['world_nodes'] = {k: _floats(v) for k, v in world_nodes.items()}
    section['strings'] = []
    for s in strings:
        entry: dict[str, Any] = {'name': s.name, 'from': s.start, 'to': s.end,
                                 'stiffness': float(s.stiffness),
                                 'rest_length': float(s.rest_length)}
        if math.isfinite(s.max_length):
            entry['max_length'] = float(s.max_length)
        if s.damping:
            entry['damping'] = float(s.damping)
        section['strings'].append(entry)
    return {SECTION: section}
