#!/usr/bin/env bash
# Regenerate the figures docs/figures/*.png (shown in docs/figures.md) with the tensegrity-stiffness CLI (one command):
#   bash scripts/make_figures.sh [extra options of `tensegrity-stiffness figures`, e.g. --scale 1.5]
# Runs scripts/setup_env.sh (idempotent; installs the pinned matplotlib and mujoco), sources
# scripts/env.sh, then `python -m tensegrity_stiffness.cli figures --out docs/figures` (the papers'
# figures and the joint's, about 2 s; the extra options go to it), the structure figures of
# docs/structures.md: `structure plot` of the 6-bar example (about 1 s) and
# scripts/six_bar_roll_figure.py (the MuJoCo twin rolled three faces by the gait: 23 s of
# simulated time, about 10 s). The PNGs are deterministic for a given matplotlib version (the
# roll's also depends on MuJoCo's; both pinned in scripts/constraints.txt).
set -euo pipefail

REPO="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$REPO"

bash scripts/setup_env.sh
# shellcheck disable=SC1091
source scripts/env.sh
python -m tensegrity_stiffness.cli figures --out docs/figures "$@"
python -m tensegrity_stiffness.cli structure plot --example six_bar.yaml \
  --out docs/figures/structure_six_bar.png --width 800 --height 600
python scripts/six_bar_roll_figure.py --out docs/figures/six_bar_roll.png
