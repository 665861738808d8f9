#!/usr/bin/env bash
# Issue "safety" acceptance sweep: the default filter (dcbf) over 100 seeds of cube8 and of
# every scenario family, in process, ground truth. Results: docs/safety.md ("100-seed
# acceptance sweep"). Usage: bench/safety_acceptance.sh [SEEDS] [JOBS] [OUT]
# (defaults 1-100, 2, runs/safety-acceptance). About 45 min on the 2-core machine.
set -euo pipefail
cd "$(dirname "$0")/.."
SEEDS=${1:-1-100}
JOBS=${2:-2}
OUT=${3:-runs/safety-acceptance}
# airborne families: 15 s (the crossings end by ~13 s; formation is reported by the
# 25 s, 10-seed sweep in docs/safety.md)
.venv/bin/gcs mission sweep scenarios/cube8.toml scenarios/swap_centre.toml \
  scenarios/grid12.toml scenarios/cube8_dist5.toml scenarios/cube8_noise5.toml \
  --seeds "$SEEDS" --methods dcbf --jobs "$JOBS" --duration 15 --out "$OUT/airborne" \
  --allow-unsafe  # cube8_noise5 is outside the noise bound on purpose (docs/safety.md)
# ground start, take-off, formation, mission, land-all at 22 s: the scenario's 36 s
.venv/bin/gcs mission sweep scenarios/ground8.toml \
  --seeds "$SEEDS" --methods dcbf --jobs "$JOBS" --out "$OUT/ground"
