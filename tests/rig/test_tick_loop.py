"""The rig's tick loop without ROS: a plant that keeps a ledger of what it was given is the known answer."""

from __future__ import annotations

import time

import numpy as np
import pytest

from g2p.plant import NOMINAL_TICK_HZ, TickSample
from g2p.rig.envelope import EnvelopeConfig
from g2p.rig.tick_loop import CommandOutcome, Job, Pacing, Tick, TickLoop, TickLoopConfig
from g2p.safety import BASELINE_ACTIVATION

BASE = np.full(3, BASELINE_ACTIVATION)
# The loop's plumbing, without the envelope's joint rules (tests/rig/test_envelope.py tests those): the
# ledger's joint angle is a running sum, and its steps are any size.
PLUMBING = EnvelopeConfig(soft_limits=False, max_step=1.0)


class LedgerPlant:
    """Applies each activation clamped to [baseline, 1]; its joint 0 angle is the sum of all applied so far.

    `fail_at`: the step number (from 1) that raises instead, once.
    """

    tick_hz = NOMINAL_TICK_HZ

    def __init__(self, fail_at: int | None = None) -> None:
        self.applied: list[np.ndarray] = []
        self.resets = 0
        self.fail_at = fail_at
        self.total = 0.0

    def _sample(self, activation: np.ndarray) -> TickSample:
        z3 = np.zeros(3)
        t = len(self.applied) / self.tick_hz
        return TickSample(t, activation, np.array([self.total, 0.0]), np.zeros(2), 0.0, 0.0, z3, z3, z3)

    def reset(self) -> TickSample:
        self.resets += 1
        self.total = 0.0
        return self._sample(BASE.copy())

    def step(self, activation: np.ndarray) -> TickSample:
        if self.fail_at == len(self.applied) + 1:
            self.fail_at = None  # once
            raise RuntimeError("encoder lost")
        applied = np.clip(activation, BASELINE_ACTIVATION, 1.0)
        self.applied.append(applied)
        self.total += float(applied.sum())
        return self._sample(applied)

    def close(self) -> None:
        pass


class Receiver:
    """Collects emitted ticks; delivers them (calls `then`) only when told to, like a slow publisher."""

    def __init__(self, deliver: bool = True) -> None:
        self.ticks: list[Tick] = []
        self.deliver = deliver

    def __call__(self, tick: Tick) -> None:
        self.ticks.append(tick)
        if self.deliver and tick.then is not None:
            tick.then()

    def flush(self) -> None:
        for tick in self.ticks:
            if tick.then is not None:
                tick.then()


def caller_loop(plant: LedgerPlant, pacing: Pacing = Pacing.PLANT, **kwargs) -> tuple[TickLoop, Receiver]:
    receiver = Receiver(kwargs.pop("deliver", True))
    loop = TickLoop(
        plant, pacing, TickLoopConfig(fast_max_real_time_factor=0.0, envelope=PLUMBING, **kwargs), receiver
    )
    loop.start(threaded=False)
    return loop, receiver


def play(loop: TickLoop, job: Job, ticks: int | None = None) -> None:
    assert loop.reserve()
    loop.play(job)
    for _ in range(ticks if ticks is not None else job.ticks_total):
        loop.tick()


def test_a_sequence_plays_its_rows_one_per_tick_then_baseline() -> None:
    plant = LedgerPlant()
    loop, receiver = caller_loop(plant)
    rows = np.array([[0.2, 0.5, 1.0], [0.9, 0.15, 0.3], [0.15, 0.7, 0.6]])
    job = Job(activations=rows)
    play(loop, job)
    assert job.done.is_set() and job.error == "" and not job.cancel
    loop.release()
    loop.tick()
    np.testing.assert_array_equal(plant.applied, [*rows, BASE])
    assert [s.position_rad[0] for s in job.samples] == pytest.approx(np.cumsum(rows.sum(axis=1)))
    assert [t.number for t in receiver.ticks] == [1, 2, 3, 4]
    assert receiver.ticks[2].then is not None  # the last tick of the job ends it


def test_a_job_is_done_only_once_its_last_tick_is_delivered() -> None:
    loop, receiver = caller_loop(LedgerPlant(), deliver=False)
    job = Job(activations=np.full((2, 3), 0.5))
    play(loop, job)
    assert len(job.samples) == 2 and not job.done.is_set()
    receiver.flush()
    assert job.done.is_set()


def test_a_cancel_plays_one_tick_at_baseline_and_ends_the_job() -> None:
    plant = LedgerPlant()
    loop, _ = caller_loop(plant)
    job = Job(activations=np.full((10, 3), 0.8))
    play(loop, job, ticks=4)
    loop.cancel()
    loop.tick()
    assert job.done.is_set() and job.cancel and len(job.samples) == 4
    np.testing.assert_array_equal(plant.applied[-1], BASE)
    # After a cancel the gate holds baseline: an old command does not come back.
    loop.release()
    loop.tick()
    np.testing.assert_array_equal(plant.applied[-1], BASE)


def test_commands_are_clamped_held_and_dropped_to_baseline_by_the_watchdog() -> None:
    plant = LedgerPlant()
    loop, _ = caller_loop(plant, watchdog_ticks=3)
    assert loop.command([0.05, 0.5, 1.7]) is CommandOutcome.APPLIED
    for _ in range(5):
        loop.tick()
    held = [0.15, 0.5, 1.0]
    np.testing.assert_array_equal(plant.applied, [held, held, held, BASE, BASE])
    assert loop.gate.counters.watchdog_trips == 1 and loop.gate.counters.clamped == 1


def test_an_invalid_command_is_rejected_and_changes_nothing() -> None:
    plant = LedgerPlant()
    loop, _ = caller_loop(plant, watchdog_ticks=3)
    loop.command([0.4, 0.4, 0.4])
    for bad in ([np.nan, 0.4, 0.4], [0.4, 0.4], [np.inf, 0.0, 0.0]):
        assert loop.command(bad) is CommandOutcome.REJECTED
    loop.tick()
    np.testing.assert_array_equal(plant.applied, [[0.4, 0.4, 0.4]])
    assert loop.gate.counters.rejected == 3


def test_commands_wait_while_a_sequence_plays() -> None:
    plant = LedgerPlant()
    loop, _ = caller_loop(plant)
    job = Job(activations=np.full((3, 3), 0.6))
    play(loop, job, ticks=1)
    assert loop.command([1.0, 1.0, 1.0]) is CommandOutcome.IGNORED
    loop.tick()
    loop.tick()
    np.testing.assert_array_equal(plant.applied, np.full((3, 3), 0.6))
    assert loop.counters.ignored_commands == 1


def test_on_demand_each_command_plays_exactly_one_tick() -> None:
    plant = LedgerPlant()
    loop, receiver = caller_loop(plant, Pacing.ON_DEMAND)
    loop.command([0.3, 0.3, 0.3])
    loop.command([0.7, 0.7, 0.7])
    loop.tick()
    loop.tick()
    np.testing.assert_array_equal(plant.applied, [[0.3] * 3, [0.7] * 3])
    assert [t.idles_after for t in receiver.ticks] == [False, True]


def test_a_reset_waits_for_no_job_and_leaves_baseline() -> None:
    plant = LedgerPlant()
    loop, receiver = caller_loop(plant)
    job = Job(activations=np.full((2, 3), 0.5))
    play(loop, job, ticks=1)
    assert isinstance(loop.request_reset(), str)  # refused while a job is reserved
    loop.tick()
    loop.release()
    loop.command([0.9, 0.9, 0.9])
    req = loop.request_reset()
    assert not isinstance(req, str)
    loop.tick()
    assert req.done.is_set() and req.success and plant.resets == 1
    reset_tick = receiver.ticks[-1]
    assert reset_tick.number == 2 and reset_tick.sample is not None and reset_tick.sample.position_rad[0] == 0
    loop.tick()
    np.testing.assert_array_equal(plant.applied[-1], BASE)  # the command before the reset is gone


def test_a_plant_fault_fails_the_job_and_drops_to_baseline() -> None:
    plant = LedgerPlant(fail_at=3)
    faults: list[Exception] = []
    loop = TickLoop(plant, Pacing.PLANT, TickLoopConfig(envelope=PLUMBING), on_fault=faults.append)
    loop.start(threaded=False)
    job = Job(activations=np.full((5, 3), 0.9))
    play(loop, job, ticks=3)
    assert job.done.is_set() and job.error == "plant fault: encoder lost" and len(job.samples) == 2
    assert [str(f) for f in faults] == ["encoder lost"] and loop.counters.faults == 1
    loop.release()
    loop.tick()
    np.testing.assert_array_equal(plant.applied[-1], BASE)


def test_stop_ends_the_job_releases_a_reset_and_ends_on_a_baseline_tick() -> None:
    plant = LedgerPlant()
    receiver = Receiver()
    loop = TickLoop(
        plant, Pacing.ON_DEMAND, TickLoopConfig(fast_max_real_time_factor=1.0, envelope=PLUMBING), receiver
    )
    loop.start()
    job = Job(activations=np.full((7800, 3), 0.7))  # 100 s at real-time pace: playing at the stop
    assert loop.reserve()
    loop.play(job)
    while len(job.samples) < 2:
        time.sleep(0.01)
    assert loop.stop()
    assert job.done.is_set() and job.error == "rig stopped"
    np.testing.assert_array_equal(plant.applied[-1], BASE)
    last = receiver.ticks[-1]
    assert last.sample is not None and last.idles_after and last.number == len(plant.applied)
    assert not loop.stop()  # idempotent
    assert isinstance(loop.request_reset(), str)


def test_a_job_given_to_a_stopped_loop_ends_at_once() -> None:
    loop = TickLoop(LedgerPlant(), Pacing.PLANT, TickLoopConfig(envelope=PLUMBING))
    job = Job(activations=np.full((2, 3), 0.5))
    loop.play(job)
    assert job.done.is_set() and job.error == "rig is not running"


def test_a_failed_heartbeat_is_a_fault_and_the_idle_loop_goes_on() -> None:
    plant = LedgerPlant()
    faults: list[Exception] = []

    def receiver(tick: Tick) -> None:
        if tick.sample is None:
            raise RuntimeError("publisher gone")
        if tick.then is not None:
            tick.then()

    loop = TickLoop(plant, Pacing.ON_DEMAND, TickLoopConfig(envelope=PLUMBING), receiver, faults.append)
    loop.start()
    try:
        deadline = time.monotonic() + 30.0
        while not faults:  # an idle loop emits a heartbeat every IDLE_HEARTBEAT_PERIOD_S
            assert time.monotonic() < deadline, "no heartbeat"
            time.sleep(0.01)
        assert loop.command([0.5, 0.5, 0.5]) is CommandOutcome.APPLIED
        while not plant.applied:
            assert time.monotonic() < deadline, "the loop stopped ticking"
            time.sleep(0.01)
    finally:
        loop.stop()
    assert str(faults[0]) == "publisher gone"
    np.testing.assert_array_equal(plant.applied[0], [0.5, 0.5, 0.5])
