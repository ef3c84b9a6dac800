"""Write every std_msgs/Int32 received on a topic as "<data> <monotonic time>" lines, until killed."""
import argparse
import sys
import time

import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32

parser = argparse.ArgumentParser()
parser.add_argument("--topic", default="/counter")
parser.add_argument("--out", required=True)
args = parser.parse_args()

rclpy.init()
node = rclpy.create_node("listener")
out = open(args.out, "w", buffering=1)
node.create_subscription(Int32, args.topic, lambda m: out.write(f"{m.data} {time.monotonic()}\n"),
                         QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
print("listening", flush=True)
try:
    rclpy.spin(node)
except KeyboardInterrupt:
    pass
out.close()
sys.exit(0)
