"""A broken length sensor and a flipped IMU named across processes (issue #41): the installed
structure_sim_node rolls the 6-bar (its scripted gait, with sensor noise) and feeds
structure_estimator_node (the filter); while it tips over, a fault is set on the twin at run time
(``faults.broken_length``, ``faults.flipped_imu``) and the estimator's ``~/trust`` names the
faulty sensor (``length[<string>]``, ``imu[<bar>]``) within 0.1 s of the fault in the data's time:
the header stamp of the estimate that names it against the stamp of the twin's first publication
with the fault (its log line). The estimator is triggered by the last bar's IMU, so an estimate
carries the stamp of the twin's publication it was made of. In real time the twin stamps a
publication with the wall clock, its simulated time kept on absolute deadlines, so the stamps are
the simulated time's up to the steps it catches up at once (counted on its /diagnostics).

No wall-clock assertion: each wait is for a condition, with a generous timeout."""

from __future__ import annotations

import re

import pytest

rclpy = pytest.importorskip('rclpy', reason='ROS 2 is set up by scripts/test.sh')
# Serial: 0.1 s of the data's time is a latency, and the filter keeps only the newest reading,
# so a stalled estimator (beside three workers) would name the fault at a later estimate.
pytestmark = [pytest.mark.ros, pytest.mark.slow, pytest.mark.serial]

from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
from rcl_interfaces.srv import SetParameters  # noqa: E402
from support.ros_harness import (  # noqa: E402
    RosClient,
    start_structure_twin_and_estimator,
    unique_namespace,
)

from tensegrity_stiffness import config  # noqa: E402
from tensegrity_stiffness.simulation.structure_gait import RECOVER, TIP  # noqa: E402
from tensegrity_stiffness.structures.structure import Structure  # noqa: E402

#: The twin's sensor noise and the estimator's stds, as ``run_twin.sh --estimate --roll``
#: (structure_twin_demo: a rolling robot's accelerations are in the IMU's std).
NOISE = {'lengths': 1e-3, 'accelerometer': 0.05, 'gyro': 0.01}
IMU_STD_ROLLING = 0.1
#: The faults: the library's filter test's (test/estimation/test_structure_estimator.py).
BROKEN, FLIPPED = 'x1b-y1a', 'z1'
#: The broken length's offset (m). The default 2 cm (20 std) while tipping was absorbed by the
#: filter in 2 of about 30 runs: with the roll's process noise the update's chi-square rose to
#: 70 for 66 degrees of freedom, under the gate, and the pose moved instead (docs/structures.md).
LENGTH_OFFSET = 0.05
BOUND_S = 0.1
#: The gait's phases in which the robot moves, and the tries to set a fault in one of them.
MOVING = (TIP, RECOVER)
MAX_TRIES = 5
#: The twin's log line of the first publication with a fault (structure_sim_node._publish).
ONSET = (r'sensor faults: {names} from the publication at simulated time (?P<time>[0-9.]+) s '
         r'\(stamp (?P<sec>\d+)\.(?P<nanosec>\d{{9}}), gait phase (?P<phase>\w+)\)')


def stamp_s(stamp) -> float:
    return stamp.sec + 1e-9 * stamp.nanosec


def trust_of(msg: DiagnosticArray) -> dict[str, str]:
    return {kv.key: kv.value for kv in msg.status[0].values}


def twin_status(msg: DiagnosticArray, name: str) -> dict[str, str] | None:
    for s in msg.status:
        if s.name == name:
            return {kv.key: kv.value for kv in s.values}
    return None


@pytest.fixture(scope='module')
def rolling(tmp_path_factory):
    structure = Structure.from_yaml(config.example_config_path('six_bar.yaml'))
    folder = tmp_path_factory.mktemp('structure_faults')
    twin_params, est_params = folder / 'twin.yaml', folder / 'estimator.yaml'
    twin_params.write_text(
        '/**:\n  ros__parameters:\n    structure:\n      config: six_bar.yaml\n'
        '    gait:\n      enabled: true\n      steps: 20\n'
        f'    faults:\n      length_offset: {LENGTH_OFFSET}\n'
        '    noise:\n' + ''.join(f'      {k}: {v}\n' for k, v in NOISE.items())
        + '      seed: 4\n')
    est_params.write_text(
        '/**:\n  ros__parameters:\n    structure:\n      config: six_bar.yaml\n'
        '    estimation:\n      method: filter\n      trigger: imu\n'
        f'    sensors:\n      length_std: {NOISE["lengths"]}\n      gyro_std: {NOISE["gyro"]}\n'
        f'      imu_std: {IMU_STD_ROLLING}\n')
    ns = unique_namespace('structure_faults')
    twin, estimator, sim_base, est_base = start_structure_twin_and_estimator(
        ns, twin_params, est_params, ('measured_lengths', 'measured_rest_lengths',
                                      'measured_contacts',
                                      *(f'imu/{bar}' for bar in structure.bar_names)))
    ros = RosClient('structure_faults_test')
    out = {
        'structure': structure, 'twin': twin, 'estimator': estimator, 'ros': ros,
        'trust': ros.subscribe(DiagnosticArray, f'{est_base}/trust'),
        'diagnostics': ros.subscribe(DiagnosticArray, '/diagnostics'),
        'twin_status': f'{sim_base}: structure twin',
        'twin_params': ros.client(SetParameters, f'{sim_base}/set_parameters'),
    }
    out['trust'].wait_for(1, timeout=60.0)
    yield out
    ros.close()
    codes = twin.stop(), estimator.stop()
    assert codes == (0, 0), twin.log()[-3000:] + estimator.log()[-3000:]
    assert 'internal error' not in twin.log() + estimator.log(), estimator.log()[-3000:]


def tipping(rolling) -> None:
    """Wait for the twin's /diagnostics to report the gait tipping the 6-bar over."""
    rolling['diagnostics'].clear()
    rolling['diagnostics'].wait_until(
        lambda m: (twin_status(m, rolling['twin_status']) or {}).get('gait phase') == 'tip',
        timeout=90.0)


def onset(rolling, names: str) -> re.Match:
    """The twin's log line of its first publication with the faults ``names`` (the last such
    line: the faults' latest onset)."""
    pattern = ONSET.format(names=re.escape(names))

    def found():
        matches = list(re.finditer(pattern, rolling['twin'].log()))
        return matches[-1] if matches else None

    rolling['diagnostics'].clear()
    # Its /diagnostics names them after the publication (the log line is written before).
    rolling['diagnostics'].wait_until(
        lambda m: (twin_status(m, rolling['twin_status']) or {}).get('faults') == names,
        timeout=30.0)
    match = found()
    assert match, rolling['twin'].log()[-3000:]
    return match


#: The delays measured (fault -> named, s of the data's time), reported at the end.
DELAYS: dict[str, float] = {}


@pytest.mark.parametrize('parameter, value, name', [
    ('faults.broken_length', BROKEN, f'length[{BROKEN}]'),
    ('faults.flipped_imu', FLIPPED, f'imu[{FLIPPED}]'),
])
def test_a_fault_set_while_rolling_is_named_within_0_1_s(rolling, parameter, value, name):
    ros, trust = rolling['ros'], rolling['trust']
    try:
        # Set while the robot rolls (tips over, or settles on its new face): /diagnostics says
        # 'tip' once a second, so the fault can land later, after the roll: then again.
        for _ in range(MAX_TRIES):
            tipping(rolling)
            trust.clear()
            result = ros.set_parameter(rolling['twin_params'], parameter, value)
            assert result.successful, result.reason
            start = onset(rolling, name)
            if start['phase'] in MOVING:
                break
            assert ros.set_parameter(rolling['twin_params'], parameter, '').successful
            onset(rolling, 'none')
        assert start['phase'] in MOVING, start.group(0)  # the robot was rolling
        t0 = int(start['sec']) + 1e-9 * int(start['nanosec'])
        named = trust.wait_until(
            lambda m: stamp_s(m.header.stamp) >= t0 and name in trust_of(m)['outliers'],
            timeout=30.0)
        earlier = [m for m in list(trust.messages) if stamp_s(m.header.stamp) < t0]
        assert not any(name in trust_of(m)['outliers'] for m in earlier)  # not named before it
        after = [m for m in list(trust.messages) if stamp_s(m.header.stamp) >= t0]
        before = after[:after.index(named)]
        delay = stamp_s(named.header.stamp) - t0
        DELAYS[name] = delay
        print(f'{name}: named {1e3 * delay:.1f} ms after the first faulty reading (simulated '
              f'{float(start["time"]):.3f} s), {len(before)} estimates before it; outliers '
              f'{trust_of(named)["outliers"]}')
        assert delay <= BOUND_S, (delay, [trust_of(m)['outliers'] for m in before])
        # Named as the faulty sensor it is, with at most one other reading left out beside it
        # (a flipped IMU's gyro reads wrong too, and does not count): while the robot rolls a
        # sound IMU was left out with the flipped one in 1 of 6 runs (imu[y2] beside imu[z1]).
        others = [o for o in trust_of(named)['outliers'].split(', ')
                  if o not in (name, f'gyro[{value}]')]
        assert len(others) <= 1, trust_of(named)
    finally:
        ros.set_parameter(rolling['twin_params'], parameter, '')


def test_an_unknown_faulty_sensor_is_refused_by_name(rolling):
    ros = rolling['ros']
    for parameter, value, reason in (
            ('faults.broken_length', 'nope', "faults.broken_length: no string 'nope' (the "
             'strings: x1a-y2a, '),
            ('faults.flipped_imu', 'x1.a', "faults.flipped_imu: no IMU on 'x1.a' (the IMUs: "
             'x1, x2, y1, y2, z1, z2)')):
        result = ros.set_parameter(rolling['twin_params'], parameter, value)
        assert not result.successful and reason in result.reason, result.reason
    assert rolling['twin'].alive()
