"""Awaitable calls into a :class:`.SolverWorker` from a node's coroutine service callbacks: the
executor keeps serving everything else while the worker computes."""

from __future__ import annotations

import threading
from typing import Any

from rclpy.node import Node
from rclpy.task import Future

from tensegrity_stiffness.ros.runtime.solver_worker import SolverWorker

#: Wall-clock time a job may take beyond its own budget (a loaded machine) before it counts as
#: an overrun and the worker is replaced.
SOLVER_GRACE_S = 5.0


class WorkerCalls:
    """``await calls(fn, args, kwargs, deadline_s)``: ``fn(*args, **kwargs)`` computed in the
    worker; raises the worker's exception, a :class:`.WorkerOverrunError` (a TimeoutError) or a
    :class:`.WorkerDiedError`."""

    def __init__(self, node: Node, worker: SolverWorker) -> None:
        self._node = node
        self._worker = worker
        # The executor polls an awaiting coroutine only when it wakes up: results wake it.
        self._wake = node.create_guard_condition(lambda: None)

    async def __call__(self, fn: Any, args: tuple, kwargs: dict[str, Any],
                       deadline_s: float) -> Any:
        done = Future(executor=self._node.executor)
        settle_lock = threading.Lock()

        def settle(result: Any = None, error: BaseException | None = None) -> None:
            with settle_lock:
                if done.done():
                    return
                if error is None:
                    done.set_result(result)
                else:  # reported to the caller by `await done`
                    done.set_exception(error)
            try:
                self._wake.trigger()
            except RuntimeError:  # a result racing the shutdown: no executor left to wake
                if self._node.context.ok():
                    raise

        self._worker.submit(fn, args, kwargs, lambda result: settle(result=result),
                            lambda error: settle(error=error), deadline_s=deadline_s)
        return await done


def answer_worker_failure(reporter: Any, kind: str, response: Any, exc: BaseException) -> Any:
    """``success: false`` for a service request whose worker overran (a TimeoutError) or died,
    logged as an error of ``kind`` by the node's :class:`.Reporter`."""
    message = (f'solver overran its budget: {exc}' if isinstance(exc, TimeoutError)
               else f'solver failed: {exc}; try again')
    reporter.warn(kind, message, error=True)
    response.success = False
    response.message = message
    return response
