"""The G2P graph of a checkout on two hosts, started as a user starts it on a Pi and a workstation.

The rig side runs ROS 2 Jazzy (the Raspberry Pi's distribution) from the checkout's Jazzy environment; the
workstation side runs the distribution of the calling process (G2P_ROS_DISTRO). Each side's processes are
the installed executables, run through the checkout's scripts/with-env in their host's namespace with the
two-host DDS profile (UDPv4 only, on the two hosts' link), either through `bringup --host ...` or one node
at a time (to kill and restart one).
"""

from __future__ import annotations

import os
import re
import signal
import subprocess
import time
from pathlib import Path
from typing import IO

from g2p_twohost.hosts import STOP_GRACE_S, Host, TwoHostError, TwoHosts

RIG_DISTRO = "jazzy"
ATTEMPT_LINE = re.compile(r"^attempt +(\d+) ", re.M)


class HostProcess:
    """A process of one of the two hosts, its output in a log file."""

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
                raise TwoHostError(f"exited ({self.popen.returncode}) before {what}:\n{self.log()[-3000:]}")
            if time.monotonic() > deadline:
                raise TwoHostError(f"no {what} within {condition_s:g} s:\n{self.log()[-3000:]}")
            time.sleep(0.05)

    def wait_for_attempt(self, number: int, timeout_s: float = 300.0) -> None:
        """Wait until `learn` reported attempt `number`."""
        self.wait_for(f"attempt {number}", timeout_s, lambda: self.attempts_done() >= number)

    def stop(self, sig: int = signal.SIGINT, timeout_s: float = 30.0) -> int:
        """Signal the process and wait for it (kill after `timeout_s`); its exit code."""
        if self.popen.poll() is None:
            self.popen.send_signal(sig)
            try:
                self.popen.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.popen.kill()
                self.popen.wait(STOP_GRACE_S)
        self._log.close()
        return self.popen.returncode

    def wait(self, timeout_s: float) -> int:
        """Wait for the process to end by itself; its exit code."""
        try:
            return self.popen.wait(timeout_s)
        except subprocess.TimeoutExpired as err:
            raise TwoHostError(f"still running after {timeout_s:g} s:\n{self.log()[-3000:]}") from err


class TwoHostGraph:
    """Starts the graph on two hosts: the rig host's processes on Jazzy, the workstation's on this session's.

    Args:
        hosts: the two hosts (open).
        checkout: the project's checkout, bootstrapped (its scripts/ set up each side's environment).
        workdir: working directory of every process (bags/ and log/ go there).
        run_id: the run's id (the rig host's recorder names the bag after it).
    """

    def __init__(self, hosts: TwoHosts, checkout: Path, workdir: Path, run_id: str) -> None:
        self.hosts = hosts
        self._with_env = checkout / "scripts" / "with-env"
        self._ros2_run = checkout / "scripts" / "ros2-run"
        self.workdir = workdir
        workdir.mkdir(parents=True, exist_ok=True)
        self.run_id = run_id
        self.bag = workdir / "bags" / run_id
        self._n = 0

    def _start(self, host: Host, name: str, argv: list[str], env: dict[str, str]) -> HostProcess:
        self._n += 1
        log_path = self.workdir / f"{self._n:02d}-{host}-{name}.log"
        log = open(log_path, "wb")
        popen = self.hosts.popen(host, argv, env=env, cwd=self.workdir, stdout=log, stderr=subprocess.STDOUT)
        return HostProcess(popen, log_path, log)

    def _environment(self, host: Host) -> dict[str, str]:
        """The environment `host`'s commands start from: its distribution (the rig's is Jazzy)."""
        env = _outside_environment()
        env["G2P_ROS_DISTRO"] = RIG_DISTRO if host == "rig" else os.environ.get("G2P_ROS_DISTRO", "kilted")
        return env

    def _in_ros(
        self, host: Host, name: str, command: list[str], env: dict[str, str], discovery: str | None = None
    ) -> HostProcess:
        """`command` in `host`'s ROS environment (scripts/with-env), optionally with a discovery range.

        with-env keeps one host on loopback; the nodes of a two-host graph use the link.
        """
        prefix = [str(self._with_env)]
        if discovery is not None:
            prefix += ["env", f"ROS_AUTOMATIC_DISCOVERY_RANGE={discovery}"]
        return self._start(host, name, [*prefix, *command], env)

    def _with_profile(
        self, host: Host, name: str, command: list[str], extra_env: dict[str, str] | None = None
    ) -> HostProcess:
        """`command` on `host` with the two-host DDS profile of its distribution.

        Discovery is SUBNET unless `extra_env` names a range.
        """
        env = self._environment(host)
        env[_PROFILE_VARIABLE[env["G2P_ROS_DISTRO"]]] = str(self._profile(host, env))
        env.update(extra_env or {})
        return self._in_ros(host, name, command, env, env.pop("ROS_AUTOMATIC_DISCOVERY_RANGE", "SUBNET"))

    def bringup(self, host: Host, *args: str) -> HostProcess:
        """`bringup --host rig|workstation` on `host`, over the hosts' link (bringup writes the profile)."""
        interface = self.hosts.rig_tun if host == "rig" else self.hosts.ws_tun
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
        command = [str(self._ros2_run), "g2p_bringup", "bringup", *options]
        return self._in_ros(host, f"bringup-{side}", command, self._environment(host))

    def node(self, host: Host, package: str, executable: str, *args: str) -> HostProcess:
        """One installed node on `host`, with the two-host DDS profile of its distribution."""
        return self._with_profile(host, executable, [str(self._ros2_run), package, executable, *args])

    def python(
        self, host: Host, script: Path, *args: str, extra_env: dict[str, str] | None = None
    ) -> HostProcess:
        """A Python script on `host` in its ROS environment, with the two-host DDS profile."""
        return self._with_profile(host, script.stem, ["python", str(script), *args], extra_env)

    def _profile(self, host: Host, env: dict[str, str]) -> Path:
        """The two-host profile for `host`'s address, made by that host's distribution, as bringup does.

        The XML of Fast DDS 2 and 3 differ.
        """
        path = self.workdir / f"fastdds-{host}.xml"
        if not path.exists():
            address = self.hosts.ip(host)
            make = f"from g2p_bringup.dds import two_host_profile; print(two_host_profile({address!r}))"
            done = subprocess.run(
                [str(self._with_env), "python", "-c", make],
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
    """This process's environment without the ROS environment it runs in.

    scripts/with-env sets up the other distribution's from scratch: its libraries must not be shadowed
    by this one's.
    """
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
