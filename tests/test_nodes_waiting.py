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
