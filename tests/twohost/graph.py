"""The G2P graph on a two-host bench, started the way a user starts it on a Pi and a workstation.

The rig side runs ROS 2 Jazzy (the Raspberry Pi's distribution) from the project's Jazzy environment; the
workstation side runs the distribution of this test session. Each side's processes are the installed
executables, started in their host's namespace with the two-host DDS profile (UDPv4 only, on the
bench's link), either through `bringup --host ...` or one node at a time (to kill and restart one).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path
from typing import IO

from tests.nodes.rosproc import stop_process
from tests.twohost.bench import Host, TwoHostBench

ROOT = Path(__file__).resolve().parents[2]
ROS2_RUN = ROOT / "scripts" / "ros2-run"
RIG_DISTRO = "jazzy"
# The same short learning run everywhere: babbling (rig s), attempts of 4 cycles.
SHORT_RUN = {
    "learner.babbling.duration_s": "20.0",
    "cycle.n_cycles": "4",
    "search.exploitation_attempts": "4",
}
ATTEMPT_LINE = re.compile(r"^attempt +(\d+) ", re.M)


class HostProcess:
    """A process of one host of the bench, its output in a log file."""

    def __init__(self, popen: subprocess.Popen[bytes], log_path: Path, log: IO[bytes]) -> None:
        self.popen = popen
        self.log_path = log_path
        self._log = log

    def log(self) -> str:
        """What the process printed so far."""
        if not self._log.closed:
            self._log.flush()
        return self.log_path.read_text(errors="replace")

    def attempts_done(self) -> int:
        """The highest attempt number `learn` reported so far (0 before the first)."""
        numbers = [int(n) for n in ATTEMPT_LINE.findall(self.log())]
        return max(numbers, default=0)

    def wait_for(self, what: str, condition_s: float, check: object) -> None:
        """Wait until `check()` is true; fail with the log after `condition_s` or if the process ended."""
        deadline = time.monotonic() + condition_s
        while not check():  # type: ignore[operator]
            if self.popen.poll() is not None:
                raise AssertionError(f"exited ({self.popen.returncode}) before {what}:\n{self.log()[-3000:]}")
            if time.monotonic() > deadline:
                raise AssertionError(f"no {what} within {condition_s:g} s:\n{self.log()[-3000:]}")
            time.sleep(0.05)

    def wait_for_attempt(self, number: int, timeout_s: float = 300.0) -> None:
        """Wait until `learn` reported attempt `number`."""
        self.wait_for(f"attempt {number}", timeout_s, lambda: self.attempts_done() >= number)

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 30.0) -> int:
        """Signal the process and wait for it (kill after `timeout_s`); its exit code."""
        code = stop_process(self.popen, sig, timeout_s)
        self._log.close()
        return code

    def wait(self, timeout_s: float) -> int:
        """Wait for the process to end by itself; its exit code."""
        try:
            return self.popen.wait(timeout_s)
        except subprocess.TimeoutExpired as err:
            raise AssertionError(f"still running after {timeout_s:g} s:\n{self.log()[-3000:]}") from err


class TwoHostGraph:
    """Starts the graph's processes on a bench: the rig host's on Jazzy, the workstation's on this session's.

    Args:
        bench: the bench (open).
        workdir: working directory of every process (bags/ and log/ go there).
        run_id: the run's id (the rig host's recorder names the bag after it).
    """

    def __init__(self, bench: TwoHostBench, workdir: Path, run_id: str) -> None:
        self.bench = bench
        self.workdir = workdir
        workdir.mkdir(parents=True, exist_ok=True)
        self.run_id = run_id
        self.bag = workdir / "bags" / run_id
        self._n = 0

    def _start(self, host: Host, name: str, argv: list[str], env: dict[str, str]) -> HostProcess:
        self._n += 1
        log_path = self.workdir / f"{self._n:02d}-{host}-{name}.log"
        log = open(log_path, "wb")
        popen = self.bench.popen(host, argv, env=env, cwd=self.workdir, stdout=log, stderr=subprocess.STDOUT)
        return HostProcess(popen, log_path, log)

    def _environment(self, host: Host) -> dict[str, str]:
        """The environment `host`'s commands start from: its distribution (the rig's is Jazzy)."""
        env = _outside_environment()
        env["G2P_ROS_DISTRO"] = RIG_DISTRO if host == "rig" else os.environ.get("G2P_ROS_DISTRO", "kilted")
        return env

    def _in_ros(
        self, host: Host, name: str, command: list[str], env: dict[str, str], discovery: str | None = None
    ) -> HostProcess:
        """`command` in `host`'s ROS environment (scripts/with-env), optionally with a discovery range
        (with-env keeps one host on loopback; the nodes of a two-host graph use the link)."""
        prefix = [str(ROOT / "scripts" / "with-env")]
        if discovery is not None:
            prefix += ["env", f"ROS_AUTOMATIC_DISCOVERY_RANGE={discovery}"]
        return self._start(host, name, [*prefix, *command], env)

    def _with_profile(
        self, host: Host, name: str, command: list[str], extra_env: dict[str, str] | None = None
    ) -> HostProcess:
        """`command` on `host` with the two-host DDS profile of its distribution (SUBNET discovery unless
        `extra_env` names a range)."""
        env = self._environment(host)
        env[_PROFILE_VARIABLE[env["G2P_ROS_DISTRO"]]] = str(self._profile(host, env))
        env.update(extra_env or {})
        return self._in_ros(host, name, command, env, env.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"))

    def bringup(self, host: Host, *args: str) -> HostProcess:
        """`bringup --host rig|workstation` on `host`, over the bench's link (bringup writes the profile)."""
        interface = self.bench.rig_tun if host == "rig" else self.bench.ws_tun
        side = "rig" if host == "rig" else "workstation"
        options = [
            "--host",
            side,
            "--dds-interface",
            interface,
            "--run-id",
            self.run_id,
            "--no-report",
            *args,
        ]
        command = [str(ROS2_RUN), "g2p_bringup", "bringup", *options]
        return self._in_ros(host, f"bringup-{side}", command, self._environment(host))

    def node(self, host: Host, package: str, executable: str, *args: str) -> HostProcess:
        """One installed node on `host`, with the two-host DDS profile of its distribution."""
        return self._with_profile(host, executable, [str(ROS2_RUN), package, executable, *args])

    def python(
        self, host: Host, script: Path, *args: str, extra_env: dict[str, str] | None = None
    ) -> HostProcess:
        """A Python script on `host` in its ROS environment, with the two-host DDS profile."""
        return self._with_profile(host, script.stem, ["python", str(script), *args], extra_env)

    def _profile(self, host: Host, env: dict[str, str]) -> Path:
        """The two-host profile for `host`'s address, made by that host's distribution (the XML of Fast
        DDS 2 and 3 differ), as bringup makes it."""
        path = self.workdir / f"fastdds-{host}.xml"
        if not path.exists():
            address = self.bench.ip(host)
            make = f"from g2p_bringup.dds import two_host_profile; print(two_host_profile({address!r}))"
            done = subprocess.run(
                [str(ROOT / "scripts" / "with-env"), "python", "-c", make],
                env=env,
                capture_output=True,
                text=True,
                timeout=600,
                check=True,
            )
            path.write_text(done.stdout)
        return path


# The variable each distribution's Fast DDS reads its profile from (g2p_bringup.dds.profile_variable).
_PROFILE_VARIABLE = {"jazzy": "FASTRTPS_DEFAULT_PROFILES_FILE", "kilted": "FASTDDS_DEFAULT_PROFILES_FILE"}


def _outside_environment() -> dict[str, str]:
    """This process's environment without the ROS environment it runs in (scripts/with-env sets up the
    other distribution's from scratch: its libraries must not be shadowed by this one's)."""
    venv = os.environ.get("VIRTUAL_ENV", "")
    # OPENBLAS_CORETYPE and OPENBLAS_L2_SIZE, set on some processors, choose the BLAS kernels, hence the
    # last bits of every map: runs compared with a one-host run need the same ones.
    keep = {
        k: v
        for k, v in os.environ.items()
        if k in ("HOME", "LANG", "LC_ALL", "TERM", "TMPDIR") or k.startswith("OPENBLAS_")
    }
    keep["ROS_DOMAIN_ID"] = os.environ.get("ROS_DOMAIN_ID", "0")  # the namespaces keep it to themselves
    keep["PATH"] = os.pathsep.join(
        p for p in os.environ.get("PATH", "").split(os.pathsep) if p and not (venv and p.startswith(venv))
    )
    return keep


def set_args(settings: dict[str, str], node: str) -> list[str]:
    """`bringup --set` arguments giving `node` these parameters."""
    return [arg for key, value in settings.items() for arg in ("--set", f"{node}.{key}={value}")]


def ros_params(settings: dict[str, str]) -> list[str]:
    """`--ros-args -p` arguments for these parameters (after a --ros-args)."""
    return [arg for key, value in settings.items() for arg in ("-p", f"{key}:={value}")]
