"""The bodies and strings of the joint and the spine as structures (the layout of
:mod:`~tensegrity_stiffness.structures.joints`), as the keyword arguments of
:class:`~tensegrity_stiffness.structures.structure.Structure`: what ``Structure.from_joint``
and ``Structure.from_chain`` build (this module does not import the structure, so the
structure's constructors and :mod:`.joints` both read it without an import circle).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.inertia import LinkInertia
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.structures.elements import Body, StringSpec

#: The bodies of a joint as a structure.
JOINT_BODIES = ('link1', 'link2')


def _joint_strings(model: JointModel, lower: str, upper: str, lower_prefix: str = '',
                   upper_prefix: str = '', name_prefix: str = '', damping: ArrayLike = 0.0
                   ) -> list[StringSpec]:
    c = np.broadcast_to(np.asarray(damping, dtype=np.float64), (model.n_strings,))
    out = []
    for j, (a, b) in enumerate(model.connections):
        lmax = float(model.max_lengths[j])
        out.append(StringSpec(f'{name_prefix}{model.string_names[j]}',
                              f'{lower}.{lower_prefix}{model.node_names[a]}',
                              f'{upper}.{upper_prefix}{model.link2_node_names[b]}',
                              float(model.k[j]), float(model.rest_lengths[j]),
                              lmax if math.isfinite(lmax) else math.inf, float(c[j])))
    return out


def _check_names(names: list[str], where: str) -> None:
    bad = [n for n in names if '.' in n or not n]
    if bad:
        raise ValueError(f'{where}: node names {bad} cannot name structure nodes (no "." '
                         'and not empty)')


def joint_structure_arguments(model: JointModel, pose: ArrayLike | None = None,
                              inertia: LinkInertia | None = None,
                              string_damping: ArrayLike = 0.0) -> dict[str, Any]:
    """The ``Structure`` arguments (bodies, strings, force law) of the joint as a structure
    (:mod:`.joints`); ``pose`` of ``link2`` (default
    ``exp(hat(initial_screw))``); ``inertia``: link 2's mass properties (default massless: the
    joint has no weights; give the dynamics'
    :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia` for its modes);
    ``string_damping`` (N s/m, one for all or one per string)."""
    _check_names(list(model.node_names) + list(model.link2_node_names), 'joint')
    T = exp_se3(model.initial_screw) if pose is None else pose
    link1 = Body.rigid(JOINT_BODIES[0], dict(zip(model.node_names, model.link1_nodes,
                                                 strict=True)), mass=0.0, fixed=True)
    nodes2 = dict(zip(model.link2_node_names, model.link2_nodes, strict=True))
    if inertia is None:
        link2 = Body.rigid(JOINT_BODIES[1], nodes2, pose=T, mass=0.0)
    else:
        link2 = Body.rigid(JOINT_BODIES[1], nodes2, pose=T, mass=inertia.mass,
                           com=inertia.com, inertia=inertia.inertia_matrix(model.link2_nodes))
    return {'bodies': [link1, link2],
            'strings': _joint_strings(model, *JOINT_BODIES, damping=string_damping),
            'force_law': model.force_law}


def link_name(k: int) -> str:
    """The body name of a spine's link ``k`` (0: the base)."""
    return f'link{k}'


def chain_structure_arguments(chain: JointChain, screws: ArrayLike | None = None,
                              inertias: Sequence[LinkInertia] | None = None,
                              string_damping: ArrayLike = 0.0) -> dict[str, Any]:
    """The ``Structure`` arguments (bodies, strings, gravity, force law) of the spine as a
    structure (:mod:`.joints`), its links at the frames ``L_k`` of
    ``screws`` (default the joints' unloaded screws); ``inertias``: one
    :class:`~tensegrity_stiffness.mechanics.inertia.LinkInertia` per moving link for its mass
    properties (default: the chain's masses and centres of mass, massless links massless; an
    inertia of None is the default of the joint's link-2 nodes, as the dynamics'). Gravity is
    the chain's when it has weights (a chain without link masses has none, as its statics);
    the bodies weigh their masses, so inertias with other masses than a weighted chain's
    ``link_masses`` are refused. ``string_damping`` (N s/m) for all."""
    n = chain.n_joints
    if inertias is not None and (len(inertias) != n or not all(
            isinstance(i, LinkInertia) for i in inertias)):
        raise ValueError(f'inertias must be {n} LinkInertia (one per link)')
    xi = chain.unloaded_screws() if screws is None else chain.validated_screws(screws)
    L = chain.link_transforms(xi)
    bodies = []
    strings: list[StringSpec] = []
    for k in range(n + 1):
        nodes: dict[str, Any] = {}
        if k >= 1:
            model = chain.joints[k - 1]
            _check_names(list(model.link2_node_names), f'joint_{k}')
            nodes.update({f'j{k}_{name}': p for name, p in
                          zip(model.link2_node_names, model.link2_nodes, strict=True)})
        if k < n:
            model = chain.joints[k]
            _check_names(list(model.node_names), f'joint_{k + 1}')
            offset = np.eye(4) if k == 0 else chain.link_offsets[k - 1]
            moved = model.link1_nodes @ offset[:3, :3].T + offset[:3, 3]
            nodes.update({f'j{k + 1}_{name}': p for name, p in
                          zip(model.node_names, moved, strict=True)})
        if k == 0:
            bodies.append(Body.rigid(link_name(0), nodes, mass=0.0, fixed=True))
        elif inertias is not None:
            li = inertias[k - 1]
            bodies.append(Body.rigid(link_name(k), nodes, pose=L[k - 1], mass=li.mass,
                                     com=li.com, inertia=li.inertia_matrix(
                                         chain.joints[k - 1].link2_nodes)))
        else:
            m = float(chain.link_masses[k - 1])
            bodies.append(Body.rigid(link_name(k), nodes, pose=L[k - 1], mass=m,
                                     com=chain.link_coms[k - 1],
                                     inertia=None if m > 0.0 else (0.0, 0.0, 0.0)))
    for k in range(1, n + 1):
        strings += _joint_strings(chain.joints[k - 1], link_name(k - 1), link_name(k),
                                  f'j{k}_', f'j{k}_', f'j{k}_', string_damping)
    g = chain.gravity if chain.has_weights(chain.gravity) else np.zeros(3)
    if inertias is not None and np.any(g != 0.0) and not np.allclose(
            [li.mass for li in inertias], chain.link_masses, rtol=1e-15, atol=0.0):
        raise ValueError("inertias: a structure's bodies weigh their mass, and the chain's "
                         'weights are of other masses (its link_masses)')
    return {'bodies': bodies, 'strings': strings,
            'gravity': g.copy() if np.any(g != 0.0) else None, 'force_law': _one_law(chain)}


def _one_law(chain: JointChain) -> str:
    laws = {model.force_law for model in chain.joints}
    if len(laws) != 1:
        raise ValueError(f'the joints of a spine as one structure need one force law, got '
                         f'{sorted(laws)}')
    return laws.pop()
