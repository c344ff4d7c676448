#!/usr/bin/env bash
# Set up (idempotent) and run the main job on the built-in simulator:
# model check, then the thesis pipeline (identification sweeps -> friction map -> energy-optimal
# and trapezoidal circles with compensation -> circle without -> report under runs/<id>/).
# Extra arguments go to thesis_run (e.g. --quick, --verbose).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$ROOT/scripts/setup.sh"
set +u
source "$ROOT/scripts/env.sh"
set -u
export MPLBACKEND=Agg
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
ros2 run irb_description model_check
exec ros2 run irb_bringup thesis_run "$@"
