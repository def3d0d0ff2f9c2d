"""Playback (pure): the replay options and bag log time <-> wall-clock offsets for a rate factor."""
from __future__ import annotations

import argparse
from dataclasses import dataclass


def add_playback_arguments(p: argparse.ArgumentParser) -> None:
    """The replay options shared by ``player_node`` and ``clothfold replay``."""
    p.add_argument("bag", help="bag: x.mcap or a rosbag2 bag directory")
    p.add_argument("--rate", "-r", type=float, default=1.0, help="rate factor (2 = twice as fast)")
    p.add_argument("--topics", nargs="*", default=None, help="only these topics (default: all)")
    p.add_argument("--loop", "-l", action="store_true", help="repeat until interrupted")
    p.add_argument("--start-offset", type=float, default=0.0, help="skip the first S seconds of the bag")
    p.add_argument("--clock", type=float, nargs="?", const=40.0, default=None, metavar="HZ",
                   help="publish /clock with bag time at HZ (default 40) and before each message")
    p.add_argument("--delay", type=float, default=1.0, help="wait S seconds for discovery before playing")


@dataclass(frozen=True)
class PlaybackClock:
    """Maps bag time to wall time: a message logged at ``t`` ns is due ``(t - bag_start_ns) / rate``
    ns after ``wall_start`` (s, monotonic). rate > 0 (2 = twice as fast)."""

    bag_start_ns: int
    wall_start: float
    rate: float = 1.0

    def __post_init__(self) -> None:
        if not self.rate > 0:
            raise ValueError(f"playback rate must be > 0, got {self.rate}")

    def due(self, log_time_ns: int) -> float:
        """Monotonic wall time (s) at which a message logged at ``log_time_ns`` is due."""
        return self.wall_start + (log_time_ns - self.bag_start_ns) / 1e9 / self.rate

    def bag_time_ns(self, wall_now: float) -> int:
        """Bag time (ns) corresponding to monotonic wall time ``wall_now`` (s)."""
        return self.bag_start_ns + int(round((wall_now - self.wall_start) * self.rate * 1e9))
