#!/usr/bin/env bash
# Set up (if needed), then run the grasp demo. Arguments go to grasp_demo (try --help).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh </dev/null
# shellcheck disable=SC1091
source scripts/env.sh

if command -v ros2 >/dev/null 2>&1; then
  exec ros2 run gripper_ros grasp_demo "$@"
else
  # the ROS wheels have no ros2cli: run the installed console script directly
  exec "$ROOT/install/gripper_ros/lib/gripper_ros/grasp_demo" "$@"
fi
