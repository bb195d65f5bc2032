"""The learner node's goal handling, in-process with real rclpy: refused goals, and a goal with no rig.

The node runs in this process (rclpy's default Context, spun as `learn` spins it) with no rig on the
graph; a peer node in a Context of its own sends the goals.
"""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
import rclpy
from action_msgs.msg import GoalStatus
from rclpy.parameter import Parameter

from g2p.learning.run_events import Event
from g2p_interfaces.action import Attempt, Babble, Learn, Track
from g2p_interfaces.msg import LearnerEvent
from g2p_learner.learner_node import LearnerNode
from g2p_ros.action_client import ActionClient
from g2p_ros.contract import EVENT_QOS
from g2p_ros.spinner import BackgroundSpinner, MultiThreadedExecutor
from tests.ros.rosproc import RosPeer, wait_until

RIG_TIMEOUT_S = 0.5


class GoalPeer(RosPeer):
    """The learner's four action clients, and its events collected."""

    def __init__(self) -> None:
        super().__init__("goal_peer")
        names = {Babble: "babble", Attempt: "attempt", Learn: "learn", Track: "track"}
        self.clients = {action: ActionClient(self.node, action, name) for action, name in names.items()}
        self.events: list[LearnerEvent] = []
        self.node.create_subscription(LearnerEvent, "learner/events", self.events.append, EVENT_QOS)
        self.start()
        self.wait_for_servers({names[a]: c.server_is_ready for a, c in self.clients.items()}, 30.0)

    def send(self, goal: Any) -> Any:
        """Send a goal of whichever action it belongs to; its goal handle."""
        action = next(a for a in self.clients if isinstance(goal, a.Goal))
        return self.wait(self.clients[action].send_goal_async(goal), 30.0)

    def destroy_entities(self) -> None:
        for client in self.clients.values():
            client.destroy()


@pytest.fixture
def learner() -> Iterator[LearnerNode]:
    """The learner node with no rig to find, waiting RIG_TIMEOUT_S for one."""
    rclpy.init()
    node = LearnerNode([Parameter("rig_timeout_s", value=RIG_TIMEOUT_S)])
    executor = MultiThreadedExecutor(num_threads=4)
    executor.add_node(node)
    spinner = BackgroundSpinner(executor).start()
    yield node
    spinner.stop()
    node.destroy_node()
    rclpy.shutdown()


@pytest.fixture
def peer(learner: LearnerNode) -> Iterator[GoalPeer]:
    p = GoalPeer()
    yield p
    p.close()


def test_invalid_goals_are_rejected_before_anything_runs(
    learner: LearnerNode, peer: GoalPeer, tmp_path: Path
) -> None:
    (tmp_path / "a").mkdir()
    (tmp_path / "b").mkdir()
    refused = [
        Babble.Goal(duration_s=-1.0),
        Attempt.Goal(features=[0.5] * 10),  # no map yet
        Attempt.Goal(features=[0.5] * 9),
        Learn.Goal(threshold_mm=float("nan")),
        Learn.Goal(dataset_bag=str(tmp_path / "a"), resume_bag=str(tmp_path / "b")),
        Learn.Goal(dataset_bag=str(tmp_path / "missing")),
        Track.Goal(mode=5),
    ]
    for goal in refused:
        assert not peer.send(goal).accepted, goal
    assert learner.session.learner.refinements == 0 and len(learner.session.learner.dataset) == 0
    # A refused goal does not hold the learner: a valid one is taken (and, with no rig, aborted).
    handle = peer.send(Babble.Goal(duration_s=1.0))
    assert handle.accepted
    assert peer.wait(handle.get_result_async(), 30.0).status == GoalStatus.STATUS_ABORTED


def test_a_valid_goal_without_a_rig_aborts_naming_the_missing_servers_and_frees_the_learner(
    learner: LearnerNode, peer: GoalPeer
) -> None:
    for _ in range(2):  # the learner takes a goal again once the first ended
        handle = peer.send(Babble.Goal(duration_s=1.0))
        assert handle.accepted
        response = peer.wait(handle.get_result_async(), 30.0)
        assert response.status == GoalStatus.STATUS_ABORTED
        message = response.result.message
        assert message.startswith(f"not on the graph after {RIG_TIMEOUT_S:g} s: /leg/run_activations, ")
        assert message.endswith("reset")  # the rig's reset service (named as rclpy's client names it)
    wait_until(lambda: len(peer.events) >= 2, 10.0, "the two run_end events")
    for event in peer.events:
        assert event.event == Event.RUN_END.value and event.run_id == learner.session.run_id
        assert json.loads(event.detail) == {"error": message}
    assert len(learner.session.learner.dataset) == 0  # nothing was babbled
