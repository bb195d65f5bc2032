"""Known answers of the identification: a replay at the truth reproduces the recording; a fit recovers
parameters it was not told; what the data cannot determine is reported so; a fit that stops short says so."""

from __future__ import annotations

import numpy as np
import pytest

from g2p.babbling import BabblingConfig, babbling_activations
from g2p.identification import FitConfig, FitError, Segment, fit, replay
from g2p.identification.fit import angle_errors_rad, replay_config, rmse_rad
from g2p.identification.segments import segment_of
from g2p.plant import Recording
from g2p.sim import AIR_CARRIAGE_HEIGHT_M, MujocoLeg, MujocoLegConfig
from g2p.sim.calibration import LegCalibration
from g2p.sim.sensors import encoder_step_rad

AIR = MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M)
# The hidden rig: the model changed on exactly the parameters fitted below.
TRUTH = {
    "motor_lag_s": 0.04,
    "motor_max_current_a": 7.2,
    "m1_proximal_arm_m": -0.055,
    "proximal_encoder_offset_rad": 0.02,
    "distal_encoder_offset_rad": -0.015,
}


def hidden_babbling(seconds: float, seed: int = 0) -> Segment:
    """Babbling recorded on the hidden rig in the air, with its jittered ticks and 14-bit encoders."""
    hidden = MujocoLeg(
        MujocoLegConfig(carriage_height_m=AIR_CARRIAGE_HEIGHT_M, seed=seed + 1),
        calibration=LegCalibration(TRUTH),
    )
    acts = babbling_activations(np.random.default_rng(seed), BabblingConfig(), round(seconds * 78))
    start = hidden.reset()
    return segment_of(
        Recording.from_samples([hidden.step(a) for a in acts]), "babbling", previous_t_s=start.t_s
    )


@pytest.fixture(scope="module")
def babbling() -> Segment:
    return hidden_babbling(20.0)


def test_a_replay_at_the_truth_reads_what_the_rig_recorded(babbling: Segment) -> None:
    (rep,) = replay([babbling], replay_config(AIR), LegCalibration(TRUTH))
    # The recorded ticks' durations come from their stamps: the replay is the same physics, tick for tick;
    # it differs only by the recording's 14-bit quantization.
    np.testing.assert_allclose(
        rep.position_rad, babbling.position_rad, atol=0.51 * encoder_step_rad(14) + 1e-9
    )
    np.testing.assert_allclose(rep.current_a, babbling.current_a, atol=1e-9)


@pytest.mark.slow
def test_a_fit_recovers_the_parameters_it_was_not_told(babbling: Segment) -> None:
    result = fit([babbling], AIR, FitConfig(parameters=tuple(TRUTH), workers=2))
    for e in result.estimates:
        truth = TRUTH[e.name]
        assert e.determined, e
        tolerance = dict(abs=0.005) if e.name.endswith("offset_rad") else dict(rel=0.02)
        assert e.value == pytest.approx(truth, **tolerance), e
    before = rmse_rad(angle_errors_rad([babbling], AIR, LegCalibration({})))
    after = rmse_rad(angle_errors_rad([babbling], AIR, result.calibration))
    assert after < before / 3
    assert result.cost_after < result.cost_before


def test_what_the_data_cannot_determine_is_reported_so(babbling: Segment) -> None:
    # In the air the belt never moves: its drag has no effect on anything recorded.
    short = babbling.head(300)
    result = fit([short], AIR, FitConfig(parameters=("motor_lag_s", "belt_drag_n"), workers=1))
    by_name = {e.name: e for e in result.estimates}
    assert by_name["motor_lag_s"].determined
    assert not by_name["belt_drag_n"].determined and by_name["belt_drag_n"].interval == np.inf
    assert result.calibration.undetermined == ("belt_drag_n",)


def test_a_fit_that_stops_short_raises(babbling: Segment) -> None:
    with pytest.raises(FitError, match="did not converge after 1 evaluations"):
        fit(
            [babbling.head(200)],
            AIR,
            FitConfig(parameters=("motor_lag_s", "m1_proximal_arm_m"), max_evaluations=1, workers=1),
        )
