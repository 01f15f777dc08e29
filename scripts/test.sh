#!/usr/bin/env bash
# Set up (if needed), then run the test suite in an isolated ROS graph.
#   bash scripts/test.sh                       # python -m pytest test -q
#   bash scripts/test.sh -k grasp -x           # extra pytest options are passed through
#   bash scripts/test.sh test/test_foo.py      # path arguments replace the default `test`
#   ROS2_OVERLAY=../ros2-overlay/install bash scripts/test.sh   # with the real launch and control_msgs
# Exits non-zero on any failure, including "no tests collected" (pytest exit 5).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh </dev/null
# shellcheck disable=SC1091
source scripts/env.sh

# The ros-jazzy wheels have no launch, launch_ros, ros2cli or control_msgs, so test_launch and the
# gripper_cmd test skip. An overlay built from their Jazzy sources (ros2-overlay's build.sh) makes
# them run: point ROS2_OVERLAY at its install folder.
if [[ -n "${ROS2_OVERLAY:-}" ]]; then
  if [[ -f "$ROS2_OVERLAY/local_setup.bash" ]]; then
    set +u
    # shellcheck disable=SC1091
    source "$ROS2_OVERLAY/local_setup.bash"
    set -u
    echo "[test] ROS 2 overlay: $ROS2_OVERLAY (launch and control_msgs tests run)" >&2
  else
    echo "[test] ROS2_OVERLAY=$ROS2_OVERLAY has no local_setup.bash: launch and control_msgs tests skip" >&2
  fi
fi

# An isolated graph per run: LOCALHOST discovery and a ROS_DOMAIN_ID of our own (1..100, valid
# for Fast DDS), starting from a PID-derived value and held with a lock file for the whole run so
# that concurrent runs on this machine never share a domain. GRIPPER_ROS_TEST_DOMAIN_ID forces one.
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset ROS_STATIC_PEERS ROS_LOCALHOST_ONLY || true
if [[ -n "${GRIPPER_ROS_TEST_DOMAIN_ID:-}" ]]; then
  ROS_DOMAIN_ID="$GRIPPER_ROS_TEST_DOMAIN_ID"
else
  start=$(( $$ % 100 ))
  ROS_DOMAIN_ID=$(( start + 1 ))
  if command -v flock >/dev/null 2>&1; then
    lockdir="${TMPDIR:-/tmp}/gripper_ros_domains.$(id -u)"
    mkdir -p "$lockdir"
    for i in $(seq 0 99); do
      cand=$(( (start + i) % 100 + 1 ))
      exec {lockfd}>"$lockdir/$cand.lock"
      if flock -n "$lockfd"; then ROS_DOMAIN_ID=$cand; break; fi
      exec {lockfd}>&-
    done
  fi
fi
export ROS_DOMAIN_ID
export PYTHONDONTWRITEBYTECODE="${PYTHONDONTWRITEBYTECODE:-1}"

# Default target `test` unless the caller names a path (file, dir or node id) of their own.
targets=(test)
for a in "$@"; do
  if [[ "$a" != -* && -e "${a%%::*}" ]]; then targets=(); break; fi
done

echo "[test] ROS_DOMAIN_ID=$ROS_DOMAIN_ID ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE" >&2
set +e
python -m pytest "${targets[@]}" -q "$@" </dev/null
rc=$?
set -e
if [[ $rc -eq 5 ]]; then
  echo "[test] FAILED: pytest collected no tests (exit 5)" >&2
elif [[ $rc -ne 0 ]]; then
  echo "[test] FAILED (pytest exit $rc)" >&2
fi
exit $rc
