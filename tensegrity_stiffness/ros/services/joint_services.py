"""The joint node's services as pure functions: request validation and response filling, with
no rclpy (requests and responses are the generated message objects, or anything with the same
fields), so they are tested without a node.

``~/solve_equilibrium`` is validated here, tried on the node's executor under a small budget
(:data:`QUICK_SOLVE_ITERATIONS`, :data:`QUICK_SOLVE_BUDGET_S`) and handed to the worker process
only when that try does not converge; ``~/design_rest_lengths`` is computed in the worker; the
planar services are answered here whole.
"""

from __future__ import annotations

import math
import threading
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from tensegrity_stiffness.geometry.screw import single_screw
from tensegrity_stiffness.mechanics.design import (
    DesignResult,
    design_request_from_service,
    design_response_fields,
)
from tensegrity_stiffness.mechanics.equilibrium import EquilibriumResult
from tensegrity_stiffness.mechanics.planar import PlanarMechanism
from tensegrity_stiffness.mechanics.plausibility import (
    check_rest_lengths,
    check_screw,
    check_wrench,
)
from tensegrity_stiffness.nodes.stiffness_node import JointNodeSettings
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.services.responses import fail

FloatArray = NDArray[np.float64]

#: Newton iterations of the equilibrium solve tried on the node's executor before a request goes
#: to the worker process. A request near the last solution converges in 3 (docs/performance.md:
#: 0.15-0.7 ms), which the worker's hop (about 2 ms) would multiply; a hard one goes on in the
#: worker, with its time budget and kill-on-hang.
QUICK_SOLVE_ITERATIONS = 8
#: Wall-clock budget (s) of that try, past its first ``MIN_NEWTON_ITERATIONS`` steps: what the
#: executor (and the GIL the fast lane shares) gives a service request at most.
QUICK_SOLVE_BUDGET_S = 0.002


#: Requests of one service in progress at once (being solved or waiting for the worker); one
#: more is answered at once with ``success: false`` and :meth:`OutstandingRequests.enter`'s
#: message (issue #42: past 10 outstanding, requests were dropped unanswered by the service's
#: request queue, 10 deep by default, while the service's callback group was held by the one
#: awaiting the worker).
MAX_OUTSTANDING_REQUESTS = 32
#: Depth of the services' request queues (the middleware's history): a burst of up to this many
#: is taken and answered or refused; the node takes each request at once (a reentrant group).
SERVICE_QUEUE_DEPTH = 1000


class OutstandingRequests:
    """The count of one service's requests in progress, bounded by ``limit``
    (thread-safe)."""

    def __init__(self, service: str, limit: int = MAX_OUTSTANDING_REQUESTS) -> None:
        self.service = service
        self.limit = limit
        self.count = 0
        self.refused = 0
        self._lock = threading.Lock()

    def enter(self) -> str | None:
        """Count a new request in, or the refusal to answer it with when ``limit`` are in
        progress."""
        with self._lock:
            if self.count >= self.limit:
                self.refused += 1
                return (f'busy: {self.count} {self.service} requests are in progress (at most '
                        f'{self.limit}); send it again once one is answered')
            self.count += 1
            return None

    def leave(self) -> None:
        """A request answered."""
        with self._lock:
            self.count -= 1


@dataclass(frozen=True)
class EquilibriumJob:
    """The arguments of one :func:`solve_equilibrium` call, validated."""

    external_wrench: FloatArray
    rest_lengths: FloatArray | None
    initial_screw: FloatArray
    time_budget: float
    max_iterations: int

    def kwargs(self) -> dict[str, Any]:
        """The solver's keyword arguments for the worker: the node's budget and iterations."""
        return {'rest_lengths': self.rest_lengths, 'initial_screw': self.initial_screw,
                'time_budget': self.time_budget, 'max_iterations': self.max_iterations}

    def quick_kwargs(self) -> dict[str, Any]:
        """The same for the try on the executor: Newton steps only, at most
        :data:`QUICK_SOLVE_ITERATIONS` and :data:`QUICK_SOLVE_BUDGET_S` (never more than the
        node's own)."""
        return {**self.kwargs(), 'time_budget': min(self.time_budget, QUICK_SOLVE_BUDGET_S),
                'max_iterations': min(self.max_iterations, QUICK_SOLVE_ITERATIONS),
                'newton_only': True}


def equilibrium_job(request: Any, settings: JointNodeSettings,
                    last_solution: FloatArray | None) -> EquilibriumJob:
    """Validate a ``SolveEquilibrium`` request; ValueError naming the field. An empty
    ``initial_screw`` starts from the last solution, else from ``joint.initial_screw``."""
    for name in ('rest_lengths', 'initial_screw'):
        n = len(getattr(request, name))
        if n > settings.max_array_length:  # rejected before anything is converted
            raise ValueError(f'{name}: too many elements: {n} > max_length '
                             f'{settings.max_array_length}')
    model = settings.model
    rest = None
    if len(request.rest_lengths):
        rest = check_rest_lengths(model, np.asarray(request.rest_lengths, dtype=np.float64))
    # the strings' capacity at the request's rest lengths, as solve_equilibrium judges it
    W = check_wrench(model, conversions.msg_to_wrench(request.external_wrench),
                     rest_lengths=rest)
    if len(request.initial_screw):
        x0 = request.initial_screw
    else:
        x0 = last_solution if last_solution is not None else model.initial_screw
    x0 = single_screw(x0, 'initial_screw')
    check_screw(model, x0, 'initial_screw')
    return EquilibriumJob(W, rest, x0, settings.equilibrium_time_budget,
                          settings.equilibrium_max_iterations)


def fill_equilibrium(response: Any, result: EquilibriumResult) -> bool:
    """Fill a ``SolveEquilibrium`` response from a solver result; True when it is a usable
    equilibrium (the node then keeps its screw as the next default start)."""
    response.success = bool(result.success)
    response.message = result.message
    response.iterations = int(result.iterations)
    response.residual = float(result.residual) if math.isfinite(result.residual) else -1.0
    if not result.success or result.state is None:
        return False
    state = result.state
    if not (math.isfinite(result.energy) and all(np.isfinite(a).all() for a in (
            result.screw, state.transform, state.wrench, state.stiffness,
            state.cartesian_stiffness, state.tensions))):
        # e.g. a start so far out that the string lengths overflow: F evaluates to 0 there
        response.success = False
        response.message = 'no usable equilibrium: the state at the solution is not finite'
        return False
    response.screw = result.screw.tolist()
    response.pose = conversions.transform_to_pose(state.transform)
    response.string_wrench = conversions.wrench_to_msg(state.wrench)
    response.stiffness = state.stiffness.ravel().tolist()
    response.cartesian_stiffness = state.cartesian_stiffness.ravel().tolist()
    response.tensions = state.tensions.tolist()
    response.energy = float(result.energy)
    response.stable = bool(result.stable)
    return True


def design_kwargs(request: Any, settings: JointNodeSettings, reference: FloatArray
                  ) -> dict[str, Any]:
    """Keyword arguments of :func:`design.design_rest_lengths` (after the model) from a
    ``DesignRestLengths`` request; ValueError naming the field. A target pose is converted on the
    branch nearest ``reference`` (the node's last screw)."""
    for name in ('target_screw', 'target_cartesian_stiffness'):
        n = len(getattr(request, name))
        if n > settings.max_array_length:
            raise ValueError(f'{name}: too many elements: {n} > max_length '
                             f'{settings.max_array_length}')
    pose = request.target_pose
    return design_request_from_service(
        request.target_screw, [pose.position.x, pose.position.y, pose.position.z],
        [pose.orientation.x, pose.orientation.y, pose.orientation.z, pose.orientation.w],
        conversions.msg_to_wrench(request.external_wrench), request.tension_min,
        request.tension_max, request.target_cartesian_stiffness, reference)


def fill_design(response: Any, result: DesignResult) -> Any:
    """Fill a ``DesignRestLengths`` response from a design result."""
    for name, value in design_response_fields(result).items():
        setattr(response, name, value)
    return response


def planar_forward(planar: PlanarMechanism, request: Any, response: Any) -> Any:
    """Answer a ``PlanarForwardKinematics`` request."""
    try:
        fk = planar.forward(request.actuator_length, request.actuator_angle)
    except ValueError as exc:
        return fail(response, f'invalid request: {exc}')
    if not fk.actuator_in_range:
        return fail(response, (
            f'actuator (L3 = {request.actuator_length:.6g} m, theta1 = '
            f'{request.actuator_angle:.6g} rad) is outside the actuator workspace '
            f'L3 in [{planar.L3_min:.6g}, {planar.L3_max:.6g}], theta1 in '
            f'[{planar.theta1_min:.6g}, {planar.theta1_max:.6g}]'))
    values = (fk.x, fk.y, fk.theta2, fk.stiffness, fk.energy, fk.jacobian_determinant)
    if not all(math.isfinite(v) for v in values) or not np.isfinite(fk.jacobian).all():
        return fail(response, 'no isolated equilibrium here (neutral point): every theta2 is '
                              'an equilibrium')
    response.success = True
    response.x, response.y = float(fk.x), float(fk.y)
    response.platform_angle = float(fk.theta2)
    response.stiffness = float(fk.stiffness)
    response.energy = float(fk.energy)
    response.stable = bool(fk.stable)
    response.in_range = bool(fk.theta2_in_range)
    response.jacobian = np.asarray(fk.jacobian, dtype=np.float64).ravel().tolist()
    response.jacobian_determinant = float(fk.jacobian_determinant)
    response.singularities = list(fk.singularities)
    notes = []
    if not fk.theta2_in_range:
        notes.append('theta2 outside its allowed range')
    if fk.singularities:
        notes.append('singular: ' + ', '.join(fk.singularities))
    response.message = 'ok' + (' (' + '; '.join(notes) + ')' if notes else '')
    return response


def planar_inverse(planar: PlanarMechanism, request: Any, response: Any) -> Any:
    """Answer a ``PlanarInverseKinematics`` request."""
    try:
        solutions = planar.inverse(request.x, request.y)
    except ValueError as exc:
        return fail(response, f'invalid request: {exc}')
    response.actuator_length = [float(s.L3) for s in solutions]
    response.actuator_angle = [float(s.theta1) for s in solutions]
    response.platform_angle = [float(s.theta2) for s in solutions]
    response.stiffness = [float(s.stiffness) for s in solutions]
    response.stable = [bool(s.stable) for s in solutions]
    response.success = len(solutions) > 0
    response.message = (f'{len(solutions)} solution(s)' if solutions
                        else f'unreachable: {solutions.reason}')
    return response
