#!/usr/bin/env bash
# The whole loop without hardware: set up (idempotent), then start the MuJoCo twin (sim_node,
# slowly swinging a load) and the stiffness node wired together, and print a live one-line
# summary once a second (input rate, pose, smallest and largest eigenvalue of K_c, slack
# strings, latency). Ctrl-C stops both nodes cleanly.
#   bash scripts/run_twin.sh [--spine | --control] [--duration SECONDS] [--swing N] [--swing-period S]
#                            [--rate HZ] [--publish-every N] [--config FILE.yaml] [-- ROS ARGS]
# A structure's twin (structure_sim_node) with its live line (time, centre of mass, contact nodes,
# slack strings, the gait's phase, real-time factor) and, with --estimate, structure_estimator_node
# on its sensors and the estimate's error against the twin's truth:
#   bash scripts/run_twin.sh --structure six_bar|three_bar|FILE.yaml [--roll N] [--estimate]
#                            [--method filter|static] [--markers] [--duration S] [-- ROS ARGS]
# Arguments after -- go to every node: run_twin.sh --control --config FILE -- -p limits.tension_max:=3
# Environment: see scripts/env.sh (LOCALHOST discovery, ROS_DOMAIN_ID default 42 if unset).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# Run from any folder: relative paths (--config FILE) are the caller's.
bash "$REPO/scripts/setup_env.sh"
# shellcheck disable=SC1091
source "$REPO/scripts/env.sh"

demo=twin_demo
for arg in "$@"; do
  if [[ "$arg" == -- ]]; then break; fi
  if [[ "$arg" == --structure ]]; then demo=structure_twin_demo; fi
done
exec "$REPO/install/tensegrity_stiffness/lib/tensegrity_stiffness/$demo" "$@"
