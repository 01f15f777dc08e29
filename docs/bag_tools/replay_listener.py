"""Count the joint_states a replay delivers (reliable, keep_all), until told to stop (SIGINT).

A node with ``use_sim_time``: it subscribes /clock too, as any node that follows a ``--clock``
replay does. Told to stop once the replay has ended, it takes what its history still holds and
prints its count. ``--stop-at-first``: stop this process (SIGSTOP) at the first message, as a
machine too busy to run it would; ``kill -CONT`` lets it go on.
"""
import os
import signal
import sys

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.parameter import Parameter
from rclpy.qos import HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from sensor_msgs.msg import JointState

stop_at_first = '--stop-at-first' in sys.argv[1:]
told = []
signal.signal(signal.SIGINT, lambda *_: told.append(True))
rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
node = rclpy.create_node('replay_listener',
                         parameter_overrides=[Parameter('use_sim_time', value=True)])
got = []


def on_joint_state(msg):
    if stop_at_first and not got:
        os.kill(os.getpid(), signal.SIGSTOP)
    got.append(msg.position[0])


node.create_subscription(JointState, '/gripper/joint_states', on_joint_state,
                         QoSProfile(history=HistoryPolicy.KEEP_ALL,
                                    reliability=ReliabilityPolicy.RELIABLE))
ex = EventsExecutor()
ex.add_node(node)
while not told:
    ex.spin_once(timeout_sec=0.1)
while True:                                     # what its history still holds
    before = len(got)
    ex.spin_once(timeout_sec=0.1)
    if len(got) == before:
        break
print(f'listener: {len(got)} joint_states received (last position {got[-1] if got else None} m'
      f', clock {node.get_clock().now().nanoseconds * 1e-9:g} s)')
node.destroy_node()
rclpy.shutdown()
