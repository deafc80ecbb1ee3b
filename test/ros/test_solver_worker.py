"""The solver worker's deadline runs from its readiness, and a worker is ready only after its
``preload`` modules are imported: a fresh worker's imports (numpy, scipy, the solvers: seconds
on a loaded machine) never count against a job's budget. A structure node's equilibrium overran
its 5 s budget at load 14 when the first job imported them (2026-12-08)."""

from __future__ import annotations

import sys
import threading
from pathlib import Path

import pytest

from tensegrity_stiffness.ros.runtime.solver_worker import SolverWorker, WorkerOverrunError

#: A module whose import takes longer than the job's deadline.
SLOW_MODULE = """
import time
time.sleep({seconds})


def answer() -> int:
    return 42
"""
IMPORT_S = 3.0
DEADLINE_S = 2.0


def run(worker: SolverWorker, fn, deadline_s: float) -> object:
    """``fn()`` in the worker: its result, or the error it ended with."""
    done = threading.Event()
    outcome: list[object] = []

    def settle(value: object) -> None:
        outcome.append(value)
        done.set()

    worker.submit(fn, (), {}, settle, settle, deadline_s=deadline_s)
    assert done.wait(60.0), 'no answer from the worker in 60 s'
    return outcome[0]


@pytest.fixture
def slow_module(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    """A fresh module (unique name: never imported before in this process) that sleeps on
    import; the spawned worker finds it on the parent's ``sys.path``."""
    name = f'slow_import_{tmp_path.name.replace("-", "_")}'
    (tmp_path / f'{name}.py').write_text(SLOW_MODULE.format(seconds=IMPORT_S))
    monkeypatch.syspath_prepend(str(tmp_path))
    yield name
    sys.modules.pop(name, None)


def test_a_preloaded_module_s_import_does_not_count_against_the_deadline(slow_module) -> None:
    module = __import__(slow_module)  # here too, to pickle the function by reference
    worker = SolverWorker('test worker', preload=(slow_module,))
    try:
        assert run(worker, module.answer, DEADLINE_S) == 42
        assert worker.restarts == 0
    finally:
        worker.close()


def test_without_the_preload_the_import_overruns_the_deadline(slow_module) -> None:
    """What the preload prevents (this test fails if the import stops counting some other way):
    the job's own unpickling imports the module inside its deadline."""
    module = __import__(slow_module)
    worker = SolverWorker('test worker')
    try:
        error = run(worker, module.answer, DEADLINE_S)
        assert isinstance(error, WorkerOverrunError), error
    finally:
        worker.close()
