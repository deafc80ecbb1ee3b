"""Test suite root: ``test/<area>/`` mirrors ``tensegrity_stiffness/<area>/`` (``ros/`` the
nodes, ``kernel/`` the compiled kernel, ``package/`` the layout, docs and builds); the shared
harnesses are the :mod:`support` package beside this file, importable because pytest puts this
folder on ``sys.path`` for its ``conftest.py``.

The skip rule: outside the set-up environment (a plain ``pip install .`` and ``pytest``) a test
whose dependency is missing (rclpy, MuJoCo, rosbags, the compiled kernel, the colcon build) is
skipped. Inside it (``scripts/test.sh`` and so ``.ci/run`` export ``TENSEGRITY_REQUIRE_ALL=1``)
every such skip is a failure that names the reason, collection skips (``pytest.importorskip`` at
a module's top) included: a broken install cannot pass as a green run. Only the skips a user
asks for (:func:`requested_skip`) stay skips. The run ends with the skip count, each skip named
with its reason (``[tests] skipped: 0``)."""

from __future__ import annotations

import os

import pytest

#: Set by scripts/test.sh: every skip not asked for is a failure.
REQUIRE_ALL = os.environ.get('TENSEGRITY_REQUIRE_ALL', '') == '1'


def requested_skip(reason: str) -> bool:
    """A skip the user asked for, which stays a skip under REQUIRE_ALL: the kernel switched off
    (``TENSEGRITY_STIFFNESS_KERNEL=off`` selects the numpy path, so the kernel's own tests have
    nothing to run; their reasons name the variable)."""
    from tensegrity_stiffness.mechanics.kernel import KERNEL_ENV, OFF_VALUES

    return os.environ.get(KERNEL_ENV, '').lower() in OFF_VALUES and KERNEL_ENV in reason


def _skip_reason(report: pytest.CollectReport | pytest.TestReport) -> str:
    longrepr = report.longrepr
    if isinstance(longrepr, tuple) and len(longrepr) == 3:
        return str(longrepr[2]).removeprefix('Skipped: ')
    return str(longrepr)


def _fail_unrequested_skip(report: pytest.CollectReport | pytest.TestReport) -> None:
    """Under REQUIRE_ALL, turn a skip (not an xfail, not a requested one) into a failure that
    says why."""
    if not (REQUIRE_ALL and report.skipped) or hasattr(report, 'wasxfail'):
        return
    reason = _skip_reason(report)
    if requested_skip(reason):
        return
    report.outcome = 'failed'
    report.longrepr = (f'skipped inside the set-up environment (TENSEGRITY_REQUIRE_ALL=1, '
                       f'scripts/test.sh), which has every dependency: {reason}')


@pytest.hookimpl(hookwrapper=True)
def pytest_make_collect_report(collector: pytest.Collector):
    outcome = yield
    _fail_unrequested_skip(outcome.get_result())


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    outcome = yield
    _fail_unrequested_skip(outcome.get_result())


def pytest_terminal_summary(terminalreporter) -> None:
    """The skip count, each skip with where and why (also without ``-rs``)."""
    skipped = [r for r in terminalreporter.stats.get('skipped', [])
               if not hasattr(r, 'wasxfail')]
    terminalreporter.write_line(f'[tests] skipped: {len(skipped)}')
    for report in skipped:
        terminalreporter.write_line(f'[tests]   {report.nodeid}: {_skip_reason(report)}')
