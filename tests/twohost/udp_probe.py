"""A tiny UDP sender / receiver / echo / round-trip probe, run inside a two-host namespace by the tests.

Each datagram starts with ``!QQ``: a sequence number and the sender's CLOCK_MONOTONIC time (ns) when it was
sent; CLOCK_MONOTONIC is one clock per machine, shared by all network namespaces, so a receiver in another
namespace can compute the one-way delay. Modes (each prints one JSON line at the end, on stdout)::

    recv --bind ADDR --port P [--group G --iface ADDR] [--count N] [--duration S] [--idle S]
        prints {"ready": true} once bound, then {"received": n, "records": [[seq, send_ns, recv_ns, size]...]}
    send --to ADDR --port P --count N --rate PPS --size BYTES [--iface ADDR --ttl T]
        (rate 0: as fast as possible) prints {"sent": n, "send_ns": [...], "errors": e}
    echo --bind ADDR --port P [--duration S]
        sends every datagram back to where it came from; prints {"ready": true}, at the end {"echoed": n}
    rtt --to ADDR --port P --count N --rate PPS [--timeout S]
        prints {"rtt_ms": [...], "lost": k}; each probe waits up to --timeout for its echo

SIGTERM ends recv and echo early; they still print their result line.
"""

from __future__ import annotations

import argparse
import json
import signal
import socket
import struct
import sys
import time
from typing import Any

HEADER = struct.Struct("!QQ")
RCVBUF = 8 * 1024 * 1024  # bytes; big enough that a briefly descheduled receiver loses nothing
SO_RCVBUFFORCE = getattr(socket, "SO_RCVBUFFORCE", 33)  # Linux value; Python 3.11 does not export it
_stop = False


def _on_term(*_: object) -> None:
    global _stop
    _stop = True


def _emit(obj: dict[str, Any]) -> None:
    sys.stdout.write(json.dumps(obj) + "\n")
    sys.stdout.flush()


def _udp_socket() -> socket.socket:
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        sock.setsockopt(socket.SOL_SOCKET, SO_RCVBUFFORCE, RCVBUF)  # root: above rmem_max
    except OSError:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RCVBUF)
    return sock


def _payload(seq: int, size: int) -> bytes:
    return HEADER.pack(seq, time.monotonic_ns()) + b"\0" * max(0, size - HEADER.size)


def _pace(start: float, index: int, rate: float) -> None:
    """Sleep until packet ``index`` is due at ``rate`` packets/s from ``start`` (monotonic s)."""
    if rate > 0:
        wait = start + index / rate - time.monotonic()
        if wait > 0:
            time.sleep(wait)


def recv(args: argparse.Namespace) -> None:
    sock = _udp_socket()
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    if args.group:
        sock.bind((args.group, args.port))
        mreq = socket.inet_aton(args.group) + socket.inet_aton(args.iface or "0.0.0.0")
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_ADD_MEMBERSHIP, mreq)
    else:
        sock.bind((args.bind, args.port))
    sock.settimeout(0.05)  # so SIGTERM and the deadlines are noticed promptly
    _emit({"ready": True})
    records: list[list[int]] = []
    deadline = time.monotonic() + args.duration
    last = None
    while not _stop and time.monotonic() < deadline and (args.count <= 0 or len(records) < args.count):
        if last is not None and time.monotonic() - last > args.idle:
            break
        try:
            data = sock.recv(65536)
        except TimeoutError:
            continue
        now = time.monotonic_ns()
        last = time.monotonic()
        if len(data) >= HEADER.size:
            seq, sent = HEADER.unpack_from(data)
            records.append([seq, sent, now, len(data)])
    _emit({"received": len(records), "records": records})


def send(args: argparse.Namespace) -> None:
    sock = _udp_socket()
    if args.iface:
        sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_IF, socket.inet_aton(args.iface))
    sock.setsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL, args.ttl)
    send_ns: list[int] = []
    errors = 0
    start = time.monotonic()
    for seq in range(args.count):
        _pace(start, seq, args.rate)
        payload = _payload(seq, args.size)
        try:
            sock.sendto(payload, (args.to, args.port))
        except OSError:
            errors += 1  # e.g. ENOBUFS when blasting faster than the TUN queue drains
        send_ns.append(HEADER.unpack_from(payload)[1])
    _emit({"sent": len(send_ns), "send_ns": send_ns, "errors": errors})


def echo(args: argparse.Namespace) -> None:
    sock = _udp_socket()
    sock.bind((args.bind, args.port))
    sock.settimeout(0.05)
    _emit({"ready": True})
    echoed = 0
    deadline = time.monotonic() + args.duration
    while not _stop and time.monotonic() < deadline:
        try:
            data, peer = sock.recvfrom(65536)
        except TimeoutError:
            continue
        sock.sendto(data, peer)
        echoed += 1
    _emit({"echoed": echoed})


def rtt(args: argparse.Namespace) -> None:
    sock = _udp_socket()
    sock.connect((args.to, args.port))
    rtts: list[float] = []
    lost = 0
    start = time.monotonic()
    for seq in range(args.count):
        _pace(start, seq, args.rate)
        sock.send(_payload(seq, args.size))
        give_up = time.monotonic() + args.timeout
        while True:
            remaining = give_up - time.monotonic()
            if remaining <= 0:
                lost += 1
                break
            sock.settimeout(remaining)
            try:
                data = sock.recv(65536)
            except TimeoutError:
                continue
            got, sent = HEADER.unpack_from(data)
            if got == seq:  # late echoes of earlier probes are ignored
                rtts.append((time.monotonic_ns() - sent) / 1e6)
                break
    _emit({"rtt_ms": rtts, "lost": lost})


def main(argv: list[str] | None = None) -> None:
    signal.signal(signal.SIGTERM, _on_term)
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="mode", required=True)
    p = sub.add_parser("recv")
    p.add_argument("--bind", default="0.0.0.0")
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--group", help="multicast group to join")
    p.add_argument("--iface", help="address of the interface to join the group on")
    p.add_argument("--count", type=int, default=0, help="stop after this many datagrams (0: no limit)")
    p.add_argument("--duration", type=float, default=60.0, help="stop after this many seconds")
    p.add_argument("--idle", type=float, default=2.0, help="stop this many seconds after the last datagram")
    p.set_defaults(func=recv)
    p = sub.add_parser("send")
    p.add_argument("--to", required=True)
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--count", type=int, required=True)
    p.add_argument("--rate", type=float, default=100.0, help="datagrams/s (0: unpaced)")
    p.add_argument("--size", type=int, default=64, help="UDP payload bytes")
    p.add_argument("--iface", help="address of the interface to send multicast from")
    p.add_argument("--ttl", type=int, default=1)
    p.set_defaults(func=send)
    p = sub.add_parser("echo")
    p.add_argument("--bind", default="0.0.0.0")
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--duration", type=float, default=60.0)
    p.set_defaults(func=echo)
    p = sub.add_parser("rtt")
    p.add_argument("--to", required=True)
    p.add_argument("--port", type=int, required=True)
    p.add_argument("--count", type=int, required=True)
    p.add_argument("--rate", type=float, default=50.0)
    p.add_argument("--size", type=int, default=64)
    p.add_argument("--timeout", type=float, default=1.0, help="seconds to wait for each echo")
    p.set_defaults(func=rtt)
    args = parser.parse_args(argv)
    args.func(args)


if __name__ == "__main__":
    main()
