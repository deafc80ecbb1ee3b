#!/usr/bin/env bash
# Regenerate the figures docs/figures/*.png (shown in docs/figures.md) with the tensegrity-stiffness CLI (one command):
#   bash scripts/make_figures.sh [extra options of `tensegrity-stiffness figures`, e.g. --scale 1.5]
# Runs scripts/setup_env.sh (idempotent; installs the pinned matplotlib), sources scripts/env.sh,
# then `python -m tensegrity_stiffness.cli figures --out docs/figures`. The PNGs are deterministic
# for a given matplotlib version (pinned in scripts/constraints.txt).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"

bash scripts/setup_env.sh
# shellcheck disable=SC1091
source scripts/env.sh
python -m tensegrity_stiffness.cli figures --out docs/figures "$@"
