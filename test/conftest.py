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
with its reason (``[tests] skipped: 0``).

The tiers: tests that time something (deadlines, rates, latencies, a control loop's ticks) carry
``@pytest.mark.serial`` and run alone; the rest can run in parallel (pytest-xdist). scripts/test.sh
runs ``TENSEGRITY_TIER=parallel`` (every test not marked serial, ``-n 3``), then
``TENSEGRITY_TIER=serial`` (the serial ones, one process); without the variable every test runs.
The tier is chosen here rather than by ``-m`` so that a caller's own ``-m``/``-k`` still applies.
Each xdist worker takes its own ROS domain (``ROS_DOMAIN_ID`` + its index, reserved by
scripts/test.sh as ``TENSEGRITY_DOMAINS`` consecutive free domains), so that the nodes of tests
running side by side never discover each other."""

from __future__ import annotations

import os
from typing import Any

import pytest

#: Set by scripts/test.sh: every skip not asked for is a failure.
REQUIRE_ALL = os.environ.get('TENSEGRITY_REQUIRE_ALL', '') == '1'
#: The tiers a run can select with TENSEGRITY_TIER (empty: every test).
TIERS = ('parallel', 'serial')
TIER = os.environ.get('TENSEGRITY_TIER', '')
if TIER not in TIERS + ('',):
    raise pytest.UsageError(f'TENSEGRITY_TIER must be one of {TIERS} or empty, got {TIER!r}')


def own_domain_per_worker() -> None:
    """An xdist worker ``gwN`` uses ROS domain ``ROS_DOMAIN_ID + N`` when scripts/test.sh
    reserved ``TENSEGRITY_DOMAINS`` > N domains from ``ROS_DOMAIN_ID`` (set before any test
    module creates a ROS context; node processes inherit it)."""
    worker = os.environ.get('PYTEST_XDIST_WORKER', '')
    reserved = int(os.environ.get('TENSEGRITY_DOMAINS', '0') or 0)
    if not (worker.startswith('gw') and reserved and os.environ.get('ROS_DOMAIN_ID')):
        return
    index = int(worker[2:])
    if index >= reserved:
        raise pytest.UsageError(f'xdist worker {worker} has no ROS domain: scripts/test.sh '
                                f'reserved {reserved} (TENSEGRITY_DOMAINS)')
    os.environ['ROS_DOMAIN_ID'] = str(int(os.environ['ROS_DOMAIN_ID']) + index)


own_domain_per_worker()


#: The files of the parallel pass that take longest (seconds summed per file over one parallel
#: pass with three workers on the 2-core machine, 2026-12-08, load 8-14 from other work: the
#: figures are about 2.5 times a quiet run's, their order is what counts), started first so
#: that no long file is left for the end of the pass while the other workers idle (xdist hands
#: out whole files in collection order with ``--no-loadscope-reorder``). Files not listed
#: follow in their usual order.
LONGEST_FIRST = (
    'test/package/test_workspace_build.py',  # 243 s: a colcon build of a fresh clone
    'test/estimation/test_calibration.py',   # 173 s
    'test/ros/test_node_lifecycle.py',       # 147 s
    'test/ros/test_stiffness_bridge.py',     # 143 s
    'test/package/test_benches.py',          # 132 s
    'test/cli/test_calibration_command.py',  # 118 s
    'test/estimation/test_filter_twin.py',   # 115 s
    'test/control/test_control_twin.py',     # 111 s
    'test/cli/test_cli.py',                  # 97 s
    'test/ros/test_spine_node.py',           # 86 s
    'test/ros/test_tf.py',                   # 86 s: builds tf2_msgs where the setup did not
    'test/estimation/test_structure_estimator.py',  # 77 s
    'test/ros/test_your_joint_nodes.py',     # 74 s
    'test/ros/test_record.py',               # 72 s
    'test/estimation/test_estimation_chain.py',  # 70 s
    'test/cli/test_hostile_command_line.py',  # 69 s
    'test/cli/test_your_joint.py',           # 69 s
    'test/cli/test_structure_cli.py',        # 66 s
    'test/ros/test_estimator_trust.py',      # 63 s
    'test/ros/test_robustness.py',           # 60 s
    'test/ros/test_sim_node.py',             # 54 s
    'test/ros/test_control_demo_joints.py',  # 51 s
    'test/ros/test_structure_sim_node.py',   # 39 s
)


def _longest_first(items: list[pytest.Item]) -> None:
    rank = {path: i for i, path in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split('::')[0], len(rank)))  # stable


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Keep the tier TENSEGRITY_TIER selects (the others deselected, as ``-m`` does); in the
    parallel tier, the longest files first."""
    if not TIER:
        return
    if TIER == 'parallel':
        _longest_first(items)
    keep, drop = [], []
    for item in items:
        serial = item.get_closest_marker('serial') is not None
        (keep if serial == (TIER == 'serial') else drop).append(item)
    if drop:
        config.hook.pytest_deselected(items=drop)
        items[:] = keep


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


def plain(value: Any) -> Any:
    """``value`` as plain Python data (numpy scalars and arrays through ``tolist``, containers
    item by item, anything else its ``str``): what pytest-xdist's workers can send of a
    ``record_property`` (execnet serializes builtins only)."""
    if value is None or type(value) in (str, int, float, bool):  # not numpy.float64 (a float)
        return value
    if isinstance(value, (list, tuple)):
        return type(value)(plain(v) for v in value)
    if isinstance(value, dict):
        return {plain(k): plain(v) for k, v in value.items()}
    if hasattr(value, 'tolist'):
        return plain(value.tolist())
    return str(value)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo):
    outcome = yield
    report = outcome.get_result()
    _fail_unrequested_skip(report)
    report.user_properties = [(name, plain(value)) for name, value in report.user_properties]


def pytest_terminal_summary(terminalreporter) -> None:
    """The skip count, each skip with where and why (also without ``-rs``)."""
    skipped = [r for r in terminalreporter.stats.get('skipped', [])
               if not hasattr(r, 'wasxfail')]
    terminalreporter.write_line(f'[tests] skipped: {len(skipped)}')
    for report in skipped:
        terminalreporter.write_line(f'[tests]   {report.nodeid}: {_skip_reason(report)}')
