#!/usr/bin/env bash
# Kept as a thin forwarder: the structure twin's live line is `run_twin.sh --structure`.
#   bash scripts/run_structure_twin.sh [--structure six_bar|three_bar|FILE.yaml] [--roll N]
#                                      [--estimate] [--duration S] [-- extra --ros-args arguments]
# is `bash scripts/run_twin.sh --structure six_bar ...` (six_bar when --structure is not given).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
case " $* " in
  *" --structure "*) exec bash "$REPO/scripts/run_twin.sh" "$@" ;;
  *) exec bash "$REPO/scripts/run_twin.sh" --structure six_bar "$@" ;;
esac
