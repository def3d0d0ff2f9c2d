"""Topic names, QoS profiles and the `main()` runner shared by the clothfold nodes.

The QoS here is the robot interface contract (docs/robot-interface.md): a real driver
must offer compatible QoS on the same topics.
"""
from __future__ import annotations

import faulthandler
import signal
import sys
import traceback
from typing import Callable

import rclpy
from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

# -- topics -------------------------------------------------------------------------------
CLOCK = "/clock"
CLOTH_STATE = "/cloth/state"
CLOTH_MARKER = "/cloth/marker"
CLOTH_POINTS = "/cloth/points"
KEYPOINTS = "/keypoints"
FOLD_SPEC = "/fold/spec"
FOLD_RESULT = "/fold/result"
FOLD_ACTIVE = "/fold/active"  # the spec trajectory_node is executing (stamped with its start time)
PLAN_FOLD = "/plan_fold"
EXECUTE_FOLD = "/execute_fold"


def gripper_topic(i: int, leaf: str) -> str:
    """/gripper_<i>/<leaf>: leaf is target_pose, command, pose, path, state or marker."""
    return f"/gripper_{i}/{leaf}"


# -- QoS ----------------------------------------------------------------------------------
def _qos(depth: int, durability: DurabilityPolicy = DurabilityPolicy.VOLATILE) -> QoSProfile:
    return QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=depth, reliability=ReliabilityPolicy.RELIABLE,
                      durability=durability)


LATCHED = _qos(1, DurabilityPolicy.TRANSIENT_LOCAL)  # /fold/spec, /keypoints, /cloth/state, paths
# per-step visualisation (cloth mesh, gripper boxes): latched for a late viewer, and deep enough
# that a slow reader (the recorder, a viewer on a busy machine) gets every step: a reliable
# KEEP_LAST writer drops its oldest unacknowledged sample when its history is full
STREAMED = _qos(100, DurabilityPolicy.TRANSIENT_LOCAL)
TARGETS = _qos(1000)  # streamed target poses: reliable, deep (lock-step needs every sample)
COMMANDS = _qos(10)  # gripper open/close
RESULTS = _qos(10)  # /fold/result
FEEDBACK = _qos(10)  # actual gripper poses, visualisation
CLOCK_QOS = _qos(10)  # /clock publisher (reliable; rclpy's best-effort subscriber is compatible)


# -- running a node -------------------------------------------------------------------------
class ShutdownFailure(RuntimeError):
    """Raised by a node's destroy_node when it could not finish its work (e.g. close its bag):
    `run` then reports it and exits 1 (other errors of a context torn down are ignored)."""


def run(factory: Callable[[], Node], args: list[str] | None = None, threads: int = 1) -> int:
    """rclpy.init, build the node, spin until SIGINT/SIGTERM, clean shutdown.

    Start-up errors (bad parameters, ...) are printed as one clear line; exit code 2.
    """
    if hasattr(faulthandler, "register"):
        faulthandler.register(signal.SIGUSR1, all_threads=True)  # kill -USR1 <pid>: dump every thread's stack
    rclpy.init(args=sys.argv if args is None else args)
    node = None
    code = 0
    spinning = False
    try:
        node = factory()
        executor = MultiThreadedExecutor(num_threads=threads) if threads > 1 else SingleThreadedExecutor()
        executor.add_node(node)
        spinning = True
        executor.spin()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception as err:  # start-up failure: one clear line, no traceback noise
        if spinning and not rclpy.ok():
            # SIGINT/SIGTERM shut the context down while the executor was between two waits: rclpy then
            # raises e.g. "RCLError: failed to initialize wait set"; that is a normal shutdown
            pass
        else:
            name = getattr(factory, "__name__", "node")
            print(f"[{name}] fatal: {type(err).__name__}: {err}", file=sys.stderr, flush=True)
            if node is not None:
                traceback.print_exc()
            code = 2
    finally:
        if node is not None:
            try:
                node.destroy_node()
            except ShutdownFailure as err:  # work the node could not finish (a bag not closed): exit 1
                print(f"[{getattr(factory, '__name__', 'node')}] shutdown failed: {err}", file=sys.stderr, flush=True)
                code = code or 1
            except Exception:  # noqa: BLE001 - rclpy tearing down a context already shut down
                pass
        rclpy.try_shutdown()
    return code
