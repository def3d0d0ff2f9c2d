"""LockedActionClient: a response cannot be taken between sending a goal and recording it.

The race it closes (rclpy records a goal's sequence number only after sending it; a
response taken by another executor thread in between is dropped and the caller times
out) is made deterministic here: the handle's send starts a second thread that takes
data at once, and we look whether that take finished before send_goal_async returned.
"""
from __future__ import annotations

import threading

import pytest
import rclpy
from clothfold_msgs.action import ExecuteFold
from rclpy.action import ActionClient
from rclpy.node import Node

from clothfold_ros.nodes.action_client import LockedActionClient


class _RacingHandle:
    """Proxy of an action client handle: after each send, another thread calls take_data."""

    def __init__(self, client: ActionClient):
        self.inner = client._client_handle
        self.client = client
        self.take_done_before_return: list[bool] = []
        self.taker: threading.Thread | None = None

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def send_goal_request(self, request):
        seq = self.inner.send_goal_request(request)
        done = threading.Event()
        self.taker = threading.Thread(target=lambda: (self.client.take_data(), done.set()), daemon=True)
        self.taker.start()
        self.take_done_before_return.append(done.wait(0.3))
        return seq


@pytest.fixture
def node():
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, domain_id=179)
    n = Node("action_client_race", context=ctx)
    yield n
    n.destroy_node()
    rclpy.shutdown(context=ctx)


@pytest.mark.parametrize("cls, expect_take_first", [(ActionClient, True), (LockedActionClient, False)])
def test_take_waits_for_the_goal_to_be_recorded(node, cls, expect_take_first):
    client = cls(node, ExecuteFold, "/race_execute_fold")
    handle = _RacingHandle(client)
    client._client_handle = handle
    for flag in ("goal_response", "cancel_response", "result_response", "feedback", "status"):
        setattr(client, f"_is_{flag}_ready", False)  # set by is_ready() in a wait set; nothing is ready here
    future = client.send_goal_async(ExecuteFold.Goal())
    handle.taker.join(5.0)
    assert not handle.taker.is_alive()
    # plain rclpy: the second thread could take (and drop) the response before the goal was recorded
    assert handle.take_done_before_return == [expect_take_first]
    assert not future.done()  # no server: the goal stays pending, recorded
    client.destroy()
