"""The command line run in-process for a test: :func:`run` (exit code, stdout, stderr) and
:func:`run_json` (the ``--json`` report of a command that succeeds), through pytest's
``capsys``."""

import json
from typing import Any

import pytest

from tensegrity_stiffness.cli.parser import main


def run(capsys: pytest.CaptureFixture, *argv: object) -> tuple[int, str, str]:
    """``tensegrity-stiffness ARGV...`` (each argument as ``str``): its exit code and what it
    printed to stdout and stderr."""
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


def run_json(capsys: pytest.CaptureFixture, *argv: object) -> Any:
    """The parsed ``--json`` report of ``ARGV... --json``, asserting exit code 0 (stderr as the
    message)."""
    code, out, err = run(capsys, *argv, '--json')
    assert code == 0, err
    return json.loads(out)
