"""Two grippers started side by side as docs/USING.md "Two grippers" says: one TF tree.

``grasp_demo --serve --namespace left`` and ``--namespace right --no-clock`` (and, where
``ros2 launch`` is installed, ``gripper.launch.py namespace:=left`` / ``namespace:=right``) on
one domain, and a listener of its own on ``/tf``, ``/tf_static``, each ``robot_description``
and each ``joint_states``, with tf2's listener QoS (tf2_ros ``transform_listener.h``: depth 100,
reliable; ``/tf_static`` transient local). Known answers, from each robot_description: its links
are the TF frames its gripper publishes, each child under its joint's parent (one parent per
frame), the moving finger at the joint's origin plus the position of the joint_states message
with the same stamp along the joint's axis; its movable joint is the one name joint_states
carries. No frame, link or joint name is the other gripper's, and no frame has two publishers
(no child frame twice at one stamp).
"""
from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import threading
import time

from gripper_ros.wire import (FINGER_JOINT, FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER,
                              qualified, TOPIC_JOINT_STATES, TOPIC_ROBOT_DESCRIPTION, TOPIC_TF,
                              TOPIC_TF_STATIC)
from helpers import urdf_tree
import pytest
import rclpy
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from tf2_msgs.msg import TFMessage

GRIPPERS = ('left', 'right')
START_TIMEOUT_S = 90.0
"""Generous bounds on events (a start-up, enough messages), never a pace asserted."""
LISTEN_TIMEOUT_S = 60.0
MATCHED = 50
"""/tf messages of each gripper's moving finger checked against its joint_states (0.5 s)."""
TF_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                    reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
TF_STATIC_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                           reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.TRANSIENT_LOCAL)
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


class Started:
    """One gripper's processes (a process group), its output read by a thread."""

    def __init__(self, command: list[str], ready: str):
        self.proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                     text=True, stdin=subprocess.DEVNULL,
                                     start_new_session=True)
        self.lines: list[str] = []
        self.ready = threading.Event()
        self._ready = ready
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.proc.stdout:
            self.lines.append(line)
            if self._ready in line:
                self.ready.set()
        self.ready.set()                       # ended: nothing more will come

    def stop(self) -> None:
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGINT)
            try:
                self.proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                os.killpg(self.proc.pid, signal.SIGKILL)
                self.proc.wait()
        self._reader.join(timeout=10)


def _serve(namespace: str, tmp_path) -> Started:
    return Started([sys.executable, '-m', 'gripper_ros.apps.grasp_demo', '--serve',
                    '--namespace', namespace, '--output', str(tmp_path / namespace)]
                   + (['--no-clock'] if namespace != GRIPPERS[0] else []),
                   f'serving /{namespace}/grasp')


def _launch(namespace: str, tmp_path) -> Started:
    return Started(['ros2', 'launch', 'gripper_ros', 'gripper.launch.py',
                    f'namespace:={namespace}']
                   + (['publish_clock:=false'] if namespace != GRIPPERS[0] else []),
                   f'[{namespace}.plant_simulator]: plant ready')


def _launch_available() -> bool:
    try:
        import launch_ros  # noqa: F401
    except ImportError:
        return False
    return shutil.which('ros2') is not None


class Listener:
    """What a tf2 listener and a joint_states reader of each gripper receive."""

    def __init__(self, context: Context):
        self.node = rclpy.create_node('tf_tree_listener', context=context)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.tf: list = []                 # (child, parent, stamp_ns, x, y, z) of /tf
        self.tf_static: dict = {}           # child -> set of parents
        self.descriptions: dict[str, str] = {}
        self.joint_states: dict[str, dict] = {ns: {} for ns in GRIPPERS}  # stamp -> msg
        self.node.create_subscription(TFMessage, TOPIC_TF, self._on_tf, TF_QOS)
        self.node.create_subscription(TFMessage, TOPIC_TF_STATIC, self._on_static, TF_STATIC_QOS)
        for ns in GRIPPERS:
            self.node.create_subscription(
                String, qualified(ns, TOPIC_ROBOT_DESCRIPTION),
                lambda msg, ns=ns: self.descriptions.__setitem__(ns, msg.data), LATCHED)
            self.node.create_subscription(
                JointState, qualified(ns, TOPIC_JOINT_STATES),
                lambda msg, ns=ns: self.joint_states[ns].__setitem__(_ns(msg.header.stamp), msg),
                TF_QOS)

    def _on_tf(self, msg) -> None:
        for t in msg.transforms:
            v = t.transform.translation
            self.tf.append((t.child_frame_id, t.header.frame_id, _ns(t.header.stamp),
                            v.x, v.y, v.z))

    def _on_static(self, msg) -> None:
        for t in msg.transforms:
            self.tf_static.setdefault(t.child_frame_id, set()).add(t.header.frame_id)

    def spin_until(self, done, timeout_s: float, check_every_s: float = 0.1) -> bool:
        """Take messages until ``done()`` (asked every ``check_every_s``) or ``timeout_s``."""
        deadline = time.monotonic() + timeout_s
        while not done():
            if time.monotonic() > deadline:
                return False
            until = time.monotonic() + check_every_s
            while time.monotonic() < until:
                self.executor.spin_once(timeout_sec=check_every_s)
        return True


def _ns(stamp) -> int:
    return stamp.sec * 1_000_000_000 + stamp.nanosec


def _moving(joints: dict) -> tuple[str, tuple]:
    (name, joint), = [(n, j) for n, j in joints.items() if j[0] != 'fixed']
    return name, joint


def _matched(listener: Listener, ns: str, joints: dict) -> list:
    """Return the /tf transforms of ``ns``'s moving finger whose joint_states stamp was seen."""
    _, (_, _, child, _, _) = _moving(joints)
    seen = listener.joint_states[ns]
    return [t for t in list(listener.tf) if t[0] == child and t[2] in seen]


@pytest.mark.parametrize('how', ['grasp_demo --serve', 'ros2 launch'])
def test_grippers_side_by_side_publish_one_tree_their_descriptions_name(how, tmp_path):
    if how == 'ros2 launch' and not _launch_available():
        pytest.skip('ros2 launch is not installed (the ros-jazzy wheels): run with the overlay')
    start = _serve if how == 'grasp_demo --serve' else _launch
    started = {}
    context = Context()
    rclpy.init(context=context)
    try:
        for ns in GRIPPERS:                     # side by side: only the first publishes /clock
            started[ns] = start(ns, tmp_path)
        for ns in GRIPPERS:
            assert started[ns].ready.wait(START_TIMEOUT_S) and started[ns].proc.poll() is None, \
                ''.join(started[ns].lines)
        listener = Listener(context)
        trees = {}

        def complete() -> bool:
            if set(listener.descriptions) != set(GRIPPERS):
                return False
            for ns in GRIPPERS:
                trees.setdefault(ns, urdf_tree(listener.descriptions[ns]))
                fixed = {j[2] for j in trees[ns][1].values() if j[0] == 'fixed'}
                if not fixed <= set(listener.tf_static) or \
                        len(_matched(listener, ns, trees[ns][1])) < MATCHED:
                    return False
            return True

        assert listener.spin_until(complete, LISTEN_TIMEOUT_S), (
            f'descriptions {sorted(listener.descriptions)}, static {listener.tf_static}, '
            f'{len(listener.tf)} /tf transforms, joint_states '
            f'{ {ns: len(v) for ns, v in listener.joint_states.items()} }')
        if how == 'grasp_demo --serve':
            for ns in GRIPPERS:                  # the banner says the names a user needs
                banner = next(line for line in started[ns].lines if 'serving' in line)
                assert f'joint {ns}_{FINGER_JOINT}, TF frames under {ns}_{FRAME_BASE}' in banner
        _check_one_tree(listener, trees)
    finally:
        for s in started.values():
            s.stop()
        rclpy.try_shutdown(context=context)


def _check_one_tree(listener: Listener, trees: dict) -> None:
    links = {ns: trees[ns][0] for ns in GRIPPERS}
    joints = {ns: trees[ns][1] for ns in GRIPPERS}
    # each gripper's names: the default prefix from its namespace, none shared
    for ns in GRIPPERS:
        names = (FRAME_BASE, FRAME_FIXED_FINGER, FRAME_MOVING_FINGER)
        assert links[ns] == {f'{ns}_{n}' for n in names}
    assert not links['left'] & links['right']
    assert not set(joints['left']) & set(joints['right'])
    owner = {link: ns for ns in GRIPPERS for link in links[ns]}
    parent_of = {ns: {j[2]: j[1] for j in joints[ns].values()} for ns in GRIPPERS}
    # every frame published is a link of one description, under the parent it names
    published = {child: set(parents) for child, parents in listener.tf_static.items()}
    tf = list(listener.tf)
    for child, parent, *_ in tf:
        published.setdefault(child, set()).add(parent)
    assert set(published) <= set(owner), sorted(set(published) - set(owner))
    for child, parents in published.items():
        assert parents == {parent_of[owner[child]][child]}, (child, parents)
    for ns in GRIPPERS:                         # every link but the root is published
        root = links[ns] - set(parent_of[ns])
        assert root == {f'{ns}_{FRAME_BASE}'}
        assert {c for c in published if owner[c] == ns} == links[ns] - root
    # one publisher per frame: no child twice at one stamp
    stamped = [(child, stamp) for child, _, stamp, *_ in tf]
    assert len(stamped) == len(set(stamped))
    # the moving finger where the gripper's own joint_states put it, at that message's stamp
    for ns in GRIPPERS:
        name, (_, _, child, xyz, axis) = _moving(joints[ns])
        matched = _matched(listener, ns, joints[ns])
        assert len(matched) >= MATCHED
        for _, _, stamp, *translation in matched:
            state = listener.joint_states[ns][stamp]
            assert list(state.name) == [name]
            assert state.header.frame_id == f'{ns}_{FRAME_BASE}'   # the URDF's root link
            expected = [o + a * state.position[0] for o, a in zip(xyz, axis)]
            assert translation == pytest.approx(expected, abs=1e-12)
