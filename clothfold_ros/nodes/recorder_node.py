"""recorder_node: record ROS 2 topics (serialized CDR) into one MCAP bag in the rosbag2 layout.

Usage: ``recorder_node --output PATH [--topics T1 T2 ...] [--exclude REGEX] [--include-hidden]
[--ros-args ...]``. Records every topic (default) or the given ones; new topics are
discovered every ``--discovery-period`` s. Each topic is subscribed with ``raw=True``, KEEP_ALL
(no queued message is ever replaced by a newer one) and a QoS compatible with its publishers
(transient_local when all of them offer it, best effort when any is best effort); the
publishers' offered QoS and type hash are stored. Prints ``recording to PATH`` (flushed) once
ready, logs ``matched TOPIC`` once a topic's subscription has matched a publisher (wait for it
before sending what must be recorded), and ``bag closed: PATH (N messages)`` after
SIGINT/SIGTERM (``bag NOT closed: ...`` and exit 1 when it cannot be closed); a SIGKILL loses
at most the last ~``--chunk-age`` s (see ``clothfold bag recover``). Topics that cannot be
recorded are listed, never dropped silently, and so are messages the middleware reports lost
before they reached the recorder (its message-lost event, counted per topic).

Frames: tf2_msgs is not in the PyPI wheels, so the nodes publish no /tf; the recorder writes
them into the bag (unless ``--no-tf``): at the start one latched /tf_static
(tf2_msgs/msg/TFMessage) with world -> table and every ``--static-tf``, and for every recorded
``/gripper_<i>/pose`` (geometry_msgs/PoseStamped) a /tf message <its frame> -> gripper_<i>
with the same stamp and log time. Live /tf and /tf_static publishers (a real install) are
recorded into the same channels. See docs/recording.md.
"""
from __future__ import annotations

import argparse
import importlib
import re
import sys
import time
from typing import Any

from rclpy.event_handler import SubscriptionEventCallbacks, UnsupportedEventTypeError
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args

from ..bag import BagError, BagWriter, from_profile, message_definition
from ..bag.tf import (TF_QOS, TF_STATIC_QOS, TF_STATIC_TOPIC, TF_TOPIC, TF_TYPE, Transform, encode_tf_message,
                      tf_definition)
from . import conversions as rc
from .common import ShutdownFailure, run

ROOT_TRANSFORM = ("world", "table")  # /tf_static: the fixed root above the table frame every message uses
GRIPPER_POSE = re.compile(r"^/(gripper_\d+)/pose$")  # PoseStamped -> /tf <frame_id> -> gripper_<i>


def message_class(type_name: str) -> Any:
    """Python class of ``pkg/msg/Type`` (ImportError/AttributeError if its package is not built)."""
    pkg, kind, name = type_name.split("/")
    return getattr(importlib.import_module(f"{pkg}.{kind}"), name)


def is_hidden(topic: str) -> bool:
    """True for hidden topics (a name component starting with '_', e.g. action internals)."""
    return any(part.startswith("_") for part in topic.split("/"))


def subscription_qos(offers: list[QoSProfile]) -> QoSProfile:
    """A subscription QoS that matches every offer (and gets latched data when all are latched).
    KEEP_ALL: a message received but not yet written is never replaced by a newer one (a
    KEEP_LAST queue drops the oldest without any event when a burst outruns the writer)."""
    best_effort = any(o.reliability == ReliabilityPolicy.BEST_EFFORT for o in offers)
    latched = bool(offers) and all(o.durability == DurabilityPolicy.TRANSIENT_LOCAL for o in offers)
    return QoSProfile(history=HistoryPolicy.KEEP_ALL,
                      reliability=ReliabilityPolicy.BEST_EFFORT if best_effort else ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if latched else DurabilityPolicy.VOLATILE)


class RecorderNode(Node):
    """Discovers topics, subscribes raw and writes every message to a BagWriter."""

    def __init__(self, output: str, topics: list[str] | None = None, exclude: str | None = None,
                 include_hidden: bool = False, discovery_period: float = 0.5, chunk_age: float = 1.0,
                 tf: bool = True, static_tf: list[Transform] | None = None) -> None:
        super().__init__("clothfold_recorder")
        self.output = output
        self.wanted = None if not topics else {t if t.startswith("/") else "/" + t for t in topics}
        self.exclude = re.compile(exclude) if exclude else None
        self.include_hidden = include_hidden
        self.writer = BagWriter(output, overwrite=True, max_chunk_age=chunk_age)
        self.subs: dict[str, Any] = {}
        self.matched: set[str] = set()  # topics whose subscription has matched a publisher (logged once)
        self.skipped: dict[str, str] = {}  # topic -> reason it is not recorded
        self.lost: dict[str, int] = {}  # topic -> messages the middleware reports lost before they reached us
        self._lost_unsupported = False
        self._publishers_seen: dict[str, list] = {}  # topic -> its publishers' info at subscription
        self.tf = tf and self._selected(TF_TOPIC)
        self._tf_warned: set[str] = set()
        if tf and self._selected(TF_STATIC_TOPIC):
            self._write_static_tf(static_tf or [])
        self.discover()
        self.create_timer(discovery_period, self.discover)
        self.create_timer(max(0.05, chunk_age / 4), self.writer.flush_if_due)
        print(f"recording to {output}", flush=True)

    # -- discovery ----------------------------------------------------------------------
    def _selected(self, topic: str) -> bool:
        if self.wanted is not None:
            return topic in self.wanted
        if not self.include_hidden and is_hidden(topic):
            return False
        return not (self.exclude and self.exclude.search(topic))

    def discover(self) -> None:
        """Subscribe to every selected topic that has publishers and is not handled yet; log
        `matched TOPIC` once a subscription has matched a publisher (from then on, what that
        publisher sends is recorded: callers that must not miss a message wait for this line)."""
        self._report_matches()
        for topic, types in self.get_topic_names_and_types():
            if topic in self.subs or topic in self.skipped or not self._selected(topic):
                continue
            if len(types) != 1:
                self._skip(topic, f"has {len(types)} types ({', '.join(types)})")
                continue
            publishers = self.get_publishers_info_by_topic(topic)
            offers = [i.qos_profile for i in publishers]
            if not offers:
                continue  # only subscribers so far: wait for a publisher
            try:
                cls = message_class(types[0])
                message_definition(types[0])
            except (ImportError, AttributeError, ValueError) as err:
                self._skip(topic, f"type {types[0]} is not importable ({err})")
                continue
            except BagError as err:
                self._skip(topic, str(err))
                continue
            self.subs[topic] = self._subscribe(cls, topic, types[0], subscription_qos(offers))
            self._publishers_seen[topic] = publishers  # the channel's offers if its first message comes at shutdown
            self.get_logger().info(f"recording {topic} ({types[0]})")
        self._report_matches()

    def _subscribe(self, cls: Any, topic: str, type_name: str, qos: QoSProfile) -> Any:
        """A raw subscription writing to the bag, with a message-lost handler where the middleware
        has that event (without one, said once: losses are then not counted)."""
        def on_message(data: bytes, info: dict) -> None:
            self._on_message(topic, type_name, data, info)

        try:
            return self.create_subscription(cls, topic, on_message, qos, raw=True, event_callbacks=SubscriptionEventCallbacks(
                message_lost=lambda status: self._on_lost(topic, status)))
        except UnsupportedEventTypeError:
            if not self._lost_unsupported:
                self._lost_unsupported = True
                self.get_logger().warning("this middleware reports no lost messages: losses are not counted")
            return self.create_subscription(cls, topic, on_message, qos, raw=True)

    def _report_matches(self) -> None:
        for topic, sub in self.subs.items():
            if topic not in self.matched and (n := sub.get_publisher_count()) > 0:
                self.matched.add(topic)
                self.get_logger().info(f"matched {topic} ({n} publisher(s))")

    def _skip(self, topic: str, reason: str) -> None:
        self.skipped[topic] = reason
        self.get_logger().warning(f"not recording {topic}: {reason}")

    # -- messages -----------------------------------------------------------------------
    def _on_lost(self, topic: str, status: Any) -> None:
        """The middleware's message-lost event (e.g. best-effort samples missing on the wire):
        counted per topic, logged, and listed when the bag closes."""
        n = int(status.total_count_change)
        if n <= 0:
            return
        self.lost[topic] = self.lost.get(topic, 0) + n
        self.get_logger().warning(f"{n} message(s) on {topic} lost before they reached the recorder "
                                  f"({self.lost[topic]} on it so far)")

    def _on_message(self, topic: str, type_name: str, data: bytes, info: dict) -> None:
        log_ns = int(info.get("received_timestamp") or 0) or time.time_ns()
        pub_ns = int(info.get("source_timestamp") or 0) or log_ns
        if topic not in self.writer.topics:  # channel at first message: offers of publishers known by now
            try:
                pubs = self.get_publishers_info_by_topic(topic)
            except Exception:  # noqa: BLE001 - the context is shut down (written at shutdown): those at subscription
                pubs = self._publishers_seen.get(topic, [])
            type_hash = message_definition(type_name).type_hash
            if not type_hash and pubs:
                type_hash = str(pubs[0].topic_type_hash)
            self.writer.add_topic(topic, type_name, [from_profile(p.qos_profile) for p in pubs], type_hash=type_hash,
                                  definition=message_definition(type_name).text)
        self.writer.write(topic, data, log_ns, pub_ns)
        if self.tf and type_name == "geometry_msgs/msg/PoseStamped" and (m := GRIPPER_POSE.match(topic)):
            self._write_gripper_tf(m.group(1), data, log_ns, pub_ns)

    # -- frames (tf2_msgs is not installed from the wheels: written here) ------------------
    def _add_tf_topic(self, topic: str, qos) -> None:
        if topic not in self.writer.topics:
            text, type_hash = tf_definition()
            self.writer.add_topic(topic, TF_TYPE, [qos], definition=text, type_hash=type_hash)

    def _write_static_tf(self, extra: list[Transform]) -> None:
        self._add_tf_topic(TF_STATIC_TOPIC, TF_STATIC_QOS)
        frames = [Transform(*ROOT_TRANSFORM, 0), *extra]
        self.writer.write(TF_STATIC_TOPIC, encode_tf_message(frames), time.time_ns())

    def _write_gripper_tf(self, child: str, data: bytes, log_ns: int, pub_ns: int) -> None:
        from geometry_msgs.msg import PoseStamped
        from rclpy.serialization import deserialize_message

        try:
            m = deserialize_message(data, PoseStamped)
            p, q = m.pose.position, m.pose.orientation
            t = Transform(m.header.frame_id or ROOT_TRANSFORM[1], child,
                          rc.time_to_ns(m.header.stamp),
                          (p.x, p.y, p.z), (q.x, q.y, q.z, q.w))
        except (BagError, ValueError, TypeError) as err:
            if child not in self._tf_warned:  # once per gripper; the pose itself is recorded
                self._tf_warned.add(child)
                self.get_logger().warning(f"no /tf for {child}: {err}")
            return
        self._add_tf_topic(TF_TOPIC, TF_QOS)
        self.writer.write(TF_TOPIC, encode_tf_message([t]), log_ns, pub_ns)

    def _drain(self) -> int:
        """Write the messages received but not yet handed to a callback (the executor stops at
        SIGINT with them still queued; they can be taken after the context is shut down)."""
        n = 0
        for topic, sub in list(self.subs.items()):
            try:
                while True:
                    with sub.handle:
                        taken = sub.handle.take_message(sub.msg_type, sub.raw)
                    if taken is None:
                        break
                    sub.callback(*taken)
                    n += 1
            except Exception as err:  # noqa: BLE001 - a subscription torn down: what was written stays
                print(f"recorder: could not take the messages still queued on {topic}: {type(err).__name__}: {err}",
                      file=sys.stderr, flush=True)
        return n

    def destroy_node(self) -> None:
        """Write what is still queued, close the bag (complete file with summary) and report."""
        if not self.writer.closed:
            try:
                if (queued := self._drain()):
                    print(f"recorder: {queued} message(s) still queued at shutdown written", file=sys.stderr,
                          flush=True)
                self.writer.close()
            except Exception as err:  # noqa: BLE001 - e.g. disk full: say so, the file lacks its summary
                print(f"bag NOT closed: {self.output}: {type(err).__name__}: {err}; its messages up to the last "
                      f"complete chunk: clothfold bag recover {self.output}", file=sys.stderr, flush=True)
                super().destroy_node()
                raise ShutdownFailure(f"bag {self.output} not closed: {err}") from err
            for topic, reason in sorted(self.skipped.items()):
                print(f"recorder: skipped {topic}: {reason}", file=sys.stderr, flush=True)
            for topic, n in sorted(self.lost.items()):
                print(f"recorder: {n} message(s) on {topic} lost before they reached the recorder "
                      "(reported by the middleware; not in the bag)", file=sys.stderr, flush=True)
            if self.wanted:
                for topic in sorted(self.wanted - set(self.writer.topics)):
                    print(f"recorder: no messages on {topic}", file=sys.stderr, flush=True)
            print(f"bag closed: {self.output} ({self.writer.message_count} messages)", flush=True)
        super().destroy_node()


def build_parser(prog: str = "recorder_node") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="Record ROS 2 topics into one MCAP bag (rosbag2 layout).")
    p.add_argument("--output", "-o", required=True, help="bag path: x.mcap (single file) or a bag directory")
    p.add_argument("--topics", nargs="*", default=None, help="topics to record (default: all)")
    p.add_argument("--exclude", default=None, help="regex: do not record matching topics")
    p.add_argument("--include-hidden", action="store_true", help="also record hidden topics (e.g. /x/_action/...)")
    p.add_argument("--discovery-period", type=float, default=0.5, help="topic discovery period (s)")
    p.add_argument("--chunk-age", type=float, default=1.0, help="max age of unwritten data (s), bounds kill loss")
    p.add_argument("--no-tf", action="store_true",
                   help="do not write /tf_static (world -> table) and /tf (table -> gripper_<i>, from /gripper_<i>/pose)")
    p.add_argument("--static-tf", nargs=9, action="append", default=[],
                   metavar=("PARENT", "CHILD", "X", "Y", "Z", "QX", "QY", "QZ", "QW"),
                   help="one more fixed frame in /tf_static (m, quaternion), e.g. a camera: table camera 0 0 1 1 0 0 0")
    return p


def static_transforms(values: list[list[str]]) -> list[Transform]:
    """--static-tf arguments as Transforms (ValueError/BagError for a bad one)."""
    out = []
    for parent, child, *nums in values:
        v = [float(x) for x in nums]
        out.append(Transform(parent, child, 0, tuple(v[:3]), tuple(v[3:])))
    return out


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["recorder_node", *argv])
    args = build_parser().parse_args(remove_ros_args(full)[1:])
    if args.exclude:
        try:
            re.compile(args.exclude)
        except re.error as err:
            print(f"recorder_node: bad --exclude regex: {err}", file=sys.stderr)
            return 2
    try:
        static = static_transforms(args.static_tf)
    except (ValueError, BagError) as err:
        print(f"recorder_node: bad --static-tf: {err}", file=sys.stderr)
        return 2

    def recorder_node() -> RecorderNode:
        return RecorderNode(args.output, args.topics, args.exclude, args.include_hidden, args.discovery_period,
                            args.chunk_age, tf=not args.no_tf, static_tf=static)

    return run(recorder_node, full)


if __name__ == "__main__":
    sys.exit(main())
