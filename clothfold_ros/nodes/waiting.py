"""Waiting on a condition variable until a probe gives a value or a deadline passes, and on an
rclpy future that another thread's executor completes (no rclpy import)."""
from __future__ import annotations

import threading
import time
from typing import Callable, TypeVar

T = TypeVar("T")


def wait_until(cond: threading.Condition, probe: Callable[[], T | None], timeout: float,
               poll: float | None = None) -> T | None:
    """Hold `cond` and call `probe` until it returns something other than None (returned),
    waiting on `cond` in between (at most `poll` s at a time, None = until notified); None
    once `timeout` s have passed. Exceptions from `probe` propagate."""
    deadline = time.monotonic() + timeout
    with cond:
        while True:
            value = probe()
            if value is not None:
                return value
            left = deadline - time.monotonic()
            if left <= 0:
                return None
            cond.wait(left if poll is None else min(left, poll))


def wait_future(future, timeout: float) -> bool:
    """Block until `future` (an rclpy Future, completed by an executor spinning in another
    thread) is done; False if `timeout` s pass first (the future stays pending)."""
    done = threading.Event()
    future.add_done_callback(lambda _: done.set())
    return done.wait(timeout)
