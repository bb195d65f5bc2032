"""Join two TUN devices in two network namespaces and forward IP packets between them, impaired.

Run by path or as ``python -m g2p_twohost.forwarder``; it needs root (CAP_NET_ADMIN) and only the standard
library::

    forwarder.py --rig-netns /run/netns/A --rig-tun g2prig --ws-netns /run/netns/B --ws-tun g2pws --seed 1

It creates TUN device ``--rig-tun`` inside the rig namespace and ``--ws-tun`` inside the workstation
namespace (the devices never exist in the caller's namespace), prints one ``{"ready": true, ...}`` line on
stdout, then forwards every packet read from one device to the other. The caller gives the devices addresses
and brings them up (see hosts.py). The devices vanish when the forwarder exits.

Impairments, per direction (``ws_to_rig``, ``rig_to_ws``):

- one-way delay ``delay_ms`` plus jitter, uniform in [-jitter_ms, +jitter_ms], never below 0 ms. Each packet
  draws its own hold time, so with jitter packets reorder as they do with netem (a packet held 11 ms overtakes
  one held 29 ms sent 1 ms earlier). Fast DDS copes with that, and it is what a real jittery link does.
- random loss with probability ``loss`` (0..1), from an RNG seeded with ``--seed`` (one stream per direction).
- partition: while on, every packet both ways is dropped, including packets already held for delay.

Control: JSON lines on stdin, one JSON line reply each on stdout::

    {"cmd": "set", "delay_ms": 20, "jitter_ms": 10, "loss": 0.02}   -> {"ok": true}
    {"cmd": "set", "direction": "ws_to_rig", "loss": 0.5}             (only that direction)
    {"cmd": "partition", "on": true}                                  -> {"ok": true}
    {"cmd": "counters"}                          -> {"ok": true, "partition": false, "ws_to_rig": {...}, ...}
    {"cmd": "reset"}   (zero the counters and delay statistics)       -> {"ok": true}
    {"cmd": "quit"}                                                   -> {"ok": true}, then exit

A bad command gets ``{"ok": false, "error": "..."}``. The forwarder exits cleanly (status 0) on stdin EOF,
``quit``, SIGTERM or SIGINT. Diagnostics go to stderr.
"""

from __future__ import annotations

import argparse
import ctypes
import errno
import fcntl
import heapq
import json
import math
import os
import random
import select
import signal
import struct
import sys
import time
from dataclasses import dataclass, field
from typing import Any

CLONE_NEWNET = 0x40000000
TUNSETIFF = 0x400454CA
IFF_TUN = 0x0001
IFF_NO_PI = 0x1000
READ_SIZE = 65536  # larger than any packet a TUN with MTU <= 65535 hands over
READ_BATCH = 64  # packets read from one device before looking at the other and at the clock
MAX_HELD = 200_000  # packets held for delay, per direction, before new ones are dropped (memory bound)
DIRECTIONS = ("ws_to_rig", "rig_to_ws")

_libc = ctypes.CDLL(None, use_errno=True)


def _setns(fd: int, what: str) -> None:
    """Move the calling thread into the network namespace open as ``fd``."""
    if _libc.setns(fd, CLONE_NEWNET) != 0:
        err = ctypes.get_errno()
        raise OSError(err, f"setns into {what} failed: {os.strerror(err)}")


def open_tun_in_netns(netns_path: str, ifname: str) -> int:
    """Create TUN device ``ifname`` (IFF_TUN | IFF_NO_PI) inside the network namespace at ``netns_path``.

    The thread enters the namespace, opens /dev/net/tun there (the device belongs to the namespace of the
    opener) and returns to its own namespace; the descriptor keeps working afterwards.

    Returns:
        A non-blocking descriptor; each read gives one IP packet, each write injects one.
    """
    if len(ifname.encode()) > 15:
        raise ValueError(f"interface name {ifname!r} is longer than 15 bytes")
    own = os.open("/proc/thread-self/ns/net", os.O_RDONLY | os.O_CLOEXEC)
    try:
        target = os.open(netns_path, os.O_RDONLY | os.O_CLOEXEC)
    except OSError as exc:
        os.close(own)
        raise OSError(exc.errno, f"cannot open network namespace {netns_path}: {exc.strerror}") from exc
    try:
        _setns(target, netns_path)
        try:
            fd = os.open("/dev/net/tun", os.O_RDWR | os.O_NONBLOCK | os.O_CLOEXEC)
            try:
                fcntl.ioctl(fd, TUNSETIFF, struct.pack("16sH22x", ifname.encode(), IFF_TUN | IFF_NO_PI))
            except OSError as exc:
                os.close(fd)
                raise OSError(
                    exc.errno, f"TUNSETIFF {ifname} in {netns_path} failed: {exc.strerror}"
                ) from exc
        finally:
            _setns(own, "the forwarder's own namespace")
    finally:
        os.close(target)
        os.close(own)
    return fd


@dataclass
class HoldStats:
    """Count, mean, standard deviation, min and max of the hold times of forwarded packets."""

    count: int = 0
    sum_ns: int = 0
    sum_sq_ms: float = 0.0
    min_ns: int | None = None
    max_ns: int | None = None

    def add(self, ns: int) -> None:
        """Add one packet's hold time (ns)."""
        self.count += 1
        self.sum_ns += ns
        self.sum_sq_ms += (ns / 1e6) ** 2
        self.min_ns = ns if self.min_ns is None else min(self.min_ns, ns)
        self.max_ns = ns if self.max_ns is None else max(self.max_ns, ns)

    def snapshot(self) -> dict[str, Any]:
        """{count, mean, sd, min, max} in ms (None before the first packet)."""
        n = self.count
        mean = self.sum_ns / n / 1e6 if n else None
        return {
            "count": n,
            "mean": mean,
            "sd": math.sqrt(max(0.0, self.sum_sq_ms / n - mean**2)) if mean is not None else None,
            "min": self.min_ns / 1e6 if self.min_ns is not None else None,
            "max": self.max_ns / 1e6 if self.max_ns is not None else None,
        }


@dataclass
class Direction:
    """Impairment settings and counters of one direction of the link."""

    name: str
    rng: random.Random
    delay_ms: float = 0.0
    jitter_ms: float = 0.0
    loss: float = 0.0
    held: list[tuple[int, int, int, bytes]] = field(default_factory=list)  # (due_ns, seq, read_ns, packet)
    seq: int = 0
    last_released_seq: int = -1
    forwarded_packets: int = 0
    forwarded_bytes: int = 0
    dropped_loss_packets: int = 0
    dropped_loss_bytes: int = 0
    dropped_partition_packets: int = 0
    dropped_partition_bytes: int = 0
    dropped_overflow_packets: int = 0
    write_errors: int = 0
    reordered_packets: int = 0
    hold: HoldStats = field(default_factory=HoldStats)  # actual: from read to write
    drawn: HoldStats = field(default_factory=HoldStats)  # the rule's: delay + jitter as drawn

    def reset(self) -> None:
        """Zero the counters and the delay statistics (held packets stay held)."""
        for name in (
            "forwarded_packets",
            "forwarded_bytes",
            "dropped_loss_packets",
            "dropped_loss_bytes",
            "dropped_partition_packets",
            "dropped_partition_bytes",
            "dropped_overflow_packets",
            "write_errors",
            "reordered_packets",
        ):
            setattr(self, name, 0)
        self.hold, self.drawn = HoldStats(), HoldStats()

    def hold_ns(self) -> int:
        """The hold time for the next packet: delay + uniform jitter, at least 0 ns."""
        ms = self.delay_ms
        if self.jitter_ms > 0:
            ms += self.rng.uniform(-self.jitter_ms, self.jitter_ms)
        return max(0, round(ms * 1e6))

    def snapshot(self) -> dict[str, Any]:
        """Counters, settings and hold-time statistics (ms) as a JSON-ready dict."""
        return {
            "delay_ms": self.delay_ms,
            "jitter_ms": self.jitter_ms,
            "loss": self.loss,
            "forwarded_packets": self.forwarded_packets,
            "forwarded_bytes": self.forwarded_bytes,
            "dropped_loss_packets": self.dropped_loss_packets,
            "dropped_loss_bytes": self.dropped_loss_bytes,
            "dropped_partition_packets": self.dropped_partition_packets,
            "dropped_partition_bytes": self.dropped_partition_bytes,
            "dropped_overflow_packets": self.dropped_overflow_packets,
            "write_errors": self.write_errors,
            "reordered_packets": self.reordered_packets,
            "held_packets": len(self.held),
            "hold_ms": self.hold.snapshot(),
            "drawn_ms": self.drawn.snapshot(),
        }


class Forwarder:
    """The forwarding loop: select() on both TUNs, stdin and a signal pipe; a heap of held packets each way.

    Args:
        rig_fd: TUN descriptor in the rig namespace.
        ws_fd: TUN descriptor in the workstation namespace.
        seed: seed of the loss and jitter RNGs.
    """

    def __init__(self, rig_fd: int, ws_fd: int, seed: int) -> None:
        self.rig_fd = rig_fd
        self.ws_fd = ws_fd
        # Packets read from the ws TUN go to the rig TUN and vice versa.
        self.dirs = {
            "ws_to_rig": Direction("ws_to_rig", random.Random(f"{seed}/ws_to_rig")),
            "rig_to_ws": Direction("rig_to_ws", random.Random(f"{seed}/rig_to_ws")),
        }
        self.out_fd = {"ws_to_rig": rig_fd, "rig_to_ws": ws_fd}
        self.partitioned = False
        self.stopping = False
        self._stdin_buf = b""

    # -- packets ----------------------------------------------------------------------------------------

    def _write(self, d: Direction, packet: bytes, read_ns: int, drawn_ns: int) -> None:
        try:
            os.write(self.out_fd[d.name], packet)
        except OSError as exc:
            # EIO: the device is down; other errors are counted too, the link simply lost the packet.
            d.write_errors += 1
            if exc.errno not in (errno.EIO, errno.EAGAIN, errno.ENOBUFS):
                print(f"forwarder: write {d.name}: {exc}", file=sys.stderr)
            return
        d.hold.add(time.monotonic_ns() - read_ns)
        d.drawn.add(drawn_ns)
        d.forwarded_packets += 1
        d.forwarded_bytes += len(packet)

    def _ingress(self, d: Direction, packet: bytes, read_ns: int) -> None:
        if self.partitioned:
            d.dropped_partition_packets += 1
            d.dropped_partition_bytes += len(packet)
            return
        if d.loss > 0 and d.rng.random() < d.loss:
            d.dropped_loss_packets += 1
            d.dropped_loss_bytes += len(packet)
            return
        seq = d.seq
        d.seq += 1
        hold = d.hold_ns()
        if hold == 0 and not d.held:
            d.last_released_seq = seq
            self._write(d, packet, read_ns, hold)
        elif len(d.held) >= MAX_HELD:
            d.dropped_overflow_packets += 1
        else:
            heapq.heappush(d.held, (read_ns + hold, seq, read_ns, packet))

    def _read_from(self, fd: int, d: Direction) -> None:
        for _ in range(READ_BATCH):
            try:
                packet = os.read(fd, READ_SIZE)
            except BlockingIOError:
                return
            if not packet:
                return
            self._ingress(d, packet, time.monotonic_ns())

    def _release_due(self, now: int) -> None:
        for d in self.dirs.values():
            held = d.held
            while held and held[0][0] <= now:
                due_ns, seq, read_ns, packet = heapq.heappop(held)
                if self.partitioned:
                    d.dropped_partition_packets += 1
                    d.dropped_partition_bytes += len(packet)
                    continue
                if seq < d.last_released_seq:
                    d.reordered_packets += 1
                else:
                    d.last_released_seq = seq
                self._write(d, packet, read_ns, due_ns - read_ns)

    def _next_due(self) -> int | None:
        dues = [d.held[0][0] for d in self.dirs.values() if d.held]
        return min(dues) if dues else None

    # -- control ----------------------------------------------------------------------------------------

    def handle(self, line: str) -> dict[str, Any]:
        """Carry out one control command (a JSON object) and return the reply."""
        try:
            msg = json.loads(line)
        except json.JSONDecodeError as exc:
            return {"ok": False, "error": f"not JSON: {exc}"}
        if not isinstance(msg, dict):
            return {"ok": False, "error": "a command is a JSON object"}
        cmd = msg.get("cmd")
        if cmd == "set":
            return self._set(msg)
        if cmd == "partition":
            on = msg.get("on", True)
            if not isinstance(on, bool):
                return {"ok": False, "error": "partition: 'on' must be true or false"}
            self.partitioned = on
            return {"ok": True, "partition": on}
        if cmd == "counters":
            return {
                "ok": True,
                "partition": self.partitioned,
                **{k: d.snapshot() for k, d in self.dirs.items()},
            }
        if cmd == "reset":
            for d in self.dirs.values():
                d.reset()
            return {"ok": True}
        if cmd == "quit":
            self.stopping = True
            return {"ok": True}
        return {"ok": False, "error": f"unknown cmd {cmd!r} (set, partition, counters, reset, quit)"}

    def _set(self, msg: dict[str, Any]) -> dict[str, Any]:
        direction = msg.get("direction", "both")
        if direction == "both":
            targets = list(self.dirs.values())
        elif direction in self.dirs:
            targets = [self.dirs[direction]]
        else:
            return {
                "ok": False,
                "error": f"set: direction must be both, ws_to_rig or rig_to_ws, not {direction!r}",
            }
        new: dict[str, float] = {}
        for key in ("delay_ms", "jitter_ms", "loss"):
            if key not in msg:
                continue
            value = msg[key]
            if isinstance(value, bool) or not isinstance(value, (int, float)) or value != value:
                return {"ok": False, "error": f"set: {key} must be a number, not {value!r}"}
            if value < 0 or (key == "loss" and value > 1):
                return {"ok": False, "error": f"set: {key}={value} out of range"}
            new[key] = float(value)
        unknown = set(msg) - {"cmd", "direction", "delay_ms", "jitter_ms", "loss"}
        if unknown:
            return {"ok": False, "error": f"set: unknown keys {sorted(unknown)}"}
        for d in targets:
            for key, value in new.items():
                setattr(d, key, value)
        return {"ok": True}

    def _read_stdin(self) -> None:
        chunk = os.read(0, 65536)
        if not chunk:
            self.stopping = True
            return
        self._stdin_buf += chunk
        while b"\n" in self._stdin_buf:
            line, self._stdin_buf = self._stdin_buf.split(b"\n", 1)
            if line.strip():
                reply = self.handle(line.decode(errors="replace"))
                sys.stdout.write(json.dumps(reply) + "\n")
                sys.stdout.flush()

    # -- loop -------------------------------------------------------------------------------------------

    def run(self, wake_fd: int) -> None:
        """Forward until stdin EOF, ``quit`` or a byte on ``wake_fd`` (written by the signal handler)."""
        fds = [self.ws_fd, self.rig_fd, 0, wake_fd]
        while not self.stopping:
            now = time.monotonic_ns()
            self._release_due(now)
            due = self._next_due()
            # select() takes a float timeout with microsecond resolution (epoll would round up to 1 ms).
            timeout = None if due is None else max(0.0, (due - time.monotonic_ns()) / 1e9)
            readable, _, _ = select.select(fds, [], [], timeout)
            for fd in readable:
                if fd == self.ws_fd:
                    self._read_from(fd, self.dirs["ws_to_rig"])
                elif fd == self.rig_fd:
                    self._read_from(fd, self.dirs["rig_to_ws"])
                elif fd == 0:
                    self._read_stdin()
                else:
                    self.stopping = True


def main(argv: list[str] | None = None) -> int:
    """Parse arguments, open both TUNs, print the ready line and forward until told to stop."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rig-netns", required=True, help="path of the rig namespace, e.g. /run/netns/NAME")
    parser.add_argument("--rig-tun", required=True, help="TUN device name to create in the rig namespace")
    parser.add_argument("--ws-netns", required=True, help="path of the workstation namespace")
    parser.add_argument(
        "--ws-tun", required=True, help="TUN device name to create in the workstation namespace"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the loss and jitter RNGs")
    args = parser.parse_args(argv)

    read_end, write_end = os.pipe2(os.O_NONBLOCK | os.O_CLOEXEC)
    signal.set_wakeup_fd(write_end)
    # A handler must exist for the wakeup byte to be written; the loop sees the byte and stops.
    signal.signal(signal.SIGTERM, lambda *_: None)
    signal.signal(signal.SIGINT, lambda *_: None)
    try:
        rig_fd = open_tun_in_netns(args.rig_netns, args.rig_tun)
        ws_fd = open_tun_in_netns(args.ws_netns, args.ws_tun)
    except (OSError, ValueError) as exc:
        print(f"forwarder: {exc}", file=sys.stderr)
        return 2
    forwarder = Forwarder(rig_fd, ws_fd, args.seed)
    sys.stdout.write(json.dumps({"ready": True, "rig_tun": args.rig_tun, "ws_tun": args.ws_tun}) + "\n")
    sys.stdout.flush()
    try:
        forwarder.run(read_end)
    except BrokenPipeError:
        pass  # the controller went away: same as stdin EOF
    finally:
        os.close(rig_fd)
        os.close(ws_fd)
    return 0


if __name__ == "__main__":
    sys.exit(main())
