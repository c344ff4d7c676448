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
# readers, cores) on two workers, and beside them the end-to-end runs on simulated time
# (marker `lockstep_e2e`: lockstep, so the shared cores change their duration, not their
# result; each uses about one core); then the other ROS tests (marker `ros`: nodes,
# processes, the graph, timing) one at a time, so that nothing else competes with their
# control loops. All always run; the exit code is the worst of them.
e2e_log="$(mktemp -t irb_e2e.XXXXXX)"
e2e_tmp="$(mktemp -d -t irb_e2e_tmp.XXXXXX)"    # its own base for tmp_path: no shared numbering
echo "[test] 1/2 tests without ROS processes (-m 'not ros', 2 workers; ROS_DOMAIN_ID=$ROS_DOMAIN_ID) and, beside them, the lockstep end-to-end runs (-m lockstep_e2e; output below when both end)"
set +e
python -m pytest -m 'ros and lockstep_e2e' -p no:cacheprovider --basetemp "$e2e_tmp/t" \
    --durations=5 >"$e2e_log" 2>&1 &
e2e_pid=$!
python -m pytest -m 'not ros' -n 2 --durations=15
rc1=$?
wait "$e2e_pid"
rc3=$?
echo "[test] lockstep end-to-end runs (-m lockstep_e2e), run beside the above:"
cat "$e2e_log"
rm -rf "$e2e_log" "$e2e_tmp"
echo "[test] 2/2 ROS tests (-m 'ros and not lockstep_e2e', one at a time)"
python -m pytest -m 'ros and not lockstep_e2e' --durations=25
rc2=$?
set -e
echo "[test] tests without ROS processes: exit $rc1; lockstep end-to-end: exit $rc3; other ROS tests: exit $rc2"
rc=$(( rc1 > rc2 ? rc1 : rc2 ))
exit $(( rc > rc3 ? rc : rc3 ))
