#!/usr/bin/env bash
# A calibration recording from the MuJoCo twin, for `tensegrity-stiffness calibrate` and `bag`:
# starts sim_node (a joint, publishing at 100 Hz with load-cell noise), records its topics with
# `tensegrity-stiffness record --node sim`, drives it through a seeded sequence of quasi-static
# holds (python -m tensegrity_stiffness.ros.calibration_holds: new rest lengths and a load each),
# then stops the recorder and the twin cleanly (SIGINT). docs/recorded_data.md.
#   bash scripts/record_calibration.sh OUTPUT [--namespace NS] [--config FILE.yaml]
#        [--holds N] [--hold S] [--seed N] [--rest-spread M] [--force N] [--moment NM]
#        [-- TWIN_ARGUMENTS...]
# TWIN_ARGUMENTS go to sim_node after its defaults, e.g. the "true" joint the calibration should
# find: -- -p 'joint.stiffness:=[80.0]' -p 'joint.rest_length_offsets:=[0.0005]'
# Environment: see scripts/env.sh (LOCALHOST discovery, ROS_DOMAIN_ID default 42 if unset).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [[ $# -lt 1 || "$1" == -* ]]; then
  sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//' >&2
  exit 2
fi
OUT="$1"
shift
NS=/calibration
CONFIG=""
HOLDS=()
TWIN=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --namespace) NS="$2"; shift 2 ;;
    --config) CONFIG="$2"; shift 2 ;;
    --) shift; TWIN=("$@"); break ;;
    *) HOLDS+=("$1"); shift ;;
  esac
done

# shellcheck disable=SC1091
source "$REPO/scripts/env.sh"
CONFIG="${CONFIG:-$(python -c 'from tensegrity_stiffness import config; print(config.packaged_config_path())')}"
EXE="$(python -c 'from ament_index_python.packages import get_package_prefix as p; print(p("tensegrity_stiffness"))')/lib/tensegrity_stiffness"
LOGS="$(mktemp -d -t record_calibration_XXXXXX)"

"$EXE/sim_node" --ros-args --params-file "$CONFIG" -r "__ns:=$NS" \
  -p sim.publish_every:=10 -p noise.tensions:=0.005 -p noise.lengths:=0.0001 \
  ${TWIN[@]+"${TWIN[@]}"} >"$LOGS/sim_node.log" 2>&1 &
SIM=$!
"$EXE/tensegrity-stiffness" record "$OUT" --node sim --namespace "$NS" >"$LOGS/record.log" 2>&1 &
REC=$!
stop() {
  kill -INT "$REC" 2>/dev/null || true
  wait "$REC" 2>/dev/null || true
  kill -INT "$SIM" 2>/dev/null || true
  wait "$SIM" 2>/dev/null || true
}
trap stop EXIT
echo "record_calibration: sim_node in $NS (ROS_DOMAIN_ID=$ROS_DOMAIN_ID), recording into $OUT; logs in $LOGS"
python -m tensegrity_stiffness.ros.calibration_holds --namespace "$NS" --config "$CONFIG" \
  --subscribers 2 ${HOLDS[@]+"${HOLDS[@]}"}
trap - EXIT
kill -INT "$REC"
wait "$REC" && code=0 || code=$?
cat "$LOGS/record.log"
kill -INT "$SIM"
wait "$SIM" || true
exit "$code"
