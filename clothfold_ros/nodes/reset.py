"""Start over with a new shirt: call each pipeline node's `~/reset` (std_srvs/Trigger) in order.

What `ros2 service call /<node>/reset std_srvs/srv/Trigger` does once per node on a ROS 2
install. The order matters: the cloth is laid flat first (cloth_sim_node; a real robot has
none), then keypoint_node forgets the folds its keypoints follow, then the planner forgets the
folds it counted, so no node plans from another's stale history.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Sequence

#: Nodes with a ~/reset service, in the order they are reset.
RESET_ORDER: tuple[str, ...] = ("cloth_sim_node", "keypoint_node", "fold_planner_node")


@dataclass(frozen=True)
class ResetOutcome:
    """One node's answer: reached (its service matched within the timeout) and its reply."""

    node: str
    service: str
    reached: bool
    success: bool
    message: str


def service_name(node: str) -> str:
    """`/<node>/reset` for a node name; a name starting with '/' is taken as the full service name."""
    if not node or any(c.isspace() for c in node):
        raise ValueError(f"not a node or service name: {node!r}")
    return node if node.startswith("/") else f"/{node}/reset"


def reset_nodes(nodes: Sequence[str] = RESET_ORDER, timeout: float = 5.0) -> list[ResetOutcome]:
    """Call every node's reset service, one after another (timeout in s per node, for discovery
    and the reply). A node whose service does not appear is reported, not waited for twice."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from std_srvs.srv import Trigger

    if not (timeout > 0):
        raise ValueError(f"timeout must be > 0 s, got {timeout}")
    services = [service_name(n) for n in nodes]  # validate every name before touching ROS
    context = rclpy.Context()
    rclpy.init(args=[], context=context)
    outcomes = []
    try:
        node = rclpy.create_node("clothfold_reset", context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        for name, srv in zip(nodes, services):
            client = node.create_client(Trigger, srv)
            if not client.wait_for_service(timeout_sec=timeout):
                outcomes.append(ResetOutcome(name, srv, False, False, f"no {srv} service within {timeout:g} s"))
                continue
            future = client.call_async(Trigger.Request())
            deadline = time.monotonic() + timeout
            while not future.done() and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=0.05)
            if not future.done():
                future.cancel()
                outcomes.append(ResetOutcome(name, srv, True, False, f"{srv} did not answer within {timeout:g} s"))
                continue
            reply = future.result()
            outcomes.append(ResetOutcome(name, srv, True, bool(reply.success), reply.message))
        executor.shutdown()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=context)
    return outcomes


def exit_code(outcomes: Sequence[ResetOutcome], required: Sequence[str]) -> int:
    """0 when every reached node reset and every required node was reached (and at least one
    was), else 1."""
    reached = [o for o in outcomes if o.reached]
    if not reached or any(not o.success for o in reached):
        return 1
    return 1 if any(not o.reached and o.node in required for o in outcomes) else 0
