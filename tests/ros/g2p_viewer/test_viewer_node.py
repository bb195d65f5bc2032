"""The installed `view` executable: the live graph and a recorded run, seen by a real Foxglove client."""

from __future__ import annotations

import json
import math
import os
import signal
import socket
import time
from pathlib import Path

import pytest
from std_msgs.msg import Header

from g2p.bags.ticks import header_stamp_ns
from g2p_interfaces.msg import LearnerEvent
from g2p_ros import contract
from tests.ros.rig_nodes import RigPeer, start_sim
from tests.ros.rosproc import ROOT, NodeProcess, wait_until
from tests.viewer.foxglove_client import FoxgloveClient

SAMPLE = ROOT / "bags" / "samples" / "treadmill-60s-babbling"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def learner_event(kind: str, stamp_ns: int, **fields: object) -> LearnerEvent:
    msg = LearnerEvent(header=Header(), run_id="run", event=kind, phase="exploration", attempt=1)
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(stamp_ns, 1_000_000_000)
    for name in (
        "reward_mm",
        "energy_j",
        "tracking_mse_deg2",
        "tracking_rmse_rad",
        "best_reward_mm",
        "sigma",
    ):
        setattr(msg, name, float(fields.pop(name, math.nan)))  # type: ignore[arg-type]
    msg.detail = json.dumps(fields.pop("detail", {}))
    return msg


def test_the_live_viewer_shows_the_rigs_joint_states_on_its_own_leg(tmp_path: Path, peer: RigPeer) -> None:
    # The rig's leg hangs 0.6 m above the belt (in the air), not the packaged 0.42 m: the viewer draws
    # the leg of the rig's robot_description.
    sim = start_sim(tmp_path, "time_mode:=realtime", "leg.carriage_height_m:=0.6")
    port = free_port()
    viewer = NodeProcess("g2p_viewer", "view", ["--ros-args", "-p", f"port:={port}"], tmp_path)
    events = peer.node.create_publisher(LearnerEvent, "learner/events", contract.EVENT_QOS)
    client = FoxgloveClient(f"ws://127.0.0.1:{port}", 90, {"/view/joints": 200, "/view/attempts": 1})
    wait_until(lambda: events.get_subscription_count() > 0, 30.0, "the viewer to subscribe to the events")
    # The attempt starts at a tick both the viewer (its first tick at the client) and the peer received:
    # the viewer counts the ticks since from there on (under load it may match the rig seconds late).
    viewer_first, _ = client.first_message("/view/joints", 60.0)

    def peer_latest() -> int:
        with peer.lock:
            return (
                header_stamp_ns(peer.received["joint_states"][-1].header)
                if peer.received["joint_states"]
                else 0
            )

    wait_until(lambda: peer_latest() >= viewer_first, 30.0, "the rig's joint states at the peer")
    cycle = [[0.1 * k, -0.05 * k] for k in range(7)]
    start_stamp = peer_latest()
    events.publish(learner_event("attempt_start", start_stamp, detail={"desired_cycle_rad": cycle}))
    time.sleep(3.0)
    events.publish(learner_event("attempt_end", start_stamp + 3_000_000_000, reward_mm=12.5, energy_j=4.0))
    received = client.result()
    assert viewer.stop() == 0, viewer.log()
    assert sim.stop() == 0, sim.log()
    assert received.returncode == 0, received.stderr + viewer.log()

    with peer.lock:
        rig = {
            header_stamp_ns(m.header): (list(m.position), list(m.velocity))
            for m in peer.received["joint_states"]
        }
    # Ticks from before the peer's subscription matched the rig's reached only the viewer.
    joints = [(t, m) for t, m in received.messages["/view/joints"] if t >= min(rig)]
    assert len(joints) >= 150
    for log_time, msg in joints:
        position, velocity = rig[log_time]
        assert [msg["proximal_rad"], msg["distal_rad"]] == position[:2]
        assert [msg["proximal_velocity_rad_s"], msg["distal_velocity_rad_s"]] == velocity[:2]
    during = [(t, m) for t, m in joints if m["attempt"] == 1]
    assert during, "no tick of the attempt reached the client"
    ticks_before = {t: sum(1 for s in rig if start_stamp < s < t) for t, _ in during}
    for log_time, msg in during:
        assert msg["tick"] == ticks_before[log_time]
        assert [msg["proximal_desired_rad"], msg["distal_desired_rad"]] == cycle[msg["tick"] % len(cycle)]
    ((_, attempt),) = received.messages["/view/attempts"]
    assert (attempt["attempt"], attempt["reward_mm"], attempt["energy_j"]) == (1, 12.5, 4.0)
    hips = [
        e["spheres"][0]["pose"]["position"]["z"]
        for _, update in received.messages["/view/scene"]
        for e in update["entities"]
        if e["id"] == "leg"
    ]
    assert hips and hips[-1] == pytest.approx(0.6)


def test_view_replays_a_bag_to_a_client_and_exits(tmp_path: Path) -> None:
    port = free_port()
    replay = NodeProcess("g2p_viewer", "view", [str(SAMPLE), "--rate", "200", "--port", str(port)], tmp_path)
    # The replay waits for a client: the one that connects now sees the whole run, its 6 attempts too,
    # though it reads nothing while the replay plays (0.6 s at rate 200) and for a while after: the server
    # keeps what it could not yet send, and serves it until the client leaves.
    client = FoxgloveClient(f"ws://127.0.0.1:{port}", 90, {"/view/attempts": 6})
    client.first_message("/view/joints", 60)
    os.kill(client.popen.pid, signal.SIGSTOP)
    time.sleep(3.0)
    os.kill(client.popen.pid, signal.SIGCONT)
    received = client.result()
    assert received.returncode == 0, received.stderr + replay.log()
    replay.popen.wait(60)  # the client has left
    assert replay.stop() == 0, replay.log()
    assert "replayed 9487 ticks" in replay.log()
    rewards = [m["reward_mm"] for _, m in received.messages["/view/attempts"]]
    summary = json.loads((SAMPLE / "summary.json").read_text())
    assert rewards == pytest.approx([a["reward_mm"] for a in summary["attempts"]])


def test_view_of_a_missing_bag_names_it(tmp_path: Path) -> None:
    missing = tmp_path / "no-such-run"
    proc = NodeProcess("g2p_viewer", "view", [str(missing), "--port", "0"], tmp_path)
    assert proc.popen.wait(60) == 2
    proc.stop()
    assert str(missing) in proc.log()
