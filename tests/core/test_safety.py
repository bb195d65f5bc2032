"""The activation gate: validation, clamping, the watchdog, the stop."""

from __future__ import annotations

import numpy as np
import pytest

from g2p.safety import ActivationGate, InvalidActivation, check_activation_sequence


def test_the_gate_clamps_holds_and_times_out_to_baseline() -> None:
    gate = ActivationGate(timeout_ticks=2, baseline=0.15)
    np.testing.assert_array_equal(gate.next_activation(), [0.15] * 3)  # no command yet: baseline
    np.testing.assert_array_equal(gate.command([-0.2, 0.6, 1.4]), [0.15, 0.6, 1.0])
    ticks = [gate.next_activation().tolist() for _ in range(4)]
    assert ticks == [[0.15, 0.6, 1.0], [0.15, 0.6, 1.0], [0.15] * 3, [0.15] * 3]
    c = gate.counters
    assert (c.accepted, c.clamped, c.rejected, c.watchdog_trips) == (1, 1, 0, 1)


def test_a_rejected_command_neither_changes_the_output_nor_feeds_the_watchdog() -> None:
    gate = ActivationGate(timeout_ticks=2, baseline=0.15)
    gate.command([0.5, 0.5, 0.5])
    gate.next_activation()
    assert gate.command([np.nan, 0.5, 0.5]) is None and gate.command([0.5, 0.5]) is None
    assert gate.next_activation().tolist() == [0.5] * 3
    assert gate.next_activation().tolist() == [0.15] * 3  # two ticks since the valid command
    assert gate.counters.rejected == 2


def test_stop_drops_to_baseline_until_the_next_command() -> None:
    gate = ActivationGate(timeout_ticks=5, baseline=0.15)
    gate.command([0.9, 0.9, 0.9])
    assert gate.stop().tolist() == [0.15] * 3
    assert gate.next_activation().tolist() == [0.15] * 3
    assert gate.counters.watchdog_trips == 0  # a stop is not a watchdog trip
    gate.command([0.3, 0.3, 0.3])
    assert gate.next_activation().tolist() == [0.3] * 3


@pytest.mark.parametrize(
    ("sequence", "reason"),
    [
        (np.zeros((0, 3)), "shape"),
        (np.zeros((4, 2)), "shape"),
        (np.array([[0.2, np.nan, 0.2]]), "non-finite values, first at row 0"),
        (np.array([[0.2, 0.2, 0.2], [0.2, 1.2, 0.2]]), "outside [0, 1], first at row 1"),
    ],
)
def test_an_invalid_sequence_is_refused_with_its_reason(sequence: np.ndarray, reason: str) -> None:
    with pytest.raises(InvalidActivation, match=reason.replace("[", r"\[").replace("]", r"\]")):
        check_activation_sequence(sequence)
