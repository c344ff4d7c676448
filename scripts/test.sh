#!/usr/bin/env bash
# Set up (idempotent) and run every test of the workspace: `scripts/test.sh [pytest args]`.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
"$ROOT/scripts/setup.sh"
set +u
source "$ROOT/scripts/env.sh"
set -u
# Keep DDS traffic on this machine and away from other runs: a random domain per run.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$((RANDOM % 90 + 1))}"
export MPLBACKEND=Agg
cd "$ROOT"
echo "[test] pytest (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
exec python -m pytest "$@"
