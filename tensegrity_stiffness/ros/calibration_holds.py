"""A scripted sequence of holds for a calibration recording from the twin
(``scripts/record_calibration.sh``; docs/recorded_data.md, "A calibration recording from the
twin"): drives a running ``sim_node`` of a joint through ``--holds`` quasi-static holds while
``tensegrity-stiffness record`` records it.

Each hold commands new rest lengths (the config's within +-``--rest-spread``, uniform) on the
twin's ``~/rest_lengths`` (latched, once per hold) and a load on its ``~/external_wrench``
(normal: ``--force`` N and ``--moment`` N m per component; on link 2 in {1}, re-published every
:data:`WRENCH_PERIOD_S` during the hold, as a force-torque sensor streams), then keeps both for
``--hold`` seconds, longer than the quasi-static window of ``calibrate`` (0.5 s). A hold whose
equilibrium under the config's model (at the commanded rest lengths plus the config's
``joint.rest_length_offsets``) is not found, not stable or has a string at its maximum length is
drawn again, as a lab avoids such states. Seeded (``--seed``): the same sequence every run.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import rclpy
from geometry_msgs.msg import WrenchStamped
from std_msgs.msg import Float64MultiArray

from tensegrity_stiffness import config
from tensegrity_stiffness.mechanics.equilibrium import solve_equilibrium
from tensegrity_stiffness.mechanics.joint import JointModel
from tensegrity_stiffness.nodes.registry import values_from_config
from tensegrity_stiffness.nodes.shared_parameters import rest_length_offsets
from tensegrity_stiffness.nodes.stiffness_node import STIFFNESS_NODE_PARAMETERS
from tensegrity_stiffness.ros import conversions
from tensegrity_stiffness.ros.runtime.topics import LATCHED_QOS, input_qos

#: Seconds between re-publications of a hold's load.
WRENCH_PERIOD_S = 0.05
#: Defaults: holds, seconds per hold, rest-length spread (m), load std (N, N m).
DEFAULT_HOLDS = 30
DEFAULT_HOLD_S = 1.0
DEFAULT_REST_SPREAD = 2e-3
DEFAULT_FORCE = 0.3
DEFAULT_MOMENT = 0.005
#: Attempts at drawing one admissible hold.
MAX_DRAWS = 1000


def draw_holds(model: JointModel, offsets: np.ndarray, count: int, seed: int,
               rest_spread: float, force: float, moment: float
               ) -> list[tuple[np.ndarray, np.ndarray]]:
    """``count`` (commanded rest lengths (n,), load (6,)) whose equilibrium under ``model`` (at
    the commands plus ``offsets``) is found, stable and below every maximum length."""
    rng = np.random.default_rng(seed)
    holds: list[tuple[np.ndarray, np.ndarray]] = []
    previous = model.initial_screw
    for _ in range(MAX_DRAWS):
        if len(holds) == count:
            return holds
        command = model.rest_lengths + rng.uniform(-rest_spread, rest_spread, model.n_strings)
        load = np.concatenate([rng.normal(0.0, force, 3), rng.normal(0.0, moment, 3)])
        try:
            eq = solve_equilibrium(model, load, command + offsets, initial_screw=previous)
        except ValueError:  # rest lengths the model refuses
            continue
        if eq.success and eq.stable and eq.state is not None and not eq.state.saturated.any():
            holds.append((command, load))
            previous = eq.screw
    raise ValueError(f'no {count} admissible holds in {MAX_DRAWS} draws: smaller '
                     '--rest-spread, --force or --moment')


def parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(
        prog='python -m tensegrity_stiffness.ros.calibration_holds',
        description="Drive a running sim_node (a joint) through a seeded sequence of "
                    'quasi-static holds (rest lengths and a load each) for a calibration '
                    'recording; scripts/record_calibration.sh records them.')
    p.add_argument('--namespace', default='/calibration', help="the twin's namespace")
    p.add_argument('--config', type=Path, default=None,
                   help="the twin's parameter file (default: the packaged default_joint.yaml)")
    p.add_argument('--holds', type=int, default=DEFAULT_HOLDS, help='number of holds')
    p.add_argument('--hold', type=float, default=DEFAULT_HOLD_S, metavar='S',
                   help=f'seconds per hold (default {DEFAULT_HOLD_S:g}; calibrate needs > 0.5)')
    p.add_argument('--seed', type=int, default=0)
    p.add_argument('--rest-spread', type=float, default=DEFAULT_REST_SPREAD, metavar='M',
                   help=f'rest lengths within +-M of the config (default {DEFAULT_REST_SPREAD})')
    p.add_argument('--force', type=float, default=DEFAULT_FORCE, metavar='N',
                   help=f'load force std per component (default {DEFAULT_FORCE})')
    p.add_argument('--moment', type=float, default=DEFAULT_MOMENT, metavar='NM',
                   help=f'load moment std per component (default {DEFAULT_MOMENT})')
    p.add_argument('--subscribers', type=int, default=1, metavar='K',
                   help='start once ~/rest_lengths has K subscribers (the twin, and the '
                        'recorder: 2)')
    p.add_argument('--wait', type=float, default=30.0, metavar='S',
                   help='give up when they are not there within S seconds')
    return p


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    if args.holds < 1 or not args.hold > 0.0:
        print('calibration_holds: --holds must be >= 1 and --hold > 0', file=sys.stderr)
        return 2
    path = args.config or config.packaged_config_path()
    values = values_from_config(path, STIFFNESS_NODE_PARAMETERS)
    model = JointModel.from_yaml(path)
    try:
        holds = draw_holds(model, rest_length_offsets(values, model.n_strings), args.holds,
                           args.seed, args.rest_spread, args.force, args.moment)
    except ValueError as exc:
        print(f'calibration_holds: {exc}', file=sys.stderr)
        return 2
    rclpy.init(args=None)
    node = rclpy.create_node('calibration_holds', start_parameter_services=False)
    base = f'{args.namespace.rstrip("/")}/sim_node'
    rest_pub = node.create_publisher(Float64MultiArray, f'{base}/rest_lengths', LATCHED_QOS)
    wrench_pub = node.create_publisher(WrenchStamped, f'{base}/external_wrench',
                                       input_qos(10, 'reliable'))
    try:
        deadline = time.monotonic() + args.wait
        while (rest_pub.get_subscription_count() < args.subscribers
               or wrench_pub.get_subscription_count() < 1):
            if time.monotonic() > deadline:
                print(f'calibration_holds: {base} (and the recorder) not subscribed within '
                      f'{args.wait:g} s', file=sys.stderr)
                return 2
            time.sleep(0.05)
        for i, (command, load) in enumerate(holds):
            rest_pub.publish(conversions.vector_to_multiarray(command, 'rest lengths [m]'))
            wrench = WrenchStamped(wrench=conversions.wrench_to_msg(load))
            wrench.header.frame_id = values['frames.link1']
            end = time.monotonic() + args.hold
            while (now := time.monotonic()) < end:
                wrench.header.stamp = node.get_clock().now().to_msg()
                wrench_pub.publish(wrench)
                time.sleep(min(WRENCH_PERIOD_S, end - now))
            print(f'hold {i + 1}/{len(holds)}: rest lengths within '
                  f'{np.abs(command - model.rest_lengths).max() * 1e3:.2f} mm of the config, '
                  f'load |f| {np.linalg.norm(load[:3]):.3f} N |m| '
                  f'{np.linalg.norm(load[3:]):.4f} N m', flush=True)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == '__main__':
    sys.exit(main())
