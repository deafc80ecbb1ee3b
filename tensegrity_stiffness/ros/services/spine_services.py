"""The spine node's services as pure functions: request validation and response filling, with
no rclpy (requests and responses are the generated message objects, or anything with the same
fields), so they are tested without a node.

``~/solve_equilibrium`` (``SolveChainEquilibrium``) is validated here and solved in the worker
process (:func:`tensegrity_stiffness.mechanics.chain.solve_chain_equilibrium`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.mechanics.chain import ChainEquilibriumResult
from tensegrity_stiffness.nodes.spine_node import (
    SpineNodeSettings,
    rest_lengths_input,
    screws_input,
)
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.services.responses import fail

FloatArray = NDArray[np.float64]

__all__ = ['ChainEquilibriumJob', 'chain_equilibrium_job', 'fail', 'fill_chain_equilibrium']


@dataclass(frozen=True)
class ChainEquilibriumJob:
    """The arguments of one :func:`solve_chain_equilibrium` call after the chain, validated."""

    tip_wrench: FloatArray
    gravity: FloatArray | None
    rest_lengths: tuple[FloatArray, ...] | None
    initial_screws: FloatArray | None
    time_budget: float
    max_iterations: int

    def args(self) -> tuple[Any, ...]:
        return (self.tip_wrench, self.gravity,
                None if self.rest_lengths is None else list(self.rest_lengths),
                self.initial_screws)

    def kwargs(self) -> dict[str, Any]:
        return {'time_budget': self.time_budget, 'max_iterations': self.max_iterations}


def chain_equilibrium_job(request: Any, settings: SpineNodeSettings,
                          last_solution: FloatArray | None) -> ChainEquilibriumJob:
    """Validate a ``SolveChainEquilibrium`` request; ValueError naming the field. Empty
    ``rest_lengths``: the node's current ones; empty ``initial_screws``: the last solution, else
    every joint's unloaded equilibrium; ``use_gravity`` false: no link weights."""
    for name in ('rest_lengths', 'initial_screws'):
        n = len(getattr(request, name))
        if n > settings.max_array_length:  # rejected before anything is converted
            raise ValueError(f'{name}: too many elements: {n} > max_length '
                             f'{settings.max_array_length}')
    W = conversions.msg_to_wrench(request.tip_wrench)
    chain = settings.chain
    rest = settings.rest_lengths
    if len(request.rest_lengths):
        try:
            rest = rest_lengths_input(np.asarray(request.rest_lengths, dtype=np.float64), chain)
        except ValueError as exc:
            raise ValueError(f'rest_lengths: {exc}') from None
    x0 = last_solution
    if len(request.initial_screws):
        values = np.asarray(request.initial_screws, dtype=np.float64)
        if not np.isfinite(values).all():
            raise ValueError('initial_screws must be finite')
        try:
            x0 = screws_input(values, chain.n_joints)
        except ValueError as exc:
            raise ValueError(f'initial_screws: {exc}') from None
    gravity = None if request.use_gravity else np.zeros(3)
    return ChainEquilibriumJob(W, gravity, rest, None if x0 is None else np.array(x0),
                               settings.equilibrium_time_budget,
                               settings.equilibrium_max_iterations)


def fill_chain_equilibrium(response: Any, result: ChainEquilibriumResult) -> bool:
    """Fill a ``SolveChainEquilibrium`` response from a solver result; True when it is a usable
    equilibrium (the node then keeps its screws as the next default start)."""
    response.success = bool(result.success)
    response.message = result.message
    response.iterations = int(result.iterations)
    response.residual = float(result.residual) if math.isfinite(result.residual) else -1.0
    state = result.state
    if not result.success or state is None:
        return False
    arrays = (result.screws, result.tip_transform, result.tip_stiffness,
              result.tip_stiffness_tool, state.wrenches)
    if any(a is None or not np.isfinite(a).all() for a in arrays):
        # a singular tip stiffness, or a state that overflowed far out
        response.success = False
        response.message = ('no usable equilibrium: ' + result.message if result.tip_stiffness
                            is None else 'no usable equilibrium: the state is not finite')
        return False
    response.screws = np.ravel(result.screws).tolist()
    response.tip_pose = conversions.transform_to_pose(result.tip_transform)
    response.tip_stiffness = np.ravel(result.tip_stiffness_tool).tolist()
    response.tip_stiffness_base = np.ravel(result.tip_stiffness).tolist()
    response.joint_wrenches = np.ravel(state.wrenches).tolist()
    response.stable = bool(result.stable)
    return True
