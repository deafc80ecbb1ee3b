"""What the tests share: the repository's paths, the ROS test harness (:mod:`.ros_harness`:
node processes, a client, inboxes that wait on conditions), input fuzzing (:mod:`.fuzz_inputs`),
the reference comparisons of joints (:mod:`.joint_compare`), estimation trials on the twin
(:mod:`.estimation_trials`), calibration recordings made by the twin
(:mod:`.calibration_recordings`), stand-in controllers run as processes
(:mod:`.controller_standins`), the bag command's recordings (:mod:`.bag_recordings`,
:mod:`.spine_bag_recordings`), seeded screws and the exact dT/dxi (:mod:`.screw_samples`) and
the workspace check run inside a colcon workspace (:mod:`.workspace_check`)."""

from pathlib import Path

#: The repository root.
REPO = Path(__file__).resolve().parents[2]
