"""Count the joint_states a replay delivers: until 3 s pass without one, at most ARGV[1] s."""
import sys
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

rclpy.init()
node = rclpy.create_node('replay_listener')
got = []
last = [0.0]            # when the newest message came


def on_joint_states(msg):
    got.append(msg.position[0])
    last[0] = time.monotonic()


node.create_subscription(JointState, '/gripper/joint_states', on_joint_states,
                         QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE))
ex = EventsExecutor()
ex.add_node(node)
deadline = time.monotonic() + float(sys.argv[1])
# until the replay has ended (3 s without a message after the first), at most argv[1] seconds
while time.monotonic() < deadline and not (got and time.monotonic() - last[0] > 3.0):
    ex.spin_once(timeout_sec=0.1)
print(f'listener: {len(got)} joint_states received (last position {got[-1] if got else None} m)')
node.destroy_node()
rclpy.shutdown()
