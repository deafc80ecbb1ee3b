"""Awaitable calls into a :class:`.SolverWorker` from a node's coroutine callbacks: the
service awaits the result while the executor keeps serving the topics. Shared by the package's
nodes."""

from __future__ import annotations

import threading
from typing import Any

from rclpy.node import Node
from rclpy.task import Future

from tensegrity_stiffness.ros.solver_worker import SolverWorker


class WorkerCalls:
    """A :class:`.SolverWorker` (``worker``) of ``node`` and the guard condition that wakes the
    node's executor when a result comes back."""

    def __init__(self, node: Node, name: str) -> None:
        self._node = node
        self.worker = SolverWorker(name)
        self._wake = node.create_guard_condition(lambda: None)

    async def call(self, fn: Any, args: tuple, kwargs: dict[str, Any], deadline_s: float) -> Any:
        """``fn(*args, **kwargs)`` computed in the worker process and awaited, so that the
        executor keeps serving the topics meanwhile; raises the worker's exception, a
        :class:`WorkerOverrunError` (a TimeoutError) or a :class:`WorkerDiedError`."""
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
            # The executor polls the awaiting coroutine only when it wakes up: wake it.
            self._wake.trigger()

        self.worker.submit(fn, args, kwargs, lambda result: settle(result=result),
                           lambda error: settle(error=error), deadline_s=deadline_s)
        return await done

    def close(self) -> None:
        self.worker.close()


def worker_failure_message(exc: BaseException) -> str:
    """What a service answers when the worker overran (a TimeoutError) or died."""
    return (f'solver overran its budget: {exc}' if isinstance(exc, TimeoutError)
            else f'solver failed: {exc}; try again')


def answer_worker_failure(reporter: Any, kind: str, response: Any, exc: BaseException) -> Any:
    """Log the worker's overrun or death (an error, throttled) and answer ``success: false``
    with :func:`worker_failure_message`."""
    message = worker_failure_message(exc)
    reporter.warn(kind, message, error=True)
    response.success = False
    response.message = message
    return response
