"""The MuJoCo model (MJCF text) of any structure: the physics of a structure twin. No mujoco
import here (the XML is text); the tests load it in MuJoCo.

* Each free body is a MuJoCo body with a free joint at its pose (the body frame is the
  structure's), its mass, centre of mass and full inertia from the structure (an ``inertial``
  element, so the geoms add no mass); a fixed body is a body without a joint (welded to the
  world); world nodes are sites of the world body.
* A bar is drawn as a capsule from node ``a`` to node ``b`` of its radius (no contact); every
  node of a body is a site and, when the structure has a ground, a contact sphere of radius
  ``node_radius`` centred on the node.
* Each string is a spatial tendon between its two sites with ``stiffness = k``,
  ``springlength = "0 l0"`` (no tension at or below the rest length: MuJoCo's tendon spring is
  Hooke's law with the slack deadband, the library's ``force_law: hooke``; the paper's law has no
  MuJoCo tendon and is refused) and ``damping`` the string's; a finite ``max_length`` is a
  tendon length limit (an inextensible stop, as the joint's twin: MuJoCo has no constant tension
  past it).
* The ground is a plane through ``height normal - node_radius normal`` (the spheres then touch
  it when their nodes are at the structure's ground) with friction ``mu``, elliptic friction
  cones (Coulomb's, as the equilibrium's) and contact ``solref`` stiffer than MuJoCo's default.
* Gravity is the structure's (0 without one).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from tensegrity_stiffness.geometry.quaternion import rotation_to_quaternion
from tensegrity_stiffness.structures.elements import BAR
from tensegrity_stiffness.structures.structure import Structure


@dataclass(frozen=True)
class StructureMjcfOptions:
    """``timestep`` (s), ``integrator``, ``node_radius`` (m) of the contact spheres,
    ``contact_time_constant`` (s, the first entry of the contacts' ``solref``),
    ``joint_damping`` (N s/m and N m s/rad on each free joint, 0: none; to let a twin settle),
    ``string_width`` (m, drawing only)."""

    timestep: float = 1e-3
    integrator: str = 'implicitfast'
    node_radius: float = 0.005
    contact_time_constant: float = 0.005
    joint_damping: float = 0.0
    string_width: float = 0.002


def _num(x: float) -> str:
    return repr(float(x))


def _vec(values: ArrayLike) -> str:
    return ' '.join(_num(v) for v in np.asarray(values, dtype=float).ravel())


def _quat_wxyz(R: np.ndarray) -> list[float]:
    x, y, z, w = rotation_to_quaternion(R)
    return [w, x, y, z]


def _site(body: str, node: str) -> str:
    return f'{body}.{node}'


def structure_mjcf(structure: Structure, poses: ArrayLike | None = None,
                   options: StructureMjcfOptions | None = None,
                   name: str = 'tensegrity_structure') -> str:
    """MJCF text of ``structure`` at ``poses`` ((N, 4, 4) or (N, 7); default the config's),
    module docstring. Bodies are named as the structure's, sites ``body.node`` (world nodes
    ``world.node``), tendons after the strings. ValueError for the paper's force law or a free
    body without mass."""
    opts = options or StructureMjcfOptions()
    if structure.force_law != 'hooke':
        raise ValueError("MuJoCo's tendon springs are Hooke's law: the structure's force_law "
                         f'must be hooke, got {structure.force_law!r}')
    massless = [b.name for b in structure.bodies if not b.fixed and b.mass == 0.0]
    if massless:
        raise ValueError(f'MuJoCo needs a mass for every free body: {massless} have none')
    T = structure.transforms(poses)
    g = structure.gravity if structure.gravity is not None else np.zeros(3)
    root = ET.Element('mujoco', model=name)
    ET.SubElement(root, 'compiler', angle='radian', autolimits='true')
    ET.SubElement(root, 'option', timestep=_num(opts.timestep), integrator=opts.integrator,
                  gravity=_vec(g), cone='elliptic')
    ET.SubElement(ET.SubElement(root, 'visual'), 'global', offwidth='1280', offheight='960')
    world = ET.SubElement(root, 'worldbody')
    ET.SubElement(world, 'light', pos='0 0 3', dir='0 0 -1', directional='true')
    ground = structure.ground
    if ground is not None:
        n = ground.normal
        R = np.column_stack([*ground.tangents(), n])
        ET.SubElement(world, 'geom', name='ground', type='plane', size='0 0 0.05',
                      pos=_vec((ground.height - opts.node_radius) * n),
                      quat=_vec(_quat_wxyz(R)), friction=f'{_num(ground.friction)} 0 0',
                      condim='3', solref=f'{_num(opts.contact_time_constant)} 1',
                      rgba='0.8 0.8 0.8 1')
    for key, point in structure.world_nodes.items():
        ET.SubElement(world, 'site', name=_site('world', key), pos=_vec(point), size='0.004',
                      rgba='0.2 0.4 0.9 1')
    for i, body in enumerate(structure.bodies):
        element = ET.SubElement(world, 'body', name=body.name, pos=_vec(T[i, :3, 3]),
                                quat=_vec(_quat_wxyz(T[i, :3, :3])))
        if not body.fixed:
            joint = ET.SubElement(element, 'joint', name=f'{body.name}_free', type='free')
            if opts.joint_damping > 0.0:
                joint.set('damping', _num(opts.joint_damping))
            inertia = body.inertia
            ET.SubElement(element, 'inertial', pos=_vec(body.com), mass=_num(body.mass),
                          fullinertia=_vec([inertia[0, 0], inertia[1, 1], inertia[2, 2],
                                            inertia[0, 1], inertia[0, 2], inertia[1, 2]]))
        if body.kind == BAR:
            ET.SubElement(element, 'geom', name=f'{body.name}_capsule', type='capsule',
                          fromto=_vec([*body.nodes['a'], *body.nodes['b']]),
                          size=_num(body.radius), contype='0', conaffinity='0', mass='0',
                          rgba='0.6 0.4 0.2 1')
        for key, point in body.nodes.items():
            ET.SubElement(element, 'site', name=_site(body.name, key), pos=_vec(point),
                          size='0.004', rgba='0.9 0.4 0.2 1')
            if ground is not None:
                ET.SubElement(element, 'geom', name=f'{body.name}.{key}_contact',
                              type='sphere', size=_num(opts.node_radius), pos=_vec(point),
                              mass='0', condim='3', friction=f'{_num(ground.friction)} 0 0',
                              solref=f'{_num(opts.contact_time_constant)} 1',
                              contype='1', conaffinity='0', rgba='0.3 0.3 0.3 1')
    tendons = ET.SubElement(root, 'tendon')
    for s in structure.strings:
        attrs = {'name': s.name, 'stiffness': _num(s.stiffness),
                 'springlength': f'0 {_num(s.rest_length)}', 'damping': _num(s.damping),
                 'width': _num(opts.string_width), 'rgba': '0.1 0.1 0.1 1'}
        if math.isfinite(s.max_length):
            attrs.update(limited='true', range=f'0 {_num(s.max_length)}',
                         solreflimit=f'{_num(2.0 * opts.timestep)} 1')
        tendon = ET.SubElement(tendons, 'spatial', **attrs)
        ET.SubElement(tendon, 'site', site=s.start)
        ET.SubElement(tendon, 'site', site=s.end)
    ET.indent(root)
    return ET.tostring(root, encoding='unicode') + '\n'
