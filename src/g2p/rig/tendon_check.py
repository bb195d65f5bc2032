"""The tendon check: does each tendon, pulled alone at low activation, turn the joints the Fig 1d way?

Run it on a new or rewired rig before any babbling: a reversed encoder, swapped motor channels or a
tendon on the wrong side of a pulley would otherwise teach the inverse map nonsense, and a learning run
would push the leg into its stops.

    from g2p.rig import PlantRig
    report = check_tendons(PlantRig(plant))           # or a g2p_ros.rig_client.RigClient over ROS
    print(report.text())

Fig 1d: M1 turns the proximal joint ccw only; M0 turns it cw and the distal joint ccw; M2 turns both cw.
Each pull starts from rest (`reset`) and holds one motor at its level (the others at baseline) for
`hold_s`. M0's distal action needs a flexed knee to show (at rest the knee is straight, against its
stop), so M0 also pulls from a posture where M2 has flexed the knee.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from g2p.plant import JOINT_NAMES, MOTOR_NAMES, NOMINAL_TICK_HZ, FloatArray
from g2p.rig.rigs import Rig
from g2p.safety import BASELINE_ACTIVATION
from g2p.validation import require, require_positive


@dataclass(frozen=True)
class TendonCheckConfig:
    """How hard and how long each tendon is pulled.

    Attributes:
        levels: activation of each motor (M0, M1, M2) when it pulls (dimensionless), at most 0.6 so a
            miswired rig cannot hurt itself: M1 has the longest hip arm (0.3 lifts the leg ~20 deg), M2 must
            flex the knee against M0's baseline pull (0.5 flexes it ~13 deg).
        hold_s: how long each pull lasts (s).
        threshold_deg: the smallest joint rotation counted as a movement (deg).
        tick_hz: the rig's tick rate (Hz), to turn durations into ticks.
    """

    levels: tuple[float, float, float] = (0.4, 0.3, 0.5)
    hold_s: float = 1.0
    threshold_deg: float = 3.0
    tick_hz: float = NOMINAL_TICK_HZ

    def __post_init__(self) -> None:
        require(
            len(self.levels) == 3
            and all(math.isfinite(v) and BASELINE_ACTIVATION < v <= 0.6 for v in self.levels),
            "levels",
            f"must be 3 activations in ({BASELINE_ACTIVATION}, 0.6], got {self.levels!r}",
        )
        require_positive(self.hold_s, "hold_s")
        require_positive(self.threshold_deg, "threshold_deg")
        require_positive(self.tick_hz, "tick_hz")


@dataclass(frozen=True)
class Pull:
    """One tendon pulled alone, and what Fig 1d says the joints must do.

    Attributes:
        motor: index of the pulling motor (0, 1, 2 = M0, M1, M2).
        prep_motor: motor pulled first to set the starting posture (None: from rest).
        expected: expected sign of the rotation per joint, +1 ccw, -1 cw, 0 not checked, shape (2,).
    """

    motor: int
    prep_motor: int | None
    expected: tuple[int, int]


PULLS = (
    Pull(motor=1, prep_motor=None, expected=(+1, 0)),  # M1: proximal ccw only
    Pull(motor=2, prep_motor=None, expected=(-1, -1)),  # M2: both cw
    Pull(motor=0, prep_motor=None, expected=(-1, 0)),  # M0: proximal cw (the knee is at its stop)
    Pull(motor=0, prep_motor=2, expected=(0, +1)),  # M0: distal ccw, from a knee flexed by M2
)


@dataclass(frozen=True)
class PullResult:
    """What one pull did.

    Attributes:
        pull: the pull.
        change_rad: joint rotation from the start of the pull to its end, shape (2,) (rad).
        ok: every checked joint turned the expected way by at least the threshold.
    """

    pull: Pull
    change_rad: FloatArray
    ok: bool

    def text(self) -> str:
        """One line: the motor, the rotations and the verdict."""
        start = "rest" if self.pull.prep_motor is None else f"{MOTOR_NAMES[self.pull.prep_motor]} posture"
        parts = []
        for j, name in enumerate(JOINT_NAMES):
            want = {1: "ccw +", -1: "cw -", 0: "any"}[self.pull.expected[j]]
            parts.append(f"{name} {math.degrees(self.change_rad[j]):+6.1f} deg (want {want})")
        return (
            f"{MOTOR_NAMES[self.pull.motor]} from {start}: {', '.join(parts)}: {'ok' if self.ok else 'WRONG'}"
        )


@dataclass(frozen=True)
class TendonReport:
    """The results of every pull and a diagnosis.

    Attributes:
        results: one per pull, in PULLS order.
        diagnosis: what the failures point at (empty when every pull is ok).
    """

    results: tuple[PullResult, ...]
    diagnosis: tuple[str, ...]

    @property
    def ok(self) -> bool:
        """Whether every tendon moved its joints the Fig 1d way."""
        return all(r.ok for r in self.results)

    def text(self) -> str:
        """The report as lines of text."""
        lines = [r.text() for r in self.results]
        lines += self.diagnosis or ["every tendon moves its joints as in Fig 1d"]
        return "\n".join(lines)


def _judge(pull: Pull, change: FloatArray, threshold_rad: float) -> bool:
    return all(e == 0 or e * float(c) >= threshold_rad for e, c in zip(pull.expected, change, strict=True))


def diagnose(results: tuple[PullResult, ...], threshold_rad: float) -> tuple[str, ...]:
    """What a pattern of failed pulls points at.

    A joint that turns the opposite way in every pull that checks it has a reversed encoder; a joint that
    never moves has a dead encoder or a jammed joint; remaining failures point at motor channels or
    tendon routing.
    """
    hints: list[str] = []
    explained: set[int] = set()
    for j, name in enumerate(JOINT_NAMES):
        checked = [(i, r) for i, r in enumerate(results) if r.pull.expected[j] != 0]
        signs = [r.pull.expected[j] * float(r.change_rad[j]) for _, r in checked]
        if checked and all(s <= -threshold_rad for s in signs):
            hints.append(f"the {name} encoder reads reversed: flip encoders.{name}.direction in the rig YAML")
            explained |= {i for i, _ in checked}
        elif checked and all(abs(float(r.change_rad[j])) < threshold_rad for _, r in checked):
            hints.append(
                f"the {name} joint never moved: check its encoder (SPI wiring, magnet) and the joint"
            )
            explained |= {i for i, _ in checked}
    for i, r in enumerate(results):
        if not r.ok and i not in explained:
            hints.append(
                f"{MOTOR_NAMES[r.pull.motor]} does not act as in Fig 1d: check pwm.channels (motor order), "
                "its driver and its tendon routing"
            )
    return tuple(dict.fromkeys(hints))


def check_tendons(rig: Rig, config: TendonCheckConfig | None = None) -> TendonReport:
    """Pull each tendon alone from rest (see PULLS) and check the joints turn the Fig 1d way.

    Args:
        rig: the rig (an in-process `PlantRig`, or a `RigClient` on the ROS graph); it is reset before each
            pull and once at the end.
        config: how hard and how long to pull.

    Raises:
        g2p.rig.RigError: the rig could not play or reset.
    """
    cfg = config if config is not None else TendonCheckConfig()
    ticks = max(2, round(cfg.hold_s * cfg.tick_hz))
    threshold = math.radians(cfg.threshold_deg)
    results = []
    for pull in PULLS:
        rig.reset()
        start: FloatArray | None = None
        if pull.prep_motor is not None:
            prep = _alone(pull.prep_motor, cfg.levels[pull.prep_motor], ticks)
            start = rig.play(prep).position_rad[-1]
        rec = rig.play(_alone(pull.motor, cfg.levels[pull.motor], ticks))
        first = rec.position_rad[0] if start is None else start
        change = np.asarray(rec.position_rad[-1] - first, dtype=np.float64)
        results.append(PullResult(pull, change, _judge(pull, change, threshold)))
    rig.reset()
    done = tuple(results)
    return TendonReport(done, diagnose(done, threshold) if not all(r.ok for r in done) else ())


def _alone(motor: int, level: float, ticks: int) -> FloatArray:
    seq = np.full((ticks, 3), BASELINE_ACTIVATION)
    seq[:, motor] = level
    return seq
