"""Test data for the bag tests: message builders and a synthetic learning run with known answers.

Messages are built and serialized with the rosbags typestore filled from the installed .msg files, so
these tests need no ROS runtime.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from g2p.bags import BagWriter, TopicSpec, TypeRegistry
from g2p.bags.qos import make_qos

INFINITE_NS = 2**63 - 1
# rmw numbers: history keep_last=1; reliability reliable=1, best_effort=2;
# durability transient_local=1, volatile=2
SAMPLE_QOS = make_qos(1, 200, 1, 2, INFINITE_NS, INFINITE_NS, 1, INFINITE_NS, False)
CLOCK_QOS = make_qos(1, 1, 2, 2, INFINITE_NS, INFINITE_NS, 1, INFINITE_NS, False)
LATCHED_QOS = make_qos(1, 1, 1, 1, INFINITE_NS, INFINITE_NS, 1, INFINITE_NS, False)

TICK_NS = 12_820_513  # 78 Hz
T0_NS = 1_000 * 1_000_000_000


class Messages:
    """Builds and serializes messages of the installed types."""

    def __init__(self, registry: TypeRegistry) -> None:
        self.registry = registry
        self.store = registry.typestore

    def make(self, msgtype: str, **fields: Any) -> Any:
        self.registry.register(msgtype)
        return self.store.types[msgtype](**fields)

    def time(self, ns: int) -> Any:
        return self.make("builtin_interfaces/msg/Time", sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(self, ns: int, frame_id: str = "leg") -> Any:
        return self.make("std_msgs/msg/Header", stamp=self.time(ns), frame_id=frame_id)

    def cdr(self, msg: Any) -> bytes:
        return bytes(self.store.serialize_cdr(msg, msg.__msgtype__))


@dataclass
class SyntheticRun:
    """What a synthetic run bag contains, for known-answer checks."""

    path: Path
    babbling_ticks: list[int] = field(default_factory=list)
    attempt_ticks: dict[int, list[int]] = field(default_factory=dict)
    rewards: dict[int, float] = field(default_factory=dict)
    energies: dict[int, float] = field(default_factory=dict)
    mse: dict[int, float] = field(default_factory=dict)
    phases: dict[int, str] = field(default_factory=dict)
    maps: list[dict[str, np.ndarray]] = field(default_factory=list)


def tick_values(k: int) -> dict[str, Any]:
    """Deterministic tick k of the synthetic rig. Babbling ticks with k % 5 != 0 sit at a limit."""
    near = k % 5 != 0
    return {
        "t_s": (T0_NS + k * TICK_NS) * 1e-9,
        "activation": np.array([0.15 + 0.001 * (k % 800), 0.5, 1.0 - 0.001 * (k % 800)]),
        "position_rad": np.array([0.99, -0.75]) if near else np.array([0.0 + 1e-4 * k, -0.75]),
        "velocity_rad_s": np.array([0.01 * k, -0.02 * k]),
        "belt_mm": 0.5 * k,
        "belt_velocity_mm_s": 39.0,
        "current_a": np.array([0.1, 0.2, 0.3]) * (1 + k % 7),
        "power_w": np.array([1.0, 2.0, 3.0]) * (1 + k % 3),
        "energy_j": np.array([0.01, 0.02, 0.03]) * k,
    }


def rig_messages(messages: Messages, k: int, stamp: int) -> dict[str, Any]:
    """The four rig messages of synthetic tick k, stamped `stamp` (ns), by role."""
    v, h = tick_values(k), messages.header(stamp)
    return {
        "joint_states": messages.make(
            "sensor_msgs/msg/JointState",
            header=h,
            name=["proximal", "distal"],
            position=v["position_rad"],
            velocity=v["velocity_rad_s"],
            effort=np.zeros(0),
        ),
        "treadmill": messages.make(
            "g2p_interfaces/msg/Treadmill",
            header=h,
            displacement_mm=v["belt_mm"],
            velocity_mm_s=v["belt_velocity_mm_s"],
        ),
        "motor_power": messages.make(
            "g2p_interfaces/msg/MotorPower",
            header=h,
            current_a=v["current_a"],
            power_w=v["power_w"],
            energy_j=v["energy_j"],
        ),
        "applied_activation": messages.make(
            "g2p_interfaces/msg/MotorActivation", header=h, activation=v["activation"]
        ),
    }


def rig_limits_message(messages: Messages, k: int, stamp: int) -> Any:
    """Synthetic tick k's RigLimits: the envelope's ramp held M2 0.1 below its command when k % 10 == 3."""
    applied = tick_values(k)["activation"]
    changed = k % 10 == 3
    return messages.make(
        "g2p_interfaces/msg/RigLimits",
        header=messages.header(stamp),
        commanded=applied + np.array([0.0, 0.0, 0.1 if changed else 0.0]),
        joint_scale=np.ones(3),
        ramp_cap=np.where([False, False, changed], applied, 1.0),
        thermal_scale=np.ones(3),
        winding_estimate_c=np.full(3, 25.0),
        tension_estimate_n=np.full(3, 5.0),
        slack_loop_estimate_m=np.zeros(3),
        trip="",
    )


def learner_event(messages: Messages, stamp: int, run_id: str, kind: str, **fields: Any) -> Any:
    """A LearnerEvent stamped `stamp` (ns); unset numbers are NaN, unset arrays empty, detail a dict."""
    values: dict[str, Any] = dict(
        phase="",
        attempt=0,
        features=np.zeros(0),
        reward_mm=np.nan,
        energy_j=np.nan,
        tracking_mse_deg2=np.nan,
        tracking_rmse_rad=np.nan,
        best_reward_mm=np.nan,
        sigma=np.nan,
    )
    values.update(fields)
    values["detail"] = json.dumps(values.get("detail") or {})
    return messages.make(
        "g2p_interfaces/msg/LearnerEvent", header=messages.header(stamp), run_id=run_id, event=kind, **values
    )


def write_synthetic_run(
    path: Path,
    messages: Messages,
    skip_joint_state_of: int | None = 210,
    robot_descriptions: tuple[str, ...] = (),
) -> SyntheticRun:
    """A learning run: babbling (200 ticks), idle ticks, 5 attempts of 50 ticks, inverse maps, a config.

    Known answers: 80% of babbling ticks lie within 5% of a limit (limits given in run_start); rewards
    10, 30, 70 (exploration), 90, 80 (exploitation); threshold 64 mm (in run_start's search settings).
    The rig's envelope changed one tick in ten (5 per attempt; `rig_limits_message`).
    Attempts 1-3 are open loop (no "control" key, as older runs record them), 4 and 5 closed loop with a
    velocity correction of (0.1 k, 0) rad/s at every tick of attempt k.
    One tick lacks its joint_states message (when skip_joint_state_of is set), so it is incomplete.
    Each of `robot_descriptions` is published in turn on /leg/robot_description (latched), before
    the first tick, as the rig nodes publish the leg's URDF.
    """
    run = SyntheticRun(path)
    registry = messages.registry
    writer = BagWriter(path, {"g2p.run_id": path.name})
    rig_types = {
        "joint_states": "sensor_msgs/msg/JointState",
        "treadmill": "g2p_interfaces/msg/Treadmill",
        "motor_power": "g2p_interfaces/msg/MotorPower",
        "applied_activation": "g2p_interfaces/msg/MotorActivation",
    }
    handles = {
        role: writer.add_topic(TopicSpec(f"/leg/{role}", registry.definition(t), (SAMPLE_QOS,)))
        for role, t in rig_types.items()
    }
    limits = writer.add_topic(
        TopicSpec("/leg/rig_limits", registry.definition("g2p_interfaces/msg/RigLimits"), (SAMPLE_QOS,))
    )
    events = writer.add_topic(
        TopicSpec(
            "/leg/learner/events", registry.definition("g2p_interfaces/msg/LearnerEvent"), (SAMPLE_QOS,)
        )
    )
    maps = writer.add_topic(
        TopicSpec(
            "/leg/learner/inverse_map",
            registry.definition("g2p_interfaces/msg/InverseMapWeights"),
            (LATCHED_QOS,),
        )
    )
    config = writer.add_topic(
        TopicSpec("/leg/learner/config", registry.definition("std_msgs/msg/String"), (LATCHED_QOS,))
    )

    if robot_descriptions:
        described = writer.add_topic(
            TopicSpec("/leg/robot_description", registry.definition("std_msgs/msg/String"), (LATCHED_QOS,))
        )
        for n, urdf in enumerate(robot_descriptions):
            writer.write(
                described, T0_NS - 20 + n, messages.cdr(messages.make("std_msgs/msg/String", data=urdf))
            )

    k = 0

    def tick(record: list[int] | None) -> int:
        nonlocal k
        stamp = T0_NS + k * TICK_NS
        msgs = rig_messages(messages, k, stamp)
        for role, msg in msgs.items():
            if role == "joint_states" and k == skip_joint_state_of:
                continue
            writer.write(handles[role], stamp + 1000, messages.cdr(msg))
        writer.write(limits, stamp + 1000, messages.cdr(rig_limits_message(messages, k, stamp)))
        if record is not None and k != skip_joint_state_of:
            record.append(k)
        k += 1
        return stamp

    def event(
        stamp: int,
        kind: str,
        phase: str = "",
        attempt: int = 0,
        detail: dict[str, Any] | None = None,
        **values: float,
    ) -> None:
        features = np.linspace(0.15, 1.0, 10) if attempt else np.zeros(0)
        msg = learner_event(
            messages,
            stamp,
            "run-1",
            kind,
            phase=phase,
            attempt=attempt,
            features=features,
            detail=detail,
            **values,
        )
        writer.write(events, stamp + 2000, messages.cdr(msg))

    def inverse_map(stamp: int, refinement: int) -> None:
        rng = np.random.default_rng(refinement)
        arrays = {"W1": rng.normal(size=(15, 6)), "b1": rng.normal(size=15), "W2": rng.normal(size=(3, 15))}
        run.maps.append(arrays)
        named = [
            messages.make(
                "g2p_interfaces/msg/NamedArray",
                name=n,
                shape=np.array(a.shape, dtype=np.uint32),
                data=a.ravel(),
            )
            for n, a in arrays.items()
        ]
        msg = messages.make(
            "g2p_interfaces/msg/InverseMapWeights",
            header=messages.header(stamp),
            run_id="run-1",
            refinement=refinement,
            format_version=1,
            arrays=named,
            training_samples=200 + 50 * refinement,
            validation_rmse=0.1 / (1 + refinement),
        )
        writer.write(maps, stamp + 3000, messages.cdr(msg))

    writer.write(
        config,
        T0_NS - 10,
        messages.cdr(
            messages.make(
                "std_msgs/msg/String", data=json.dumps({"search": {"threshold_mm": 64.0}, "run_id": "run-1"})
            )
        ),
    )
    event(
        T0_NS - 5,
        "run_start",
        detail={"search": {"threshold_mm": 64.0}, "joint_limits_rad": [[-1.0, 1.0], [-1.5, 0.0]]},
    )
    event(T0_NS - 1, "phase_start", phase="babbling")
    for _ in range(200):
        last = tick(run.babbling_ticks)
    for _ in range(20):  # the rig idles while the map is fitted: not babbling
        idle = tick(None)
    inverse_map(idle + 1, 0)
    event(idle + 2, "phase_end", phase="babbling", detail={"ticks": 200, "samples": 12345})
    rewards = [10.0, 30.0, 70.0, 90.0, 80.0]
    for number, reward in enumerate(rewards, start=1):
        phase = "exploration" if number <= 3 else "exploitation"
        for _ in range(10):
            idle = tick(None)
        event(idle + 1, "attempt_start", phase=phase, attempt=number)
        ticks: list[int] = []
        for _ in range(50):
            last = tick(ticks)
        desired = [list(tick_values(j)["position_rad"] - 0.01) for j in ticks]
        control = {} if number <= 3 else {"control": "closed", "correction_rad_s": [[0.1 * number, 0.0]] * 50}
        event(
            last + 1,
            "attempt_end",
            phase=phase,
            attempt=number,
            detail={"desired_rad": desired, **control},
            reward_mm=reward,
            energy_j=4.0 + number,
            tracking_mse_deg2=100.0 / number,
            sigma=0.1,
            best_reward_mm=max(rewards[:number]),
        )
        inverse_map(last + 2, number)
        run.attempt_ticks[number] = ticks
        run.rewards[number] = reward
        run.energies[number] = 4.0 + number
        run.mse[number] = 100.0 / number
        run.phases[number] = phase
    event(last + 10, "run_end")
    writer.close()
    return run


@dataclass
class TickPlan:
    """A scripted rig timeline: ticks (stamp, value index) and learner events, in publishing order."""

    items: list[tuple[str, Any]] = field(default_factory=list)
    played: dict[str, list[tuple[int, int]]] = field(default_factory=dict)

    def tick(self, stamp_ns: int, k: int, segment: str | None = None) -> None:
        """Tick k (values of tick_values(k)) stamped `stamp_ns`, part of `segment` when given."""
        self.items.append(("tick", (stamp_ns, k)))
        if segment is not None:
            self.played.setdefault(segment, []).append((stamp_ns, k))

    def event(self, stamp_ns: int, kind: str, **fields: Any) -> None:
        self.items.append(("event", (stamp_ns, kind, fields)))


def write_plan(path: Path, messages: Messages, plan: TickPlan) -> None:
    """Write a scripted timeline: rig ticks with the values of tick_values(k) and LearnerEvents."""
    registry = messages.registry
    roles = {
        "joint_states": "sensor_msgs/msg/JointState",
        "treadmill": "g2p_interfaces/msg/Treadmill",
        "motor_power": "g2p_interfaces/msg/MotorPower",
        "applied_activation": "g2p_interfaces/msg/MotorActivation",
    }
    with BagWriter(path) as writer:
        handles = {
            r: writer.add_topic(TopicSpec(f"/leg/{r}", registry.definition(t))) for r, t in roles.items()
        }
        events = writer.add_topic(
            TopicSpec("/leg/learner/events", registry.definition("g2p_interfaces/msg/LearnerEvent"))
        )
        for n, (kind, item) in enumerate(plan.items):
            if kind == "tick":
                stamp, k = item
                for role, msg in rig_messages(messages, k, stamp).items():
                    writer.write(handles[role], T0_NS + n, messages.cdr(msg))
            else:
                stamp, name, fields = item
                msg = learner_event(messages, stamp, "plan", name, **fields)
                writer.write(events, T0_NS + n, messages.cdr(msg))
