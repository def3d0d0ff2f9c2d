"""Multi-process: recorder_node (SIGINT / SIGKILL) and the player, each on its own ROS_DOMAIN_ID."""
from __future__ import annotations

import json
import os
import selectors
import signal
import subprocess
import sys
import time
import zlib
from pathlib import Path

import pytest
from rclpy.serialization import serialize_message

from rosbags_decode import rosbags_messages

from clothfold_ros.bag import BagError, BagReader, BagWriter, Qos, message_definition, recover

ROOT = Path(__file__).resolve().parents[1]
N = 50

PUBLISHER = r'''
import sys, time
import rclpy
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, DurabilityPolicy
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import String
n_msgs, period = int(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("bag_test_publisher")
latched = node.create_publisher(String, "/latched", QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
latched.publish(String(data="spec"))
pose = node.create_publisher(PoseStamped, "/pose", QoSProfile(depth=100))
deadline = time.monotonic() + 30
while (pose.get_subscription_count() < 1 or latched.get_subscription_count() < 1) and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(0.2)
for i in range(n_msgs):
    m = PoseStamped()
    m.header.frame_id = "table"
    m.pose.position.x = float(i)
    pose.publish(m)
    time.sleep(period)
pose.wait_for_all_acked(Duration(seconds=5))
latched.wait_for_all_acked(Duration(seconds=5))
print("done", flush=True)
'''

SUBSCRIBER = r'''
import json, sys, time
import rclpy
from rclpy.qos import QoSProfile, DurabilityPolicy
from geometry_msgs.msg import PoseStamped
from std_msgs.msg import String
n_msgs, timeout = int(sys.argv[1]), float(sys.argv[2])
rclpy.init()
node = rclpy.create_node("bag_test_subscriber")
poses, latched = [], []
node.create_subscription(PoseStamped, "/pose", lambda m: poses.append((time.monotonic(), m.pose.position.x)),
                         QoSProfile(depth=1000))
node.create_subscription(String, "/latched", lambda m: latched.append(m.data),
                         QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL))
print("ready", flush=True)
deadline = time.monotonic() + timeout
while len(poses) < n_msgs and time.monotonic() < deadline:
    rclpy.spin_once(node, timeout_sec=0.05)
end = time.monotonic() + 0.5
while time.monotonic() < end:
    rclpy.spin_once(node, timeout_sec=0.05)
print(json.dumps({"poses": poses, "latched": latched}), flush=True)
'''


@pytest.fixture
def ros_env(request) -> dict[str, str]:
    """Environment with a ROS_DOMAIN_ID in 100..149 derived from the test name, localhost only."""
    env = dict(os.environ)
    env["ROS_DOMAIN_ID"] = str(100 + zlib.crc32(request.node.nodeid.encode()) % 50)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    return env


@pytest.fixture
def procs(tmp_path):
    """Start processes in their own process groups; kill every group at teardown."""
    started: list[subprocess.Popen] = []

    def start(args: list[str], env: dict[str, str], name: str) -> subprocess.Popen:
        err = open(tmp_path / f"{name}.stderr", "w")
        p = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=err, text=True, env=env, cwd=ROOT,
                             start_new_session=True)
        p.stderr_path = tmp_path / f"{name}.stderr"  # type: ignore[attr-defined]
        started.append(p)
        return p

    yield start
    for p in started:
        if p.poll() is None:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        p.wait(timeout=10)


def wait_line(p: subprocess.Popen, text: str, timeout: float) -> str:
    """Read stdout lines until one contains ``text``; fail with the process' stderr on timeout/exit."""
    sel = selectors.DefaultSelector()
    sel.register(p.stdout, selectors.EVENT_READ)
    deadline = time.monotonic() + timeout
    seen = []
    while time.monotonic() < deadline:
        if sel.select(timeout=max(0.0, deadline - time.monotonic())):
            line = p.stdout.readline()
            if not line:
                break
            seen.append(line)
            if text in line:
                return line
    err = Path(p.stderr_path).read_text()[-3000:]  # type: ignore[attr-defined]
    pytest.fail(f"no line with {text!r} from {p.args}: stdout {seen!r}, stderr:\n{err}")


def recorder(procs, env, out: Path, *extra: str) -> subprocess.Popen:
    p = procs([sys.executable, "-m", "clothfold_ros.nodes.recorder_node", "--output", str(out),
               "--exclude", "^/(rosout|parameter_events)$", "--no-tf", *extra], env, "recorder")
    wait_line(p, f"recording to {out}", 30)
    return p


def publish(procs, env, tmp_path: Path, n: int = N, period: float = 0.005) -> None:
    script = tmp_path / "pub.py"
    script.write_text(PUBLISHER)
    p = procs([sys.executable, str(script), str(n), str(period)], env, "publisher")
    wait_line(p, "done", 60)
    p.wait(timeout=10)


def decode_with_rosbags(path: Path) -> dict[str, list]:
    """topic -> messages decoded by rosbags (empty type store, the bag's own definitions)."""
    out: dict[str, list] = {}
    for topic, _, msg in rosbags_messages(path):
        out.setdefault(topic, []).append(msg)
    return out


def test_recorder_sigint_writes_complete_bag(procs, ros_env, tmp_path):
    out = tmp_path / "run.mcap"
    rec = recorder(procs, ros_env, out)
    publish(procs, ros_env, tmp_path)
    rec.send_signal(signal.SIGINT)
    line = wait_line(rec, "bag closed", 30)
    assert rec.wait(timeout=20) == 0
    msgs = decode_with_rosbags(out)
    assert [m.pose.position.x for m in msgs["/pose"]] == [float(i) for i in range(N)]
    assert all(m.header.frame_id == "table" for m in msgs["/pose"])
    assert [m.data for m in msgs["/latched"]] == ["spec"]
    assert line.strip() == f"bag closed: {out} ({N + 1} messages)"
    with BagReader(out) as bag:
        assert set(bag.topics) == {"/pose", "/latched"}
        latched = bag.topics["/latched"]
        assert [q.durability for q in latched.offered_qos] == ["transient_local"]
        assert [q.durability for q in bag.topics["/pose"].offered_qos] == ["volatile"]
        assert latched.type_hash == message_definition("std_msgs/msg/String").type_hash
        times = [m.log_time_ns for m in bag.messages(topics=["/pose"])]
        assert times == sorted(times) and 0 < (times[-1] - times[0]) / 1e9 < 10
        assert bag.metadata["message_count"] == N + 1


def test_recorder_sigkill_then_recover(procs, ros_env, tmp_path):
    out = tmp_path / "killed.mcap"
    rec = recorder(procs, ros_env, out, "--chunk-age", "0.2")
    publish(procs, ros_env, tmp_path)
    time.sleep(1.0)  # > chunk age + flush period: everything published is on disk
    os.killpg(rec.pid, signal.SIGKILL)
    rec.wait(timeout=10)
    with pytest.raises(BagError, match="truncated"):
        BagReader(out)
    report = recover(out, tmp_path / "fixed.mcap")
    assert not report.complete
    assert report.topics == {"/pose": N, "/latched": 1}
    msgs = decode_with_rosbags(tmp_path / "fixed.mcap")
    assert [m.pose.position.x for m in msgs["/pose"]] == [float(i) for i in range(N)]


def _replay_bag(path: Path, n: int, dt: float) -> None:
    from geometry_msgs.msg import PoseStamped
    from std_msgs.msg import String

    t0 = 1_700_000_000_000_000_000
    with BagWriter(path) as w:
        w.add_topic("/latched", "std_msgs/msg/String", [Qos(depth=1, durability="transient_local")])
        w.add_topic("/pose", "geometry_msgs/msg/PoseStamped", [Qos(depth=100)])
        w.write("/latched", serialize_message(String(data="spec")), t0)
        for i in range(n):
            m = PoseStamped()
            m.pose.position.x = float(i)
            w.write("/pose", serialize_message(m), t0 + int(i * dt * 1e9))


@pytest.mark.parametrize("rate,topics", [(1.0, []), (3.0, ["--topics", "/pose"])])
def test_replay_timing_rate_and_filter(procs, ros_env, tmp_path, rate, topics):
    n, dt = 20, 0.05
    bag = tmp_path / "play.mcap"
    _replay_bag(bag, n, dt)
    script = tmp_path / "sub.py"
    script.write_text(SUBSCRIBER)
    sub = procs([sys.executable, str(script), str(n), "30"], ros_env, "subscriber")
    wait_line(sub, "ready", 30)
    player = procs([sys.executable, "-m", "clothfold_ros.nodes.player_node", str(bag), "--rate", str(rate),
                    "--delay", "4", *topics], ros_env, "player")  # discovery on a loaded machine
    result = json.loads(wait_line(sub, "poses", 60))
    wait_line(player, f"published {n + (0 if topics else 1)} messages", 30)
    assert player.wait(timeout=20) == 0
    arrivals = [t for t, _ in result["poses"]]
    assert [x for _, x in result["poses"]] == [float(i) for i in range(n)]
    span = arrivals[-1] - arrivals[0]
    expected = (n - 1) * dt / rate
    assert abs(span - expected) < 0.25, (span, expected)
    gaps = [b - a for a, b in zip(arrivals, arrivals[1:])]
    assert min(gaps) >= 0 and sorted(gaps)[len(gaps) // 2] == pytest.approx(dt / rate, abs=0.03)
    assert result["latched"] == ([] if topics else ["spec"])


def test_replay_truncated_bag_is_a_clear_error(procs, ros_env, tmp_path):
    bag = tmp_path / "play.mcap"
    _replay_bag(bag, 200, 0.001)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    p = subprocess.run([sys.executable, "-m", "clothfold_ros.nodes.player_node", str(cut)], capture_output=True,
                       text=True, env=ros_env, cwd=ROOT, timeout=60)
    assert p.returncode == 1
    assert "Traceback" not in p.stderr and "truncated" in p.stderr and "clothfold bag recover" in p.stderr


def test_a_bag_that_cannot_be_closed_is_reported_and_fails_the_recorder(tmp_path, monkeypatch, capsys):
    """A close that fails (e.g. a full disk) was swallowed at shutdown: no 'bag closed' line, no
    error, exit code 0, a file without summary. Now it names the bag and the recover command
    and raises ShutdownFailure, for which `common.run` exits 1."""
    import rclpy

    from clothfold_ros.nodes import common
    from clothfold_ros.nodes.recorder_node import RecorderNode

    out = tmp_path / "x.mcap"
    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, domain_id=193)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    try:
        node = RecorderNode(str(out), topics=["/nothing"], tf=False)

        def full_disk():
            raise OSError(28, "No space left on device")

        monkeypatch.setattr(node.writer, "close", full_disk)
        with pytest.raises(common.ShutdownFailure, match="not closed"):
            node.destroy_node()
        err = capsys.readouterr().err
        assert "bag NOT closed" in err and f"clothfold bag recover {out}" in err
    finally:
        rclpy.try_shutdown(context=ctx)


def test_recorder_keeps_a_burst_larger_than_any_queue_depth(procs, ros_env, tmp_path):
    """3,000 messages published back to back: the recorder's subscriptions keep all (KEEP_ALL),
    so none is replaced in its queue while it writes (with a KEEP_LAST 1000 queue 246 of them were
    lost here, without any error or event)."""
    n = 3000
    out = tmp_path / "burst.mcap"
    rec = recorder(procs, ros_env, out)
    publish(procs, ros_env, tmp_path, n=n, period=0.0)  # returns once every message is acknowledged
    rec.send_signal(signal.SIGINT)  # at once: what is still queued is written at shutdown
    line = wait_line(rec, "bag closed", 60)
    assert rec.wait(timeout=20) == 0
    xs = [m.pose.position.x for m in decode_with_rosbags(out)["/pose"]]
    assert xs == [float(i) for i in range(n)], (len(xs), line)


def test_messages_the_middleware_reports_lost_are_counted_and_listed(tmp_path, monkeypatch, capsys):
    """Each recorded topic's subscription carries a message-lost handler; what it reports is
    logged and listed per topic when the bag closes (the bag cannot hold those messages)."""
    import rclpy
    from rclpy.event_handler import QoSSubscriptionEventType
    from std_msgs.msg import String

    from clothfold_ros.nodes.recorder_node import RecorderNode

    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, domain_id=194)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    try:
        talker = rclpy.create_node("talker", context=ctx)
        talker.create_publisher(String, "/chatter", 10)
        node = RecorderNode(str(tmp_path / "x.mcap"), topics=["/chatter"], tf=False)
        deadline = time.monotonic() + 10
        while "/chatter" not in node.subs and time.monotonic() < deadline:
            time.sleep(0.05)
            node.discover()
        handlers = {h.event_type: h for h in node.subs["/chatter"].event_handlers}
        lost = handlers[QoSSubscriptionEventType.RCL_SUBSCRIPTION_MESSAGE_LOST]
        for change, total in ((3, 3), (0, 3), (2, 5)):  # what rmw reports: the change since the last event
            lost.callback(type("Status", (), {"total_count_change": change, "total_count": total})())
        assert node.lost == {"/chatter": 5}
        node.destroy_node()
        err = capsys.readouterr().err
        assert "recorder: 5 message(s) on /chatter lost before they reached the recorder" in err
        talker.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_messages_still_queued_at_shutdown_are_written(tmp_path, monkeypatch, capsys):
    """The executor stops at SIGINT with messages still queued (a KEEP_ALL queue can hold many):
    the recorder takes and writes them before it closes the bag, and says how many."""
    import rclpy
    from std_msgs.msg import String

    from clothfold_ros.bag import BagReader
    from clothfold_ros.nodes.recorder_node import RecorderNode

    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, domain_id=195)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    out = tmp_path / "queued.mcap"
    try:
        talker = rclpy.create_node("talker", context=ctx)
        pub = talker.create_publisher(String, "/chatter", 10)
        node = RecorderNode(str(out), topics=["/chatter"], tf=False)
        deadline = time.monotonic() + 10
        while not (node.subs and pub.get_subscription_count()) and time.monotonic() < deadline:
            time.sleep(0.05)
            node.discover()
        for i in range(200):  # never spun: every message stays queued
            pub.publish(String(data=str(i)))
        pub.wait_for_all_acked()
        rclpy.try_shutdown(context=ctx)  # what SIGINT does
        node.destroy_node()
        assert "recorder: 200 message(s) still queued at shutdown written" in capsys.readouterr().err
        with BagReader(out) as bag:
            assert bag.topics["/chatter"].message_count == 200
            assert [q.reliability for q in bag.topics["/chatter"].offered_qos] == ["reliable"]  # as at subscription
        talker.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)


def test_a_middleware_without_the_message_lost_event_still_records(tmp_path, monkeypatch):
    """Where the middleware has no message-lost event, rclpy raises UnsupportedEventTypeError for
    the handler: the recorder subscribes without it, says once (for two topics) that losses are
    not counted, and records both."""
    import rclpy
    from rclpy.event_handler import UnsupportedEventTypeError
    from rclpy.impl.rcutils_logger import RcutilsLogger
    from std_msgs.msg import String

    from clothfold_ros.bag import BagReader
    from clothfold_ros.nodes.recorder_node import RecorderNode

    ctx = rclpy.Context()
    rclpy.init(args=[], context=ctx, domain_id=196)
    init = rclpy.node.Node.__init__
    monkeypatch.setattr(rclpy.node.Node, "__init__", lambda self, *a, **k: init(self, *a, **{"context": ctx, **k}))
    create = rclpy.node.Node.create_subscription

    def no_lost_event(self, *a, event_callbacks=None, **k):
        if event_callbacks is not None and event_callbacks.message_lost is not None:
            raise UnsupportedEventTypeError("message lost")
        return create(self, *a, **k)

    monkeypatch.setattr(rclpy.node.Node, "create_subscription", no_lost_event)
    said: list[str] = []
    warning = RcutilsLogger.warning
    monkeypatch.setattr(RcutilsLogger, "warning", lambda self, msg, **k: (said.append(msg), warning(self, msg, **k))[1])
    out = tmp_path / "nolost.mcap"
    topics = ["/chatter", "/chatter2"]
    try:
        talker = rclpy.create_node("talker", context=ctx)
        pubs = [talker.create_publisher(String, t, 10) for t in topics]
        node = RecorderNode(str(out), topics=topics, tf=False)
        deadline = time.monotonic() + 10
        while not (len(node.subs) == 2 and all(p.get_subscription_count() for p in pubs)) \
                and time.monotonic() < deadline:
            time.sleep(0.05)
            node.discover()
        for p in pubs:
            p.publish(String(data="kept"))
            p.wait_for_all_acked()
        rclpy.try_shutdown(context=ctx)
        node.destroy_node()
        with BagReader(out) as bag:
            assert [bag.topics[t].message_count for t in topics] == [1, 1]
        talker.destroy_node()
    finally:
        rclpy.try_shutdown(context=ctx)
    assert sorted(node.subs) == topics and node._lost_unsupported
    assert sum("losses are not counted" in m for m in said) == 1, said
