"""player_node: republish a bag with its original timing and QoS.

Usage: ``player_node BAG [--rate R] [--topics T ...] [--loop] [--start-offset S] [--clock [HZ]]
[--delay S]``. Messages go out in log-time order at ``(t - t0) / rate`` after start; each
topic is published with a QoS adapted from the recorded offers (reliable / transient_local
only when every recorded publisher offered it). ``--clock`` publishes rosgraph_msgs/Clock
with the bag time at HZ and before every message; a /clock recorded in the bag is then not
replayed (one clock only). A damaged or truncated bag gives a one
line error (exit code 1), topics whose type is not installed are skipped and reported.
"""
from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args

from ..bag import BagError, BagReader, Qos, playback_qos
from ..bag.playback import PlaybackClock, add_playback_arguments
from .recorder_node import message_class


def to_profile(q: Qos) -> QoSProfile:
    """rclpy QoSProfile for a playback Qos (keep_last/reliability/durability/depth)."""
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=max(1, q.depth),
                      reliability=ReliabilityPolicy.RELIABLE if q.reliability == "reliable"
                      else ReliabilityPolicy.BEST_EFFORT,
                      durability=DurabilityPolicy.TRANSIENT_LOCAL if q.durability == "transient_local"
                      else DurabilityPolicy.VOLATILE)


@dataclass
class PlayStats:
    """Published messages per topic, loops done, skipped topics (topic -> reason)."""

    published: dict[str, int] = field(default_factory=dict)
    loops: int = 0
    skipped: dict[str, str] = field(default_factory=dict)

    @property
    def total(self) -> int:
        return sum(self.published.values())


class Player:
    """Publishes the messages of an open BagReader through ``node``."""

    def __init__(self, node: Node, bag: BagReader, topics: list[str] | None = None, rate: float = 1.0,
                 loop: bool = False, start_offset: float = 0.0, clock_hz: float | None = None) -> None:
        if not 0 < rate < math.inf:
            raise BagError(f"--rate must be > 0 and finite, got {rate}")
        if not 0 <= start_offset < math.inf:
            raise BagError(f"--start-offset must be >= 0 s and finite, got {start_offset}")
        if clock_hz is not None and not 0 < clock_hz < math.inf:
            raise BagError(f"--clock must be > 0 Hz and finite, got {clock_hz}")
        self.node, self.bag, self.rate, self.loop = node, bag, rate, loop
        self.start_ns = bag.start_ns + int(start_offset * 1e9)
        self.clock_hz = clock_hz
        self.stats = PlayStats()
        names = list(bag.topics) if not topics else [t if t.startswith("/") else "/" + t for t in topics]
        unknown = [t for t in names if t not in bag.topics]
        if unknown:
            raise BagError(f"topics not in the bag: {', '.join(unknown)} (has {', '.join(sorted(bag.topics))})")
        self.publishers = {}
        if clock_hz and "/clock" in names:  # --clock publishes /clock itself: never two clocks
            names.remove("/clock")
            self.stats.skipped["/clock"] = "the bag's /clock is not replayed: --clock publishes /clock from bag time"
        for name in names:
            info = bag.topics[name]
            try:
                cls = message_class(info.type)
            except (ImportError, AttributeError, ValueError) as err:
                self.stats.skipped[name] = f"type {info.type} is not installed ({err})"
                continue
            self.publishers[name] = node.create_publisher(cls, name, to_profile(playback_qos(info.offered_qos)))
        self.clock_pub = None
        if clock_hz:
            from rosgraph_msgs.msg import Clock
            self.clock_pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=10))
            self._clock_cls = Clock

    def _publish_clock(self, t_ns: int) -> None:
        msg = self._clock_cls()
        msg.clock.sec, msg.clock.nanosec = divmod(int(t_ns), 1_000_000_000)
        self.clock_pub.publish(msg)

    def _wait_until(self, clock: PlaybackClock, due: float) -> None:
        while True:
            now = time.monotonic()
            if now >= due or not rclpy.ok():
                return
            step = min(due - now, 0.1)  # wake up to notice shutdown
            if self.clock_pub is not None:
                self._publish_clock(clock.bag_time_ns(now))
                step = min(step, 1.0 / self.clock_hz)
            time.sleep(step)

    def play(self) -> PlayStats:
        """Play once (or until interrupted with --loop); returns the statistics."""
        while rclpy.ok():
            clock = PlaybackClock(self.start_ns, time.monotonic(), self.rate)
            for msg in self.bag.messages(topics=list(self.publishers), start_ns=self.start_ns):
                self._wait_until(clock, clock.due(msg.log_time_ns))
                if not rclpy.ok():
                    break
                if self.clock_pub is not None:
                    self._publish_clock(msg.log_time_ns)
                self.publishers[msg.topic].publish(msg.data)
                self.stats.published[msg.topic] = self.stats.published.get(msg.topic, 0) + 1
            self.stats.loops += 1
            if not self.loop:
                break
        for pub in self.publishers.values():  # let reliable subscribers receive the tail
            if pub.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
                pub.wait_for_all_acked(Duration(seconds=2))
        return self.stats


def build_parser(prog: str = "player_node") -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog=prog, description="Republish a bag with its original timing and QoS.")
    add_playback_arguments(p)
    return p


def main(argv: list[str] | None = None) -> int:
    full = list(sys.argv if argv is None else ["player_node", *argv])
    return play(build_parser().parse_args(remove_ros_args(full)[1:]), full)


def play(args: argparse.Namespace, rcl_args: list[str] | None = None) -> int:
    """Replay the bag named by parsed playback options (add_playback_arguments); exit code."""
    prog = "clothfold replay"
    try:
        bag = BagReader(args.bag)
    except BagError as err:
        print(f"{prog}: error: {err}", file=sys.stderr)
        return 1
    rclpy.init(args=rcl_args)
    node = rclpy.create_node("clothfold_player")
    code = 0
    try:
        player = Player(node, bag, args.topics, args.rate, args.loop, args.start_offset, args.clock)
        for topic, reason in player.stats.skipped.items():
            print(f"{prog}: skipping {topic}: {reason}", file=sys.stderr)
        print(f"playing {args.bag}: {bag.message_count} messages, {len(player.publishers)} topics, "
              f"{bag.duration_ns / 1e9:.3f} s at rate {args.rate}", flush=True)
        time.sleep(max(0.0, args.delay))
        stats = player.play()
        print(f"published {stats.total} messages", flush=True)
    except BagError as err:
        print(f"{prog}: error: {err}", file=sys.stderr)
        code = 1
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
    finally:
        bag.close()
        node.destroy_node()
        rclpy.try_shutdown()
    return code


if __name__ == "__main__":
    sys.exit(main())
