"""What several test modules share.

Running a console main, writing an MCAP file again, holding a closed-loop re-run to its
recording, the package's executables, and checking a doc's examples.
"""
from __future__ import annotations

from dataclasses import asdict
import json
import os
from pathlib import Path
import re
import subprocess
import sys
import time
from typing import Callable

from gripper_ros.executables import EXECUTABLES
import numpy as np


REPO = Path(__file__).resolve().parents[1]
SWEEP_OUTPUT = REPO / 'docs' / 'contact_sweep.txt'
"""``contact_sweep``'s output, as docs/RESULTS.md quotes it."""
DOC_EXAMPLE_MODULES = {
    'test_docs_studies.py': ('contact_sweep.txt', 'contact_sweep_fingers.txt', 'grip_study.txt'),
    'test_docs_grip.py': ('GRIP.md',),
    'test_docs_bag_tools.py': ('BAG_TOOLS.md', 'RESULTS.md', 'STUDIES.md', 'USING.md'),
    'test_docs_transcripts.py': ('IDENTIFICATION.md', 'results_whatif.md'),
}
"""The test module that checks each doc's example outputs (``scripts/doc_examples.py --check``).

Modules of a minute or two each, since a module stays on one worker (scripts/test.sh). The
studies' tables are checked on some of their rows (:data:`STUDY_ROWS`)."""
STUDY_ROWS = 96
"""Rows of a contact_sweep table grasped again by the suite (``doc_examples.py --rows``): spread
evenly over it, so that each kind of object and contact has some; the whole study is
``doc_examples.py --check`` without it."""


EXECUTOR_BOUND_S = 60.0
"""A bound on an executor's thread running a task it was given, never reached unless it hangs."""


def in_executor(executor, action: Callable):
    """Run ``action`` in the thread that spins ``executor``; wait for it and return its value.

    Destroy a node or an entity of one that an executor spins in another thread this way:
    rclpy's executor (Jazzy, executors.py ``_wait_for_ready_callbacks``) still adds to its wait
    set an event handler whose destruction another thread requested meanwhile, and the
    InvalidHandle that raises ends its spinning thread, so that every later callback is lost.
    """
    import threading
    done = threading.Event()
    task = executor.create_task(action)
    task.add_done_callback(lambda _: done.set())
    assert done.wait(EXECUTOR_BOUND_S), 'the executor did not run the task: is it spinning?'
    return task.result()


def wait_for_recording(folder: Path, pattern: str = 'grasp_*',
                       bound_s: float = EXECUTOR_BOUND_S) -> Path:
    """Return the bag under ``folder`` matching ``pattern`` once it holds a message.

    A recording process writes its bag a chunk at a time while it records: a test that waits
    for the first one acts while the recording runs, however long the process took to get there.
    """
    from gripper_ros.bags.reader import BagError, read_bag
    deadline = time.monotonic() + bound_s
    while True:
        for bag in sorted(folder.glob(pattern)):
            try:
                if read_bag(bag, allow_empty=True).message_count > 0:
                    return bag
            except BagError:
                pass                        # not a bag yet (no file, no header)
        assert time.monotonic() < deadline, f'no {pattern} under {folder} holds a message ' \
            f'after {bound_s:g} s'
        time.sleep(0.05)


STALL_QUIET_S = 60.0
"""How long a process may use no CPU at all before it counts as hung: a machine loaded many
times over its cores still runs each runnable process several times a second."""


def cpu_s(pid: int) -> float | None:
    """Return the CPU time (user + system, s) process ``pid`` has used; None once it is gone."""
    try:
        with open(f'/proc/{pid}/stat') as f:
            fields = f.read().rsplit(')', 1)[1].split()
    except (FileNotFoundError, ProcessLookupError):
        return None
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


class ProgressWatch:
    """Tell a process that is slow from one that is hung, on a machine of any load.

    Wall time alone says nothing on a loaded machine, where a process gets a sliver of a core:
    a process that has not yet done what it is waited for (started, answered, exited) counts as
    hung once it has used no CPU for ``quiet_s`` (it waits for something that never comes), or
    more than ``budget_s`` of CPU since the watch began (it spins).
    """

    def __init__(self, pids, budget_s: float, quiet_s: float = STALL_QUIET_S):
        self.budget_s, self.quiet_s = budget_s, quiet_s
        self._first = {pid: cpu_s(pid) or 0.0 for pid in pids}
        self._last = dict(self._first)
        self._moved = dict.fromkeys(self._first, time.monotonic())

    def hung(self, pids=None) -> str:
        """Return why each of ``pids`` (default: all watched) is hung; '' while one progresses.

        A process that is gone is not waited for: it counts as hung here (the caller reads its
        exit first).
        """
        why = []
        for pid in self._first if pids is None else pids:
            used, now = cpu_s(pid), time.monotonic()
            if used is None:
                why.append(f'process {pid} is gone')
                continue
            if used > self._last[pid]:
                self._last[pid], self._moved[pid] = used, now
            if used - self._first[pid] > self.budget_s:
                why.append(f'process {pid} used {used - self._first[pid]:.0f} s of CPU')
            elif now - self._moved[pid] > self.quiet_s:
                why.append(f'process {pid} used no CPU for {self.quiet_s:.0f} s')
            else:
                return ''
        return '; '.join(why)


NATIVE_STACKS_BOUND_S = 120.0
"""A bound on gdb reading a hung process's threads (it takes seconds; more on a loaded machine)."""


def native_stacks(pid: int) -> str:
    """Return every thread's native stack of ``pid`` as gdb prints it ('' without gdb).

    A hang inside DDS or rcl shows only its Python caller in faulthandler's dump: the native
    frames say where it spins or waits. Read before the process is aborted.
    """
    import shutil
    gdb = shutil.which('gdb')
    if gdb is None:
        return ''
    try:
        done = subprocess.run([gdb, '-p', str(pid), '-batch', '-nx', '-ex', 'set pagination off',
                               '-ex', 'thread apply all bt 25'], capture_output=True, text=True,
                              timeout=NATIVE_STACKS_BOUND_S, stdin=subprocess.DEVNULL)
    except (subprocess.TimeoutExpired, OSError) as exc:
        return f'(gdb: {exc})'
    threads = done.stdout[done.stdout.find('\nThread '):] if '\nThread ' in done.stdout else ''
    return threads or f'(gdb printed no threads: {done.stderr.strip()[-500:]})'


def wait_for_exit(proc, budget_s: float = 60.0) -> int:
    """Return ``proc``'s exit code once it ends; kill it and fail if it hangs meanwhile.

    Hung as :class:`ProgressWatch` says (no CPU for a minute, or ``budget_s`` of it): a process
    a loaded machine stops slowly is waited for.
    """
    import subprocess
    watch = ProgressWatch([proc.pid], budget_s)
    while True:
        try:
            return proc.wait(timeout=1.0)
        except subprocess.TimeoutExpired:
            hung = watch.hung()
            if hung:
                proc.kill()
                proc.wait()
                raise AssertionError(f'{proc.args} did not exit: {hung}') from None


def console_scripts() -> dict[str, str]:
    """Return the package's executables: name -> the ``module:function`` each runs.

    setup.py installs each as an entry point of :mod:`gripper_ros.executables`, which preloads
    the condition-wait fix and then calls that function.
    """
    return dict(EXECUTABLES)


def claimed_peak_ratio() -> float:
    """Return the worst contact peak / F_sp of the published sweep (its "worst peak" lines).

    Tests hold every grasp to it, so that the published figure and the code cannot drift apart.
    """
    text = SWEEP_OUTPUT.read_text(encoding='utf-8')
    return max(float(x) for x in re.findall(r'^worst peak [^:]*: (\d+\.\d+) x F_sp', text,
                                            re.MULTILINE))


def within_claimed_peak(peak_ratio: float) -> bool:
    """Tell whether ``peak_ratio`` is within the claim at the claim's four decimals."""
    return round(peak_ratio, 4) <= claimed_peak_ratio()


def run_main(main: Callable, argv: list, capsys) -> tuple:
    """Run a console program's ``main(argv)``; return (exit code, captured output).

    The code is what it returned or what it passed to ``SystemExit``.
    """
    try:
        code = main(argv)
    except SystemExit as exc:
        code = exc.code
    return code, capsys.readouterr()


def assert_rerun_equals_recording(w) -> None:
    """Hold a what-if re-run without changes (``rerun.whatif(bag)``) to its recording.

    No series differs (``series_difference`` checks every field); the plotted series are equal
    bit for bit; every figure is the recorded one, but those of fields the bag's own (older)
    messages lack (the pads' readings), which the recording cannot give.
    """
    r = w.reruns[0]
    assert r.difference == '', r.difference
    rec, new = w.record.series, r.series
    for a, b in ((rec.ticks['force_n'], new.ticks['force_n']),
                 (rec.ticks['position_m'], new.ticks['position_m']),
                 (rec.ticks['position_m'], new.ticks['position_m']),
                 (rec.ticks['force_n'], new.ticks['force_n']),
                 (rec.ticks['motor_voltage_v'], new.ticks['motor_voltage_v']),
                 (rec.ticks['sensor_voltage_v'], new.ticks['sensor_voltage_v']),
                 (rec.commands['voltage_v'], new.commands['voltage_v']),
                 (rec.objects['slip_m'], new.objects['slip_m'])):
        assert a.size > 0 and np.array_equal(a, b, equal_nan=True)
    skip = {'bag'} | ({'pad_shear_max_n'} if 'tick.pad1_shear_n' in rec.absent else set())
    figures = {k: v for k, v in asdict(w.recorded).items() if k not in skip}
    again = {k: v for k, v in asdict(r.metrics).items() if k not in skip}
    assert json.dumps(figures, sort_keys=True) == json.dumps(again, sort_keys=True)


def copy_mcap(src: Path, dst: Path, *, schema_text: Callable[[str], str] | None = None,
              chunk_size: int | None = None) -> Path:
    """Write the MCAP file ``src`` again as ``dst``, record for record.

    ``schema_text`` rewrites each schema's text; ``chunk_size`` sets the chunks' size (default:
    the writer's). Header, channels, messages and metadata records are copied as they are.
    """
    from mcap.reader import make_reader
    from mcap.writer import Writer
    with open(src, 'rb') as fin, open(dst, 'wb') as fout:
        reader = make_reader(fin)
        header = reader.get_header()
        summary = reader.get_summary()
        writer = Writer(fout, **({} if chunk_size is None else {'chunk_size': chunk_size}))
        writer.start(profile=header.profile, library=header.library)
        schema_ids = {}
        for sid, schema in summary.schemas.items():
            data = schema.data
            if schema_text is not None:
                data = schema_text(data.decode('utf-8')).encode('utf-8')
            schema_ids[sid] = writer.register_schema(schema.name, schema.encoding, data)
        channel_ids = {cid: writer.register_channel(c.topic, c.message_encoding,
                                                    schema_ids[c.schema_id], c.metadata)
                       for cid, c in summary.channels.items()}
        for _, channel, message in reader.iter_messages(log_time_order=False):
            writer.add_message(channel_ids[channel.id], message.log_time, message.data,
                               message.publish_time, message.sequence)
        for record in reader.iter_metadata():
            writer.add_metadata(record.name, record.metadata)
        writer.finish()
    return dst


def urdf_tree(urdf: str) -> tuple[set, dict]:
    """Return a URDF's link names and its joints: name -> (type, parent, child, xyz, axis)."""
    import xml.etree.ElementTree as ET
    root = ET.fromstring(urdf)
    links = {link.get('name') for link in root.iter('link')}
    joints = {}
    for joint in root.iter('joint'):
        origin, axis = joint.find('origin'), joint.find('axis')
        xyz = [float(v) for v in (origin.get('xyz', '0 0 0') if origin is not None
                                  else '0 0 0').split()]
        axis_xyz = [float(v) for v in (axis.get('xyz') if axis is not None
                                       else '1 0 0').split()]
        joints[joint.get('name')] = (joint.get('type'), joint.find('parent').get('link'),
                                     joint.find('child').get('link'), xyz, axis_xyz)
    return links, joints


def frames_of_bag(bag) -> dict:
    """Return each child frame a bag's /tf and /tf_static hold -> the set of its parents."""
    from gripper_ros.wire import TOPIC_TF, TOPIC_TF_STATIC
    parents: dict = {}
    for raw in bag.messages:
        if raw.topic in (TOPIC_TF, TOPIC_TF_STATIC):
            for t in bag.decode(raw).transforms:
                parents.setdefault(t.child_frame_id, set()).add(t.header.frame_id)
    return parents


def step_into_phase(graph, phase, ticks_into: int = 0, lead_s: float = 0.0,
                    max_ticks: int = 5000) -> None:
    """Step a paused graph until its supervisor has decided ``ticks_into`` ticks of ``phase``.

    ``lead_s`` of simulated time are stepped at once first (a span known to end before the
    phase), then one tick at a time. Each step waits until its last tick has been answered
    (``wait_still``), so the phase read is the one that tick decided: the graph stands at a known
    simulated moment, however fast or slow the machine.
    """
    if lead_s > 0.0:
        stepped = graph.step(duration_s=lead_s, wall_timeout_s=60.0)
        assert stepped.success, stepped.message
        assert graph.wait_still(quiet_s=0.0), 'the lead step was not answered'
        assert graph.supervisor.logic.phase is not phase, \
            f'{lead_s} s of lead already reached {phase.name}'
    into = 0
    for _ in range(max_ticks):
        if graph.supervisor.logic.phase is phase:
            if into >= ticks_into:
                return
            into += 1
        stepped = graph.step(ticks=1, wall_timeout_s=60.0)
        assert stepped.success, stepped.message
        assert graph.wait_still(quiet_s=0.0), f'the tick at {stepped.time_s} s was not answered'
    raise AssertionError(f'{phase.name} not reached in {max_ticks} ticks '
                         f'(at {graph.supervisor.logic.phase.name})')


def in_phase(graph, phase, after: int = 20) -> Callable[[], bool]:
    """Return a predicate for the plant's publish: true from ``after`` ticks into ``phase`` on.

    Read in the plant's publish, the supervisor's phase is the one it decided for the tick
    before: the predicate holds at a known simulated moment, whatever the machine's speed.
    """
    state = {'n': 0}

    def when() -> bool:
        if graph.supervisor.logic.phase is not phase:
            return False
        state['n'] += 1
        return state['n'] > after
    return when


class TickHook:
    """Stands in for the plant's tick publisher; acts at the first tick for which ``when()`` holds.

    There it calls ``then()`` (on the executor thread, in the plant's publish) and, with
    ``silence``, publishes neither that tick nor any later one (a republished tick included), as
    if the plant had hung there. ``fired`` is set when it acted.
    """

    def __init__(self, graph, when: Callable[[], bool], then: Callable[[], None] | None = None,
                 silence: bool = False):
        import threading
        self.plant, self.when, self.then, self.silence = graph.plant, when, then, silence
        self.fired = threading.Event()
        self._real = self.plant._tick_pub
        self.plant._tick_pub = self

    def publish(self, data) -> None:
        if not self.fired.is_set() and self.when():
            self.fired.set()
            if self.then is not None:
                self.then()
        if self.silence and self.fired.is_set():
            return
        self._real.publish(data)

    def remove(self) -> None:
        self.plant._tick_pub = self._real


def tf_as_robot_state_publisher(bag, namespace: str = 'gripper',
                                publish_frequency_hz: float = 20.0) -> tuple[list, list]:
    """Return the stamps of a bag's /tf and those robot_state_publisher would publish.

    Its rule (ros/robot_state_publisher, src/robot_state_publisher.cpp, callbackJointState):
    a joint_states message gets a transform when its stamp is at least ``1000 / frequency``
    whole milliseconds past the last transform's (0 before any). A bag is a window of a longer
    run: its first transform is a joint state's at most one interval after the first.
    """
    from gripper_ros.wire import qualified, TOPIC_JOINT_STATES, TOPIC_TF

    def ns(stamp) -> int:
        return stamp.sec * 1_000_000_000 + stamp.nanosec
    joints, tf = [], []
    for raw in bag.messages:
        if raw.topic == qualified(namespace, TOPIC_JOINT_STATES):
            joints.append(ns(bag.decode(raw).header.stamp))
        elif raw.topic == TOPIC_TF:
            tf.append(ns(bag.decode(raw).transforms[0].header.stamp))
    interval_ns = int(1000.0 / publish_frequency_hz) * 1_000_000
    if not (tf and joints and tf[0] in joints and tf[0] <= joints[0] + interval_ns):
        return tf, [None]
    expected = [tf[0]]
    for stamp in joints:
        if stamp >= expected[-1] + interval_ns:
            expected.append(stamp)
    return tf, expected


def trajectory_action_client(graph):
    """Return an rclpy ActionClient of ``graph``'s FollowJointTrajectory server, once found."""
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action import ActionClient

    from gripper_ros.wire import ACTION_FOLLOW_JOINT_TRAJECTORY, qualified
    action = graph.run_in_executor(lambda: ActionClient(
        graph.client_node, FollowJointTrajectory,
        qualified(graph.namespace, ACTION_FOLLOW_JOINT_TRAJECTORY)))
    assert action.wait_for_server(timeout_sec=30.0)
    return action


def wait_future(future, timeout_s: float = 120.0):
    """Wait (wall, a bound for a slow machine) until ``future`` is done; return its result.

    For futures another thread's executor completes (an action client's goal and result).
    """
    import threading
    done = threading.Event()
    future.add_done_callback(lambda _f: done.set())
    assert done.wait(timeout_s), 'no answer in time'
    return future.result()


def doc_examples(*args: str, timeout_s: float = 3600.0):
    """Run ``scripts/doc_examples.py ARGS``; return the completed process (output captured)."""
    return subprocess.run([sys.executable, str(REPO / 'scripts' / 'doc_examples.py'), *args],
                          stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          timeout=timeout_s, check=False)


def assert_doc_examples_printed(doc: str, scratch: Path, *options: str) -> None:
    """Assert that every example output ``doc`` shows is what its command prints now.

    ``options``: doc_examples.py's, e.g. ``--rows N`` (a study's table on N of its rows).
    """
    done = doc_examples('--check', '--scratch', str(scratch), *options, doc)
    assert done.returncode == 0, done.stdout[-6000:] + done.stderr[-2000:]
