# Source this file (bash): `source scripts/env.sh` after scripts/setup.sh.
# Gives the venv, the ROS 2 underlay (/opt/ros/jazzy or the wheels) and ros2_ws/install.
_irb_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
if [ "$(cat "$_irb_root/.venv/.irb-mode" 2>/dev/null)" = system ]; then
  [ "${ROS_DISTRO:-}" = jazzy ] || source /opt/ros/jazzy/setup.bash
fi
source "$_irb_root/.venv/bin/activate"
if [ "$(cat "$_irb_root/.venv/.irb-mode" 2>/dev/null)" = wheels ]; then
  case ":${AMENT_PREFIX_PATH:-}:" in
    *":$_irb_root/.venv:"*) ;;
    *) export AMENT_PREFIX_PATH="$_irb_root/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
  esac
fi
source "$_irb_root/ros2_ws/install/setup.bash"
export IRB_ROOT="$_irb_root"
unset _irb_root
