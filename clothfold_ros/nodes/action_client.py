"""An rclpy ActionClient that is safe to call from a thread other than its executor's.

rclpy's ActionClient sends a request first and records its sequence number afterwards.
When an executor spins in another thread (PipelineClient's background spin, or a
MultiThreadedExecutor serving a service callback), a fast server's response can be taken
in between: rclpy then logs "Ignoring unexpected goal response" and the future never
completes, so the caller times out although the server answered. This client holds one
lock across send-and-record and across taking responses, so a response is only taken
once its request is recorded.
"""
from __future__ import annotations

import threading

from rclpy.action import ActionClient


class LockedActionClient(ActionClient):
    """ActionClient whose send/record and take steps exclude each other (see module doc)."""

    def __init__(self, *args, **kwargs) -> None:
        self._send_lock = threading.RLock()
        super().__init__(*args, **kwargs)

    def send_goal_async(self, *args, **kwargs):
        with self._send_lock:
            return super().send_goal_async(*args, **kwargs)

    def _cancel_goal_async(self, *args, **kwargs):
        with self._send_lock:
            return super()._cancel_goal_async(*args, **kwargs)

    def _get_result_async(self, *args, **kwargs):
        with self._send_lock:
            return super()._get_result_async(*args, **kwargs)

    def take_data(self):
        with self._send_lock:
            return super().take_data()
