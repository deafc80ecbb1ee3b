#!/usr/bin/env bash
# Side by side in one run: the same benchmarks in this checkout and in an earlier one, each in
# its own built environment, alternating (previous, this, previous, this), so that both meet
# the same machine. Numbers only; read them in the printed blocks.
#
#   bash bench/side_by_side.sh PREVIOUS_CHECKOUT [ROUNDS]
#
# PREVIOUS_CHECKOUT: a checkout set up with its own `bash scripts/setup_env.sh` (for example
# `git worktree add /tmp/previous <commit> && (cd /tmp/previous && bash scripts/setup_env.sh)`).
# What runs (each bench's own --help says more):
#   kernel `evaluate` and the batch       bench/bench_joint.py --quick
#   node latency, 1 kHz, 10 s              bench/bench_latency.py (fast lane, wait-set client)
#   estimator, library and node            bench/bench_estimator.py (1,000 estimates, 5 s node)
#   bag throughput                         bench/bench_bag.py (20,000 screws, mcap)
#   calibration time                       bench/bench_calibration.py (1,000 samples)
set -euo pipefail

THIS="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
PREVIOUS="$(cd "${1:?usage: bash bench/side_by_side.sh PREVIOUS_CHECKOUT [ROUNDS]}" && pwd)"
ROUNDS="${2:-1}"

BENCHES=(
  "bench_joint.py --quick"
  "bench_latency.py --rates 1000 --seconds 10 --paths fast --clients stiffness --client-loops lane --calls 0"
  "bench_estimator.py --repeats 1000 --seconds 5 --client-loops lane --triggers imu"
  "bench_bag.py --n 20000 --repeat 1"
  "bench_calibration.py --samples 1000 --repeats 1 --scipy-samples 0"
)

run_in() {
  local checkout="$1" bench="$2"
  # A subshell per run: each checkout's own venv, install/ and kernel.
  (
    cd "$checkout"
    unset TENSEGRITY_ENV_SOURCED PYTHONPATH AMENT_PREFIX_PATH CMAKE_PREFIX_PATH
    # shellcheck disable=SC1091
    source scripts/env.sh
    export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
    export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((100 + RANDOM % 101))}"
    # shellcheck disable=SC2086
    python bench/$bench 2>&1
  )
}

for ((round = 1; round <= ROUNDS; round++)); do
  for bench in "${BENCHES[@]}"; do
    for checkout in "$PREVIOUS" "$THIS"; do
      label="previous ($(git -C "$checkout" rev-parse --short HEAD))"
      [[ "$checkout" == "$THIS" ]] && label="this ($(git -C "$checkout" rev-parse --short HEAD))"
      echo "=== round $round: $label: $bench"
      run_in "$checkout" "$bench" || echo "(exit $?)"
    done
  done
done
