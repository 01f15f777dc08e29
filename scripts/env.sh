# shellcheck shell=bash
# Source me (do not execute):   source scripts/env.sh
# Activates the project's environment built by scripts/setup.sh: the system ROS 2 Jazzy (if that
# is what setup.sh used) or the venv's ROS wheels, the venv, and the colcon install/ overlay.
# Sets ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and a per-checkout ROS_DOMAIN_ID unless already set,
# and puts the package's programs (install/gripper_ros/lib/gripper_ros: grasp_demo, bag_info ...)
# on the PATH, as the docs' transcripts run them.
if [ -z "${BASH_VERSION:-}" ]; then echo "scripts/env.sh needs bash" >&2; return 1 2>/dev/null || exit 1; fi
_gr_root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
_gr_venv="${GRIPPER_ROS_VENV:-$_gr_root/.venv}"
# colcon's and ROS's setup files reference unset variables: never run them under `set -u`
case $- in *u*) _gr_nounset=1; set +u;; *) _gr_nounset=0;; esac

_gr_mode="$(cat "$_gr_venv/.gripper_ros_mode" 2>/dev/null || echo missing)"
if [ "$_gr_mode" = missing ] || [ ! -f "$_gr_root/install/setup.bash" ]; then
  echo "[env] not set up yet: run  bash scripts/setup.sh  first" >&2
  [ "$_gr_nounset" = 1 ] && set -u
  unset _gr_root _gr_venv _gr_mode _gr_nounset
  return 1 2>/dev/null || exit 1
fi

if [ "$_gr_mode" = system ] && [ "${ROS_DISTRO:-}" != jazzy ]; then
  # shellcheck disable=SC1091
  source /opt/ros/jazzy/setup.bash
fi
# shellcheck disable=SC1091
source "$_gr_venv/bin/activate"
if [ "$_gr_mode" = wheels ]; then
  case ":${AMENT_PREFIX_PATH:-}:" in *":$_gr_venv:"*) ;; *) export AMENT_PREFIX_PATH="$_gr_venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}";; esac
  case ":${CMAKE_PREFIX_PATH:-}:" in *":$_gr_venv:"*) ;; *) export CMAKE_PREFIX_PATH="$_gr_venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}";; esac
fi
# shellcheck disable=SC1091
source "$_gr_root/install/setup.bash"
# the ROS 2 command line of `setup.sh --ros2-cli` (ros2, ros2 launch, control_msgs), if built
if [ "$_gr_mode" = wheels ] && [ -f "$_gr_venv/ros2_cli/install/local_setup.bash" ]; then
  # shellcheck disable=SC1091
  source "$_gr_venv/ros2_cli/install/local_setup.bash"
fi

case ":$PATH:" in *":$_gr_root/install/gripper_ros/lib/gripper_ros:"*) ;;
  *) export PATH="$_gr_root/install/gripper_ros/lib/gripper_ros:$PATH";; esac
# the compiled core's cache: a link that setup.sh swaps to a whole new folder after a change
export NUMBA_CACHE_DIR="$_gr_root/install/numba_cache"
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
if [ -z "${ROS_DOMAIN_ID:-}" ]; then
  # stable per checkout, 1..100 (valid for Fast DDS), so two clones on one machine do not meet
  ROS_DOMAIN_ID=$(( $(printf '%s' "$_gr_root" | cksum | cut -d' ' -f1) % 100 + 1 ))
  export ROS_DOMAIN_ID
fi

[ "$_gr_nounset" = 1 ] && set -u
unset _gr_root _gr_venv _gr_mode _gr_nounset
true
