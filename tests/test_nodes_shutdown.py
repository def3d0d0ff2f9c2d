"""Shutdown and replay details: a SIGINT/SIGTERM that shuts the context down while the executor is
between two waits ends the node cleanly (rclpy raises "failed to initialize wait set" then), and
`clothfold replay --clock` on a bag that holds /clock publishes one clock, not two."""
from __future__ import annotations

import pytest

DOMAIN = 159


@pytest.fixture
def ros_env(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")


def test_wait_set_error_at_shutdown_is_a_clean_exit(ros_env, monkeypatch, capfd):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node

    from clothfold_ros.nodes import common

    def spin_then_signal(self):
        rclpy.shutdown()  # what rclpy's signal handler does
        raise rclpy._rclpy_pybind11.RCLError("failed to initialize wait set")

    monkeypatch.setattr(SingleThreadedExecutor, "spin", spin_then_signal)
    code = common.run(lambda: Node("shutdown_check"), ["shutdown_check"])
    assert code == 0
    assert "fatal" not in capfd.readouterr().err


def test_a_node_that_cannot_finish_at_shutdown_exits_1(ros_env, monkeypatch, capfd, tmp_path):
    """The recorder whose bag cannot be closed (a full disk) raises ShutdownFailure from
    destroy_node; `common.run` reports it and exits 1 (it exited 0, the failure swallowed)."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    from clothfold_ros.nodes import common
    from clothfold_ros.nodes.recorder_node import RecorderNode

    def spin_then_signal(self):
        rclpy.shutdown()  # SIGINT
        raise KeyboardInterrupt

    def recorder():
        node = RecorderNode(str(tmp_path / "x.mcap"), topics=["/nothing"], tf=False)

        def full_disk():
            raise OSError(28, "No space left on device")

        node.writer.close = full_disk
        return node

    monkeypatch.setattr(SingleThreadedExecutor, "spin", spin_then_signal)
    assert common.run(recorder, ["recorder_node"]) == 1
    err = capfd.readouterr().err
    assert "bag NOT closed" in err and "shutdown failed: bag" in err


def test_replay_clock_skips_the_recorded_clock(ros_env, tmp_path):
    import rclpy
    from rclpy.serialization import serialize_message
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String

    from clothfold_ros.bag import BagReader, BagWriter
    from clothfold_ros.bag.definitions import message_definition
    from clothfold_ros.nodes.player_node import Player

    path = tmp_path / "clock.mcap"
    w = BagWriter(str(path))
    for topic, cls, name in (("/clock", Clock, "rosgraph_msgs/msg/Clock"), ("/chatter", String, "std_msgs/msg/String")):
        d = message_definition(name)
        w.add_topic(topic, name, [], type_hash=d.type_hash, definition=d.text)
        for k in range(3):
            msg = cls()
            if topic == "/clock":
                msg.clock.sec = k
            else:
                msg.data = str(k)
            w.write(topic, serialize_message(msg), 1_000_000_000 + k * 1000, 1_000_000_000 + k * 1000)
    w.close()
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    try:
        node = rclpy.create_node("replay_check", context=ctx)
        bag = BagReader(str(path))
        with_clock = Player(node, bag, clock_hz=40.0)
        assert "/clock" not in with_clock.publishers and "/clock" in with_clock.stats.skipped
        assert node.count_publishers("/clock") == 1  # the player's own
        node2 = rclpy.create_node("replay_check2", context=ctx)
        plain = Player(node2, bag)  # without --clock the recorded /clock is replayed
        assert "/clock" in plain.publishers
        bag.close()
    finally:
        rclpy.try_shutdown(context=ctx)
