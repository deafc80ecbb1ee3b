"""What a sensor set determines at a joint's equilibrium (``check-config --sensors``): the
readings a set would give there, exactly, with the stds of the config's ``estimator_node``
section (``sensors.*``, or the node's defaults), estimated by
:func:`~tensegrity_stiffness.estimation.estimators.estimate_joint_state` from the equilibrium:
whether the set determines the pose, what it leaves undetermined (the estimator's own words), its
redundancy (whether it can check itself) and the pose's std. Before a lab builds its sensors,
this says, for instance, that a ring joint's 12 load cells leave its spin about its axis open.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from tensegrity_stiffness.estimation.joint_estimator import estimate_joint_state
from tensegrity_stiffness.estimation.measurements import Measurements
from tensegrity_stiffness.geometry.screw import exp_se3
from tensegrity_stiffness.nodes.estimator_node import (
    ESTIMATOR_NODE_PARAMETERS,
    EstimatorNodeSettings,
    estimator_node_settings,
)
from tensegrity_stiffness.nodes.registry import values_from_config

#: The sensors a set may name: load cells, string lengths, an IMU on link 2 (the direction of
#: gravity), a motion-capture pose, a force-torque sensor (the load measured).
SENSORS = ('tensions', 'lengths', 'imu', 'pose', 'wrench')


def parse_sensor_set(text: str) -> tuple[str, ...]:
    """``'tensions,imu'`` -> ``('tensions', 'imu')``; ValueError names an unknown sensor."""
    names = tuple(dict.fromkeys(part.strip() for part in text.split(',') if part.strip()))
    unknown = [name for name in names if name not in SENSORS]
    if not names or unknown:
        raise ValueError(f'--sensors: unknown sensor {", ".join(unknown) or repr(text)} '
                         f'(known: {", ".join(SENSORS)}; a set is comma-separated, e.g. '
                         'tensions,imu)')
    return names


def estimator_settings(path: str | Path) -> EstimatorNodeSettings:
    """The settings ``estimator_node`` runs with for the config at ``path``."""
    return estimator_node_settings(values_from_config(path, ESTIMATOR_NODE_PARAMETERS))


def sensor_set_report(settings: EstimatorNodeSettings, screw: ArrayLike,
                      sensors: tuple[str, ...]) -> dict[str, Any]:
    """What ``sensors`` determine at ``screw`` (an equilibrium under no load) under the load
    mode of ``settings`` ('measured' when the set has 'wrench'): ``determined``, ``rank``,
    ``redundancy``, ``message`` (what is undetermined and what would fix it), the pose's
    largest position std (m) and angle std (rad)."""
    model = settings.model
    screw = np.asarray(screw, dtype=np.float64)
    state = model.evaluate(screw)
    kw: dict[str, Any] = {}
    if 'tensions' in sensors:
        kw.update(tensions=state.tensions, tension_std=settings.tension_std)
    if 'lengths' in sensors:
        kw.update(lengths=state.lengths, length_std=settings.length_std)
    if 'imu' in sensors:
        base = np.asarray(settings.gravity_base) / np.linalg.norm(settings.gravity_base)
        kw.update(gravity=state.transform[:3, :3].T @ base, gravity_std=settings.gravity_std,
                  gravity_base=base)
    if 'pose' in sensors:
        kw.update(pose=exp_se3(screw), pose_covariance=np.diag(
            [settings.pose_position_std ** 2] * 3 + [settings.pose_angle_std ** 2] * 3))
    load = 'measured' if 'wrench' in sensors else settings.load_mode
    if load != 'unknown':
        kw.update(external_wrench=np.zeros(6), wrench_covariance=np.diag(
            [settings.force_std ** 2] * 3 + [settings.moment_std ** 2] * 3))
    estimate = estimate_joint_state(model, Measurements(**kw), initial_screw=screw,
                                    stiffness_std=False)
    report: dict[str, Any] = {'sensors': list(sensors), 'load': load,
                              'determined': bool(estimate.success), 'rank': estimate.rank,
                              'redundancy': estimate.redundancy,
                              'message': estimate.message}
    if estimate.success:
        std = np.sqrt(np.maximum(np.diag(estimate.covariance), 0.0))
        report.update(position_std=float(std[:3].max()), angle_std=float(std[3:].max()))
    return report


def report_line(report: dict[str, Any]) -> str:
    """One line of the text output."""
    head = f"sensors {','.join(report['sensors'])} (load {report['load']}): "
    if not report['determined']:
        return head + f"determined: no: {report['message']}"
    checks = ('checks itself' if report['redundancy'] > 0
              else 'cannot check itself: add a sensor to get warnings')
    return (head + f"determined: yes, redundancy {report['redundancy']} ({checks}), pose std "
            f"{1e3 * report['position_std']:.3g} mm / "
            f"{math.degrees(report['angle_std']):.3g} deg")
