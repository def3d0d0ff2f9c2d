#!/usr/bin/env python3
"""What a keep_all reliable subscription (the recorder's) does when its reader falls behind for good.

A child process subscribes to /reader_limit/big with the recorder's QoS (reliable, volatile,
keep_all, raw) and a message-lost handler, and takes at most about 100 messages a second; this
process publishes 100 kB messages as fast as it can (reliable, keep_last 1000) for --seconds.
The subscriber prints its resident memory every 5 s, then what it received and how many
messages the middleware reported lost. Run on a private domain:

    ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST python scripts/measure_reader_limit.py --domain 211 --seconds 20
"""
from __future__ import annotations

import argparse
import subprocess
import sys
import time

TOPIC = "/reader_limit/big"


def _rss_mib() -> int:
    with open("/proc/self/status") as f:
        return int(f.read().split("VmRSS:")[1].split()[0]) // 1024


def subscriber(domain: int, seconds: float) -> None:
    import rclpy
    from rclpy.event_handler import SubscriptionEventCallbacks
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import UInt8MultiArray

    from clothfold_ros.nodes.recorder_node import subscription_qos

    rclpy.init(domain_id=domain)
    node = Node("reader_limit_sub")
    got, lost = [0], [0]

    def on_message(_data: bytes) -> None:
        got[0] += 1
        time.sleep(0.01)  # a writer that keeps up with 100 messages a second at most

    def on_lost(status) -> None:
        lost[0] = status.total_count

    node.create_subscription(UInt8MultiArray, TOPIC, on_message, subscription_qos([]), raw=True,
                             event_callbacks=SubscriptionEventCallbacks(message_lost=on_lost))
    ex = SingleThreadedExecutor()
    ex.add_node(node)
    print("subscribed", flush=True)
    t0, mark = time.monotonic(), 0.0
    while (el := time.monotonic() - t0) < seconds:
        ex.spin_once(timeout_sec=0.1)
        if el >= mark:
            print(f"  t = {el:4.0f} s: received {got[0]:6d}, lost reported {lost[0]:7d}, RSS {_rss_mib()} MiB", flush=True)
            mark += 5.0
    print(f"subscriber: received {got[0]}, lost reported by the middleware {lost[0]}, RSS {_rss_mib()} MiB", flush=True)
    rclpy.shutdown()


def publisher(domain: int, seconds: float) -> None:
    import rclpy
    from rclpy.node import Node
    from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
    from std_msgs.msg import UInt8MultiArray

    rclpy.init(domain_id=domain)
    node = Node("reader_limit_pub")
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.VOLATILE)
    pub = node.create_publisher(UInt8MultiArray, TOPIC, qos)
    deadline = time.monotonic() + 30
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    msg = UInt8MultiArray(data=bytes(100_000))
    t0, n, slowest = time.monotonic(), 0, 0.0
    while time.monotonic() - t0 < seconds:
        a = time.monotonic()
        pub.publish(msg)
        slowest, n = max(slowest, time.monotonic() - a), n + 1
    print(f"publisher: {n} messages of 100 kB in {seconds:g} s, slowest publish() {slowest * 1e3:.1f} ms", flush=True)
    rclpy.shutdown()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--domain", type=int, default=211, help="ROS_DOMAIN_ID to use (default 211)")
    ap.add_argument("--seconds", type=float, default=20.0, help="how long the publisher floods (default 20)")
    ap.add_argument("--role", choices=("sub",), help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.role == "sub":
        subscriber(args.domain, args.seconds)
        return 0
    child = subprocess.Popen([sys.executable, __file__, "--role", "sub", "--domain", str(args.domain),
                              "--seconds", str(args.seconds + 10.0)], stdout=subprocess.PIPE, text=True)
    assert child.stdout is not None
    print(child.stdout.readline().strip(), flush=True)  # "subscribed"
    publisher(args.domain, args.seconds)
    for line in child.stdout:
        print(line.rstrip(), flush=True)
    return child.wait()


if __name__ == "__main__":
    sys.exit(main())
