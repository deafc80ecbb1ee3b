"""The control demo's live line without ROS (:class:`tensegrity_stiffness.ros.control_demo.
ControlMonitor` fills it from ``/diagnostics`` and the twin's pose): :func:`control_line` and the
pose error it shows beside the estimate's, :func:`pose_error`. No ROS import.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from tensegrity_stiffness.geometry.screw import log_se3


def pose_error(target: np.ndarray, pose: np.ndarray) -> tuple[float, float]:
    """(|p - p_target| m, rotation angle of R_target^T R rad) of two (4, 4) poses."""
    position = float(np.linalg.norm(pose[:3, 3] - target[:3, 3]))
    rotation = float(np.linalg.norm(log_se3(np.linalg.inv(target) @ pose)[:3]))
    return position, rotation


def diagnostic_number(value: str | None, spec: str = '.3g') -> str:
    """A diagnostic value formatted, '-' when absent or not a number."""
    try:
        return format(float(value), spec)
    except (TypeError, ValueError):
        return '-'


def control_line(head: str, controller: Mapping[str, str], message: str,
                 estimator: Mapping[str, str], true_error: tuple[float, float] | None) -> str:
    """One live line of the control demo: ``head`` (time and phase), then from the
    controller's ``/diagnostics`` values the pose error, the twin's own (``true_error``: m,
    rad; None unknown), the ``K_c`` error, the saturated strings, ``feasible`` with the
    controller's reason (its status ``message``) when a tick is infeasible, the tick time and
    rate, the missed ticks, the latency and the estimator's consistent share. ``head`` alone
    before the controller has a state."""
    v = controller
    if 'pose error [m, rad]' not in v:  # no state yet: nothing to show
        return head
    # [dx dy dz rx ry rz]: metres, then radians
    error = np.array(v['pose error [m, rad]'].strip('[]').replace(',', ' ').split(), float)
    rotation_deg = np.degrees(np.linalg.norm(error[3:]))
    kc_error = v.get('stiffness error', '-') if v.get('stiffness target') == 'set' else '-'
    true_text = '-' if true_error is None else \
        f'{1e3 * true_error[0]:.3f} mm {np.degrees(true_error[1]):.3f} deg'
    feasible = v.get('feasible', '-')
    why = f' ({message})' if feasible == 'false' and message else ''
    number = diagnostic_number
    return (f'{head}  pose error {1e3 * np.linalg.norm(error[:3]):.3f} mm '
            f'{rotation_deg:.3f} deg (true {true_text})  K_c error {kc_error}  '
            f'saturated {v.get("saturated strings", "-")}  feasible {feasible}{why}'
            f'  tick {number(v.get("tick time [ms]"))} ms  rate '
            f'{number(v.get("achieved tick rate [Hz]"), "4.0f")}/'
            f'{number(v.get("tick rate [Hz]"), ".0f")} Hz  missed '
            f'{v.get("missed ticks", "-")}  latency '
            f'{number(v.get("latency from the reading median [ms]"))}/'
            f'{number(v.get("latency from the reading p99 [ms]"))} ms  consistent '
            f'{number(estimator.get("consistent share"), ".1%")}')
