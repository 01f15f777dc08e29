"""Count the joint_states a replay delivers for ARGV[1] wall seconds (reliable, depth 10000)."""
import sys
import time

import rclpy
from rclpy.experimental import EventsExecutor
from rclpy.qos import QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState

rclpy.init()
node = rclpy.create_node('replay_listener')
got = []
node.create_subscription(JointState, '/gripper/joint_states', lambda m: got.append(m.position[0]),
                         QoSProfile(depth=10000, reliability=ReliabilityPolicy.RELIABLE))
ex = EventsExecutor()
ex.add_node(node)
deadline = time.monotonic() + float(sys.argv[1])
while time.monotonic() < deadline:
    ex.spin_once(timeout_sec=0.1)
print(f'listener: {len(got)} joint_states received (last position {got[-1] if got else None} m)')
node.destroy_node()
rclpy.shutdown()
