"""The viewer (g2p.viewer): what it shows of known joint states and events, through a real Foxglove client."""

from __future__ import annotations

import json
import math
from pathlib import Path

import foxglove
import numpy as np
import pytest
from mcap.reader import make_reader

from g2p.bags.dataset import load_run
from g2p.bags.events import RunEvent
from g2p.description.urdf import packaged_leg_description
from g2p.validation import ConfigError
from g2p.viewer.channels import ATTEMPTS_TOPIC, JOINTS_TOPIC, SCENE_TOPIC, joints_message
from g2p.viewer.layout import layout_json, packaged_layout_path
from g2p.viewer.replay import replay_bag
from g2p.viewer.server import LegViewer, ViewerConfig
from g2p.viewer.state import BELT_MARK_SPACING_M, ViewState, belt_marks_x
from tests.viewer.foxglove_client import FoxgloveClient

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "bags" / "samples" / "treadmill-60s-babbling"
LEG = packaged_leg_description()
HIP_Z = 0.42  # the packaged leg: hip axis 0.42 m above the belt, 0.2 m thigh and shank, pad 37 mm below
TICK_NS = 12_800_000


def event(kind: str, attempt: int = 0, stamp_ns: int = 0, **fields: object) -> RunEvent:
    detail = fields.pop("detail", {})
    values = {
        "reward_mm": math.nan,
        "energy_j": math.nan,
        "tracking_mse_deg2": math.nan,
        "tracking_rmse_rad": math.nan,
        "best_reward_mm": math.nan,
        "sigma": math.nan,
        **fields,
    }
    return RunEvent(
        stamp_ns=stamp_ns,
        log_time_ns=stamp_ns,
        run_id="run",
        event=kind,
        phase="exploitation" if attempt else "",
        attempt=attempt,
        features=np.zeros(10),
        detail=detail,  # type: ignore[arg-type]
        **values,  # type: ignore[arg-type]
    )


def test_the_foot_of_a_known_posture_is_where_the_leg_puts_it() -> None:
    state = ViewState(LEG)
    frame = state.joint_state(5, np.array([math.pi / 2, 0.0]), np.array([0.1, 0.2]))
    # Hip flexed 90 deg, knee straight: the leg points forward, horizontal, at hip height.
    np.testing.assert_allclose(frame.foot_m, [0.437, HIP_Z], atol=1e-12)
    frame = state.joint_state(6, np.array([0.0, -math.pi / 2]), np.zeros(2))
    # Thigh down, knee flexed 90 deg: the shank points backward from the knee, 0.2 m below the hip.
    np.testing.assert_allclose(frame.foot_m, [-0.237, HIP_Z - 0.2], atol=1e-12)
    scene = state.scene()
    assert scene is not None
    np.testing.assert_allclose(
        scene.keypoints,
        [[0, HIP_Z], [0, HIP_Z - 0.2], [-0.2, HIP_Z - 0.2], [-0.237, HIP_Z - 0.2]],
        atol=1e-12,
    )
    np.testing.assert_allclose(scene.trail, [[0.437, HIP_Z], [-0.237, HIP_Z - 0.2]], atol=1e-12)
    assert frame.desired_rad is None and frame.attempt == 0 and frame.tick == -1


def test_the_desired_angles_follow_the_announced_cycle_from_the_first_tick_after_the_start() -> None:
    state = ViewState(LEG)
    cycle = np.array([[0.1, -0.1], [0.2, -0.2], [0.3, -0.3]])
    state.joint_state(1000, np.zeros(2), np.zeros(2))
    state.event(event("attempt_start", 4, stamp_ns=1000, detail={"desired_cycle_rad": cycle.tolist()}))
    # The tick stamped with the start itself (the reset sample) is not the attempt's.
    assert state.joint_state(1000, np.zeros(2), np.zeros(2)).desired_rad is None
    frames = [state.joint_state(1000 + k * TICK_NS, np.zeros(2), np.zeros(2)) for k in range(1, 6)]
    assert [f.tick for f in frames] == [0, 1, 2, 3, 4]
    np.testing.assert_array_equal([f.desired_rad for f in frames], cycle[[0, 1, 2, 0, 1]])
    assert all(f.attempt == 4 for f in frames)
    scene = state.scene()
    assert scene is not None and scene.desired_foot_path is not None
    np.testing.assert_allclose(
        scene.desired_foot_path[0], [0.2 * math.sin(0.1), HIP_Z - 0.2 * math.cos(0.1) - 0.237]
    )
    summary = state.event(
        event(
            "attempt_end",
            4,
            stamp_ns=99,
            reward_mm=70.0,
            best_reward_mm=80.0,
            sigma=0.05,
            detail={"control": "closed"},
        )
    )
    assert summary is not None and (summary.reward_mm, summary.best_reward_mm, summary.control) == (
        70.0,
        80.0,
        "closed",
    )
    after = state.joint_state(1000 + 6 * TICK_NS, np.zeros(2), np.zeros(2))
    assert after.desired_rad is None and after.attempt == 0
    assert state.scene().desired_foot_path is None  # type: ignore[union-attr]


def test_a_start_event_that_comes_after_its_first_ticks_still_counts_them() -> None:
    state = ViewState(LEG)
    for k in range(4):  # ticks 1, 2 and 3 come after the start's stamp (0) but before its event
        state.joint_state(k * TICK_NS, np.zeros(2), np.zeros(2))
    state.event(event("attempt_start", 1, stamp_ns=0, detail={"desired_cycle_rad": [[0.0, 0.0]] * 5}))
    assert state.joint_state(4 * TICK_NS, np.zeros(2), np.zeros(2)).tick == 3


def test_a_known_first_tick_stamp_starts_the_attempt_there() -> None:
    state = ViewState(LEG)
    first = 5 * TICK_NS
    state.event(
        event(
            "attempt_start",
            1,
            stamp_ns=0,
            detail={"desired_cycle_rad": [[1.0, 2.0]], "first_tick_stamp_ns": first + 3},
        )
    )
    ticks = [state.joint_state(k * TICK_NS, np.zeros(2), np.zeros(2)) for k in range(1, 8)]
    assert [t.tick for t in ticks] == [-1, -1, -1, -1, 0, 1, 2]


def test_the_belt_marks_move_backward_with_the_belt() -> None:
    still = belt_marks_x(0.0, 0.3)
    moved = belt_marks_x(10.0, 0.3)  # 10 mm of travel: the marks are 10 mm further toward -x
    assert 0.0 in still and np.all(np.abs(moved) <= 0.3)
    np.testing.assert_allclose(moved[1:] - moved[:-1], BELT_MARK_SPACING_M)
    assert np.any(np.isclose(moved, -0.010))
    np.testing.assert_allclose(belt_marks_x(50.0, 0.3), still, atol=1e-12)  # one spacing later, the same


def test_unmeasured_values_are_null_in_json() -> None:
    frame = ViewState(LEG).joint_state(1, np.array([0.1, -0.2]), np.zeros(2))
    message = joints_message(frame)
    assert message["proximal_desired_rad"] is None
    assert json.loads(json.dumps(message, allow_nan=False)) == message


def test_invalid_viewer_settings_are_refused_with_the_field() -> None:
    for bad, field in (
        ({"port": 70000}, "port"),
        ({"scene_rate_hz": 0.0}, "scene_rate_hz"),
        ({"host": " "}, "host"),
    ):
        with pytest.raises(ConfigError, match=field):
            ViewerConfig(**bad)  # type: ignore[arg-type]


def test_a_second_viewer_on_a_taken_port_fails_clearly() -> None:
    with LegViewer(LEG, ViewerConfig(port=0)) as first:
        with pytest.raises(RuntimeError):
            LegViewer(LEG, ViewerConfig(port=first.port))


def test_a_foxglove_client_sees_the_channels_and_the_leg_where_the_joint_states_put_it() -> None:
    seconds = iter(range(1_000_000))  # a wall clock a second ahead at every look: a scene every tick
    with LegViewer(LEG, ViewerConfig(port=0), clock=lambda: float(next(seconds))) as viewer:
        assert viewer.url.startswith("ws://127.0.0.1:")  # loopback unless asked
        client = FoxgloveClient(viewer.url, 60, {JOINTS_TOPIC: 39, SCENE_TOPIC: 40, ATTEMPTS_TOPIC: 1})
        assert viewer.wait_for_client(channels=3, timeout_s=60)
        cycle = [[0.3, -0.5], [0.2, -0.4]]
        viewer.event(event("attempt_start", 1, stamp_ns=0, detail={"desired_cycle_rad": cycle}))
        viewer.treadmill(12.5)
        postures = {}
        for k in range(1, 40):
            q = np.array([0.4 * math.sin(k / 5), -0.6 + 0.3 * math.cos(k / 5)])
            postures[k * TICK_NS] = q
            viewer.joint_state(k * TICK_NS, q, np.array([0.0, 0.1]))
        viewer.event(
            event("attempt_end", 1, stamp_ns=40 * TICK_NS, reward_mm=75.0, best_reward_mm=75.0, energy_j=30.0)
        )
        received = client.result()
    assert received.returncode == 0, received.stderr
    assert received.server["name"] == "G2P rig"
    channels = received.channels
    assert (channels[SCENE_TOPIC]["encoding"], channels[SCENE_TOPIC]["schemaName"]) == (
        "protobuf",
        "foxglove.SceneUpdate",
    )
    for topic, title in ((JOINTS_TOPIC, "g2p.JointFrame"), (ATTEMPTS_TOPIC, "g2p.AttemptSummary")):
        assert channels[topic]["encoding"] == "json" and channels[topic]["schemaEncoding"] == "jsonschema"
        assert json.loads(channels[topic]["schema"])["title"] == title
    joints = received.messages[JOINTS_TOPIC]
    for log_time, msg in joints:
        q = postures[log_time]
        assert (msg["proximal_rad"], msg["distal_rad"]) == (q[0], q[1])
        knee, ankle = [0.2 * math.sin(q[0]), HIP_Z - 0.2 * math.cos(q[0])], None
        ankle = [knee[0] + 0.2 * math.sin(q.sum()), knee[1] - 0.2 * math.cos(q.sum())]
        foot = [ankle[0] + 0.037 * math.sin(q.sum()), ankle[1] - 0.037 * math.cos(q.sum())]
        assert msg["foot_x_m"] == pytest.approx(foot[0], abs=1e-12)
        assert msg["foot_z_m"] == pytest.approx(foot[1], abs=1e-12)
        assert msg["belt_displacement_mm"] == 12.5
        k = log_time // TICK_NS - 1
        assert [msg["proximal_desired_rad"], msg["distal_desired_rad"]] == cycle[k % 2]
    assert len(joints) == 39
    scenes = received.messages[SCENE_TOPIC]
    assert len(scenes) == 40  # one per tick, one at the attempt's end (with the tick before it)
    for log_time, update in scenes:
        q = postures[log_time]
        entities = {e["id"]: e for e in update["entities"]}
        assert {"leg", "belt"} <= set(entities)
        assert all(e["frame_id"] == "treadmill" for e in entities.values())
        joints_xz = [
            (s["pose"]["position"]["x"], s["pose"]["position"]["z"]) for s in entities["leg"]["spheres"]
        ]
        expected = [(0.0, HIP_Z), (0.2 * math.sin(q[0]), HIP_Z - 0.2 * math.cos(q[0]))]
        expected.append((expected[1][0] + 0.2 * math.sin(q.sum()), expected[1][1] - 0.2 * math.cos(q.sum())))
        np.testing.assert_allclose(joints_xz, expected, atol=1e-12)
    for _, update in scenes[:-1]:
        paths = [e for e in update["entities"] if e["id"] == "desired_foot_path"]
        assert len(paths) == 1 and len(paths[0]["lines"][0]["points"]) == 2
    assert [d["id"] for d in scenes[-1][1]["deletions"]] == ["desired_foot_path"]
    ((_, attempt),) = received.messages[ATTEMPTS_TOPIC]
    assert (attempt["attempt"], attempt["reward_mm"], attempt["energy_j"], attempt["sigma"]) == (
        1,
        75.0,
        30.0,
        None,
    )


def test_a_replayed_bag_shows_every_tick_with_the_desired_angles_of_its_attempt(tmp_path: Path) -> None:
    # A second sink on the viewer's context records everything it logs, so nothing a slow client drops
    # hides a mistake.
    out = tmp_path / "view.mcap"
    with LegViewer(LEG, ViewerConfig(port=0)) as viewer:
        writer = foxglove.open_mcap(out, context=viewer.context)
        shown = replay_bag(SAMPLE, viewer, rate=float("inf"))
        writer.close()
    run = load_run(SAMPLE)
    assert shown == len(run.ticks.stamps_ns)
    with open(out, "rb") as f:
        logged = [
            (c.topic, json.loads(m.data))
            for _, c, m in make_reader(f).iter_messages()
            if c.message_encoding == "json"
        ]
    joints = [m for t, m in logged if t == JOINTS_TOPIC]
    np.testing.assert_array_equal(
        [[m["proximal_rad"], m["distal_rad"]] for m in joints], run.ticks.recording.position_rad
    )
    for a in run.attempts:
        rows = [m for m in joints if m["attempt"] == a.attempt]
        assert a.desired_position_rad is not None and len(rows) == len(a.recording)
        np.testing.assert_array_equal(
            [[m["proximal_desired_rad"], m["distal_desired_rad"]] for m in rows], a.desired_position_rad
        )
    attempts = [m for t, m in logged if t == ATTEMPTS_TOPIC]
    assert [m["reward_mm"] for m in attempts] == pytest.approx([a.reward_mm for a in run.attempts])


def test_the_shipped_layout_is_the_generated_one_and_shows_the_viewer_topics() -> None:
    shipped = packaged_layout_path().read_text()
    assert shipped == layout_json(), "regenerate it: python -m g2p.viewer.layout > src/g2p/viewer/layout.json"
    text = json.dumps(json.loads(shipped))
    for topic in (SCENE_TOPIC, JOINTS_TOPIC, ATTEMPTS_TOPIC):
        assert topic in text
