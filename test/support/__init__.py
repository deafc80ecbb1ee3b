"""What the tests share: the repository's paths, the ROS test harness (:mod:`.ros_harness`:
node processes, a client, inboxes that wait on conditions), input fuzzing (:mod:`.fuzz_inputs`),
the reference comparisons of joints (:mod:`.joint_compare`), estimation trials on the twin
(:mod:`.estimation_trials`), calibration recordings made by the twin
(:mod:`.calibration_recordings`), stand-in controllers run as processes
(:mod:`.controller_standins`), the bag command's recordings (:mod:`.bag_recordings`,
:mod:`.spine_bag_recordings`), seeded screws and the exact dT/dxi (:mod:`.screw_samples`), the
command line run in-process (:mod:`.cli_runs`), the kernels' live-array checks
(:mod:`.kernel_checks`) and the workspace check run inside a colcon
workspace (:mod:`.workspace_check`)."""

import os
import random
from pathlib import Path

#: The repository root.
REPO = Path(__file__).resolve().parents[2]
#: The packaged configs of the default joint and spine, in the source tree.
JOINT_CONFIG = REPO / 'config' / 'default_joint.yaml'
SPINE_CONFIG = REPO / 'config' / 'default_spine.yaml'


def use_own_ros_domain() -> int:
    """For a script run by hand (the benches): ROS discovery on this host only and a domain id
    of this run (random in 100-200, so that runs side by side do not see each other's nodes),
    set in the environment before any node or client starts. Returns the domain id."""
    domain = random.randint(100, 200)
    os.environ['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    os.environ['ROS_DOMAIN_ID'] = str(domain)
    return domain
