"""`HardwareLeg`: the physical leg as a `g2p.plant.Plant`, composed of its devices.

One absolute-deadline loop on a monotonic clock: tick k ends at t0 + k / tick_hz, whatever the jitter of
the ticks before it. Within a tick, `step` writes the clamped activations as duty cycles, samples the
three current sensors on a 500 Hz grid until the tick's deadline, then reads the two joint encoders and
the belt counter. The caller (the ROS rig server) publishes between ticks; that time belongs to the next
tick, so the period holds as long as a tick's work and the publishing fit in it.

Faults: a failed read (encoder parity error or error flag, SPI or I2C OSError) is retried at once, counted,
and the tick keeps the last good value. A tick where a device still failed is a faulted tick; after
`max_consecutive_faults` of them in a row the plant latches a `HardwareFault`: outputs to baseline (off if
the PWM cannot be written), and every later `step` or `reset` raises until `close`.

Safety: a watchdog thread drops the outputs to baseline when no tick ran for `step_watchdog_s` while the
plant runs (the loop died or stalled); `close` holds baseline for `close_hold_s`, then switches the
outputs off and releases the buses.
"""

from __future__ import annotations

import functools
import logging
import math
import threading
from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import TypeVar

import numpy as np

from g2p.hardware.clock import Clock, MonotonicClock
from g2p.hardware.devices import RigDevices
from g2p.hardware.errors import EncoderErrorFlag, EncoderParityError, HardwareError, HardwareFault
from g2p.hardware.ina219 import INA219
from g2p.hardware.ls7366r import BeltOdometer
from g2p.hardware.realtime import StallWatchdog, request_sched_fifo
from g2p.hardware.wiring import WiringConfig
from g2p.plant import N_JOINTS, N_MOTORS, NOMINAL_TICK_HZ, FloatArray, TickSample
from g2p.safety import BASELINE_ACTIVATION, check_activation, clamp_activation
from g2p.validation import require, require_non_negative, require_positive

_log = logging.getLogger(__name__)
_T = TypeVar("_T")


def _named(device: str, err: Exception) -> str:
    """`device: error`, without repeating the device when the error already names it."""
    text = str(err)
    return text if text.startswith(device) else f"{device}: {text}"


def _read_power(sensor: INA219) -> tuple[float, float, bool]:
    """One reading of a current sensor: (current (A), bus voltage (V), whether the power overflowed)."""
    current = sensor.read_current_a()
    voltage, overflow = sensor.read_bus_voltage_v()
    return current, voltage, overflow


@dataclass(frozen=True)
class HardwareLegConfig:
    """Timing, fault handling and settling of the hardware plant (the wiring is in `WiringConfig`).

    Attributes:
        tick_hz: rate of the absolute-deadline tick loop (Hz); the rig ran at about 78 Hz.
        current_sample_hz: rate at which the three current sensors are sampled within ticks (Hz).
        baseline_activation: the activation always applied at least (dimensionless, the paper's 15%).
        max_consecutive_faults: ticks in a row with a failed read or write after which the plant latches a
            HardwareFault (outputs to baseline, every later step raises).
        retries: immediate re-reads (or re-writes) of a device within a tick after a failure.
        dither_amplitude: reset's hip dither: peak activation added to baseline (dimensionless; 0: none).
        dither_hz: frequency of the dither (Hz), well below tick_hz / 4.
        dither_s: duration of the dither, its amplitude falling linearly to 0 (s).
        settle_velocity_rad_s: reset counts the joints as still below this speed (rad/s).
        settle_hold_s: reset returns once the joints have been still for this long (s).
        settle_min_s: reset holds baseline for at least this long (s).
        settle_timeout_s: reset stops waiting after this long and returns the posture reached (s).
        close_hold_s: close holds baseline this long before switching the outputs off (s).
        step_watchdog_s: while running, the outputs drop to baseline when no tick ran for this long (s);
            0 disables the watchdog thread.
        sched_fifo_priority: 1..99: switch the thread running the ticks to SCHED_FIFO at this priority when
            permitted (CAP_SYS_NICE or an rtprio limit); 0: leave the scheduling alone.
    """

    tick_hz: float = NOMINAL_TICK_HZ
    current_sample_hz: float = 500.0
    baseline_activation: float = BASELINE_ACTIVATION
    max_consecutive_faults: int = 5
    retries: int = 1
    dither_amplitude: float = 0.05
    dither_hz: float = 5.0
    dither_s: float = 2.0
    settle_velocity_rad_s: float = 0.05
    settle_hold_s: float = 0.5
    settle_min_s: float = 0.5
    settle_timeout_s: float = 10.0
    close_hold_s: float = 0.2
    step_watchdog_s: float = 0.1
    sched_fifo_priority: int = 0

    def __post_init__(self) -> None:
        require_positive(self.tick_hz, "tick_hz")
        require_positive(self.current_sample_hz, "current_sample_hz")
        require(
            math.isfinite(self.baseline_activation) and 0.0 <= self.baseline_activation < 1.0,
            "baseline_activation",
            f"must be in [0, 1), got {self.baseline_activation!r}",
        )
        require(
            isinstance(self.max_consecutive_faults, int) and self.max_consecutive_faults >= 1,
            "max_consecutive_faults",
            f"must be an integer >= 1, got {self.max_consecutive_faults!r}",
        )
        require(
            isinstance(self.retries, int) and 0 <= self.retries <= 10,
            "retries",
            f"must be an integer in [0, 10], got {self.retries!r}",
        )
        require(
            math.isfinite(self.dither_amplitude)
            and 0.0 <= self.dither_amplitude <= 1.0 - self.baseline_activation,
            "dither_amplitude",
            f"must be in [0, 1 - baseline_activation], got {self.dither_amplitude!r}",
        )
        require(
            math.isfinite(self.dither_hz) and 0.0 < self.dither_hz <= self.tick_hz / 4.0,
            "dither_hz",
            f"must be in (0, tick_hz / 4], got {self.dither_hz!r}",
        )
        require_non_negative(self.dither_s, "dither_s")
        require_positive(self.settle_velocity_rad_s, "settle_velocity_rad_s")
        for name in ("settle_hold_s", "settle_min_s", "close_hold_s", "step_watchdog_s"):
            require_non_negative(getattr(self, name), name)
        require(
            math.isfinite(self.settle_timeout_s) and self.settle_timeout_s >= self.settle_min_s,
            "settle_timeout_s",
            f"must be >= settle_min_s ({self.settle_min_s}), got {self.settle_timeout_s!r}",
        )
        require(
            self.step_watchdog_s == 0.0 or self.step_watchdog_s >= 2.0 / self.tick_hz,
            "step_watchdog_s",
            f"must be 0 (off) or at least two ticks ({2.0 / self.tick_hz:.4f} s), "
            f"got {self.step_watchdog_s!r}",
        )
        require(
            isinstance(self.sched_fifo_priority, int) and 0 <= self.sched_fifo_priority <= 99,
            "sched_fifo_priority",
            f"must be an integer in [0, 99], got {self.sched_fifo_priority!r}",
        )


@dataclass
class HardwareCounters:
    """What the hardware plant counted since it was opened (reported on /diagnostics).

    Attributes:
        ticks: ticks run (steps and the ticks of resets).
        late_ticks: ticks whose work ran past the next tick's deadline (the loop re-synchronised).
        max_late_s: the largest delay of a tick's sensor read past its deadline (s).
        current_samples: current-sensor sampling rounds (all three sensors each).
        sampled_s: time covered by ticks that sampled currents (s), for the achieved sampling rate.
        encoder_parity_errors: encoder frames that failed their parity check.
        encoder_error_flags: encoder frames with the error flag set.
        spi_errors: SPI transfers that raised OSError.
        i2c_errors: I2C transactions that raised OSError.
        pwm_errors: PWM writes that raised OSError (I2C or sysfs).
        current_overflows: INA219 readings with the math-overflow flag set.
        faulted_ticks: ticks in which a device still failed after the retries.
        consecutive_faulted_ticks: the current run of faulted ticks.
        hardware_faults: persistent faults latched (0 or 1 until close).
        watchdog_trips: times the watchdog dropped the outputs to baseline.
        settle_timeouts: resets that returned before the joints were still.
        sched_fifo: 1 when the tick thread runs SCHED_FIFO.
    """

    ticks: int = 0
    late_ticks: int = 0
    max_late_s: float = 0.0
    current_samples: int = 0
    sampled_s: float = 0.0
    encoder_parity_errors: int = 0
    encoder_error_flags: int = 0
    spi_errors: int = 0
    i2c_errors: int = 0
    pwm_errors: int = 0
    current_overflows: int = 0
    faulted_ticks: int = 0
    consecutive_faulted_ticks: int = 0
    hardware_faults: int = 0
    watchdog_trips: int = 0
    settle_timeouts: int = 0
    sched_fifo: int = 0

    @property
    def current_sample_rate_hz(self) -> float:
        """Current-sensor sampling rounds per second of ticking (Hz)."""
        return self.current_samples / self.sampled_s if self.sampled_s > 0 else 0.0


# The dither's two half-waves (Fig 1d routing): M1 alone turns the hip ccw; M0 and M2 together turn it cw
# with the knee held straight (M0's knee arm exceeds M2's), so the dither moves the hip only.
_DITHER_CCW = np.array([0.0, 1.0, 0.0])
_DITHER_CW = np.array([1.0, 0.0, 1.0])


def dither_activation(config: HardwareLegConfig) -> FloatArray:
    """The activations of reset's hip dither, one row per tick, shape (N, 3) (N = 0 when disabled).

    a(t) = baseline + A (1 - t / T) [max(s, 0) * (0, 1, 0) + max(-s, 0) * (1, 0, 1)], s = sin(2 pi f t):
    a decaying alternating hip torque that carries the hip through its friction dead band, so that every
    reset ends at the same posture (within an encoder count on the fake rig, against +-1.5 deg without).
    """
    n = round(config.dither_s * config.tick_hz) if config.dither_amplitude > 0 else 0
    t = np.arange(n) / config.tick_hz
    amplitude = config.dither_amplitude * (1.0 - t / config.dither_s) if n else t
    s = np.sin(2.0 * math.pi * config.dither_hz * t)
    out: FloatArray = (
        config.baseline_activation
        + (amplitude * np.maximum(s, 0.0))[:, None] * _DITHER_CCW
        + (amplitude * np.maximum(-s, 0.0))[:, None] * _DITHER_CW
    )
    return out


class _Tick:
    """Readings accumulated during one tick."""

    def __init__(self) -> None:
        self.faults: list[str] = []
        self.current_sum = np.zeros(N_MOTORS)
        self.power_sum = np.zeros(N_MOTORS)
        self.n = np.zeros(N_MOTORS, dtype=np.int64)
        self.rounds = 0


class HardwareLeg:
    """The physical leg, treadmill and motors, driven one tick at a time from the rig's devices.

    Construction reads every sensor once (the belt odometer's origin) and leaves the outputs off. `reset`
    switches them on at baseline tension and waits for the joints to settle; `step` then runs ticks;
    `hold_baseline` stops running with the outputs at baseline; `close` switches them off.

    Args:
        devices: the devices, set up, outputs off (`g2p.hardware.devices.open_devices` or the fakes).
        wiring: the wiring description (belt calibration).
        config: timing, fault and settling settings.
        clock: the loop's clock; None uses the monotonic clock.

    Raises:
        HardwareError: the first reading of a sensor failed.
    """

    def __init__(
        self,
        devices: RigDevices,
        wiring: WiringConfig,
        config: HardwareLegConfig | None = None,
        clock: Clock | None = None,
    ) -> None:
        self.config = cfg = config if config is not None else HardwareLegConfig()
        self.wiring = wiring
        self.counters = HardwareCounters()
        self._dev = devices
        self._outputs = devices.outputs
        self._clock = clock if clock is not None else MonotonicClock()
        self._period = 1.0 / cfg.tick_hz
        self._sample_period = 1.0 / cfg.current_sample_hz
        self._baseline = np.full(N_MOTORS, cfg.baseline_activation)
        self._odometer = BeltOdometer(
            wiring.belt.counts_per_rev, wiring.belt.drum_radius_mm, wiring.belt.direction
        )
        self._io = threading.RLock()  # one bus transaction group at a time: ticks, watchdog, close
        self._closed = False
        self._running = False
        self._fault: HardwareFault | None = None
        self._realtime_threads: set[int] = set()

        first = _Tick()
        self._angles = self._read_angles(first, np.zeros(N_JOINTS))
        self._belt_mm = self._read_belt(first)
        if first.faults:
            raise HardwareError(f"first sensor reading failed: {'; '.join(first.faults)}")
        now = self._clock.now()
        self._t_read = now
        self._next_deadline = now + self._period
        self._next_sample = now
        self._last_sample_t = now
        self._last_activity = now
        self._current = np.zeros(N_MOTORS)
        self._power = np.zeros(N_MOTORS)
        self._energy = np.zeros(N_MOTORS)

        self._watchdog: StallWatchdog | None = None
        if cfg.step_watchdog_s > 0:
            self._watchdog = StallWatchdog(
                cfg.step_watchdog_s, self.seconds_since_activity, lambda: self._running, self._on_stall
            )

    # ----------------------------------------------------------------------------------------- Plant API
    @property
    def tick_hz(self) -> float:
        """Nominal tick rate (Hz)."""
        return self.config.tick_hz

    def reset(self) -> TickSample:
        """Switch the outputs on at baseline (first call), shake off joint friction, wait until still.

        Three phases: baseline until the joints are still (the leg stops swinging); a decaying hip dither
        (`dither_amplitude` for `dither_s` at `dither_hz`, see `dither_activation`) that carries the hip
        through the friction dead band around the hanging posture, so every reset ends at the same one;
        baseline again until still. "Still": both joint speeds below `settle_velocity_rad_s` for
        `settle_hold_s`, and at least `settle_min_s` at baseline; a phase that is not still after
        `settle_timeout_s` is counted in `settle_timeouts` and the posture reached is returned.

        Returns:
            The last tick's sample: baseline activation, the resting posture.

        Raises:
            HardwareFault: a persistent fault is latched (now, or earlier).
            RuntimeError: the plant is closed.
        """
        self._require_usable()
        self._maybe_realtime()
        with self._io:
            self._require_open()
            if not self._running:
                self._start_outputs()
        dither = dither_activation(self.config)
        if len(dither) == 0:
            return self._settle()
        self._settle()
        for activation in dither:
            self._tick(activation)
        return self._settle()

    def _settle(self) -> TickSample:
        """Tick at baseline until the joints are still (see `reset`); returns the last sample."""
        cfg = self.config
        t0 = self._clock.now()
        still_since: float | None = None
        while True:
            sample = self._tick(self._baseline.copy())
            if np.all(np.abs(sample.velocity_rad_s) < cfg.settle_velocity_rad_s):
                still_since = sample.t_s if still_since is None else still_since
            else:
                still_since = None
            elapsed = sample.t_s - t0
            if (
                elapsed >= cfg.settle_min_s
                and still_since is not None
                and sample.t_s - still_since >= cfg.settle_hold_s
            ):
                return sample
            if elapsed >= cfg.settle_timeout_s:
                self.counters.settle_timeouts += 1
                _log.warning("reset: the joints did not settle within %.1f s", cfg.settle_timeout_s)
                return sample

    def step(self, activation: FloatArray) -> TickSample:
        """Apply activations for one tick and return its sample; blocks until the tick's deadline.

        Args:
            activation: shape (3,), finite; clamped to [baseline, 1] before it reaches the PWM.

        Raises:
            ValueError: the activation is not 3 finite numbers (nothing is written, no tick passes).
            HardwareFault: a persistent fault is latched (after waiting for the tick's deadline).
            RuntimeError: the plant is closed, or not running (call `reset` first).
        """
        commanded = check_activation(activation)
        self._require_usable()
        if not self._running:
            raise RuntimeError("the outputs are not running: call reset() first")
        self._maybe_realtime()
        return self._tick(clamp_activation(commanded, self.config.baseline_activation))

    def hold_baseline(self) -> None:
        """Stop running with the outputs at baseline tension (the drivers stay enabled).

        Raises:
            OSError: the baseline could not be written.
        """
        with self._io:
            self._running = False
            if not self._closed and self._outputs.enabled:
                self._outputs.apply(self._baseline)

    def close(self) -> None:
        """Hold baseline for `close_hold_s`, switch the outputs off, release the devices. Idempotent."""
        if self._watchdog is not None:
            self._watchdog.stop()
        with self._io:
            if self._closed:
                return
            self._closed = True
            self._running = False
            try:
                if self._outputs.enabled and self._fault is None:
                    self._outputs.apply(self._baseline)
                    self._clock.sleep_until(self._clock.now() + self.config.close_hold_s)
            except OSError as err:
                _log.error("close: could not write baseline: %s", err)
            finally:
                try:
                    self._dev.close()
                except OSError as err:
                    _log.error("close: could not switch the outputs off cleanly: %s", err)

    # ----------------------------------------------------------------------------------------- state
    @property
    def running(self) -> bool:
        """Whether the outputs are on and ticks are expected (between `reset` and `hold_baseline`)."""
        return self._running

    @property
    def fault(self) -> HardwareFault | None:
        """The latched persistent fault, if any."""
        return self._fault

    @property
    def closed(self) -> bool:
        """Whether `close` was called."""
        return self._closed

    def seconds_since_activity(self) -> float:
        """Time since the last tick or current sample (s, the plant's clock)."""
        return self._clock.now() - self._last_activity

    def diagnostics(self) -> dict[str, float | int | str]:
        """Counters and state as flat key/values for /diagnostics."""
        values: dict[str, float | int | str] = dict(asdict(self.counters))
        values["current_sample_rate_hz"] = round(self.counters.current_sample_rate_hz, 1)
        values["max_late_s"] = round(self.counters.max_late_s, 6)
        values["sampled_s"] = round(self.counters.sampled_s, 3)
        values["running"] = int(self._running)
        values["fault"] = str(self._fault) if self._fault is not None else ""
        return values

    # ----------------------------------------------------------------------------------------- the tick
    def _tick(self, applied: FloatArray) -> TickSample:
        tick = _Tick()
        self._write(applied, tick)
        if self._watchdog is not None:
            self._watchdog.rearm()
        deadline = self._next_deadline
        while self._next_sample < deadline:
            self._clock.sleep_until(self._next_sample)
            self._sample_currents(tick)
            now = self._clock.now()
            self._next_sample += self._sample_period
            if self._next_sample <= now:  # fell behind: skip the missed slots, never burst
                self._next_sample = now + self._sample_period
        self._clock.sleep_until(deadline)
        if tick.rounds == 0:
            self._sample_currents(tick)
        t_read = self._clock.now()
        angles = self._read_angles(tick, self._angles)
        belt_mm = self._read_belt(tick)
        dt = t_read - self._t_read
        velocity = (angles - self._angles) / dt if dt > 0 else np.zeros(N_JOINTS)
        belt_velocity = (belt_mm - self._belt_mm) / dt if dt > 0 else 0.0
        ok = tick.n > 0
        self._current = np.where(ok, tick.current_sum / np.maximum(tick.n, 1), self._current)
        self._power = np.where(ok, tick.power_sum / np.maximum(tick.n, 1), self._power)
        self._angles, self._belt_mm, self._t_read = angles, belt_mm, t_read

        c = self.counters
        c.ticks += 1
        c.sampled_s += self._period
        c.max_late_s = max(c.max_late_s, t_read - deadline)
        end = self._clock.now()
        self._last_activity = end
        self._next_deadline = deadline + self._period
        if end > self._next_deadline:  # overran a whole tick: start a new grid rather than catch up
            c.late_ticks += 1
            self._next_deadline = end + self._period
        self._account(tick)
        return TickSample(
            t_s=t_read,
            activation=applied.copy(),
            position_rad=angles.copy(),
            velocity_rad_s=velocity,
            belt_mm=float(belt_mm),
            belt_velocity_mm_s=float(belt_velocity),
            current_a=self._current.copy(),
            power_w=self._power.copy(),
            energy_j=self._energy.copy(),
        )

    def _account(self, tick: _Tick) -> None:
        c = self.counters
        if not tick.faults:
            c.consecutive_faulted_ticks = 0
            return
        c.faulted_ticks += 1
        c.consecutive_faulted_ticks += 1
        if c.consecutive_faulted_ticks >= self.config.max_consecutive_faults:
            fault = HardwareFault(
                f"{c.consecutive_faulted_ticks} consecutive faulted ticks; last: {'; '.join(tick.faults)}"
            )
            self._latch(fault)
            raise fault

    def _latch(self, fault: HardwareFault) -> None:
        """Latch a persistent fault: outputs to baseline, or off when the PWM cannot be written."""
        with self._io:
            self._fault = fault
            self._running = False
            self.counters.hardware_faults += 1
            _log.error("hardware fault: %s", fault)
            try:
                self._outputs.apply(self._baseline)
            except OSError as err:
                _log.error("cannot write baseline after the fault (%s): switching the outputs off", err)
                try:
                    self._outputs.off()
                except OSError as err2:
                    _log.error("cannot switch the outputs off either: %s", err2)

    # ----------------------------------------------------------------------------------------- device I/O
    def _try(self, tick: _Tick, device: str, bus_errors: str, transaction: Callable[[], _T]) -> _T | None:
        """Run one device transaction under the bus lock, retried up to `retries` times at once.

        Each failure is counted: an encoder's parity error or error flag under its own counter, any other
        OSError under `bus_errors` (a `HardwareCounters` field). When every try failed, the tick records a
        fault naming the device and None is returned (the caller keeps the last good value).
        """
        last: Exception | None = None
        for _ in range(self.config.retries + 1):
            with self._io:
                self._require_open()
                try:
                    return transaction()
                except EncoderParityError as err:
                    self.counters.encoder_parity_errors += 1
                    last = err
                except EncoderErrorFlag as err:
                    self.counters.encoder_error_flags += 1
                    last = err
                except OSError as err:
                    setattr(self.counters, bus_errors, getattr(self.counters, bus_errors) + 1)
                    last = err
        assert last is not None
        tick.faults.append(_named(device, last))
        return None

    def _write(self, applied: FloatArray, tick: _Tick) -> None:
        self._try(tick, "PWM write", "pwm_errors", lambda: self._outputs.apply(applied))

    def _sample_currents(self, tick: _Tick) -> None:
        t = self._clock.now()
        dt = min(t - self._last_sample_t, self._period)
        self._last_sample_t = t
        self._last_activity = t
        for i, sensor in enumerate(self._dev.current_sensors):
            reading = self._try(tick, sensor.name, "i2c_errors", functools.partial(_read_power, sensor))
            if reading is None:
                continue
            current, voltage, overflow = reading
            if overflow:
                self.counters.current_overflows += 1
            power = current * voltage
            tick.current_sum[i] += current
            tick.power_sum[i] += power
            tick.n[i] += 1
            self._energy[i] += power * dt
        tick.rounds += 1
        self.counters.current_samples += 1

    def _read_angles(self, tick: _Tick, previous: FloatArray) -> FloatArray:
        angles = previous.copy()
        for j, encoder in enumerate(self._dev.encoders):
            angle = self._try(tick, encoder.name, "spi_errors", encoder.read_angle_rad)
            if angle is not None:
                angles[j] = angle
        return angles

    def _read_belt(self, tick: _Tick) -> float:
        counter = self._dev.belt
        count = self._try(tick, counter.name, "spi_errors", counter.read_count)
        return self._odometer.travel_mm if count is None else self._odometer.update(count)

    # ----------------------------------------------------------------------------------------- helpers
    def _start_outputs(self) -> None:
        """Baseline duty first, then enable the drivers; start a fresh tick grid."""
        self._outputs.apply(self._baseline)
        if not self._outputs.enabled:
            self._outputs.enable()
        now = self._clock.now()
        self._angles = self._read_angles(_Tick(), self._angles)  # the posture now, for the first velocity
        self._next_deadline = now + self._period
        self._next_sample = now
        self._last_sample_t = now
        self._last_activity = now
        self._t_read = now
        self._running = True

    def _require_open(self) -> None:
        if self._closed:
            raise RuntimeError("the hardware plant is closed")

    def _require_usable(self) -> None:
        self._require_open()
        if self._fault is not None:
            # Keep the caller's loop paced while it reacts: wait for the tick's deadline, then raise.
            self._clock.sleep_until(self._next_deadline)
            self._next_deadline = max(self._next_deadline, self._clock.now()) + self._period
            raise HardwareFault(f"latched: {self._fault}")

    def _maybe_realtime(self) -> None:
        priority = self.config.sched_fifo_priority
        ident = threading.get_ident()
        if priority <= 0 or ident in self._realtime_threads:
            return
        self._realtime_threads.add(ident)
        if request_sched_fifo(priority):
            self.counters.sched_fifo = 1

    def _on_stall(self) -> bool:
        """The watchdog's action: outputs to baseline (off if that fails) when the loop really stalled."""
        limit = self.config.step_watchdog_s
        with self._io:
            if not self._running or self._closed or self.seconds_since_activity() < limit:
                return False
            self.counters.watchdog_trips += 1
            _log.warning("watchdog: no tick for %.3f s: outputs to baseline", self.seconds_since_activity())
            try:
                self._outputs.apply(self._baseline)
            except OSError as err:
                _log.error("watchdog: cannot write baseline (%s): switching the outputs off", err)
                try:
                    self._outputs.off()
                except OSError:
                    pass
            return True
