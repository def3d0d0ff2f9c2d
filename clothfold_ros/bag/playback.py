"""Playback timing (pure): bag log time <-> wall-clock offsets for a rate factor."""
from __future__ import annotations

from dataclasses import dataclass


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
