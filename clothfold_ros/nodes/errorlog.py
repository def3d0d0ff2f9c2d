"""ErrorLog: which input errors a node logs, so that none vanish without a line. Pure: no rclpy.

Errors are counted by kind: the caller's key plus the message with its numbers blanked, so
distinct errors are distinct kinds and the same error with other values is one. The first
of a kind is logged; later ones of the same kind at most once per `interval` wall seconds,
each line carrying the kind's count and how many were not logged since the previous line.
A bad input after a quiet spell is therefore always logged, and a flood costs one line per
interval and kind.
"""
from __future__ import annotations

import re
import time
from typing import Callable

_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


class ErrorLog:
    def __init__(self, interval: float = 1.0, clock: Callable[[], float] = time.monotonic) -> None:
        self.interval = float(interval)
        self.clock = clock
        self.counts: dict[str, int] = {}
        self._last: dict[str, float] = {}
        self._unlogged: dict[str, int] = {}

    def record(self, kind: str, text: str) -> str | None:
        """Count one error; the line to log now, or None (counted, reported with the next line)."""
        kind = f"{kind}: {_NUMBER.sub('#', text)}"
        n = self.counts.get(kind, 0) + 1
        self.counts[kind] = n
        now = self.clock()
        last = self._last.get(kind)
        if last is not None and now - last < self.interval:
            self._unlogged[kind] = self._unlogged.get(kind, 0) + 1
            return None
        skipped = self._unlogged.pop(kind, 0)
        self._last[kind] = now
        note = f"#{n} of this kind" + (f"; {skipped} more not logged since the last line" if skipped else "")
        return f"{text} ({note})"

    def unlogged(self) -> dict[str, int]:
        """Kinds with errors counted but not logged yet, and how many."""
        return {k: v for k, v in self._unlogged.items() if v}

    def flush(self) -> str | None:
        """One line reporting every error not logged yet (None if there are none); resets them."""
        left = self.unlogged()
        self._unlogged.clear()
        if not left:
            return None
        return "errors not logged individually: " + "; ".join(f"{v} x [{k}]" for k, v in sorted(left.items()))
