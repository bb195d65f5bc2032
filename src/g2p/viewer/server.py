"""The live view: a Foxglove WebSocket server (foxglove-sdk) showing a run as it happens.

    viewer = LegViewer(description)                   # ws://127.0.0.1:8765, loopback only by default
    viewer.joint_state(stamp_ns, position, velocity)  # per rig tick
    viewer.treadmill(displacement_mm)
    viewer.event(run_event)                           # per learner event

Open it in Foxglove (the app or app.foxglove.dev): Open connection -> Foxglove WebSocket ->
ws://127.0.0.1:8765, then import the layout src/g2p/viewer/layout.json.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from types import TracebackType

from foxglove import Context, start_server
from foxglove.websocket import ChannelView, Client, ServerListener

from g2p.bags.events import RunEvent
from g2p.description import FloatArray, LegDescription
from g2p.validation import require, require_positive
from g2p.viewer.channels import ViewChannels
from g2p.viewer.state import ViewState


@dataclass(frozen=True)
class ViewerConfig:
    """Where the viewer listens and how often it redraws.

    Attributes:
        host: address the WebSocket server listens on. Loopback by default: the viewer is reachable from
            another machine only when asked (e.g. "0.0.0.0", or the lab network's address).
        port: TCP port (0: any free one).
        scene_rate_hz: most 3D scene updates per second of wall time (the joint plot gets every tick).
        message_backlog: outgoing messages queued per client. When a slow client lets the queue fill,
            foxglove-sdk drops its oldest message; a replay sizes it to hold the whole run.
    """

    host: str = "127.0.0.1"
    port: int = 8765
    scene_rate_hz: float = 30.0
    message_backlog: int = 1024

    def __post_init__(self) -> None:
        require(bool(self.host.strip()), "host", "must name an address, e.g. 127.0.0.1")
        require(
            isinstance(self.port, int) and 0 <= self.port <= 65535,
            "port",
            f"must be an integer in [0, 65535], got {self.port!r}",
        )
        require_positive(self.scene_rate_hz, "scene_rate_hz")
        require(
            isinstance(self.message_backlog, int) and self.message_backlog > 0,
            "message_backlog",
            f"must be a positive integer, got {self.message_backlog!r}",
        )


class _Subscriptions(ServerListener):
    """The clients' subscriptions, (client id, channel id) (the other callbacks keep their no-op defaults).

    foxglove-sdk reports a client's disconnection as the end of each of its subscriptions.
    """

    def __init__(self) -> None:
        self.current: set[tuple[int, int]] = set()
        self.changed = threading.Condition()

    def on_subscribe(self, client: Client, channel: ChannelView) -> None:
        with self.changed:
            self.current.add((client.id, channel.id))
            self.changed.notify_all()

    def on_unsubscribe(self, client: Client, channel: ChannelView) -> None:
        with self.changed:
            self.current.discard((client.id, channel.id))
            self.changed.notify_all()

    def wait(self, done: Callable[[], bool], stop: threading.Event | None, timeout_s: float | None) -> bool:
        """Wait until `done()` (False when `stop` was set or the timeout passed first)."""
        deadline = None if timeout_s is None else time.monotonic() + timeout_s
        with self.changed:
            while not done():
                if (stop is not None and stop.is_set()) or (
                    deadline is not None and time.monotonic() > deadline
                ):
                    return False
                self.changed.wait(0.1)
        return True


class LegViewer:
    """A run shown on a Foxglove WebSocket server.

    Every tick goes to /view/joints; the 3D scene (/view/scene) at most ViewerConfig.scene_rate_hz times a
    second of wall time, so that a fast simulated run (a thousand ticks a second) does not flood the
    client, and at once on an attempt's start and end.

    Args:
        description: the leg to draw until `set_description` gives the rig's own.
        config: where to listen, how often to redraw.
        name: the server's name, as the Foxglove app shows it.
        clock: wall clock (s), for the scene's rate.

    Raises:
        RuntimeError: the server cannot listen (e.g. the port is taken).
    """

    def __init__(
        self,
        description: LegDescription,
        config: ViewerConfig | None = None,
        name: str = "G2P rig",
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.config = config or ViewerConfig()
        self.state = ViewState(description)
        self._scene_period_s = 1.0 / self.config.scene_rate_hz
        self._clock = clock
        self._next_scene_s = -float("inf")
        self.context = Context()
        self.channels = ViewChannels(self.context)
        self._subscriptions = _Subscriptions()
        self.server = start_server(
            name=name,
            host=self.config.host,
            port=self.config.port,
            context=self.context,
            server_listener=self._subscriptions,
            message_backlog_size=self.config.message_backlog,
        )

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self.server.port)

    @property
    def url(self) -> str:
        """The address a Foxglove client opens (ws://host:port)."""
        return f"ws://{self.config.host}:{self.port}"

    def wait_for_client(
        self, channels: int = 1, stop: threading.Event | None = None, timeout_s: float | None = None
    ) -> bool:
        """Wait until clients have subscribed to `channels` of the viewer's channels.

        Returns:
            Whether they have (False when `stop` was set or the timeout passed first).
        """
        subscribed = self._subscriptions.current
        return self._subscriptions.wait(
            lambda: len({channel for _, channel in subscribed}) >= channels, stop, timeout_s
        )

    def wait_for_clients_to_leave(
        self, stop: threading.Event | None = None, timeout_s: float | None = None
    ) -> bool:
        """Wait until no client is subscribed to any channel (each has disconnected or unsubscribed).

        `close` drops what the server has not yet sent (foxglove-sdk's stop ends each client's send
        loop), so a server that must deliver everything it logged waits for this first.

        Returns:
            Whether they have (False when `stop` was set or the timeout passed first).
        """
        return self._subscriptions.wait(lambda: not self._subscriptions.current, stop, timeout_s)

    def set_description(self, description: LegDescription) -> None:
        """Draw the rig's own leg from now on (its robot_description)."""
        self.state.set_description(description)

    def treadmill(self, displacement_mm: float) -> None:
        """A treadmill sample: the belt's cumulative travel (mm)."""
        self.state.treadmill(displacement_mm)

    def joint_state(self, stamp_ns: int, position_rad: FloatArray, velocity_rad_s: FloatArray) -> None:
        """A rig tick's joint state: (proximal, distal) angles (rad) and velocities (rad/s)."""
        self.channels.log_joints(self.state.joint_state(stamp_ns, position_rad, velocity_rad_s))
        now = self._clock()
        if now >= self._next_scene_s:
            self._next_scene_s = now + self._scene_period_s
            self._log_scene()

    def event(self, event: RunEvent) -> None:
        """A learner event."""
        summary = self.state.event(event)
        if summary is not None:
            self.channels.log_attempt(summary)
        if event.event in ("attempt_start", "attempt_end"):
            self._log_scene()

    def _log_scene(self) -> None:
        frame = self.state.scene()
        if frame is not None:
            self.channels.log_scene(frame, self.state.description)

    def close(self) -> None:
        """Stop the server: clients are disconnected, and what was not yet sent to them is dropped."""
        self.server.stop()

    def __enter__(self) -> LegViewer:
        return self

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
