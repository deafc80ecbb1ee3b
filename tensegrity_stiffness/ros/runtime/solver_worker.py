"""Solves in a worker process, so that a node's topics keep being answered while one runs.

Not a thread of the node's process: a solve is Python and numpy holding the GIL for its whole
budget, and the executor thread, which gives the GIL up at every wait and publish, then gets it
back only after a switch interval each time (the convoy effect, docs/nodes.md "Robustness").
Spawned, not forked (the node's process runs the middleware's threads).

One reader thread per worker waits on the worker's pipe and on its process sentinel at once, so
a worker that dies (the OOM killer, a signal) is noticed at once and a fresh one is started: the
job it was running fails with :class:`WorkerDiedError` naming the cause, the jobs it had not
started yet (the worker reports each start) go to the fresh worker, as do the jobs after. A job
that does not come back within its deadline fails with :class:`WorkerOverrunError` and the worker
is replaced. Jobs run one at a time, so a job's deadline runs from the moment it is the oldest
job held and the worker is ready (its imports done: the ``preload`` modules, imported before the
worker says so, so that a fresh worker's numpy, scipy and solver imports, seconds on a loaded
machine, never count against a job's budget): a worker stopped by a signal, that never starts
the job, overruns too. Nothing here imports rclpy; results are handed to callbacks on
the reader thread.
"""

from __future__ import annotations

import importlib
import itertools
import multiprocessing
import os
import signal
import threading
from collections.abc import Callable
from multiprocessing.connection import Connection, wait
from typing import Any

#: Nice value of the worker: on a busy machine the kernel favours the node's topic thread; a solve
#: then gets fewer iterations within its budget.
WORKER_NICE = 10
#: Seconds to wait for a worker to end after SIGKILL at close.
JOIN_TIMEOUT_S = 2.0
#: What the worker reports: ready (imports done), a job started, done (a result), failed (an
#: exception).
READY, STARTED, DONE, FAILED = 'ready', 'started', 'done', 'failed'


class WorkerDiedError(RuntimeError):
    """The worker process ended while it held the job."""


class WorkerOverrunError(TimeoutError):
    """The job did not come back within its deadline; the worker was replaced."""


def _serve(conn: Connection, preload: tuple[str, ...] = ()) -> None:
    """The worker's loop: import the ``preload`` modules, say it is ready, then run ``(job, fn,
    args, kwargs)`` requests and send back results."""
    os.nice(WORKER_NICE)
    # Ctrl-C in a terminal reaches the whole process group: the node ends its worker itself.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    for module in preload:
        try:
            importlib.import_module(module)
        except Exception:  # the job that needs it reports the import's error
            pass
    conn.send((None, READY, None))
    while True:
        try:
            job, fn, args, kwargs = conn.recv()
            conn.send((job, STARTED, None))
        except (EOFError, OSError):  # the node closed the pipe: done
            return
        try:
            reply = (job, DONE, fn(*args, **kwargs))
        except Exception as exc:  # reported to the caller
            reply = (job, FAILED, exc)
        try:
            conn.send(reply)
        except (BrokenPipeError, OSError):
            return


def describe_exit(exitcode: int | None) -> str:
    """``'killed by SIGKILL'``, ``'exit status 1'``, ... for a process's exit code."""
    if exitcode is None:
        return 'still running'
    if exitcode < 0:
        try:
            return f'killed by {signal.Signals(-exitcode).name}'
        except ValueError:
            return f'killed by signal {-exitcode}'
    return f'exit status {exitcode}'


class _Job:
    __slots__ = ('deadline_s', 'on_error', 'on_result', 'request', 'started', 'timer')

    def __init__(self, request: tuple, on_result: Callable[[Any], None],
                 on_error: Callable[[BaseException], None], deadline_s: float | None) -> None:
        self.request = request
        self.on_result = on_result
        self.on_error = on_error
        self.deadline_s = deadline_s
        self.started = False
        self.timer: threading.Timer | None = None


class SolverWorker:
    """A worker process that runs one job at a time, replaced when it dies or overruns.

    ``name`` appears in error messages (``'equilibrium worker'``). ``preload``: the modules each
    worker imports before it is ready (the modules of the functions it will run). ``restarts``
    counts the replacements; ``pid`` is the current worker's process id.
    """

    def __init__(self, name: str = 'solver worker', preload: tuple[str, ...] = ()) -> None:
        self.name = name
        self.preload = tuple(preload)
        self.restarts = 0
        self._context = multiprocessing.get_context('spawn')
        self._lock = threading.Lock()
        self._ids = itertools.count()
        self._jobs: dict[int, _Job] = {}
        self._closed = False
        self._process: Any = None
        self._conn: Connection | None = None
        self._ready = False
        self._start()

    @property
    def pid(self) -> int | None:
        process = self._process
        return None if process is None else process.pid

    def _start(self) -> None:
        """Start a worker and its reader thread (called with the lock held or at init)."""
        parent, child = self._context.Pipe()
        process = self._context.Process(target=_serve, args=(child, self.preload), daemon=True,
                                        name='tensegrity_solver')
        process.start()
        child.close()
        self._process, self._conn, self._ready = process, parent, False
        threading.Thread(target=self._read, args=(process, parent), daemon=True,
                         name='tensegrity_solver_reader').start()

    def submit(self, fn: Callable, args: tuple, kwargs: dict[str, Any],
               on_result: Callable[[Any], None], on_error: Callable[[BaseException], None],
               deadline_s: float | None = None) -> None:
        """Run ``fn(*args, **kwargs)`` in the worker; its result goes to ``on_result`` and its
        exception (or a :class:`WorkerDiedError` / :class:`WorkerOverrunError`) to ``on_error``,
        on a thread of this object; ``deadline_s`` as in the module docstring. ``fn`` and its
        arguments must be picklable."""
        with self._lock:
            if self._closed:
                raise RuntimeError(f'{self.name} is closed')
            key = next(self._ids)
            job = self._jobs[key] = _Job((key, fn, args, kwargs), on_result, on_error,
                                         deadline_s)
            conn = self._conn
            self._arm_oldest()
        self._send(conn, job)

    @staticmethod
    def _send(conn: Connection, job: _Job) -> None:
        try:
            conn.send(job.request)
        except (BrokenPipeError, OSError):  # the worker just died: the reader re-sends the job
            pass

    def _arm_oldest(self) -> None:
        """Start the deadline of the oldest job held, once the worker is ready (lock held)."""
        if not self._ready or not self._jobs:
            return
        key, job = next(iter(self._jobs.items()))
        if job.deadline_s is not None and job.timer is None:
            job.timer = threading.Timer(job.deadline_s, self._overrun, (key, job.deadline_s))
            job.timer.daemon = True
            job.timer.start()

    def _settle(self, key: int, result: Any = None, error: BaseException | None = None) -> None:
        with self._lock:
            job = self._jobs.pop(key, None)
            self._arm_oldest()
        if job is None:
            return
        if job.timer is not None:
            job.timer.cancel()
        if error is None:
            job.on_result(result)
        else:
            job.on_error(error)

    def _overrun(self, key: int, deadline_s: float) -> None:
        with self._lock:
            process = self._process if key in self._jobs else None
        if process is None:
            return
        process.kill()  # the reader sees it end and starts a fresh worker
        self._settle(key, error=WorkerOverrunError(
            f'no result within {deadline_s:.3g} s; {self.name} replaced'))

    def _read(self, process: Any, conn: Connection) -> None:
        """Results of ``process`` until it ends; then fail what it held and replace it."""
        while True:
            try:
                ready = wait([conn, process.sentinel])
            except OSError:  # the pipe was closed by close()
                break
            if conn in ready:
                try:
                    key, status, value = conn.recv()
                except (EOFError, OSError):
                    break
                if status == READY:
                    with self._lock:
                        self._ready = True
                        self._arm_oldest()
                elif status == STARTED:
                    with self._lock:
                        job = self._jobs.get(key)
                        if job is not None:
                            job.started = True
                elif status == DONE:
                    self._settle(key, result=value)
                else:
                    self._settle(key, error=value)
                continue
            break
        process.join(JOIN_TIMEOUT_S)
        with self._lock:
            if self._closed or self._process is not process:
                return
            running = [self._jobs.pop(key) for key in
                       [key for key, job in self._jobs.items() if job.started]]
            waiting = list(self._jobs.values())
            cause = f'the {self.name} died ({describe_exit(process.exitcode)})'
            self.restarts += 1
            self._start()
            for job in waiting:
                if job.timer is not None:  # its deadline restarts on the fresh worker
                    job.timer.cancel()
                    job.timer = None
                self._send(self._conn, job)
        conn.close()
        for job in running:
            if job.timer is not None:
                job.timer.cancel()
            job.on_error(WorkerDiedError(f'{cause}; a fresh one was started'))

    def close(self) -> None:
        """End the worker at once (a running job is abandoned; its callbacks are not called)."""
        with self._lock:
            self._closed = True
            process, conn = self._process, self._conn
            jobs, self._jobs = list(self._jobs.values()), {}
        for job in jobs:
            if job.timer is not None:
                job.timer.cancel()
        if process is not None:
            process.kill()
            process.join(JOIN_TIMEOUT_S)
        if conn is not None:
            conn.close()
