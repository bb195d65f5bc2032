"""The tests' Foxglove protocol client (tests/foxglove_client/client.mjs, @foxglove/ws-protocol), run."""

from __future__ import annotations

import json
import shutil
import subprocess
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import pytest

CLIENT_DIR = Path(__file__).resolve().parents[1] / "foxglove_client"


@dataclass
class Received:
    """What the client saw.

    Attributes:
        returncode: 0 when every needed topic got its messages, 1 on timeout, 2 on a decoding error.
        stderr: the client's complaints.
        server: the server's name and capabilities.
        channels: topic -> its advertisement (encoding, schemaName, schemaEncoding, schema for JSON).
        messages: topic -> [(log time ns, decoded message)], in arrival order.
    """

    returncode: int
    stderr: str
    server: dict[str, Any] = field(default_factory=dict)
    channels: dict[str, dict[str, Any]] = field(default_factory=dict)
    messages: dict[str, list[tuple[int, dict[str, Any]]]] = field(default_factory=dict)


class FoxgloveClient:
    """The client connected to `url` (retrying until the server is up) until it has `need` messages.

    Args:
        url: ws://host:port.
        seconds: give up after this long (s).
        need: topic -> how many messages to wait for.
        until_close: instead, until the server closes the connection (it stopped).
    """

    def __init__(
        self, url: str, seconds: float, need: dict[str, int] | None = None, until_close: bool = False
    ) -> None:
        node = shutil.which("node")
        if node is None:
            pytest.skip("Node.js is not installed: the Foxglove client test needs it (and npm)")
        assert (CLIENT_DIR / "node_modules" / "@foxglove" / "ws-protocol").is_dir(), (
            f"the client's npm packages are missing in {CLIENT_DIR}: run scripts/bootstrap"
        )
        args = [node, str(CLIENT_DIR / "client.mjs"), url, "--seconds", str(seconds)]
        for topic, n in (need or {}).items():
            args += ["--need", f"{topic}={n}"]
        if until_close:
            args.append("--until-close")
        self.popen = subprocess.Popen(args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self._lines: list[str] = []
        self._stderr: list[str] = []
        self._cv = threading.Condition()
        self._readers = [
            threading.Thread(target=self._read, args=(self.popen.stdout, self._lines), daemon=True),
            threading.Thread(target=self._read, args=(self.popen.stderr, self._stderr), daemon=True),
        ]
        for reader in self._readers:
            reader.start()

    def _read(self, stream: Any, into: list[str]) -> None:
        for line in stream:
            with self._cv:
                into.append(line)
                self._cv.notify_all()
        with self._cv:
            into.append("")  # the end
            self._cv.notify_all()

    def first_message(self, topic: str, timeout_s: float) -> tuple[int, dict[str, Any]]:
        """The first message on `topic` (log time ns, decoded), as soon as it arrived."""

        def found() -> tuple[int, dict[str, Any]] | None:
            for line in self._lines:
                if not line:
                    raise AssertionError(f"the client exited before a message on {topic}: {self._stderr}")
                record = json.loads(line)
                if record["kind"] == "message" and record["topic"] == topic:
                    return int(record["logTimeNs"]), record["data"]
            return None

        with self._cv:
            assert self._cv.wait_for(lambda: found() is not None, timeout_s), f"no message on {topic}"
            first = found()
        assert first is not None
        return first

    def result(self, timeout_s: float = 600.0) -> Received:
        """Wait for the client to exit and parse what it printed."""
        self.popen.wait(timeout=timeout_s)
        for reader in self._readers:
            reader.join()
        received = Received(self.popen.returncode, "".join(self._stderr))
        for line in filter(None, self._lines):
            record = json.loads(line)
            if record["kind"] == "server":
                received.server = record
            elif record["kind"] == "advertise":
                received.channels[record["topic"]] = record
            else:
                received.messages.setdefault(record["topic"], []).append(
                    (int(record["logTimeNs"]), record["data"])
                )
        return received
