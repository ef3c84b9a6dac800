"""Publish std_msgs/Int32 0..count-1 on a topic with a given list of gaps (cycled), then exit.

Used by the CLI and bag tests as "another process that publishes". The gaps make the
timing irregular so a replay that ignored the recorded timing would be caught.
"""
import argparse
import time

import rclpy
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Int32

parser = argparse.ArgumentParser()
parser.add_argument("--topic", default="/counter")
parser.add_argument("--count", type=int, default=20)
parser.add_argument("--gaps", type=float, nargs="+", default=[0.05])
parser.add_argument("--start-delay", type=float, default=1.0)
parser.add_argument("--forever", action="store_true", help="keep publishing the last value")
parser.add_argument("--wait-subscribers", type=int, default=0, help="first wait for this many subscribers")
parser.add_argument("--latched", action="store_true", help="transient-local durability")
args = parser.parse_args()

rclpy.init()
node = rclpy.create_node("talker")
durability = DurabilityPolicy.TRANSIENT_LOCAL if args.latched else DurabilityPolicy.VOLATILE
publisher = node.create_publisher(Int32, args.topic, QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE,
                                                                durability=durability))
try:
    while publisher.get_subscription_count() < args.wait_subscribers:
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(args.start_delay)
    i = 0
    while i < args.count or args.forever:
        publisher.publish(Int32(data=min(i, args.count - 1)))
        time.sleep(args.gaps[i % len(args.gaps)])
        i += 1
    time.sleep(0.5)
except KeyboardInterrupt:
    pass
node.destroy_node()
rclpy.try_shutdown()
