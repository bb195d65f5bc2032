"""`MujocoLeg`: the MuJoCo simulation of the tendon-driven leg on its treadmill, as a `g2p.plant.Plant`.

Each `step` is one rig tick: the clamped activations are held for a jittered tick period, the physics is
sub-stepped within it, and the sample reads what the rig's sensors would read at the end of the tick
(quantized encoder angles, their finite-difference velocity, the belt odometer, mean motor current and
power over the tick, cumulative energy). The rig's physical limits (g2p.sim.limits) act within each
sub-step: the supply voltage caps the current, windings heat, tendons snap or derail. See docs/SIMULATOR.md
for the model and its parameters.
"""

from __future__ import annotations

import math
from types import TracebackType

import mujoco
import numpy as np

from g2p.plant import MOTOR_NAMES, N_MOTORS, FloatArray, TickSample
from g2p.safety import check_activation, clamp_activation
from g2p.sim.calibration import MAX_ENCODER_DELAY_S, LegCalibration
from g2p.sim.config import MujocoLegConfig
from g2p.sim.limits import (
    COOLDOWN_HYSTERESIS_K,
    NUMERICS,
    PhysicalLimits,
    available_current_a,
    winding_temperature_c,
)
from g2p.sim.model import IntArray, LegModel, ModelError, load_leg_model
from g2p.sim.motor import electrical_power_w
from g2p.sim.sensors import TickClock, quantize_angle

# The belt body is a finite box; its slide coordinate is folded back by this much whenever it strays further
# than this from rest, and the odometer keeps the sum. The box is uniform, so the contact does not change.
_BELT_WRAP_M = 0.5
_STATE = mujoco.mjtState.mjSTATE_INTEGRATION
# The resting posture is found by lowering the carriage from this much above its set height (m) ...
_LOWER_FROM_M = 0.05
# ... over this long (s), the way the rig's carriage is lowered onto the belt.
_LOWER_S = 0.5


class SimulationError(RuntimeError):
    """The physics diverged (non-finite state); the plant must be reset before it steps again."""


class MujocoLeg:
    """The simulated rig: a planar two-joint leg driven by three tendons, over a treadmill belt.

    Construction compiles the model and finds the resting posture as the rig does (baseline tension, the
    carriage lowered onto the belt, `config.settle_s` to settle); it stores that state, and every `reset`
    returns to it exactly. The belt odometer, the energy meters, the windings' temperatures and the clock
    run on across resets, as on the rig.

    When a limit trips (g2p.sim.limits: a winding's cut-out, a snapped or derailed tendon), `fault` says
    why, and the plant goes on stepping with that motor off or that tendon without force until `reset`.

    A calibration (g2p.sim.calibration) sets the model's physical parameters, and the sensors' own: each
    encoder reads the joint angle `encoder_delay_s` before the end of the tick plus its zero offset, then
    quantized.

    Args:
        config: the rig settings (defaults: treadmill mode, 78 Hz with 0.8 ms jitter).
        rng: generator of the tick jitter; None seeds one from `config.seed`.
        calibration: the leg's calibration; None loads the one `config.calibration` names.

    Raises:
        ConfigError: invalid configuration (raised by MujocoLegConfig).
        ModelError: the MJCF model lacks an element the plant needs (the message names the file, and every
            custom numeric missing with the packaged model's line for it).
    """

    def __init__(
        self,
        config: MujocoLegConfig | None = None,
        rng: np.random.Generator | None = None,
        calibration: LegCalibration | None = None,
    ) -> None:
        self.config = config if config is not None else MujocoLegConfig()
        cfg = self.config
        self.calibration = calibration if calibration is not None else cfg.leg_calibration
        self._leg: LegModel = load_leg_model(
            cfg.resolved_model_path, cfg.carriage_height_m, self.calibration, numerics=NUMERICS.values()
        )
        self._model = self._leg.model
        self._data = mujoco.MjData(self._model)
        # Views on the MjData buffers (they stay valid: MjData is never reallocated), to keep ticks cheap.
        self._qpos, self._qvel = self._data.qpos, self._data.qvel
        self._act, self._ctrl = self._data.act, self._data.ctrl
        spool = self._leg.spool_qpos
        contiguous = bool(np.all(np.diff(spool) == 1))
        self._spools: slice | IntArray = slice(int(spool[0]), int(spool[-1]) + 1) if contiguous else spool
        self._clock = TickClock(
            rng if rng is not None else np.random.default_rng(cfg.seed), cfg.tick_hz, cfg.tick_jitter_s
        )
        self._n_sub = cfg.substeps
        self._baseline = np.full(N_MOTORS, cfg.baseline_activation)
        motor = self._leg.motor
        self._i_max = motor.max_current_a
        # Per-substep scratch: activation (normalised current) and spool angles at the substep boundaries.
        self._act_hist = np.empty((self._n_sub, N_MOTORS))
        self._spool_hist = np.empty((self._n_sub + 1, N_MOTORS))
        # The encoders: zero offsets, and the delay read from a history of the angles at sub-step ends
        # (times (H,) in s, angles (H, 2) in rad, oldest first) long enough for the largest delay.
        self._encoder_offset = self.calibration.encoder_offset_rad
        self._encoder_delay_s = self.calibration.encoder_delay_s
        shortest_tick_s = cfg.nominal_period_s - cfg.tick_jitter_s
        span_ticks = math.ceil(MAX_ENCODER_DELAY_S / shortest_tick_s) + 1
        n_hist = span_ticks * self._n_sub + 1 if self._encoder_delay_s > 0 else 0
        self._hist_t = np.zeros(n_hist)
        self._hist_q = np.zeros((n_hist, 2))
        self._joint_arms = self._tendon_joint_arms()
        try:
            self.limits = PhysicalLimits.from_model(self._model)
        except ModelError as err:
            raise ModelError(f"{cfg.resolved_model_path}: {err}") from err
        self._stiffness = np.array(self._model.tendon_stiffness[:N_MOTORS])  # restored when re-tendoned
        self._current_hist = np.empty((self._n_sub, N_MOTORS))
        self._winding_c = np.full(N_MOTORS, self.limits.ambient_c)
        self._motor_on = np.ones(N_MOTORS)  # 0 for a motor its driver cut out
        self._peak_tension_n = np.zeros(N_MOTORS)
        self._slack_payout_m = np.zeros(N_MOTORS)  # cable paid out into each slack tendon (m)
        self.max_slack_payout_m = np.zeros(N_MOTORS)
        """The most cable paid out into a slack tendon since construction, per tendon (m)."""
        self._fault = ""

        self._time_s = 0.0
        self._energy_j = np.zeros(N_MOTORS)
        self._rest_state = self._settle()
        self._belt_rest_m = float(self._data.qpos[self._leg.belt_qpos])
        self._belt_base_m = -self._belt_rest_m  # the odometer reads 0 at the first rest posture
        self._prev_angle: FloatArray  # the encoders' last reading (rad), set by _hold_encoders and step
        self._hold_encoders()
        self._diverged = False
        self._closed = False

    # ----------------------------------------------------------------------------------------- Plant API
    @property
    def tick_hz(self) -> float:
        """Nominal tick rate (Hz)."""
        return self.config.tick_hz

    def reset(self) -> TickSample:
        """Return to the resting posture (motors at baseline, belt at rest) and return a sample at rest.

        The belt odometer, energy meters and clock are not reset; no time passes, unless the rig tripped.
        A tripped rig is put right first, as an operator would: its tendons back in their channels, and
        the time a cut-out winding takes to cool 10 K below its cut-out passes (the clock advances by it).
        """
        self._require_open()
        belt_now = float(self._data.qpos[self._leg.belt_qpos])
        if np.isfinite(belt_now):
            self._belt_base_m += belt_now - self._belt_rest_m
        self._clear_trip()
        mujoco.mj_setState(self._model, self._data, self._rest_state, _STATE)
        mujoco.mj_forward(self._model, self._data)
        self._diverged = False
        return self._still_sample()

    def reset_episode(
        self, rng: np.random.Generator, noise_scale: float, keep_heat: bool = False
    ) -> TickSample:
        """Start an episode as a fresh rig would: `reset`, meters at 0, joints perturbed, jitter from `rng`.

        For reinforcement learning (g2p.rl.envs): the belt odometer and the energy meters read 0 again, so
        that an episode's numbers do not depend on the ones before it (the same generator state gives the same
        episode, bit for bit), and the windings are at ambient temperature; the joint angles move by
        U(-noise_scale, noise_scale) rad and the joint velocities by noise_scale * N(0, 1) rad/s, as in
        Gymnasium's MuJoCo environments; the tick jitter is drawn from `rng` from now on. The clock runs on.

        Args:
            rng: the generator of the perturbation and, from now on, of the tick jitter.
            noise_scale: scale of the perturbation (rad, rad/s); 0 = the resting posture exactly.
            keep_heat: keep the windings' temperatures (a rig that ran before), instead of ambient.

        Returns:
            A sample at the perturbed posture (the velocity reads 0: the encoders have no history yet).

        Raises:
            ValueError: `noise_scale` is negative or not finite.
        """
        if not (math.isfinite(noise_scale) and noise_scale >= 0):
            raise ValueError(f"noise_scale: must be finite and >= 0, got {noise_scale}")
        self.reset()
        self._belt_base_m = -self._belt_rest_m
        self._energy_j[:] = 0.0
        if not keep_heat:
            self._winding_c[:] = self.limits.ambient_c
        self._clock = TickClock(rng, self.config.tick_hz, self.config.tick_jitter_s)
        leg = self._leg
        if noise_scale > 0:
            self._qpos[leg.joint_qpos] += rng.uniform(-noise_scale, noise_scale, size=leg.joint_qpos.shape)
            self._qvel[leg.joint_dof] += noise_scale * rng.standard_normal(leg.joint_dof.shape)
            mujoco.mj_forward(self._model, self._data)
        return self._still_sample()

    def step(self, activation: FloatArray, period_s: float | None = None) -> TickSample:
        """Apply activations for one tick and return the tick's sample.

        Args:
            activation: shape (3,), finite; values are clamped to [baseline, 1] before they are applied.
            period_s: the tick's duration (s), to replay a recorded tick; None draws it from the tick clock.

        Raises:
            ValueError: the activation is not 3 finite numbers (nothing changes: no time passes).
            SimulationError: the physics diverged during the tick; call `reset` before stepping again.
        """
        self._require_open()
        commanded = check_activation(activation)  # raises before anything is touched
        if self._diverged:
            raise SimulationError("the simulation diverged earlier; call reset() first")
        applied = clamp_activation(commanded, self.config.baseline_activation)
        model, data, n = self._model, self._data, self._n_sub
        qpos, qvel, act, spools = self._qpos, self._qvel, self._act, self._spools
        leg, limits, motor = self._leg, self.limits, self._leg.motor
        spool_dof, applied_force = leg.spool_dof, data.qfrc_applied
        current_hist = self._current_hist
        peak = self._peak_tension_n
        peak[:] = 0.0
        payout, radius = self._slack_payout_m, motor.spool_radius_m
        period = self._clock.next_period() if period_s is None else period_s
        dt = period / n
        model.opt.timestep = dt
        self._ctrl[:] = applied
        act_hist, spool_hist = self._act_hist, self._spool_hist
        delayed = self._encoder_delay_s > 0
        if delayed:
            hist_t, hist_q = self._hist_t, self._hist_q
            hist_t[:-n], hist_q[:-n] = hist_t[n:], hist_q[n:]
        for k in range(n):
            # Actuator force in a step uses the activation at its start; qpos moves by dt * new qvel, so
            # torque * spool displacement is the exact work of the step. The actuator applies the commanded
            # current's torque; the applied force takes off what the supply voltage (or a cut-out) denies.
            act_hist[k] = act
            spool_hist[k] = qpos[spools]
            commanded = act * self._i_max
            current = available_current_a(commanded, qvel[spool_dof], motor, limits.supply_voltage_v)
            current *= self._motor_on
            current_hist[k] = current
            applied_force[spool_dof] = motor.kt_nm_per_a * (current - commanded)
            mujoco.mj_step(model, data)
            np.maximum(peak, -data.qfrc_spring[spool_dof], out=peak)
            # The cable a spool has paid out (net of what it reeled back in) since its tendon went slack:
            # the loose loop at the spool; a taut tendon takes the loop back up.
            slack = data.ten_length[:N_MOTORS] < 0.0
            payout[:] = np.where(slack, np.maximum(payout - qvel[spool_dof] * (radius * dt), 0.0), 0.0)
            if delayed:
                hist_t[k - n] = self._time_s + (k + 1) * dt
                hist_q[k - n] = qpos[self._leg.joint_qpos]
        spool_hist[n] = qpos[spools]
        if not math.isfinite(qpos.sum() + self._qvel.sum()):
            self._diverged = True
            raise SimulationError(
                f"the simulation diverged at t = {self._time_s + period:.4f} s; call reset()"
            )

        current = current_hist  # (n, 3) A
        spool_speed = (spool_hist[1:] - spool_hist[:-1]) * (1.0 / dt)  # (n, 3) rad/s, mean over each substep
        power = electrical_power_w(current, spool_speed, motor)  # (n, 3) W
        power_sum = power.sum(axis=0)
        self._energy_j += power_sum * dt
        self._time_s += period
        peak *= 1.0 / motor.spool_radius_m  # N
        copper_w = (current * current).sum(axis=0) * (motor.resistance_ohm / n)
        self._winding_c = winding_temperature_c(self._winding_c, copper_w, period, limits)
        self._check_limits()
        self._wrap_belt()
        angle = self._read_angles()
        velocity = (angle - self._prev_angle) * (1.0 / period)  # what the driver computes from encoder counts
        self._prev_angle = angle
        return self._sample(
            act=applied, angle=angle, velocity=velocity, current=current.sum(axis=0) / n, power=power_sum / n
        )

    def set_joint_state(self, position_rad: FloatArray, velocity_rad_s: FloatArray | None = None) -> None:
        """Move the joints to a given true state at once, each tendon keeping its stretch (the spools follow).

        For identification by multiple shooting (g2p.identification): a replay is put back on the recorded
        joint state at the start of each window. The encoders' history becomes the new posture.

        Args:
            position_rad: true joint angles, shape (2,) (rad).
            velocity_rad_s: true joint velocities, shape (2,) (rad/s); None keeps the present ones.
        """
        self._require_open()
        leg, qpos, qvel = self._leg, self._qpos, self._qvel
        dq = np.asarray(position_rad, dtype=np.float64) - qpos[leg.joint_qpos]
        dv = np.zeros(2)
        if velocity_rad_s is not None:
            dv = np.asarray(velocity_rad_s, dtype=np.float64) - qvel[leg.joint_dof]
        arms = self._joint_arms  # (3, 2): tendon length per joint angle (m/rad)
        radius = leg.motor.spool_radius_m
        qpos[leg.joint_qpos] += dq
        qvel[leg.joint_dof] += dv
        qpos[leg.spool_qpos] -= arms @ dq / radius
        qvel[leg.spool_dof] -= arms @ dv / radius
        mujoco.mj_forward(self._model, self._data)
        self._hold_encoders()

    def _tendon_joint_arms(self) -> FloatArray:
        """The fixed tendons' coefficients on the two joints, shape (3, 2) (m/rad)."""
        model, leg = self._model, self._leg
        arms = np.zeros((3, 2))
        for t in range(3):
            for w in range(int(model.tendon_adr[t]), int(model.tendon_adr[t] + model.tendon_num[t])):
                jid = int(model.wrap_objid[w])
                for j, qadr in enumerate(leg.joint_qpos):
                    if int(model.jnt_qposadr[jid]) == int(qadr):
                        arms[t, j] = float(model.wrap_prm[w])
        return arms

    def close(self) -> None:
        """Drop the motors to baseline and refuse further steps."""
        self._data.ctrl[:] = self._baseline
        self._closed = True

    # ----------------------------------------------------------------------------------------- limits
    @property
    def fault(self) -> str:
        """Why the rig is tripped ("" when it is not): see g2p.sim.limits. `reset` puts it right."""
        return self._fault

    @property
    def winding_temperature_c(self) -> FloatArray:
        """The windings' temperatures, shape (3,) (deg C, M0, M1, M2)."""
        return self._winding_c.copy()

    @property
    def slack_payout_m(self) -> FloatArray:
        """The cable each spool has paid into its slack tendon now, shape (3,) (m; 0 for a taut tendon)."""
        return self._slack_payout_m.copy()

    @property
    def peak_tension_n(self) -> FloatArray:
        """The tendons' highest tension over the sub-steps of the last tick, shape (3,) (N)."""
        return self._peak_tension_n.copy()

    def _check_limits(self) -> None:
        """Trip on a winding past its cut-out, a tendon past its breaking tension or off its channel."""
        limits, model = self.limits, self._model
        trips = []
        for i, name in enumerate(MOTOR_NAMES):
            if self._motor_on[i] and self._winding_c[i] >= limits.winding_cutout_c:
                self._motor_on[i] = 0.0
                trips.append(f"{name}'s winding reached {self._winding_c[i]:.1f} degC: its driver cut out")
            if model.tendon_stiffness[i] == 0.0:
                continue
            payout_m = float(self._slack_payout_m[i])
            self.max_slack_payout_m[i] = max(self.max_slack_payout_m[i], payout_m)
            if self._peak_tension_n[i] > limits.tendon_breaking_n:
                trips.append(
                    f"tendon {name} snapped at {self._peak_tension_n[i]:.0f} N "
                    f"(breaks above {limits.tendon_breaking_n:g} N)"
                )
            elif payout_m > limits.tendon_derail_payout_m:
                trips.append(
                    f"tendon {name} left its channel: its spool paid {1000 * payout_m:.0f} mm of cable "
                    f"into it slack (derails beyond {1000 * limits.tendon_derail_payout_m:g} mm)"
                )
            else:
                continue
            model.tendon_stiffness[i] = 0.0  # off the spool or broken: it carries no force
        if trips and not self._fault:
            self._fault = "; ".join(trips)

    def _clear_trip(self) -> None:
        """Put a tripped rig right: re-tendon it and let cut-out windings cool (the clock runs on)."""
        self._model.tendon_stiffness[:N_MOTORS] = self._stiffness
        self._slack_payout_m[:] = 0.0
        off = self._motor_on == 0.0
        if off.any():
            limits = self.limits
            above = float(np.max(self._winding_c[off])) - limits.ambient_c
            target = limits.winding_cutout_c - COOLDOWN_HYSTERESIS_K - limits.ambient_c
            if above > target:
                wait_s = limits.winding_time_constant_s * math.log(above / target)
                self._winding_c = winding_temperature_c(self._winding_c, np.zeros(N_MOTORS), wait_s, limits)
                self._time_s += wait_s
        self._motor_on[:] = 1.0
        self._fault = ""

    def __enter__(self) -> MujocoLeg:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    # ----------------------------------------------------------------------------------------- diagnostics
    @property
    def model(self) -> mujoco.MjModel:
        """The compiled MuJoCo model (for viewers and diagnostics; do not change it while stepping)."""
        return self._model

    @property
    def data(self) -> mujoco.MjData:
        """The MuJoCo state (for viewers and diagnostics; do not change it)."""
        return self._data

    @property
    def leg_model(self) -> LegModel:
        """The model with the addresses and motor constants the plant uses."""
        return self._leg

    @property
    def time_s(self) -> float:
        """The plant clock: simulated time since construction, across resets (s)."""
        return self._time_s

    @property
    def true_position_rad(self) -> FloatArray:
        """Joint angles before encoder quantization, shape (2,) (rad)."""
        return np.array(self._data.qpos[self._leg.joint_qpos], dtype=np.float64)

    @property
    def tendon_tension_n(self) -> FloatArray:
        """Tendon tensions the physics applied in the last substep, shape (3,) (N, M0, M1, M2).

        Read from the spring force on each spool, so a tendon that pushed would show a negative value.
        """
        spring = np.array(self._data.qfrc_spring[self._leg.spool_dof], dtype=np.float64)
        return -spring / self._leg.motor.spool_radius_m

    # ----------------------------------------------------------------------------------------- internals
    def _settle(self) -> FloatArray:
        """Find the resting posture as the rig does: hang the leg clear, lower the carriage, let it settle.

        The leg starts straight and motionless with the carriage raised by _LOWER_FROM_M, holds baseline
        activation for _LOWER_S while the carriage is lowered to its set height at constant speed, then
        for `settle_s` more. Returns the state reached (the physics is deterministic, so is the state).
        """
        model, data, leg, cfg = self._model, self._data, self._leg, self.config
        mujoco.mj_resetData(model, data)
        data.act[:] = self._baseline
        data.ctrl[:] = self._baseline
        # Pre-wind the spools to the baseline stretch so the tendons start taut, not with a jerk.
        tension = self._baseline * leg.motor.max_tension_n
        slack_end = model.tendon_lengthspring[:, 1]
        data.qpos[leg.spool_qpos] = (slack_end + tension / model.tendon_stiffness) / leg.motor.spool_radius_m
        model.opt.timestep = cfg.nominal_period_s / self._n_sub
        carriage_z = float(model.body_pos[leg.carriage_body, 2])
        n_lower = max(1, round(_LOWER_S * cfg.tick_hz))
        for k in range(n_lower + 1):
            model.body_pos[leg.carriage_body, 2] = carriage_z + _LOWER_FROM_M * (1.0 - k / n_lower)
            mujoco.mj_step(model, data, self._n_sub)
        mujoco.mj_step(model, data, round(cfg.settle_s * cfg.tick_hz) * self._n_sub)
        if not np.isfinite(data.qpos).all():
            raise SimulationError("the model diverged while settling to its resting posture")
        data.qvel[leg.belt_dof] = 0.0  # the belt starts each attempt at rest
        mujoco.mj_forward(model, data)
        state = np.empty(mujoco.mj_stateSize(model, _STATE))
        mujoco.mj_getState(model, data, state, _STATE)
        return state

    def _still_sample(self) -> TickSample:
        """A sample of the present state with no tick behind it: baseline, encoder velocity 0."""
        self._hold_encoders()
        current = self._data.act * self._i_max
        return self._sample(
            act=self._baseline.copy(),
            angle=self._prev_angle,
            velocity=np.zeros(2),
            current=current,
            power=electrical_power_w(current, np.zeros(N_MOTORS), self._leg.motor),
        )

    def _hold_encoders(self) -> None:
        """The encoders' history becomes the present posture, held still until now."""
        if self._hist_t.size:
            substep_s = self.config.nominal_period_s / self._n_sub
            self._hist_t[:] = self._time_s - substep_s * np.arange(self._hist_t.size)[::-1]
            self._hist_q[:] = self._qpos[self._leg.joint_qpos]
        self._prev_angle = self._read_angles()

    def _read_angles(self) -> FloatArray:
        if self._encoder_delay_s > 0:
            t = self._time_s - self._encoder_delay_s
            hist_t, hist_q = self._hist_t, self._hist_q
            true = np.array([np.interp(t, hist_t, hist_q[:, 0]), np.interp(t, hist_t, hist_q[:, 1])])
        else:
            true = self._qpos[self._leg.joint_qpos]
        return quantize_angle(true + self._encoder_offset, self.config.encoder_bits)

    def _wrap_belt(self) -> None:
        offset = float(self._qpos[self._leg.belt_qpos]) - self._belt_rest_m
        if abs(offset) > _BELT_WRAP_M:
            shift = math.copysign(_BELT_WRAP_M, offset)
            self._qpos[self._leg.belt_qpos] -= shift
            self._belt_base_m += shift

    def _sample(
        self, act: FloatArray, angle: FloatArray, velocity: FloatArray, current: FloatArray, power: FloatArray
    ) -> TickSample:
        belt_m = self._belt_base_m + float(self._qpos[self._leg.belt_qpos])
        return TickSample(
            t_s=self._time_s,
            activation=act,
            position_rad=angle.copy(),
            velocity_rad_s=velocity,
            belt_mm=-1000.0 * belt_m,  # + when the belt moves toward -x (pushed backward)
            belt_velocity_mm_s=-1000.0 * float(self._qvel[self._leg.belt_dof]),
            current_a=current,
            power_w=power,
            energy_j=self._energy_j.copy(),
        )

    def _require_open(self) -> None:
        if self._closed:
            raise RuntimeError("the plant is closed")
