"""nodes/waiting.wait_until: a value as soon as the probe gives one, None at the deadline."""
from __future__ import annotations

import threading
import time

import pytest

from clothfold_ros.nodes.waiting import wait_until


def test_returns_the_value_once_notified_and_none_at_the_deadline():
    cond, box = threading.Condition(), []

    def later():
        time.sleep(0.1)
        with cond:
            box.append(7)
            cond.notify_all()

    threading.Thread(target=later).start()
    tic = time.monotonic()
    assert wait_until(cond, lambda: box[0] if box else None, 5.0) == 7
    assert time.monotonic() - tic < 2.0
    tic = time.monotonic()
    assert wait_until(cond, lambda: None, 0.3, poll=0.05) is None
    assert 0.3 <= time.monotonic() - tic < 2.0
    assert wait_until(cond, lambda: False, 5.0) is False  # any non-None value ends the wait


def test_probe_errors_propagate():
    with pytest.raises(RuntimeError, match="exited"):
        wait_until(threading.Condition(), lambda: (_ for _ in ()).throw(RuntimeError("exited")), 1.0)


class _Future:
    """The part of rclpy's Future the waits use: done-callbacks, completed by another thread."""

    def __init__(self, result=None):
        self._callbacks, self._result = [], result

    def add_done_callback(self, cb):
        self._callbacks.append(cb)

    def complete(self):
        for cb in self._callbacks:
            cb(self)

    def result(self):
        return self._result


def test_wait_future_returns_when_another_thread_completes_it_and_times_out_otherwise():
    from clothfold_ros.nodes.waiting import wait_future

    f = _Future()
    threading.Timer(0.05, f.complete).start()
    t = time.monotonic()
    assert wait_future(f, 5.0) and time.monotonic() - t < 2.0
    assert not wait_future(_Future(), 0.05)


def test_a_goal_given_up_on_is_cancelled_if_it_is_accepted_later():
    """fold_planner_node told its caller the goal failed (no answer in goal_timeout): a late
    acceptance must not run the fold."""
    from types import SimpleNamespace

    from clothfold_ros.nodes.fold_planner_node import _cancel_if_accepted

    cancels = []
    accepted = SimpleNamespace(accepted=True, cancel_goal_async=lambda: cancels.append("accepted"))
    refused = SimpleNamespace(accepted=False, cancel_goal_async=lambda: cancels.append("refused"))
    for handle in (accepted, refused, None):
        _cancel_if_accepted(_Future(handle))
    assert cancels == ["accepted"]
