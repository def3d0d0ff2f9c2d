"""player_node: republish a bag with its original timing and QoS.

Usage: ``player_node BAG [--rate R] [--topics T ...] [--loop] [--start-offset S] [--clock [HZ]]
[--delay S]``. Messages go out in log-time order at ``(t - t0) / rate`` after start; each
topic is published with a QoS adapted from the recorded offers (reliable / transient_local
only when every recorded publisher offered it). ``--clock`` publishes rosgraph_msgs/Clock
with the bag time at HZ and before every message; a /clock recorded in the bag is then not
replayed (one clock only). A damaged or truncated bag gives a one
line error (exit code 1), topics whose type is not installed, or was recorded with another
definition (type hash) than the installed one, are skipped and reported.
Nothing to play (every topic skipped, no message on the topics played at or after the
start offset) is a one-line error too, at start: ``--loop`` would otherwise spin.
SIGINT/SIGTERM stop the replay with its summary line and exit code 0.
"""
from __future__ import annotations

import argparse
import math
import signal
import sys
import threading
import time
from dataclasses import dataclass, field

import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import uninstall_signal_handlers
from rclpy.utilities import remove_ros_args

from ..bag import BagError, BagReader, Qos, message_definition, playback_qos
from ..bag.playback import PlaybackClock, add_playback_arguments
from .conversions import ns_to_time
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
        self.ok = node.context.ok  # False once shut down (SIGINT/SIGTERM through rclpy's handlers)
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
                installed = message_definition(info.type).type_hash
            except (ImportError, AttributeError, ValueError, BagError) as err:
                self.stats.skipped[name] = f"type {info.type} is not installed ({err})"
                continue
            if info.type_hash and installed and info.type_hash != installed:  # its bytes would not decode as the installed type
                self.stats.skipped[name] = (f"recorded with another definition of {info.type} (type hash "
                                            f"{info.type_hash}, installed {installed})")
                continue
            self.publishers[name] = node.create_publisher(cls, name, to_profile(playback_qos(info.offered_qos)))
        self._check_something_to_play(start_offset)
        self.clock_pub = None
        if clock_hz:
            from rosgraph_msgs.msg import Clock
            self.clock_pub = node.create_publisher(Clock, "/clock", QoSProfile(depth=10))
            self._clock_cls = Clock

    def _check_something_to_play(self, start_offset: float) -> None:
        """BagError when no message would be published (with --loop every pass would end at once)."""
        if not self.publishers:
            why = "; ".join(f"{t}: {r}" for t, r in self.stats.skipped.items()) or "no topic selected"
            raise BagError(f"nothing to play: every topic is skipped ({why})")
        count = sum(self.bag.topics[t].message_count for t in self.publishers)
        if count == 0:
            raise BagError(f"nothing to play: no messages on {', '.join(sorted(self.publishers))}")
        if self.start_ns > self.bag.end_ns:
            raise BagError(f"nothing to play: --start-offset {start_offset:g} s is past the end of the bag "
                           f"({self.bag.duration_ns / 1e9:.3f} s long)")

    def _publish_clock(self, t_ns: int) -> None:
        self.clock_pub.publish(self._clock_cls(clock=ns_to_time(t_ns)))

    def _wait_until(self, clock: PlaybackClock, due: float) -> None:
        while True:
            now = time.monotonic()
            if now >= due or not self.ok():
                return
            step = min(due - now, 0.1)  # wake up to notice shutdown
            if self.clock_pub is not None:
                self._publish_clock(clock.bag_time_ns(now))
                step = min(step, 1.0 / self.clock_hz)
            time.sleep(step)

    def play(self) -> PlayStats:
        """Play once (or until interrupted with --loop); returns the statistics. BagError when
        a whole pass publishes nothing (the topics played end before the start offset)."""
        while self.ok():
            clock = PlaybackClock(self.start_ns, time.monotonic(), self.rate)
            published = 0
            for msg in self.bag.messages(topics=list(self.publishers), start_ns=self.start_ns):
                self._wait_until(clock, clock.due(msg.log_time_ns))
                if not self.ok():
                    break
                if self.clock_pub is not None:
                    self._publish_clock(msg.log_time_ns)
                self.publishers[msg.topic].publish(msg.data)
                self.stats.published[msg.topic] = self.stats.published.get(msg.topic, 0) + 1
                published += 1
            if not self.ok():
                break  # stopped mid-pass: not a pass done
            self.stats.loops += 1
            if not published:  # every pass would be as empty: with --loop, a busy loop
                raise BagError(f"nothing to play: no message on {', '.join(sorted(self.publishers))} at or after "
                               f"the start offset ({(self.start_ns - self.bag.start_ns) / 1e9:g} s)")
            if not self.loop:
                break
        self._wait_for_acks()
        return self.stats

    def _wait_for_acks(self) -> None:
        """Let reliable subscribers receive the tail; not once the context is shut down (a
        SIGTERM/SIGINT stopped the replay: the publishers are invalid then)."""
        for pub in self.publishers.values():
            if not self.ok():
                return
            if pub.qos_profile.reliability != ReliabilityPolicy.RELIABLE:
                continue
            try:
                pub.wait_for_all_acked(Duration(seconds=2))
            except Exception:  # noqa: BLE001 - RCLError: the context was shut down meanwhile
                if self.ok():
                    raise
                return


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
    player = None
    try:
        player = Player(node, bag, args.topics, args.rate, args.loop, args.start_offset, args.clock)
        for topic, reason in player.stats.skipped.items():
            print(f"{prog}: skipping {topic}: {reason}", file=sys.stderr)
        print(f"playing {args.bag}: {bag.message_count} messages, {len(player.publishers)} topics, "
              f"{bag.duration_ns / 1e9:.3f} s at rate {args.rate}", flush=True)
        _sleep_unless_stopped(node, max(0.0, args.delay))
        player.play()
        if not node.context.ok():  # SIGTERM (rclpy's handler shut the context down)
            print(f"{prog}: stopped", file=sys.stderr)
    except BagError as err:
        print(f"{prog}: error: {err}", file=sys.stderr)
        code = 1
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
    finally:
        old = _ignore_stop_signals()  # a second Ctrl-C must not cut the cleanup short
        try:
            if player is not None and code == 0:
                print(f"published {player.stats.total} messages", flush=True)
            bag.close()
            node.destroy_node()
            rclpy.try_shutdown()
        finally:
            uninstall_signal_handlers()  # rclpy's (already replaced by SIG_IGN), so a later init installs them
            _restore_signals(old)
    return code


def _sleep_unless_stopped(node: Node, seconds: float) -> None:
    """time.sleep that ends early once the context is shut down (SIGTERM)."""
    deadline = time.monotonic() + seconds
    while node.context.ok() and (left := deadline - time.monotonic()) > 0:
        time.sleep(min(left, 0.1))


def _ignore_stop_signals() -> dict:
    """Ignore SIGINT/SIGTERM (main thread only); returns the handlers to restore."""
    if threading.current_thread() is not threading.main_thread():
        return {}
    old = {}
    for sig in (signal.SIGINT, signal.SIGTERM):
        old[sig] = signal.getsignal(sig)
        signal.signal(sig, signal.SIG_IGN)
    return old


def _restore_signals(old: dict) -> None:
    for sig, handler in old.items():
        signal.signal(sig, handler if handler is not None else signal.SIG_DFL)


if __name__ == "__main__":
    sys.exit(main())
