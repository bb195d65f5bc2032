"""RetryingRig on the MuJoCo leg: a sequence lost with the rig is played again, whole, from rest."""

from __future__ import annotations

import threading
import time
from typing import Any

import numpy as np
import pytest

from g2p.inverse_map import InverseMap
from g2p.plant import Recording
from g2p.rig import PlantRig, ProgressCallback, RetryingRig, RigBusy, RigCancelled, RigUnreachable
from g2p.rig.closed_loop import FeedbackConfig, TrackedRecording, Trajectory
from g2p.rig.envelope import replay
from g2p.sim import MujocoLeg, MujocoLegConfig

ACTIVATIONS = np.column_stack([np.linspace(0.2, 0.9, 40), np.full(40, 0.5), np.linspace(0.9, 0.2, 40)])


class LosingRig:
    """A real plant behind a link that is down for the first `lost_plays` plays and `busy_resets` resets.

    A lost play plays part of the sequence before the rig is lost, as a cut link would leave it.
    """

    def __init__(self, lost_plays: int = 0, busy_resets: int = 0, down_resets: int = 0) -> None:
        self.rig = PlantRig(MujocoLeg(MujocoLegConfig()))
        self.lost_plays, self.busy_resets, self.down_resets = lost_plays, busy_resets, down_resets
        self.calls: list[str] = []

    def reset(self) -> None:
        self.calls.append("reset")
        if self.down_resets > 0:
            self.down_resets -= 1
            raise RigUnreachable("no answer to reset")
        if self.busy_resets > 0:
            self.busy_resets -= 1
            raise RigBusy("a sequence is in progress")
        self.rig.reset()

    def play(
        self,
        activations: np.ndarray,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> Recording:
        self.calls.append("play")
        if self.lost_plays > 0:
            self.lost_plays -= 1
            self.rig.play(activations[: len(activations) // 2])  # the rig played on, unseen
            raise RigUnreachable("no word from the rig for 2.0 s")
        return self.rig.play(activations, progress, cancel)

    def play_trajectory(
        self,
        trajectory: Trajectory,
        progress: ProgressCallback | None = None,
        cancel: threading.Event | None = None,
    ) -> TrackedRecording:
        self.calls.append("play_trajectory")
        if self.lost_plays > 0:
            self.lost_plays -= 1
            raise RigUnreachable("no word from the rig for 2.0 s")
        return self.rig.play_trajectory(trajectory, progress, cancel)


def clean_play() -> Recording:
    rig = PlantRig(MujocoLeg(MujocoLegConfig()))
    rig.reset()
    return rig.play(ACTIVATIONS)


def test_a_lost_sequence_is_played_again_from_rest_and_only_the_whole_one_is_returned() -> None:
    told: list[tuple[str, dict[str, Any]]] = []
    losing = LosingRig(lost_plays=2, down_resets=1)
    rig = RetryingRig(losing, limit_s=30.0, retry_pause_s=0.01, on_event=lambda e, d: told.append((e, d)))
    losing.rig.reset()
    got = rig.play(ACTIVATIONS)
    assert losing.calls == ["play", "reset", "reset", "play", "reset", "play"]
    assert rig.retries == 2
    assert [e for e, _ in told] == ["rig_lost", "rig_back", "rig_lost", "rig_back"]
    assert told[1][1]["resets"] == 2  # the first reset after the loss found the rig still away
    want = clean_play()
    assert len(got) == len(ACTIVATIONS)
    np.testing.assert_array_equal(got.activation, replay(ACTIVATIONS, got))  # through the rig's envelope
    # From rest, like a clean play (the plant's tick jitter differs from play to play: not bit for bit).
    np.testing.assert_allclose(got.position_rad[:5], want.position_rad[:5], atol=0.01)


def test_a_busy_rig_is_waited_for() -> None:
    losing = LosingRig(busy_resets=3)
    rig = RetryingRig(losing, limit_s=30.0, retry_pause_s=0.01)
    rig.reset()
    assert losing.calls == ["reset"] * 4
    assert len(rig.play(ACTIVATIONS)) == len(ACTIVATIONS)


def test_a_rig_that_does_not_come_back_within_the_limit_ends_the_call() -> None:
    rig = RetryingRig(LosingRig(lost_plays=1, down_resets=10**6), limit_s=0.3, retry_pause_s=0.01)
    start = time.monotonic()
    with pytest.raises(RigUnreachable, match=r"limit 0.3 s"):
        rig.play(ACTIVATIONS)
    assert time.monotonic() - start < 5.0


def test_a_sequence_that_never_gets_through_ends_the_call_even_when_resets_do() -> None:
    rig = RetryingRig(LosingRig(lost_plays=10**6), limit_s=0.3, retry_pause_s=0.01)
    with pytest.raises(RigUnreachable, match="has not played the sequence"):
        rig.play(ACTIVATIONS)


def test_cancel_while_waiting_for_the_rig() -> None:
    cancel = threading.Event()
    rig = RetryingRig(LosingRig(lost_plays=1, down_resets=10**6), limit_s=60.0, retry_pause_s=0.01)
    threading.Timer(0.2, cancel.set).start()
    with pytest.raises(RigCancelled):
        rig.play(ACTIVATIONS, cancel=cancel)


def test_a_lost_closed_loop_trajectory_is_played_again_from_rest() -> None:
    told: list[str] = []
    losing = LosingRig(lost_plays=1)
    rig = RetryingRig(losing, limit_s=30.0, retry_pause_s=0.01, on_event=lambda e, _d: told.append(e))
    inverse_map = InverseMap()
    inverse_map.fit(np.tile(np.linspace(-1, 1, 40)[:, None], (1, 6)), ACTIVATIONS, np.random.default_rng(0))
    trajectory = Trajectory(np.zeros((30, 6)), inverse_map, FeedbackConfig())
    got = rig.play_trajectory(trajectory)
    assert losing.calls == ["play_trajectory", "reset", "play_trajectory"]
    assert told == ["rig_lost", "rig_back"] and rig.retries == 1
    assert len(got.recording) == 30 and got.correction_rad_s.shape == (30, 2)
