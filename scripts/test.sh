#!/usr/bin/env bash
# Set up (if needed), then run the test suite in an isolated ROS graph.
#   bash scripts/test.sh                       # python -m pytest test -q
#   bash scripts/test.sh -k grasp -x           # extra pytest options are passed through
#   bash scripts/test.sh test/test_foo.py      # path arguments replace the default `test`
#   ROS2_OVERLAY=/path/install bash scripts/test.sh   # with another build of launch and control_msgs
# Exits non-zero on any failure, including "no tests collected" (pytest exit 5).
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

bash scripts/setup.sh </dev/null
# shellcheck disable=SC1091
source scripts/env.sh

# The ros-jazzy wheels have no launch, launch_ros, ros2cli or control_msgs, so test_launch and the
# gripper_cmd test skip, unless `setup.sh --ros2-cli` built them (env.sh sources them; then
# ROS2_OVERLAY says they must work: a test fails instead of skipping). ROS2_OVERLAY may also name
# another build's install folder.
venv_cli="${GRIPPER_ROS_VENV:-$ROOT/.venv}/ros2_cli/install"
if [[ -z "${ROS2_OVERLAY:-}" && -f "$venv_cli/local_setup.bash" ]]; then
  export ROS2_OVERLAY="$venv_cli"
fi
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

# An isolated graph per run: LOCALHOST discovery and ROS_DOMAIN_IDs of our own (1..100, valid
# for Fast DDS), one per pytest worker, held with lock files for the whole run so that
# concurrent runs on this machine never share a domain. Worker K takes the K-th id (see
# test/conftest.py); each is 25 away from the one before, so that the ids tests derive from
# theirs (+1, 100 + id) stay apart. GRIPPER_ROS_TEST_DOMAIN_ID forces the first.
# GRIPPER_ROS_TEST_WORKERS: pytest-xdist workers (default 3; 1 = no xdist, one process; at most 4).
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
unset ROS_STATIC_PEERS ROS_LOCALHOST_ONLY || true
WORKERS="${GRIPPER_ROS_TEST_WORKERS:-3}"
[[ "$WORKERS" =~ ^[1-4]$ ]] || { echo "[test] GRIPPER_ROS_TEST_WORKERS must be 1 to 4, not '$WORKERS'" >&2; exit 2; }
nth_of() { echo $(( ($1 - 1 + 25 * $2) % 100 + 1 )); }   # nth_of ID K: worker K's id
lock_domain() {   # lock_domain ID: hold ID's lock file open for the run (fd in locked_fd)
  exec {locked_fd}>"$lockdir/$1.lock"
  if flock -n "$locked_fd"; then return 0; fi
  exec {locked_fd}>&-
  return 1
}
lockdir="${TMPDIR:-/tmp}/gripper_ros_domains.$(id -u)"
if [[ -n "${GRIPPER_ROS_TEST_DOMAIN_ID:-}" ]]; then
  ROS_DOMAIN_ID="$GRIPPER_ROS_TEST_DOMAIN_ID"
else
  start=$(( $$ % 100 ))
  ROS_DOMAIN_ID=$(( start + 1 ))
  if command -v flock >/dev/null 2>&1; then
    mkdir -p "$lockdir"
    for i in $(seq 0 99); do
      cand=$(( (start + i) % 100 + 1 ))
      held=()
      for k in $(seq 0 $(( WORKERS - 1 ))); do
        lock_domain "$(nth_of "$cand" "$k")" || break
        held+=("$locked_fd")
      done
      if [[ ${#held[@]} == "$WORKERS" ]]; then ROS_DOMAIN_ID=$cand; break; fi
      for fd in "${held[@]}"; do exec {fd}>&-; done
    done
  fi
fi
GRIPPER_ROS_WORKER_DOMAINS="$ROS_DOMAIN_ID"
for k in $(seq 1 $(( WORKERS - 1 ))); do
  GRIPPER_ROS_WORKER_DOMAINS+=" $(nth_of "$ROS_DOMAIN_ID" "$k")"
done
export GRIPPER_ROS_WORKER_DOMAINS
export ROS_DOMAIN_ID
export PYTHONDONTWRITEBYTECODE="${PYTHONDONTWRITEBYTECODE:-1}"

# The tests' own processes (pytest and its workers, whose graphs run in-process, and every
# `python -m` they start) carry the condition-wait fix the package's executables preload
# themselves with (gripper_ros/native): a context they close must never spin in Fast DDS.
cond_wait_fix="$(python -c 'from gripper_ros.native import cond_wait_fix_path as p; print(p() or "")')"
if [[ -n "$cond_wait_fix" ]]; then
  export LD_PRELOAD="$cond_wait_fix${LD_PRELOAD:+ $LD_PRELOAD}"
else
  echo "[test] the condition-wait fix was not built (no C compiler): stops may spin in Fast DDS" >&2
fi

# Every process the tests start carries this run's token in its environment. A process still
# running after a phase (a worker that died leaves its children; a test's clean-up that missed
# one) is killed and named, so that it loads neither the next phase nor the machine after it.
export GRIPPER_ROS_TEST_RUN="$$.$RANDOM"
reap_leftovers() {
  local pids=() pid name environ
  for environ in /proc/[0-9]*/environ; do
    pid=${environ#/proc/}; pid=${pid%/environ}
    [[ $pid == "$$" || $pid == "$BASHPID" ]] && continue
    if grep -qzx "GRIPPER_ROS_TEST_RUN=$GRIPPER_ROS_TEST_RUN" "$environ" 2>/dev/null; then
      pids+=("$pid")
    fi
  done
  [[ ${#pids[@]} -eq 0 ]] && return 0
  for pid in "${pids[@]}"; do
    name=$(tr '\0' ' ' < "/proc/$pid/cmdline" 2>/dev/null | cut -c1-120)
    kill -KILL "$pid" 2>/dev/null && echo "[test] still running after the tests, killed: $pid $name" >&2
  done
  return 0
}

# Default target `test` unless the caller names a path (file, dir or node id) of their own.
targets=(test)
for a in "$@"; do
  if [[ "$a" != -* && -e "${a%%::*}" ]]; then targets=(); break; fi
done

# Workers by test file: a module's shared graph stays in one process. Most tests wait on DDS,
# subprocesses and timers: two workers kept about 1.1 of two cores busy, three keep about 1.5
# and end the parallel phase in three quarters of the time (tests wait on events and scale their
# bounds with the load, so a busier machine slows them and fails none). The tests
# marked serial (a measure against the wall clock itself: test/conftest.py says which and why)
# then run alone, in one process. The modules go to the workers in the order test/conftest.py
# collects them (the longest first), not pytest-xdist's (the most tests first). A worker that
# crashes ends the run (--max-worker-restart 0): with --dist loadfile, pytest-xdist 3.8 puts the
# dead worker's finished modules back in its queue as empty units, and the run then waits
# forever with every worker idle (xdist/scheduler/loadscope.py remove_node; pytest-xdist#1378).
echo "[test] ROS_DOMAIN_ID(s)=$GRIPPER_ROS_WORKER_DOMAINS ROS_AUTOMATIC_DISCOVERY_RANGE=$ROS_AUTOMATIC_DISCOVERY_RANGE workers=$WORKERS" >&2
set +e
if [[ "$WORKERS" != 1 ]]; then
  python -m pytest "${targets[@]}" -q -n "$WORKERS" --dist loadfile --no-loadscope-reorder --max-worker-restart 0 -m "not serial" "$@" </dev/null
  rc1=$?
  reap_leftovers
  echo "[test] the serial tests, alone:" >&2
  python -m pytest "${targets[@]}" -q -m serial "$@" </dev/null
  rc2=$?
  reap_leftovers
  # exit 5 (no tests) only when neither phase ran one; else the first failure's code
  if [[ $rc1 -eq 5 && $rc2 -eq 5 ]]; then rc=5
  else
    [[ $rc1 -eq 5 ]] && rc1=0
    [[ $rc2 -eq 5 ]] && rc2=0
    rc=$rc1; [[ $rc -eq 0 ]] && rc=$rc2
  fi
else
  python -m pytest "${targets[@]}" -q "$@" </dev/null
  rc=$?
  reap_leftovers
fi
set -e
if [[ $rc -eq 5 ]]; then
  echo "[test] FAILED: pytest collected no tests (exit 5)" >&2
elif [[ $rc -ne 0 ]]; then
  echo "[test] FAILED (pytest exit $rc)" >&2
fi
exit $rc
