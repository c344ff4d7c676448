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
if [ $# -gt 0 ]; then                 # a selection of your own: one pytest run as given
  echo "[test] pytest $* (ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
  exec python -m pytest "$@"
fi
# Every test, in two runs: the tests without ROS nodes or processes (numerics, planner,
# readers, cores) on two workers; then the ROS tests (marker `ros`: nodes, processes, the
# graph, timing) one at a time, so that nothing else competes with their control loops.
# Both always run; the exit code is the worse of the two.
echo "[test] 1/2 tests without ROS processes (-m 'not ros', 2 workers; ROS_DOMAIN_ID=$ROS_DOMAIN_ID)"
set +e
python -m pytest -m 'not ros' -n 2 --durations=15
rc1=$?
echo "[test] 2/2 ROS tests (-m ros, one at a time)"
python -m pytest -m ros --durations=25
rc2=$?
set -e
echo "[test] tests without ROS processes: exit $rc1; ROS tests: exit $rc2"
exit $(( rc1 > rc2 ? rc1 : rc2 ))
