#!/usr/bin/env bash
# The ROS 2 Jazzy command line on the ros-jazzy wheels: ros2cli and its verbs (run, topic, param,
# service, action, node, interface, pkg), launch, launch_ros (ros2 launch) and control_msgs,
# built with colcon from their pinned upstream release sources into VENV/ros2_cli, which
# scripts/env.sh sources. Run by `bash scripts/setup.sh --ros2-cli [SOURCES_DIR]`, after the
# project's own set-up, with the venv active:
#
#   bash scripts/ros2_cli.sh VENV                 # download each release from its upstream tag
#   bash scripts/ros2_cli.sh VENV SOURCES_DIR     # or take the release tarballs from a folder
#
# SOURCES_DIR holds <repository>-<version>.tar.gz for each line of SOURCES (each with a top
# folder named after its repository, checked against its sha256 below). A download takes the
# upstream archive of the pinned commit (github.com/<owner>/<repository>/archive/<commit>.tar.gz,
# whose top folder names the commit). The four wheels of requirements-ros2-cli.txt come from the
# package index. Idempotent: a stamp (sources, this script, the venv's ROS wheels) makes a run
# with nothing changed a check of a second; a change rebuilds from scratch. The first build takes
# about 6 CPU-minutes, most of it control_msgs' C/C++ type support; one package at a time.
# Knob: GRIPPER_ROS_FORCE_BUILD=1 rebuilds.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
log() { echo "[ros2-cli] $*" >&2; }
die() { echo "[ros2-cli] ERROR: $*" >&2; exit 1; }
T0=$SECONDS

VENV="${1:?usage: bash scripts/ros2_cli.sh VENV [SOURCES_DIR]}"
SOURCES_DIR="${2:-}"
PY="$VENV/bin/python"
[[ -x "$PY" && -f "$VENV/share/ament_index/resource_index/packages/rclpy" ]] ||
  die "$VENV has no ROS 2 Jazzy from the ros-jazzy-* wheels: run bash scripts/setup.sh first"
OUT="$VENV/ros2_cli"

# repository version owner commit packages sha256-of-the-release-tarball
# (the jazzy releases; the tarballs: `git archive` of the commit, limited to the packages and the
# repository's LICENSE, gzip -n)
SOURCES=(
  "ros2cli 0.32.2 ros2 de6cd27284937044d8dff47a617581c28865210c ros2cli,ros2run,ros2topic,ros2param,ros2service,ros2action,ros2node,ros2interface,ros2pkg 9e6991825a55dd9e618329becdb7b63959d56db18bf9a127492ffaab5dbe75dd"
  "launch 3.4.3 ros2 09403fcebedb68dd259e9ab6b35bd8712b6596ec launch,launch_xml,launch_yaml 1a36de2bb8ca4bf4cbcc25d52525a59ea6cf2786293c7e2698ad477a0885b386"
  "launch_ros 0.26.6 ros2 62c56e53e86812023697fe330c83d327f54e7b18 launch_ros,ros2launch a4aeaec69c2dcf8397e9c04f1451058923fe29dda94128856bc0b188a405f54d"
  "rosidl_runtime_py 0.13.1 ros2 df2361f64ecb85f65f4bf22e804424e0f1ac4197 . 3158269c066bb6ce931c55e30600bd37a8accb68370e1755f958197cd3daa9f5"
  "rcl_interfaces 2.0.2 ros2 003987ecb81a32802ab27dd6d325b8c6b8b813cc composition_interfaces b4baa0dead97642eb1bb573521c4df13c2834fac3c37222b5e507f6c6e5a6bb0"
  "control_msgs 5.8.0 ros-controls f901df2662f22a39a06aa04a85a34602c47e3cc0 control_msgs f12bdbb6dc882e2d867c82ed240d855c82f43e3143319ba3015b5eae03e84669"
)
# What the install must hold once built.
PACKAGES=(rosidl_runtime_py ros2cli ros2run ros2topic ros2param ros2service ros2action ros2node
          ros2interface ros2pkg launch launch_xml launch_yaml launch_ros ros2launch
          composition_interfaces control_msgs)

command -v cmake >/dev/null 2>&1 || die "cmake not found (control_msgs is built with cmake)"
command -v c++ >/dev/null 2>&1 || command -v g++ >/dev/null 2>&1 || die "no C++ compiler (c++/g++)"
if [[ -n "$SOURCES_DIR" ]]; then
  [[ -d "$SOURCES_DIR" ]] || die "$SOURCES_DIR: not a folder (it should hold the release tarballs)"
  SOURCES_DIR="$(cd "$SOURCES_DIR" && pwd)"
fi

# ---------------------------------------------------------------- stamp
want="$( { printf '%s\n' "${SOURCES[@]}"; sha256sum "$ROOT/scripts/ros2_cli.sh" \
           "$ROOT/requirements-ros2-cli.txt" | cut -d' ' -f1; echo "venv=$VENV";
           "$PY" -m pip freeze 2>/dev/null | grep -iE '^(ros-|colcon-|setuptools|osrf|argcomplete)' ; } \
         | sha256sum | cut -d' ' -f1)"
STAMP="$OUT/install/.gripper_ros_ros2_cli.sha256"
if [[ "${GRIPPER_ROS_FORCE_BUILD:-0}" != 1 && -f "$OUT/install/local_setup.bash" &&
      "$(cat "$STAMP" 2>/dev/null || true)" == "$want" ]]; then
  log "ROS 2 command line up to date (stamp matches) in $OUT/install"
  exit 0
fi

# ---------------------------------------------------------------- sources
rm -rf "$OUT"
mkdir -p "$OUT/src" "$OUT/download"
: > "$OUT/COLCON_IGNORE"            # a colcon crawling the venv's parent never takes these
for line in "${SOURCES[@]}"; do
  read -r repo version owner commit packages sum <<< "$line"
  if [[ -n "$SOURCES_DIR" ]]; then
    tarball="$SOURCES_DIR/$repo-$version.tar.gz"
    [[ -f "$tarball" ]] || die "$tarball is missing (SOURCES_DIR must hold $repo-$version.tar.gz)"
    echo "$sum  $tarball" | sha256sum --quiet -c - 2>/dev/null ||
      die "$tarball is not the pinned release (sha256 differs from $sum)"
    top="$repo"
  else
    tarball="$OUT/download/$repo-$commit.tar.gz"
    url="https://github.com/$owner/$repo/archive/$commit.tar.gz"
    log "downloading $repo $version ($url)"
    "$PY" - "$url" "$tarball" <<'PYEOF' || die "cannot download $url (no network? give the folder of the release tarballs: bash scripts/setup.sh --ros2-cli SOURCES_DIR)"
import shutil, sys, urllib.request
with urllib.request.urlopen(sys.argv[1], timeout=60) as answer, open(sys.argv[2], 'wb') as out:
    shutil.copyfileobj(answer, out)
PYEOF
    top="$repo-$commit"
  fi
  mkdir -p "$OUT/src/$repo"
  members=("$top/LICENSE")
  IFS=, read -ra parts <<< "$packages"
  for p in "${parts[@]}"; do
    if [[ "$p" == . ]]; then members=("$top"); else members+=("$top/$p"); fi
  done
  tar -xzf "$tarball" -C "$OUT/src/$repo" --strip-components=1 "${members[@]}" ||
    die "$tarball does not hold ${packages//,/ } under $top/"
done

# ---------------------------------------------------------------- build, one package at a time
export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
BUILD_LOG="$OUT/log/build.log"
mkdir -p "$OUT/log"
log "colcon build of ${#PACKAGES[@]} packages into $OUT/install (first time: about 6 CPU-minutes)"
set +e
PYTHONUNBUFFERED=1 colcon --log-base "$OUT/log" build --executor sequential \
  --base-paths "$OUT/src" --build-base "$OUT/build" --install-base "$OUT/install" \
  --event-handlers console_direct+ console_start_end+ \
  --cmake-args -DPython3_EXECUTABLE="$PY" -DBUILD_TESTING=OFF \
  </dev/null 2>&1 | tee "$BUILD_LOG" | grep --line-buffered -E '^(Starting|Finished|Failed|Aborted) |^colcon: error' >&2
rc=${PIPESTATUS[0]}
set -e
if ((rc != 0)); then
  log "colcon build FAILED (exit $rc); the last 60 lines of $BUILD_LOG follow"
  tail -n 60 "$BUILD_LOG" >&2
  exit 1
fi
for p in "${PACKAGES[@]}"; do
  [[ -d "$OUT/install/$p" ]] || die "package $p is missing from $OUT/install after the build"
done
( set +u
  # shellcheck disable=SC1091
  source "$OUT/install/local_setup.bash"
  ros2 pkg prefix control_msgs >/dev/null &&
  "$PY" -c 'import launch_ros, launch_xml, launch_yaml, ros2launch, control_msgs.action' ) ||
  die "the ROS 2 command line was built but does not work (see above)"
# its byte code: the tests run with PYTHONDONTWRITEBYTECODE, and `ros2` and `ros2 launch` import
# a hundred modules of it at each start
env -u PYTHONDONTWRITEBYTECODE "$PY" -m compileall -q -j 0 "$OUT/install" >/dev/null ||
  log "(byte-compiling $OUT/install failed: its modules are compiled at each start)"
echo "$want" > "$STAMP"
rm -rf "$OUT/download"
log "ready in $((SECONDS - T0)) s: ros2, ros2 launch and control_msgs (source scripts/env.sh)"
