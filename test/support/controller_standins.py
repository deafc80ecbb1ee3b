#!/usr/bin/env python3
"""Stand-ins for the controllers ``stiffness_bridge`` feeds: real rclpy nodes, each run as its own
process by the tests (``python test/support/controller_standins.py KIND --ros-args -r __ns:=/x``),
that
declare the controller's stiffness parameters with the same names, types, defaults and ranges and
refuse what the controller would refuse, with the controller's own reason text. Each publishes
every stiffness it accepted on ``~/accepted_stiffness`` (36 values, row-major, diagonal for
diagonal forms) so that a test can count and time the updates, and prints ``READY`` and the wall
time (s) once its node and its parameter services exist. ``--slow S`` (after KIND): every
parameter set takes S seconds (a controller that answers late).

Where each definition comes from (read with the ``fetch`` tool on 2026-12-01):

* ``cartesian_controllers``: fzi-forschungszentrum-informatik/cartesian_controllers, branch
  ``ros2``, commit f53f798029ea5e05993e8a5d1736c713379af0e2 (2024-10-20),
  ``cartesian_compliance_controller/src/cartesian_compliance_controller.cpp``, ``on_init()``:
  ``auto_declare<std::string>("compliance_ref_link", "")`` and ``auto_declare<double>(
  "stiffness.trans_x" ... "stiffness.rot_z")`` with defaults 500 (trans) and 50 (rot), no
  descriptor: no range, any double is taken (a negative one too); rclcpp parameters are statically
  typed, so a value of another type is refused. ``computeComplianceError()`` re-reads the six each
  cycle and uses them as a diagonal in ``compliance_ref_link``'s orientation.
* ``admittance``: ros-controls/ros2_controllers commit 94e74de35f9d04f313aca8f29df66c3a76004aa7
  (admittance_controller 6.9.0),
  ``admittance_controller/src/admittance_controller_parameters.yaml`` (generate_parameter_library):
  ``admittance.stiffness`` double_array, ``fixed_size<>: 6``,
  ``element_bounds<>: [0.0, 100000000.0]``; ``admittance.mass`` element_bounds [0.0001, 1e6];
  ``control.frame.id`` string. Reason texts of the validators: PickNikRobotics/RSL 1.3.0 (commit
  b127ab1), ``include/rsl/parameter_validators.hpp`` (``fixed_size``, ``element_bounds``,
  ``bounds``).
* ``crisp_parameters``: utiasDSL/crisp_controllers commit
  809354897a2997530f10aa2516801180aee43dee (0.1.0, 2025-08-19),
  ``src/cartesian_impedance_controller.yaml``: ``task.k_pos_x|y|z`` (default 500) and
  ``task.k_rot_x|y|z`` (default 30), double, ``bounds<>: [0.0, 5000.0]``.
* ``crisp_topic``: a ``target_stiffness`` subscription (``std_msgs/Float64MultiArray``: 6 values,
  the diagonal, or 36 row-major, refused when ``|K - K^T| > 1e-6``). This form is the one issue 22
  describes; it is NOT in the public crisp_controllers at the commit above nor in the
  zordicom/crisp_controllers fork (2ee07cf, 2025-11-05), where the stiffness is only the
  ``task.k_*`` parameters.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import rclpy
from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray

#: What the stand-in prints, then the wall time (``time.time()``, s), once its node and its
#: parameter services exist (before it spins).
READY = 'stand-in ready at'

#: Node names of the controllers (what their controller_manager entries usually are).
NODE_NAMES = {
    'cartesian_controllers': 'cartesian_compliance_controller',
    'admittance': 'admittance_controller',
    'crisp_parameters': 'cartesian_impedance_controller',
    'crisp_topic': 'cartesian_impedance_controller',
}

CARTESIAN_CONTROLLERS_NAMES = ('stiffness.trans_x', 'stiffness.trans_y', 'stiffness.trans_z',
                               'stiffness.rot_x', 'stiffness.rot_y', 'stiffness.rot_z')
CRISP_NAMES = ('task.k_pos_x', 'task.k_pos_y', 'task.k_pos_z',
               'task.k_rot_x', 'task.k_rot_y', 'task.k_rot_z')
#: Validation ranges (inclusive) of the definitions above.
ADMITTANCE_STIFFNESS_BOUNDS = (0.0, 100000000.0)
ADMITTANCE_MASS_BOUNDS = (0.0001, 1000000.0)
CRISP_BOUNDS = (0.0, 5000.0)
#: crisp's symmetry tolerance of a 36-value target_stiffness (issue 22).
CRISP_SYMMETRY_TOLERANCE = 1e-6


def _number(value: float) -> str:
    """A number as fmt prints a double in RSL's messages (shortest round-trip form)."""
    v = float(value)
    return str(int(v)) if v.is_integer() and abs(v) < 1e16 else repr(v)


def element_bounds(name: str, values: list[float], lower: float, upper: float) -> str:
    """RSL ``element_bounds``: '' when valid, else its reason text."""
    for v in values:
        if v < lower or v > upper:
            return (f"Value '{_number(v)}' in parameter '{name}' must be within bounds "
                    f"'[{_number(lower)}, {_number(upper)}]'")
    return ''


def fixed_size(name: str, values: list[float], size: int) -> str:
    """RSL ``fixed_size``: '' when valid, else its reason text."""
    if len(values) != size:
        return f"Length of parameter '{name}' is '{len(values)}' but must be equal to '{size}'"
    return ''


def bounds(name: str, value: float, lower: float, upper: float) -> str:
    """RSL ``bounds``: '' when valid, else its reason text."""
    if value < lower or value > upper:
        return (f"Parameter '{name}' with the value '{_number(value)}' must be within bounds "
                f"'[{_number(lower)}, {_number(upper)}]'")
    return ''


class ControllerStandIn(Node):
    """Declares ``declarations`` (name -> typed default) and validates every set with
    ``validators`` (name -> value -> reason, '' when valid); publishes the stiffness it holds
    after each accepted set that touched ``stiffness_names``."""

    #: Seconds each set takes (``--slow S``: a controller that answers late).
    answer_delay = 0.0

    def __init__(self, name: str, declarations: dict[str, Any],
                 validators: dict[str, Callable[[Any], str]],
                 stiffness_names: tuple[str, ...]) -> None:
        super().__init__(name)
        for pname, default in declarations.items():
            self.declare_parameter(pname, default)
        self._validators = validators
        self._stiffness_names = stiffness_names
        self._accepted = self.create_publisher(Float64MultiArray, '~/accepted_stiffness', 100)
        self.add_on_set_parameters_callback(self._validate)
        self.add_post_set_parameters_callback(self._applied)

    def _validate(self, parameters: list[Parameter]) -> SetParametersResult:
        if self.answer_delay:
            time.sleep(self.answer_delay)
        for p in parameters:
            check = self._validators.get(p.name)
            reason = check(p.value) if check is not None else ''
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _applied(self, parameters: list[Parameter]) -> None:
        if not any(p.name in self._stiffness_names for p in parameters):
            return
        values = [self.get_parameter(n).value for n in self._stiffness_names]
        diag = np.asarray(values[0] if len(values) == 1 else values, dtype=np.float64)
        self._accepted.publish(Float64MultiArray(data=np.diag(diag).ravel().tolist()))


class CrispTopicStandIn(Node):
    """Subscribes ``~/target_stiffness`` (6 or 36 row-major values; refuses an asymmetric 36,
    another count, a non-finite value) and publishes what it accepted on
    ``~/accepted_stiffness`` (36 values row-major); ``~/refused_count`` counts refusals."""

    def __init__(self) -> None:
        super().__init__(NODE_NAMES['crisp_topic'])
        self._accepted = self.create_publisher(Float64MultiArray, '~/accepted_stiffness', 100)
        self._refused = self.create_publisher(Float64MultiArray, '~/refused_count', 10)
        self._refusals = 0
        self.create_subscription(Float64MultiArray, '~/target_stiffness', self._on_target, 100)

    def _refuse(self, why: str) -> None:
        self._refusals += 1
        self.get_logger().warning(f'target_stiffness refused: {why}')
        self._refused.publish(Float64MultiArray(data=[float(self._refusals)]))

    def _on_target(self, msg: Float64MultiArray) -> None:
        values = np.asarray(msg.data, dtype=np.float64)
        if not np.all(np.isfinite(values)):
            return self._refuse('not finite')
        if values.size == 6:
            K = np.diag(values)
        elif values.size == 36:
            K = values.reshape(6, 6)
            asymmetry = float(np.abs(K - K.T).max())
            if asymmetry > CRISP_SYMMETRY_TOLERANCE:
                return self._refuse(f'|K - K^T| = {asymmetry:g} > {CRISP_SYMMETRY_TOLERANCE:g}')
        else:
            return self._refuse(f'{values.size} values (6 or 36 expected)')
        self._accepted.publish(Float64MultiArray(data=K.ravel().tolist()))
        return None


def make_node(kind: str) -> Node:
    if kind == 'cartesian_controllers':
        declarations = {'compliance_ref_link': ''}
        declarations.update({n: 500.0 if 'trans' in n else 50.0
                             for n in CARTESIAN_CONTROLLERS_NAMES})
        # no range: rclcpp's static typing (enforced by rclpy's declare_parameter too) is all
        return ControllerStandIn(NODE_NAMES[kind], declarations, {},
                                 CARTESIAN_CONTROLLERS_NAMES)
    if kind == 'admittance':
        name = 'admittance.stiffness'
        declarations = {
            name: [214.1, 214.2, 214.3, 214.4, 214.5, 214.6],
            'admittance.mass': [3.0, 3.0, 3.0, 0.05, 0.05, 0.05],
            'admittance.damping_ratio': [2.828427] * 6,
            'admittance.selected_axes': [True] * 6,
            'control.frame.id': 'tool0',
        }
        validators = {
            name: lambda v: fixed_size(name, list(v), 6) or element_bounds(
                name, list(v), *ADMITTANCE_STIFFNESS_BOUNDS),
            'admittance.mass': lambda v: fixed_size('admittance.mass', list(v), 6)
            or element_bounds('admittance.mass', list(v), *ADMITTANCE_MASS_BOUNDS),
        }
        return ControllerStandIn(NODE_NAMES[kind], declarations, validators, (name,))
    if kind == 'crisp_parameters':
        declarations = {n: 500.0 if 'pos' in n else 30.0 for n in CRISP_NAMES}
        validators = {n: (lambda v, n=n: bounds(n, v, *CRISP_BOUNDS)) for n in CRISP_NAMES}
        return ControllerStandIn(NODE_NAMES[kind], declarations, validators, CRISP_NAMES)
    if kind == 'crisp_topic':
        return CrispTopicStandIn()
    raise SystemExit(f'unknown controller kind {kind!r}; one of {sorted(NODE_NAMES)}')


def main(argv: list[str] | None = None) -> None:
    argv = list(sys.argv if argv is None else argv)
    if len(argv) < 2 or argv[1].startswith('-'):
        raise SystemExit(f'usage: {argv[0]} KIND [--slow S] [--ros-args ...]; KIND: '
                         f'{sorted(NODE_NAMES)}')
    kind = argv.pop(1)
    if len(argv) > 2 and argv[1] == '--slow':
        ControllerStandIn.answer_delay = float(argv[2])
        del argv[1:3]
    rclpy.init(args=argv)
    node = make_node(kind)
    print(f'{READY} {time.time():.6f}', flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, rclpy.executors.ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    main()
