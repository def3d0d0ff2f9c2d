"""player_node (`clothfold replay`): nothing to play is refused at once (with --loop it would
spin at full CPU; topics of types not installed, or recorded with another definition, are
skipped), and a SIGTERM/SIGINT stop is clean: exit code 0 with the summary line, also
when a second interrupt arrives while the node is being cleaned up."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import pytest
from rclpy.serialization import serialize_message

from clothfold_ros.bag import BagError, BagReader, BagWriter, Qos

ROOT = Path(__file__).resolve().parents[1]
DOMAIN = 186
T0 = 1_000_000_000


@pytest.fixture
def ros_env(monkeypatch):
    monkeypatch.setenv("ROS_DOMAIN_ID", str(DOMAIN))
    monkeypatch.setenv("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    return dict(os.environ)


def _bag(path: Path, topics: dict[str, list[float]], types: dict[str, str] | None = None) -> Path:
    """A bag of std_msgs/String: topic -> log times (s after T0); reliable offers."""
    from std_msgs.msg import String

    with BagWriter(path) as w:
        for topic in topics:
            if topic in (types or {}):  # its definition and type hash given (not the installed ones)
                w.add_topic(topic, types[topic], [Qos(depth=10)], definition="string data", type_hash="h")
            else:
                w.add_topic(topic, "std_msgs/msg/String", [Qos(depth=10)])
        for topic, times in topics.items():
            for t in times:
                w.write(topic, serialize_message(String(data=f"{topic} {t}")), T0 + int(t * 1e9))
    return path


@pytest.mark.parametrize("topics,kwargs,words", [
    ({"/a": [0.0, 1.0]}, {"start_offset": 10.0}, "--start-offset 10 s is past the end of the bag"),
    ({"/a": [0.0, 1.0], "/b": []}, {"topics": ["/b"]}, "no messages on /b"),
    ({"/a": [0.0, 1.0], "/x": [0.5]}, {"topics": ["/x"], "types": {"/x": "no_such_msgs/msg/Thing"}},
     "every topic is skipped (/x: type no_such_msgs/msg/Thing is not installed"),
    # an installed type recorded with another definition (type hash "h"): its bytes would not decode
    ({"/a": [0.0, 1.0], "/y": [0.5]}, {"topics": ["/y"], "types": {"/y": "std_msgs/msg/String"}},
     "every topic is skipped (/y: recorded with another definition of std_msgs/msg/String (type hash h, "
     "installed RIHS01_"),
])
def test_nothing_to_play_is_refused_at_start(ros_env, tmp_path, topics, kwargs, words):
    import rclpy

    from clothfold_ros.nodes.player_node import Player

    types = kwargs.pop("types", None)
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    try:
        node = rclpy.create_node("player_check", context=ctx)
        with BagReader(_bag(tmp_path / "b.mcap", topics, types)) as bag:
            with pytest.raises(BagError, match="nothing to play") as err:
                Player(node, bag, loop=True, **kwargs)
            assert words in str(err.value)
    finally:
        rclpy.try_shutdown(context=ctx)


def test_a_pass_that_publishes_nothing_ends_the_loop(ros_env, tmp_path):
    """/a ends before the start offset, the bag (/b) does not: the first pass publishes nothing;
    --loop must not repeat it (it spun at ~140k passes/s)."""
    import rclpy

    from clothfold_ros.nodes.player_node import Player

    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx)
    stopper = threading.Timer(5.0, lambda: rclpy.try_shutdown(context=ctx))  # ends a spinning loop
    stopper.start()
    try:
        node = rclpy.create_node("player_loop_check", context=ctx)
        with BagReader(_bag(tmp_path / "b.mcap", {"/a": [0.0, 0.5], "/b": [3.0]})) as bag:
            player = Player(node, bag, topics=["/a"], loop=True, start_offset=2.0)
            with pytest.raises(BagError, match=r"nothing to play: no message on /a at or after the start "
                                                r"offset \(2 s\)"):
                player.play()
            assert player.stats.loops == 1 and player.stats.total == 0
        assert ctx.ok()  # it ended by itself, not through the stopper
    finally:
        stopper.cancel()
        rclpy.try_shutdown(context=ctx)


def test_replay_refuses_a_loop_with_nothing_to_play(ros_env, tmp_path):
    bag = _bag(tmp_path / "b.mcap", {"/a": [0.0, 1.0]})
    try:
        p = subprocess.run([sys.executable, "-m", "clothfold_ros.nodes.player_node", str(bag), "--loop",
                            "--start-offset", "30", "--delay", "0"], capture_output=True, text=True, env=ros_env,
                           cwd=ROOT, timeout=60)
    except subprocess.TimeoutExpired:
        pytest.fail("the player kept looping over nothing")
    assert p.returncode == 1, p.stderr
    assert p.stderr.strip().splitlines() == [
        "clothfold replay: error: nothing to play: --start-offset 30 s is past the end of the bag (1.000 s long)"]


# player_node with Node.destroy_node sending the same signal again: the second interrupt arrives
# during the cleanup (as a launcher's or an impatient user's second Ctrl-C does)
SECOND_SIGNAL = r'''
import os, signal, sys
from rclpy.node import Node
from clothfold_ros.nodes import player_node
sig = int(sys.argv[1])
original = Node.destroy_node
def destroy_node(self):
    os.kill(os.getpid(), sig)
    return original(self)
Node.destroy_node = destroy_node
sys.exit(player_node.main(sys.argv[2:]))
'''


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT])
def test_a_stop_signal_ends_the_replay_cleanly(ros_env, tmp_path, sig):
    bag = _bag(tmp_path / "long.mcap", {"/chatter": [0.5 * k for k in range(40)]})  # 20 s
    proc = subprocess.Popen([sys.executable, "-c", SECOND_SIGNAL, str(int(sig)), str(bag), "--delay", "0"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ros_env, cwd=ROOT)
    try:
        first = proc.stdout.readline()
        assert first.startswith("playing "), (first, proc.stderr.read() if proc.poll() is not None else "")
        threading.Event().wait(1.2)  # a few messages out, on a reliable topic (acked wait at the end)
        proc.send_signal(sig)
        out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    assert "Traceback" not in err and "Error" not in err, err
    assert out.strip().startswith("published ") and out.strip().endswith(" messages"), out
    assert err.strip() in ("clothfold replay: stopped", "clothfold replay: interrupted"), err
