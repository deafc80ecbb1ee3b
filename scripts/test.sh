#!/usr/bin/env bash
# README command #2: set up (idempotent), lint, and run the test suite.
#   bash scripts/test.sh [extra pytest args]
# Runs scripts/setup_env.sh, sources scripts/env.sh, then `ruff check .` and
# `python -m pytest test -q` (always both). Exit code: pytest's (5 = no tests collected counts
# as a failure: CI must run tests); 1 if the tests pass but lint fails.
# ROS isolation: ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a ROS_DOMAIN_ID of this run: the
# caller's ROS_DOMAIN_ID if set, else a random free one in 100..200 (a domain counts as taken when
# a UDP port of its Fast DDS range 7400+250*id .. +249 is bound on this machine).
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

if [[ -z "${ROS_DOMAIN_ID:-}" ]]; then
  for _ in $(seq 1 50); do
    candidate=$((100 + RANDOM % 101))
    if ! domain_is_taken "$candidate"; then
      ROS_DOMAIN_ID="$candidate"
      break
    fi
  done
  ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((100 + RANDOM % 101))}"
fi
export ROS_DOMAIN_ID
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export TENSEGRITY_DISCOVERY_RANGE=LOCALHOST

# shellcheck disable=SC1091
source scripts/env.sh
echo "[test.sh] ROS_DOMAIN_ID=$ROS_DOMAIN_ID ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE" >&2

# Lint first, but run the tests even when lint fails (CI shows both); lint failure still fails.
echo "[test.sh] ruff check ." >&2
lint_rc=0
ruff check . --extend-exclude .venv,build,install,log || lint_rc=$?

echo "[test.sh] python -m pytest test -q $*" >&2
rc=0
python -m pytest test -q "$@" || rc=$?
if ((rc == 5)); then
  echo "[test.sh] pytest collected no tests: failing (CI must run tests)" >&2
fi
if ((rc == 0 && lint_rc != 0)); then
  echo "[test.sh] tests passed but ruff check failed (exit $lint_rc)" >&2
  rc=1
fi
exit "$rc"
