#!/usr/bin/env python3
"""How soon a node that runs first finds a controller that starts after it, side by side: the
package's Fast DDS participant profile (``ros/runtime/middleware.py``) against Fast DDS's
defaults (issue 37, item 7: a bridge streaming K_c found its controller only at the next 3 s
participant announcement). Run by hand after ``source scripts/env.sh``:

    python bench/bench_discovery.py [--runs 8]

Each run starts two clients of the controller's ``set_parameters`` service (each a process: one
with the package's profile, one without), then the controller stand-in
(``test/support/controller_standins.py``, Fast DDS defaults), and prints for both how long after
the controller's launch ``service_is_ready()`` became true (that includes the stand-in's own
start-up, some 0.3-0.5 s here). Numbers only; ``uptime`` first. The time to the bridge's first
answered call, with each side's discovery and the calls lost, before and after
``target.first_contact_timeout``: ``bench/bench_bridge_first_update.py``.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
STANDINS = ROOT / 'test' / 'support' / 'controller_standins.py'
SERVICE = 'cartesian_compliance_controller/set_parameters'
PROFILE_VARIABLES = ('FASTRTPS_DEFAULT_PROFILES_FILE', 'RMW_FASTRTPS_USE_QOS_FROM_XML')


def client(namespace: str, go: str, profile: bool) -> None:
    """One client: wait for ``go`` (the controller's launch time), then for the service."""
    if profile:
        sys.path.insert(0, str(ROOT))
        from tensegrity_stiffness.ros.runtime.middleware import bound_input_memory

        bound_input_memory()
    import rclpy
    from rcl_interfaces.srv import SetParameters

    rclpy.init()
    node = rclpy.create_node(f'discovery_{"profile" if profile else "default"}')
    service = node.create_client(SetParameters, f'{namespace}/{SERVICE}')
    print('up', flush=True)
    while not Path(go).exists() or not Path(go).read_text():
        time.sleep(0.005)
    launched = float(Path(go).read_text())
    while time.time() - launched < 15.0 and not service.service_is_ready():
        time.sleep(0.003)
    print(f'{time.time() - launched:.3f}', flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


def run_once() -> tuple[str, str]:
    namespace = f'/discovery_{uuid.uuid4().hex[:8]}'
    go = Path(tempfile.gettempdir()) / f'{namespace[1:]}.go'
    plain = {k: v for k, v in os.environ.items() if k not in PROFILE_VARIABLES}
    clients = [subprocess.Popen([sys.executable, __file__, '--client', namespace, str(go), kind],
                                stdout=subprocess.PIPE, text=True, env=plain)
               for kind in ('profile', 'default')]
    for c in clients:
        assert c.stdout.readline().strip() == 'up'
    time.sleep(1.0)
    controller = subprocess.Popen([sys.executable, str(STANDINS), 'cartesian_controllers',
                                   '--ros-args', '-r', f'__ns:={namespace}'],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, env=plain)
    go.write_text(str(time.time()))
    found = tuple(c.stdout.readline().strip() for c in clients)
    for c in clients:
        c.wait(20)
    controller.send_signal(2)
    controller.wait(20)
    go.unlink(missing_ok=True)
    return found


def main() -> None:
    if len(sys.argv) > 1 and sys.argv[1] == '--client':
        client(sys.argv[2], sys.argv[3], sys.argv[4] == 'profile')
        return
    parser = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    parser.add_argument('--runs', type=int, default=8)
    args = parser.parse_args()
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    print(subprocess.run(['uptime'], capture_output=True, text=True, check=False).stdout.strip())
    print('run  package profile [s]  Fast DDS defaults [s]  (service ready after the '
          "controller's launch)")
    for k in range(args.runs):
        profile, default = run_once()
        print(f'{k + 1:3d}  {profile:>19}  {default:>21}', flush=True)


if __name__ == '__main__':
    main()
