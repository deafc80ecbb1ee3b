"""The live line of ``bash scripts/run_twin.sh --control``
(``nodes/control_demo_line.control_line`` with the demo's time and phase, as
``ros/control_demo.ControlMonitor.line`` calls it):
from the controller's and the estimator's ``/diagnostics`` values it shows the achieved tick rate
of the rate asked, the missed ticks, the latency from a reading to its command (median / p99)
and the estimator's consistent share (issue 37, item 6); each field parses back to the value
the node reported. No node runs: the values are formatted as the nodes format them."""

from __future__ import annotations

import re

import pytest

pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')

from tensegrity_stiffness.nodes.control_demo_line import control_line
from tensegrity_stiffness.ros.control_demo import phase_at
from tensegrity_stiffness.ros.conversions import diagnostic_status
from tensegrity_stiffness.ros.runtime.paced_loop import PacedLoop

#: The fields of issue 37's item 6 as the line writes them.
FIELDS = re.compile(r'rate +(?P<achieved>\d+)/(?P<asked>\d+) Hz +missed (?P<missed>\d+) +'
                    r'latency (?P<median>[\d.]+)/(?P<p99>[\d.]+) ms +'
                    r'consistent (?P<consistent>[\d.]+)%')


def demo_line(t: float, controller: dict[str, str], estimator: dict[str, str]) -> str:
    """The line as the demo writes it at ``t`` s (its head: the time and the script's phase)."""
    return control_line(f't {t:5.1f} s  {phase_at(t):15s}', controller, '', estimator, None)


def key_values(values: list) -> dict[str, str]:
    """``values`` as a subscriber of ``/diagnostics`` reads them (formatted by the nodes'
    ``diagnostic_status``)."""
    return {kv.key: kv.value for kv in diagnostic_status('x', 'OK', '', values).values}


def controller_values(loop: PacedLoop, median_ms: float, p99_ms: float) -> dict[str, str]:
    """The controller's status values the line reads (its paced loop's own statistics)."""
    return key_values([*loop.statistics(), ('tick time [ms]', 0.131),
                       ('latency from the reading median [ms]', median_ms),
                       ('latency from the reading p99 [ms]', p99_ms),
                       ('feasible', True), ('stiffness target', 'none'),
                       ('saturated strings', 0),
                       ('pose error [m, rad]', [1e-5, -2e-5, 0.0, 0.0, 1e-4, 0.0])])


def test_the_line_shows_the_rate_missed_ticks_latency_and_consistency() -> None:
    loop = PacedLoop(500.0, lambda due: None, lambda exc: None)  # not started: no ticks
    loop.missed = 37
    line = demo_line(12.0, controller_values(loop, 2.6512, 6.875),
                        key_values([('consistent share', 0.9934)]))
    fields = FIELDS.search(line)
    assert fields is not None, line
    assert int(fields['asked']) == 500
    assert int(fields['achieved']) == 0  # the loop ran no tick in the last second
    assert int(fields['missed']) == 37
    assert float(fields['median']) == pytest.approx(2.65, abs=0.005)
    assert float(fields['p99']) == pytest.approx(6.88, abs=0.005)
    assert float(fields['consistent']) == pytest.approx(99.3, abs=0.05)
    assert line.startswith('t  12.0 s  stiffness step')
    assert 'pose error 0.022 mm 0.006 deg (true -)' in line


def test_values_not_reported_yet_are_dashes() -> None:
    """Before the latency window has a command, or before the estimator's first status, the
    fields are '-' (the line never shows a number the nodes did not report)."""
    loop = PacedLoop(500.0, lambda due: None, lambda exc: None)
    values = controller_values(loop, 1.0, 2.0)
    del values['latency from the reading median [ms]'], values['latency from the reading p99 [ms]']
    line = demo_line(1.0, values, {})
    assert 'rate    0/500 Hz  missed 0  latency -/- ms  consistent -' in line, line


def test_no_state_yet_shows_the_time_and_the_phase_only() -> None:
    assert demo_line(0.5, {}, key_values([('consistent share', 1.0)])) == 't   0.5 s  hold' + \
        ' ' * 11
