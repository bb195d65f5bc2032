"""`TwoHosts`: a "rig" and a "workstation" network namespace joined by an impairable TUN link.

The link is forwarder.py, a user-space program holding one TUN device in each namespace: the kernel here has
no netem, so delay, jitter, loss and partitions come from it. Each namespace has only ``lo`` and its TUN
(``rig_ip``/``ws_ip`` in one /24, MTU 1500, multicast on, 224.0.0.0/4 routed over the TUN, IPv6 off since
the project's Fast DDS profile is UDPv4 only). Nothing is added to the machine's own namespace: no address, no
route, no device.

    with TwoHosts() as hosts:
        rig = hosts.popen("rig", ["python", "-m", "my_rig"])
        hosts.impair(delay_ms=20, jitter_ms=10, loss=0.02)
        hosts.partition()
        hosts.restore()

On exit, and when anything fails (an exception, Ctrl-C) while it is built or used, every process in both
namespaces is stopped (SIGTERM, then SIGKILL), the forwarder is stopped and both namespaces are deleted.
"""

from __future__ import annotations

import atexit
import contextlib
import fcntl
import json
import os
import re
import secrets
import select
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
import weakref
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType
from typing import IO, Any, Literal

Host = Literal["rig", "ws"]
HOSTS: tuple[Host, ...] = ("rig", "ws")
NETNS_DIR = Path("/run/netns")
FORWARDER = Path(__file__).with_name("forwarder.py")
NAME_RE = re.compile(r"^g2p-(?:rig|ws|probe)-(\d+)-[0-9a-f]+$")
LOCK_DIR = Path("/tmp")
REPLY_TIMEOUT_S = 10.0  # the forwarder answers in microseconds; this only bounds a hung one
STOP_GRACE_S = 3.0  # how long processes get between SIGTERM and SIGKILL


class TwoHostError(RuntimeError):
    """Building, driving or tearing down the two hosts failed."""


def _run(argv: Sequence[str], what: str | None = None) -> str:
    """Run a command, return its stdout; raise TwoHostError with its stderr when it fails."""
    try:
        done = subprocess.run(list(argv), capture_output=True, text=True, timeout=30)
    except (OSError, subprocess.TimeoutExpired) as exc:
        raise TwoHostError(f"{what or ' '.join(argv)} failed: {exc}") from exc
    if done.returncode != 0:
        detail = (done.stderr or done.stdout).strip()
        raise TwoHostError(f"{what or ' '.join(argv)} failed (exit {done.returncode}): {detail}")
    return done.stdout


def netns_pids(ns: str) -> list[int]:
    """Pids of the processes whose network namespace is ``ns`` (``ip netns pids``); [] if it is gone."""
    try:
        out = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.TimeoutExpired):
        return []
    return [int(p) for p in out.split() if p.isdigit()]


def _kill_all_in(ns: str, grace_s: float = STOP_GRACE_S) -> None:
    """SIGTERM every process in namespace ``ns``, then SIGKILL what is still there after ``grace_s``."""
    for sig, wait in ((signal.SIGTERM, grace_s), (signal.SIGKILL, grace_s)):
        pids = netns_pids(ns)
        if not pids:
            return
        for pid in pids:
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.kill(pid, sig)
        deadline = time.monotonic() + wait
        while time.monotonic() < deadline and netns_pids(ns):
            time.sleep(0.05)


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def _delete_netns(ns: str) -> None:
    """Stop everything in ``ns`` and delete it; quiet if it is already gone."""
    if not (NETNS_DIR / ns).exists():
        return
    _kill_all_in(ns)
    _run(["ip", "netns", "delete", ns], f"ip netns delete {ns}")


def cleanup_stale() -> list[str]:
    """Delete two-host namespaces (``g2p-rig-*``, ``g2p-ws-*``) whose owner pid is dead, and their processes.

    Best effort: a namespace that cannot be deleted is left alone.

    Returns:
        The names of the namespaces deleted.
    """
    removed: list[str] = []
    try:
        names = sorted(p.name for p in NETNS_DIR.iterdir())
    except OSError:
        return removed
    for name in names:
        match = NAME_RE.match(name)
        if not match or _pid_alive(int(match.group(1))):
            continue
        try:
            _delete_netns(name)
        except TwoHostError as exc:
            print(f"twohost: could not remove stale namespace {name}: {exc}", file=sys.stderr)
            continue
        removed.append(name)
    return removed


def available() -> str | None:
    """None when two hosts can be built here, else why not (for pytest.skip)."""
    if os.geteuid() != 0:
        return "the two hosts need root (network namespaces, TUN devices)"
    if shutil.which("ip") is None:
        return "the two hosts need iproute2's `ip` command"
    try:
        os.close(os.open("/dev/net/tun", os.O_RDWR))
    except OSError as exc:
        return f"cannot open /dev/net/tun: {exc.strerror}"
    probe = f"g2p-probe-{os.getpid()}-{secrets.token_hex(3)}"
    try:
        _run(["ip", "netns", "add", probe], f"ip netns add {probe}")
    except TwoHostError as exc:
        return str(exc)
    try:
        _run(["ip", "netns", "delete", probe], f"ip netns delete {probe}")
    except TwoHostError as exc:
        return str(exc)
    return None


def _claim_subnet() -> tuple[int, IO[str]]:
    """Lock a third octet (0..254) of 10.77.X.0/24 for one pair of hosts: no two pairs share a subnet.

    Two pairs are separate networks anyway; distinct subnets keep logs and captures unambiguous. The lock is
    an flock on a file in /tmp, held until the hosts close (or the process dies).
    """
    for octet in range(255):
        lock = open(LOCK_DIR / f"g2p-twohost-10.77.{octet}.lock", "w")
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            lock.close()
            continue
        return octet, lock
    raise TwoHostError("no free subnet in 10.77.0.0/16 (255 pairs of hosts at once?)")


_open_hosts: weakref.WeakSet[TwoHosts] = weakref.WeakSet()


@atexit.register
def _close_leftovers() -> None:
    for hosts in list(_open_hosts):
        hosts.close()


class TwoHosts:
    """Two network namespaces, "rig" and "ws" (workstation), joined by an impairable point-to-point link.

    Args:
        third_octet: use subnet 10.77.<third_octet>.0/24; None locks a free one.
        seed: seed of the forwarder's loss and jitter RNGs.
        mtu: MTU of both TUN devices (bytes).

    Attributes:
        rig_ns, ws_ns: namespace names (unique: ``g2p-rig-<pid>-<hex>``, ``g2p-ws-<pid>-<hex>``).
        rig_ip, ws_ip: addresses of the two ends (``10.77.X.1``, ``10.77.X.2``), prefix ``prefix_len``.
        subnet: e.g. ``"10.77.0.0/24"``.
        rig_tun, ws_tun: TUN device names inside the namespaces.
    """

    prefix_len = 24
    rig_tun = "g2prig"
    ws_tun = "g2pws"

    def __init__(self, third_octet: int | None = None, seed: int = 0, mtu: int = 1500) -> None:
        tag = f"{os.getpid()}-{secrets.token_hex(3)}"
        self.rig_ns = f"g2p-rig-{tag}"
        self.ws_ns = f"g2p-ws-{tag}"
        self.seed = seed
        self.mtu = mtu
        self._requested_octet = third_octet
        self._lock: IO[str] | None = None
        self.third_octet = -1
        self._forwarder: subprocess.Popen[str] | None = None
        self._forwarder_log: IO[str] | None = None
        self._procs: list[subprocess.Popen[Any]] = []
        self._machine_ids: list[Path] = []
        self._created: list[str] = []
        self._ctl = threading.Lock()
        self._closed = False

    # -- addresses --------------------------------------------------------------------------------------

    @property
    def rig_ip(self) -> str:
        """Address of the rig end of the link."""
        return f"10.77.{self.third_octet}.1"

    @property
    def ws_ip(self) -> str:
        """Address of the workstation end of the link."""
        return f"10.77.{self.third_octet}.2"

    @property
    def subnet(self) -> str:
        """The link's subnet, CIDR."""
        return f"10.77.{self.third_octet}.0/{self.prefix_len}"

    def ns(self, host: Host) -> str:
        """Namespace name of ``host`` ("rig" or "ws")."""
        if host not in HOSTS:
            raise ValueError(f"host must be 'rig' or 'ws', not {host!r}")
        return self.rig_ns if host == "rig" else self.ws_ns

    def ip(self, host: Host) -> str:
        """Address of ``host`` on the link."""
        return self.rig_ip if self.ns(host) == self.rig_ns else self.ws_ip

    # -- life cycle -------------------------------------------------------------------------------------

    def __enter__(self) -> TwoHosts:
        try:
            self.open()
        except BaseException:
            self.close()
            raise
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def open(self) -> None:
        """Build the namespaces, start the forwarder and configure both ends (``with`` calls it)."""
        _open_hosts.add(self)
        cleanup_stale()
        if self._requested_octet is None:
            self.third_octet, self._lock = _claim_subnet()
        else:
            if not 0 <= self._requested_octet <= 254:
                raise ValueError(f"third_octet must be in 0..254, not {self._requested_octet}")
            self.third_octet = self._requested_octet
        for ns in (self.rig_ns, self.ws_ns):
            _run(["ip", "netns", "add", ns], f"ip netns add {ns}")
            self._created.append(ns)
            self._in(ns, "link", "set", "lo", "up")
            # IPv6 off before the TUN exists, so it never gets a link-local address or sends solicitations
            # (the DDS profile is UDPv4 only, and stray packets would blur the forwarder's counters).
            for conf in ("all", "default"):
                _run(["ip", "netns", "exec", ns, "sysctl", "-qw", f"net.ipv6.conf.{conf}.disable_ipv6=1"])
        self._start_forwarder()
        for ns, tun, addr in (
            (self.rig_ns, self.rig_tun, self.rig_ip),
            (self.ws_ns, self.ws_tun, self.ws_ip),
        ):
            # txqueuelen: room for a burst while the forwarder is briefly descheduled (default 500 packets).
            self._in(
                ns, "link", "set", "dev", tun, "mtu", str(self.mtu), "multicast", "on", "txqueuelen", "5000"
            )
            self._in(ns, "addr", "add", f"{addr}/{self.prefix_len}", "dev", tun)
            self._in(ns, "link", "set", "dev", tun, "up")
            self._in(ns, "route", "add", "224.0.0.0/4", "dev", tun)

    def _in(self, ns: str, *args: str) -> str:
        return _run(["ip", "-n", ns, *args], f"ip -n {ns} {' '.join(args)}")

    def _start_forwarder(self) -> None:
        self._forwarder_log = tempfile.TemporaryFile("w+")
        self._forwarder = subprocess.Popen(
            [
                sys.executable,
                str(FORWARDER),
                "--rig-netns",
                str(NETNS_DIR / self.rig_ns),
                "--rig-tun",
                self.rig_tun,
                "--ws-netns",
                str(NETNS_DIR / self.ws_ns),
                "--ws-tun",
                self.ws_tun,
                "--seed",
                str(self.seed),
            ],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=self._forwarder_log,
            text=True,
            bufsize=1,
        )
        ready = self._read_reply("start")
        if not ready.get("ready"):
            raise TwoHostError(f"forwarder did not get ready: {ready}")

    def forwarder_log(self) -> str:
        """What the forwarder wrote on stderr so far."""
        if self._forwarder_log is None or self._forwarder_log.closed:
            return ""
        self._forwarder_log.seek(0)
        return self._forwarder_log.read()

    def close(self) -> None:
        """Stop every process in both namespaces, the forwarder, and delete the namespaces.

        Idempotent, and every step can be repeated: if a second Ctrl-C interrupts it, the atexit hook runs
        it again.
        """
        if self._closed:
            return
        errors: list[str] = []
        for ns in self._created:
            _kill_all_in(ns)
        for proc in self._procs:  # reap our children (and any that left the namespace)
            with contextlib.suppress(OSError):
                proc.kill()
            with contextlib.suppress(subprocess.TimeoutExpired):
                proc.wait(timeout=STOP_GRACE_S)
        self._stop_forwarder()
        for ns in self._created:
            try:
                _delete_netns(ns)
            except TwoHostError as exc:
                errors.append(str(exc))
        for path in self._machine_ids:
            path.unlink(missing_ok=True)
        if self._forwarder_log is not None:
            self._forwarder_log.close()
        if self._lock is not None:
            self._lock.close()  # releases the flock
        self._closed = True
        _open_hosts.discard(self)
        if errors:
            raise TwoHostError("; ".join(errors))

    def _stop_forwarder(self) -> None:
        proc = self._forwarder
        if proc is None:
            return
        if proc.poll() is None:
            with contextlib.suppress(OSError):
                proc.stdin.close()  # type: ignore[union-attr]  # EOF: the forwarder exits on its own
            try:
                proc.wait(timeout=STOP_GRACE_S)
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    proc.wait(timeout=STOP_GRACE_S)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        for stream in (proc.stdin, proc.stdout):
            with contextlib.suppress(OSError):
                stream.close()  # type: ignore[union-attr]

    @property
    def forwarder(self) -> subprocess.Popen[str] | None:
        """The forwarder process (None before it starts); its pid is not in either namespace."""
        return self._forwarder

    # -- processes --------------------------------------------------------------------------------------

    def popen(
        self, host: Host, argv: Sequence[str], env: dict[str, str] | None = None, **kw: Any
    ) -> subprocess.Popen[Any]:
        """Start ``argv`` inside ``host``'s namespace (``ip netns exec``); stopped when the hosts close.

        ``ip netns exec`` execs the command, so the returned Popen's pid is the command's own. ``env`` None
        inherits this process's environment; other keywords go to subprocess.Popen.
        """
        if self._closed or self._forwarder is None:
            raise TwoHostError("popen on two hosts that are not open")
        # Each host has its own machine id, as two computers do: Fast DDS 3 takes participants with the
        # same /etc/machine-id for one host's and then only talks to them on whitelisted local addresses.
        # `ip netns exec` gives the command a mount namespace of its own, so the bind mount stays in it.
        bind = 'mount --bind "$0" /etc/machine-id && exec "$@"'
        proc = subprocess.Popen(
            ["ip", "netns", "exec", self.ns(host), "sh", "-c", bind, str(self._machine_id(host)), *argv],
            env=env,
            **kw,
        )
        self._procs.append(proc)
        return proc

    def _machine_id(self, host: Host) -> Path:
        """A machine-id file of this host's own (32 hex digits), made on first use."""
        path = Path(tempfile.gettempdir()) / f"{self.ns(host)}.machine-id"
        if not path.exists():
            path.write_text(secrets.token_hex(16) + "\n")
            self._machine_ids.append(path)
        return path

    def pids(self, host: Host) -> list[int]:
        """Pids of every process now in ``host``'s namespace."""
        return netns_pids(self.ns(host))

    # -- link control -----------------------------------------------------------------------------------

    def _read_reply(self, what: str) -> dict[str, Any]:
        proc = self._forwarder
        assert proc is not None and proc.stdout is not None
        ready, _, _ = select.select([proc.stdout], [], [], REPLY_TIMEOUT_S)
        line = proc.stdout.readline() if ready else ""
        if not line:
            proc.poll()
            raise TwoHostError(
                f"forwarder gave no reply to {what} (exit status {proc.returncode}); its log:\n"
                + self.forwarder_log()
            )
        reply: dict[str, Any] = json.loads(line)
        return reply

    def command(self, cmd: dict[str, Any]) -> dict[str, Any]:
        """Send one control command to the forwarder (see forwarder.py) and return its reply."""
        proc = self._forwarder
        if proc is None or self._closed:
            raise TwoHostError("the two hosts are not open")
        with self._ctl:
            try:
                proc.stdin.write(json.dumps(cmd) + "\n")  # type: ignore[union-attr]
                proc.stdin.flush()  # type: ignore[union-attr]
            except OSError as exc:
                raise TwoHostError(f"forwarder is gone ({exc}); its log:\n{self.forwarder_log()}") from exc
            reply = self._read_reply(json.dumps(cmd))
        if not reply.get("ok"):
            raise TwoHostError(f"forwarder refused {cmd}: {reply.get('error')}")
        return reply

    def impair(
        self,
        delay_ms: float = 0.0,
        jitter_ms: float = 0.0,
        loss: float = 0.0,
        direction: Literal["both", "ws_to_rig", "rig_to_ws"] = "both",
    ) -> None:
        """Set one-way delay (ms), jitter (± ms, uniform) and loss probability (0..1) of ``direction``.

        Calling it with no arguments makes the link clean again (a partition stays as it is).
        """
        self.command(
            {"cmd": "set", "direction": direction, "delay_ms": delay_ms, "jitter_ms": jitter_ms, "loss": loss}
        )

    def partition(self, on: bool = True) -> None:
        """Cut the link both ways (``on``), or heal it (``on=False``); packets in flight when cut are lost."""
        self.command({"cmd": "partition", "on": on})

    def restore(self) -> None:
        """End a partition. Delay, jitter and loss stay as ``impair`` set them."""
        self.partition(False)

    def counters(self) -> dict[str, Any]:
        """The forwarder's counters: ``{"partition": bool, "ws_to_rig": {...}, "rig_to_ws": {...}}``.

        Per direction: forwarded/dropped packets and bytes (loss, partition, overflow), write errors,
        reordered packets, packets held now, ``hold_ms`` {count, mean, sd, min, max}: the hold times actually
        applied, from reading a packet to writing it (ms), and ``drawn_ms``, the same of the hold times the
        link's rule drew (delay + jitter), which the actual ones exceed by the forwarder's scheduling.
        """
        reply = self.command({"cmd": "counters"})
        reply.pop("ok", None)
        return reply

    def link_stats(self, host: Host) -> dict[str, dict[str, int]]:
        """The kernel's counters of ``host``'s TUN device: ``{"rx": {...}, "tx": {...}}``, packets, bytes...

        ``tx.dropped`` on the sending side counts packets the kernel dropped because the forwarder did not
        read them in time (its queue of ``txqueuelen`` packets was full): losses the forwarder cannot see.
        """
        tun = self.rig_tun if host == "rig" else self.ws_tun
        out = self._in(self.ns(host), "-j", "-s", "link", "show", "dev", tun)
        stats = json.loads(out)[0]["stats64"]
        return {"rx": dict(stats["rx"]), "tx": dict(stats["tx"])}

    def reset_counters(self) -> None:
        """Zero the forwarder's counters and hold-time statistics."""
        self.command({"cmd": "reset"})
