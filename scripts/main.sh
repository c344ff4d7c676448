#!/usr/bin/env bash
# Set up (idempotent) and run the main job on the built-in simulator.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$ROOT/scripts/setup.sh"
set +u
source "$ROOT/scripts/env.sh"
set -u
export MPLBACKEND=Agg
# Until the simulator, controller and planner exist (issues 3, 4, 8) the main job is the model
# check: it verifies the model and prints what it computes for the thesis circle.
exec ros2 run irb_description model_check "$@"
