"""A fake rig for the recorder and replay tests, run as a process from the repository's root:
`python -m tests.ros.fake_rig_publisher publish ...`.

It publishes the rig contract's topics with their real message types and QoS (plus /clock, /diagnostics,
the learner's events and inverse maps, and a latched `~/config`), one deterministic tick after another,
so the tests can rebuild every published message and compare it field by field with the bag. It imports
only installed packages.
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import time
from typing import Any

import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
from rclpy.duration import Duration
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String

from g2p_interfaces.msg import (
    InverseMapWeights,
    LearnerEvent,
    MotorActivation,
    MotorPower,
    NamedArray,
    Treadmill,
)
from g2p_ros import contract
from g2p_ros.params import CONFIG_QOS

STAMP0_NS = 50 * 1_000_000_000
TICK_NS = 12_820_513  # 78 Hz of rig time
# Fast simulation: the rig's publishers need a history that covers the recorder's worst scheduling pause
# on a loaded machine (contract.SAMPLE_QOS keeps 200 = 40 ms at 5000 ticks/s; see docs/BAGS.md).
FAST_SIM_DEPTH = 10000
RIG_TOPICS = ["/leg/joint_states", "/leg/treadmill", "/leg/motor_power", "/leg/applied_activation"]
RELIABLE_TOPICS = [*RIG_TOPICS, "/diagnostics", "/leg/learner/events", "/leg/learner/inverse_map"]
CONFIG_TOPIC = "/leg/fake_rig/config"
CONFIG = {"fake_rig": True, "tick_ns": TICK_NS}


def tick_messages(k: int) -> list[tuple[str, Any]]:
    """The messages of tick k, in publishing order: (topic, message)."""
    ns = STAMP0_NS + k * TICK_NS
    stamp = Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)
    header = Header(stamp=stamp, frame_id="leg")
    out: list[tuple[str, Any]] = [
        ("/clock", Clock(clock=stamp)),
        (
            "/leg/joint_states",
            JointState(
                header=header,
                name=["proximal", "distal"],
                position=[1e-3 * k, -2e-3 * k],
                velocity=[0.5, -0.5],
            ),
        ),
        ("/leg/treadmill", Treadmill(header=header, displacement_mm=float(k), velocity_mm_s=39.0)),
        (
            "/leg/motor_power",
            MotorPower(
                header=header,
                current_a=[0.1, 0.2, 0.3],
                power_w=[1.0, 2.0, float(k % 9)],
                energy_j=[0.01 * k, 0.02 * k, 0.03 * k],
            ),
        ),
        ("/leg/applied_activation", MotorActivation(header=header, activation=[0.15, 0.5, (k % 100) / 100])),
    ]
    if k % 78 == 0:
        out.append(
            (
                "/diagnostics",
                DiagnosticArray(header=header, status=[DiagnosticStatus(name="fake rig", message=str(k))]),
            )
        )
    if k % 100 == 0:
        out.append(
            (
                "/leg/learner/events",
                LearnerEvent(
                    header=header,
                    run_id="fake",
                    event="attempt_start",
                    phase="exploration",
                    attempt=k // 100 + 1,
                    features=[0.5] * 10,
                    detail=json.dumps({"k": k}),
                ),
            )
        )
    if k % 500 == 0:
        out.append(
            (
                "/leg/learner/inverse_map",
                InverseMapWeights(
                    header=header,
                    run_id="fake",
                    refinement=k // 500,
                    format_version=1,
                    arrays=[NamedArray(name="W1", shape=[2, 2], data=[float(k), 1.0, 2.0, 3.0])],
                    training_samples=k,
                ),
            )
        )
    return out


def publish_main(argv: list[str]) -> None:
    """Publish `--ticks` ticks at `--rate` ticks/s (0: as fast as possible) once the recorder subscribed."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--ticks", type=int, required=True)
    parser.add_argument("--rate", type=float, default=0.0)
    parser.add_argument("--depth", type=int, default=contract.SAMPLE_QOS.depth)
    parser.add_argument("--hold", action="store_true", help="stay alive after publishing until SIGTERM")
    parser.add_argument(
        "--wait-for", nargs="*", default=RELIABLE_TOPICS, help="start once these are subscribed"
    )
    ns = parser.parse_args(argv)
    rclpy.init()
    node = rclpy.create_node("fake_rig", namespace="/leg")
    sample_qos = contract.qos(ns.depth)  # SAMPLE_QOS's, with the test's depth
    types = {
        "/clock": (Clock, contract.CLOCK_QOS),
        "/diagnostics": (DiagnosticArray, contract.DIAGNOSTICS_QOS),
        "/leg/learner/events": (LearnerEvent, contract.EVENT_QOS),
        "/leg/learner/inverse_map": (InverseMapWeights, contract.MAP_QOS),
        "/leg/joint_states": (JointState, sample_qos),
        "/leg/treadmill": (Treadmill, sample_qos),
        "/leg/motor_power": (MotorPower, sample_qos),
        "/leg/applied_activation": (MotorActivation, sample_qos),
    }
    pubs = {topic: node.create_publisher(cls, topic, qos) for topic, (cls, qos) in types.items()}
    config = node.create_publisher(String, "~/config", CONFIG_QOS)
    config.publish(String(data=json.dumps(CONFIG)))
    deadline = time.monotonic() + 60
    while any(pubs[t].get_subscription_count() == 0 for t in ns.wait_for) and time.monotonic() < deadline:
        time.sleep(0.02)
    published: dict[str, int] = {t: 0 for t in pubs}
    start = time.monotonic()
    for k in range(ns.ticks):
        for topic, msg in tick_messages(k):
            pubs[topic].publish(msg)
            published[topic] += 1
        if ns.rate > 0:
            delay = start + (k + 1) / ns.rate - time.monotonic()
            if delay > 0:
                time.sleep(delay)
    elapsed = time.monotonic() - start
    for topic in RELIABLE_TOPICS:
        pubs[topic].wait_for_all_acked(Duration(seconds=30))
    print(json.dumps({"published": published, "ticks_per_s": ns.ticks / elapsed}), flush=True)
    if ns.hold:
        signal.sigwait({signal.SIGTERM, signal.SIGINT})
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    if sys.argv[1:2] == ["publish"]:
        publish_main(sys.argv[2:])
    else:
        sys.exit(
            "usage: python -m tests.ros.fake_rig_publisher publish --ticks N [--rate HZ] [--depth N] [--hold]"
        )
