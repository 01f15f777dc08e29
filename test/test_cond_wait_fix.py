"""The condition-wait fix the package's executables preload (gripper_ros/native).

- A wrapped "wait for ever" deadline (tv_sec -7426785939, tv_nsec -810837690: what the
  wheels' Fast DDS computes for steady_clock::time_point::max(), notes in
  gripper_ros/native/cond_wait_fix.c) makes glibc's pthread_cond_timedwait return EINVAL at once,
  the mutex still held; with the fix it waits until notified and returns 0. Valid deadlines
  are glibc's: one past, or one that comes before a notify, returns ETIMEDOUT.
- An executable started without the fix (``plant_simulator``, as ``ros2 run`` and ``ros2
  launch`` start it) runs with it: the same process, its library mapped.
- The race it fixes, forced in a real node executable: Ctrl-C while a discovery callback is
  held in flight at the moment rmw_fastrtps' destroy_participant calls
  ``DomainParticipant::set_listener(nullptr)`` (test/native/*.c, preloaded). The node stops,
  exit 0; without the fix the wheels' Fast DDS spins there for ever (Fast-DDS#6513).
"""
from __future__ import annotations

import errno
import os
from pathlib import Path
import shutil
import signal
import subprocess
import sys
import textwrap

from gripper_ros.native import cond_wait_fix_path
from helpers import wait_for_exit
import pytest

FIX = cond_wait_fix_path()
NATIVE_DIR = Path(__file__).resolve().parent / 'native'
STOP_CPU_S = 20.0                        # CPU a stop may use before it counts as spinning
WAIT_PROGRAM = textwrap.dedent("""
    import ctypes, sys, threading, time

    class Timespec(ctypes.Structure):
        _fields_ = [('tv_sec', ctypes.c_long), ('tv_nsec', ctypes.c_long)]

    libc = ctypes.CDLL(None)             # the process's global scope: a preloaded fix first
    cond, mutex = ctypes.create_string_buffer(128), ctypes.create_string_buffer(128)
    libc.pthread_cond_init(cond, None)
    libc.pthread_mutex_init(mutex, None)
    notified = []

    def notify():
        time.sleep(0.2)
        libc.pthread_mutex_lock(mutex)
        notified.append(True)
        libc.pthread_cond_signal(cond)
        libc.pthread_mutex_unlock(mutex)

    deadline = {'wrapped': Timespec(-7426785939, -810837690), 'past': Timespec(1, 0)}.get(
        sys.argv[1])
    if deadline is None:
        now = Timespec()
        libc.clock_gettime(0, ctypes.byref(now))           # CLOCK_REALTIME, as glibc reads it
        deadline = Timespec(now.tv_sec, now.tv_nsec)       # 'now': already due
    libc.pthread_mutex_lock(mutex)
    threading.Thread(target=notify, daemon=True).start()
    rc = 0
    while not notified:
        rc = libc.pthread_cond_timedwait(cond, mutex, ctypes.byref(deadline))
        if rc:
            break
    libc.pthread_mutex_unlock(mutex)
    print(rc, bool(notified))
""")
PEER_PROGRAM = textwrap.dedent("""
    import time, rclpy
    from std_msgs.msg import String
    rclpy.init()
    node = rclpy.create_node('cond_wait_fix_peer')
    for i in range(10 ** 6):                # a writer discovery at every peer, 5 a second
        publisher = node.create_publisher(String, f'cond_wait_fix_{i}', 10)
        time.sleep(0.2)
        node.destroy_publisher(publisher)
""")


def _without_fix() -> dict:
    """Return the environment minus any LD_PRELOAD (the test runner may preload the fix)."""
    return {k: v for k, v in os.environ.items() if k != 'LD_PRELOAD'}


def _wait(deadline: str, preload: bool) -> tuple[int, bool]:
    env = _without_fix()
    if preload:
        env['LD_PRELOAD'] = str(FIX)
    out = subprocess.run([sys.executable, '-c', WAIT_PROGRAM, deadline], env=env,
                         capture_output=True, text=True, check=True).stdout.split()
    return int(out[0]), out[1] == 'True'


needs_fix = pytest.mark.skipif(FIX is None, reason='the fix was not built (no C compiler)')


@needs_fix
def test_a_wrapped_never_deadline_waits_until_notified_with_the_fix():
    assert _wait('wrapped', preload=False) == (errno.EINVAL, False)      # glibc: refused at once
    assert _wait('wrapped', preload=True) == (0, True)


@needs_fix
@pytest.mark.parametrize('deadline', ['past', 'now'])
def test_a_valid_deadline_is_glibcs_with_the_fix(deadline):
    assert _wait(deadline, preload=True) == _wait(deadline, preload=False) == \
        (errno.ETIMEDOUT, False)


def _start_plant(tmp_path, preload: str = '') -> subprocess.Popen:
    env = _without_fix()
    if preload:
        env['LD_PRELOAD'] = preload
    env['RACE_DIR'] = str(tmp_path)
    return subprocess.Popen(
        [shutil.which('plant_simulator'), '--ros-args', '-r', '__ns:=/cond_wait_fix'],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env=env)


def _wait_for_line(proc: subprocess.Popen, words: str) -> list[str]:
    """Read the process's stderr up to a line with ``words`` (or its end); return the lines."""
    lines = []
    for line in proc.stderr:
        lines.append(line)
        if words in line:
            break
    return lines


def _stop(proc: subprocess.Popen) -> tuple[int, str]:
    """Ctrl-C ``proc``; return its exit code and stderr (a stop that hangs fails the test)."""
    proc.send_signal(signal.SIGINT)
    return wait_for_exit(proc, STOP_CPU_S), proc.stderr.read()


@needs_fix
@pytest.mark.skipif(shutil.which('plant_simulator') is None, reason='the package is not built')
def test_an_executable_started_without_the_fix_runs_with_it(tmp_path):
    proc = _start_plant(tmp_path)
    try:
        seen = _wait_for_line(proc, 'plant ready')
        assert 'plant ready' in seen[-1], ''.join(seen)
        maps = Path(f'/proc/{proc.pid}/maps').read_text()
        assert str(FIX) in maps
    finally:
        code, text = _stop(proc)
    assert code == 0, text


@needs_fix
@pytest.mark.skipif(shutil.which('plant_simulator') is None, reason='the package is not built')
@pytest.mark.skipif(shutil.which('cc') is None, reason='no C compiler for the race helpers')
def test_a_node_stopped_with_a_discovery_callback_in_flight_stops(tmp_path):
    """The race forced: the node's participant is deleted while a discovery is being handled.

    A peer creates a publisher every 0.2 s, so the node's participant keeps discovering
    writers; at Ctrl-C, rmw_fastrtps' destroy_participant calls set_listener(nullptr), which
    waits for the callbacks in flight, one of them held for 1 s (a node's clean-up may take 3 s).
    """
    helpers = []
    for source in sorted(NATIVE_DIR.glob('*.c')):
        library = tmp_path / f'{source.stem}.so'
        subprocess.run(['cc', '-O2', '-shared', '-fPIC', str(source), '-o', str(library), '-ldl'],
                       check=True)
        helpers.append(str(library))
    peer = subprocess.Popen([sys.executable, '-c', PEER_PROGRAM], stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                            env=_without_fix())
    proc = _start_plant(tmp_path, ' '.join(helpers))
    try:
        seen = _wait_for_line(proc, 'plant ready')
        assert 'plant ready' in seen[-1], ''.join(seen)
    finally:
        try:
            code, text = _stop(proc)
        finally:
            peer.kill()
            peer.wait()
    assert '[race] set_listener(nullptr) with a discovery callback held in flight' in text, text
    assert code == 0, text
