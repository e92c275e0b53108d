"""A slow bystander for the history_depth measurement (docs/benchmarks.md, "A slow bystander"):
subscribes reliable, keep-all, to the scene's data topics and sleeps 10 ms per message."""
import rclpy, time, sys
from rclpy.qos import QoSProfile, HistoryPolicy, ReliabilityPolicy, DurabilityPolicy
from sensor_msgs.msg import JointState
from geometry_msgs.msg import TwistStamped
rclpy.init(); node=rclpy.create_node('slow_bystander')
q=QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=0, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.VOLATILE)
def slow(m): time.sleep(0.01)
for t in ['/oscillator/state','/oscillator/pi2','/oscillator/impact','/oscillator/pi1']:
    node.create_subscription(JointState,t,slow,q)
node.create_subscription(TwistStamped,'/controller/velocity_correction',slow,q)
rclpy.spin(node)
