#!/usr/bin/env bash
# README command #1: set up (idempotent) and run the stiffness node with the default joint.
#   bash scripts/run_node.sh [extra ROS args, e.g. -r __ns:=/joint1 -p publish_rate:=200.0]
# Equivalent of `ros2 run tensegrity_stiffness stiffness_node --ros-args --params-file
# config/default_joint.yaml` (the ros2 CLI is not on PyPI: the executable is run directly).
# Extra arguments are appended after the params file, inside the same --ros-args section.
# Environment: see scripts/env.sh (LOCALHOST discovery, ROS_DOMAIN_ID default 42 if unset).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"

bash scripts/setup_env.sh
# shellcheck disable=SC1091
source scripts/env.sh

PARAMS="${TENSEGRITY_PARAMS_FILE:-$REPO/config/default_joint.yaml}"
exec "$REPO/install/tensegrity_stiffness/lib/tensegrity_stiffness/stiffness_node" \
  --ros-args --params-file "$PARAMS" "$@"
