"""The joint and the spine as structures: the special cases of
:class:`~tensegrity_stiffness.structures.structure.Structure` that the rest of the package knows.

* A joint (:class:`~tensegrity_stiffness.mechanics.joint.JointModel`): body ``link1`` fixed at
  the world origin with the link-1 nodes, body ``link2`` with the link-2 nodes at
  ``T = exp(hat(xi))``; string ``j`` from ``link1.<a_j>`` to ``link2.<b_j>``. The strings'
  wrench on ``link2`` is the joint's ``F`` (eq. 9) and its diagonal block of the stiffness is
  ``K_c``.
* A spine (:class:`~tensegrity_stiffness.mechanics.chain.JointChain`): bodies ``link0`` (the
  base, fixed at the world origin) to ``linkN``; link ``k`` carries joint ``k``'s link-2 nodes
  as ``j<k>_<name>`` (in {2}_k) and joint ``k+1``'s link-1 nodes as ``j<k+1>_<name>`` (moved by
  the link offset ``O_k`` into {2}_k); link ``k``'s pose is ``L_k``; its mass and centre of mass
  the chain's (massless links stay massless), gravity the chain's.
"""

from __future__ import annotations

from collections.abc import Sequence

from numpy.typing import ArrayLike

from tensegrity_stiffness.mechanics.chain import JointChain
from tensegrity_stiffness.mechanics.inertia import LinkInertia
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.structures.joint_parts import (  # noqa: F401 (public here)
    JOINT_BODIES,
    link_name,
)
from tensegrity_stiffness.structures.structure import Structure


def structure_from_joint(model: JointModel, pose: ArrayLike | None = None,
                         inertia: LinkInertia | None = None, string_damping: ArrayLike = 0.0,
                         use_kernel: bool = True) -> Structure:
    """The joint as a structure (module docstring): :meth:`Structure.from_joint`, whose
    bodies and strings are :func:`~.joint_parts.joint_structure_arguments`."""
    return Structure.from_joint(model, pose, inertia=inertia, string_damping=string_damping,
                                use_kernel=use_kernel)


def structure_from_chain(chain: JointChain, screws: ArrayLike | None = None,
                         inertias: Sequence[LinkInertia] | None = None,
                         string_damping: ArrayLike = 0.0, use_kernel: bool = True
                         ) -> Structure:
    """The spine as a structure (module docstring): :meth:`Structure.from_chain`, whose
    bodies and strings are :func:`~.joint_parts.chain_structure_arguments`."""
    return Structure.from_chain(chain, screws, inertias=inertias, string_damping=string_damping,
                                use_kernel=use_kernel)
