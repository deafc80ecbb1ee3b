#!/usr/bin/env bash
# Run the MuJoCo twin of a structure (structure_sim_node) with its live line every second:
# simulated time, centre of mass, contact nodes, slack strings, the gait's phase, real-time factor.
#   bash scripts/run_structure_twin.sh [--structure six_bar|three_bar|FILE.yaml] [--roll N]
#                                      [--duration S] [-- extra --ros-args arguments]
# --roll N runs the scripted roll over N faces (docs/structures.md); --duration stops the twin
# after S seconds (default: run until Ctrl-C). Sources scripts/env.sh (run setup_env.sh first).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
structure=six_bar
roll=0
duration=''
extra=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --structure) structure="$2"; shift 2 ;;
    --roll) roll="$2"; shift 2 ;;
    --duration) duration="$2"; shift 2 ;;
    --) shift; extra=("$@"); break ;;
    -h|--help) sed -n '2,7p' "${BASH_SOURCE[0]}" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "run_structure_twin.sh: unknown argument $1 (see --help)" >&2; exit 2 ;;
  esac
done
case "$structure" in
  *.yaml|*.yml) source_args=(-p "structure.file:=$(realpath "$structure")") ;;
  *) source_args=(-p "structure.example:=${structure}.yaml") ;;
esac
gait_args=()
if [[ "$roll" != 0 ]]; then
  gait_args=(-p gait.enabled:=true -p "gait.steps:=$roll")
fi
# shellcheck disable=SC1091
source "$REPO/scripts/env.sh"
exe="$REPO/install/tensegrity_stiffness/lib/tensegrity_stiffness/structure_sim_node"
cmd=("$exe" --live --ros-args "${source_args[@]}" "${gait_args[@]}" "${extra[@]}")
if [[ -n "$duration" ]]; then
  timeout -s INT "$duration" "${cmd[@]}" || [[ $? == 124 ]]
else
  exec "${cmd[@]}"
fi
