#!/usr/bin/env bash
# README command #2: set up (idempotent), lint, and run the test suite.
#   bash scripts/test.sh [extra pytest args]
# Runs scripts/setup_env.sh, sources scripts/env.sh, then `ruff check .` and the tests in two
# passes (always all three):
#   1. parallel: every test not marked `serial`, `python -m pytest test -n 3 --dist loadfile`
#      (pytest-xdist; a file's tests on one worker, so module fixtures start their nodes once;
#      each worker in its own ROS domain; the longest files first: test/conftest.py);
#   2. serial: the tests marked `serial` (they time something: deadlines, rates, latencies, a
#      control loop's ticks), one process, nothing beside them.
# The extra args go to both passes (`-m "not slow"`, `-k`, a file: each pass keeps its tier of
# them). TENSEGRITY_TEST_WORKERS=N sets the workers of pass 1 (0: no xdist, one process).
# OPENBLAS_NUM_THREADS and OMP_NUM_THREADS are 1 unless set (small matrices, many processes).
# TENSEGRITY_REQUIRE_ALL=1 is exported: a skip for a missing rclpy, MuJoCo, rosbags, kernel or
# build is a failure naming the reason (test/conftest.py); each pass prints its skip count.
# Exit code: the first failing pass's pytest exit code; 5 (no tests ran in either pass) counts as
# a failure: CI must run tests; 1 if the tests pass but lint fails.
# ROS isolation: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and ROS domains of this run: the
# caller's ROS_DOMAIN_ID if set, else a random free one in 100..200, and the next ones for the
# workers when free (TENSEGRITY_DOMAINS of them; a domain counts as taken when a UDP port of its
# Fast DDS range 7400+250*id .. +249 is bound on this machine).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"

bash scripts/setup_env.sh

domain_is_taken() {
  local id="$1" lo hi port f local_addr
  lo=$((7400 + 250 * id))
  hi=$((lo + 249))
  for f in /proc/net/udp /proc/net/udp6; do
    [[ -r "$f" ]] || continue
    while read -r _ local_addr _; do
      [[ "$local_addr" == *:* ]] || continue
      port=$((16#${local_addr##*:}))
      if ((port >= lo && port <= hi)); then
        return 0
      fi
    done < <(tail -n +2 "$f")
  done
  return 1
}

# Three workers on 2 cores: most tests wait on nodes (with two, a third of the CPU sat idle:
# 936 s of CPU in 689 s on two cores); docs/validation.md has the figures.
WORKERS="${TENSEGRITY_TEST_WORKERS:-3}"
if ! [[ "$WORKERS" =~ ^[0-9]+$ ]]; then
  echo "[test.sh] TENSEGRITY_TEST_WORKERS must be a number of workers, got '$WORKERS'" >&2
  exit 2
fi
domains_needed=$((WORKERS > 1 ? WORKERS : 1))

domains_are_free() {  # domains $1 .. $1+$2-1 all free
  local id
  for ((id = $1; id < $1 + $2; id++)); do
    if domain_is_taken "$id"; then
      return 1
    fi
  done
  return 0
}

if [[ -z "${ROS_DOMAIN_ID:-}" ]]; then
  for _ in $(seq 1 50); do
    candidate=$((100 + RANDOM % (102 - domains_needed)))
    if domains_are_free "$candidate" "$domains_needed"; then
      ROS_DOMAIN_ID="$candidate"
      break
    fi
  done
  ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((100 + RANDOM % (102 - domains_needed)))}"
  TENSEGRITY_DOMAINS="$domains_needed"
elif domains_are_free "$((ROS_DOMAIN_ID + 1))" "$((domains_needed - 1))"; then
  TENSEGRITY_DOMAINS="$domains_needed"
else
  TENSEGRITY_DOMAINS=1  # the workers share the caller's domain (each test its own namespace)
fi
export TENSEGRITY_DOMAINS
export ROS_DOMAIN_ID
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export TENSEGRITY_DISCOVERY_RANGE=LOCALHOST

# shellcheck disable=SC1091
source scripts/env.sh
echo "[test.sh] ROS_DOMAIN_ID=$ROS_DOMAIN_ID (TENSEGRITY_DOMAINS=$TENSEGRITY_DOMAINS) ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE" >&2

# Lint first, but run the tests even when lint fails (CI shows both); lint failure still fails.
echo "[test.sh] ruff check ." >&2
lint_rc=0
ruff check . --extend-exclude .venv,build,install,log || lint_rc=$?

export TENSEGRITY_REQUIRE_ALL=1
# One BLAS thread per process (unless the caller chose): three workers and their nodes on two
# cores, each with OpenBLAS's threads spinning on small matrices, ran 40-45 % slower (the
# dynamics, equilibrium and chain filter tests: 15-21 s against 8-13 s, same load).
export OPENBLAS_NUM_THREADS="${OPENBLAS_NUM_THREADS:-1}"
export OMP_NUM_THREADS="${OMP_NUM_THREADS:-1}"
parallel_args=()
if ((WORKERS > 0)); then
  parallel_args=(-n "$WORKERS" --dist loadfile --no-loadscope-reorder)
fi

run_pass() {  # run_pass TIER pytest-args...: pytest's exit code in pass_rc
  local tier="$1" start=$SECONDS
  shift
  echo "[test.sh] pass '$tier': TENSEGRITY_TIER=$tier python -m pytest test -q $*" >&2
  pass_rc=0
  TENSEGRITY_TIER="$tier" python -m pytest test -q "$@" || pass_rc=$?
  echo "[test.sh] pass '$tier': exit $pass_rc after $((SECONDS - start)) s" >&2
}

run_pass parallel "${parallel_args[@]}" "$@"
parallel_rc=$pass_rc
run_pass serial "$@"
serial_rc=$pass_rc

# 5 = no tests ran: a failure only when neither pass ran a test.
rc=0
if ((parallel_rc == 5 && serial_rc == 5)); then
  echo "[test.sh] pytest ran no tests in either pass: failing (CI must run tests)" >&2
  rc=5
elif ((parallel_rc != 0 && parallel_rc != 5)); then
  rc=$parallel_rc
elif ((serial_rc != 0 && serial_rc != 5)); then
  rc=$serial_rc
fi
if ((rc == 0 && lint_rc != 0)); then
  echo "[test.sh] tests passed but ruff check failed (exit $lint_rc)" >&2
  rc=1
fi
exit "$rc"
