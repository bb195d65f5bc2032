"""g2p_ros.action_client.ActionClient: a response that arrives before its request is registered is kept."""

from __future__ import annotations

import time
from typing import Any

import rclpy
from action_msgs.msg import GoalStatus
from rclpy.action import ActionServer
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node

from g2p_interfaces.action import RunActivations
from g2p_ros.action_client import ActionClient
from g2p_ros.spinner import BackgroundSpinner, wait_for_future
from tests.ros.rosproc import RosPeer

# How long the client's thread pauses between sending a request and registering it (s): far longer than
# a response takes over loopback, so the response is always taken meanwhile.
PAUSE_S = 0.3


class SlowToRegister:
    """A client handle that pauses after sending each goal and result request, as a loaded machine may."""

    def __init__(self, handle: Any) -> None:
        self._handle = handle

    def send_goal_request(self, request: Any) -> int:
        sequence_number: int = self._handle.send_goal_request(request)
        time.sleep(PAUSE_S)
        return sequence_number

    def send_result_request(self, request: Any) -> int:
        sequence_number: int = self._handle.send_result_request(request)
        time.sleep(PAUSE_S)
        return sequence_number

    def __getattr__(self, name: str) -> Any:
        return getattr(self._handle, name)


class RaceClient(RosPeer):
    """A peer with one client of the test's action, its handle slow to register requests."""

    def __init__(self) -> None:
        super().__init__("race_client")
        self.client = ActionClient(self.node, RunActivations, "/race_test")
        self.handle = self.client._client_handle
        self.client._client_handle = SlowToRegister(self.handle)
        self.start()

    def destroy_entities(self) -> None:
        self.client._client_handle = self.handle
        self.client.destroy()


def test_responses_taken_before_their_requests_are_registered_complete_the_futures() -> None:
    """Known answer: each response arrives while the sending thread pauses before registering its future.
    rclpy's client on Jazzy (ros2/rclpy#1123) drops both ("Ignoring unexpected goal response") and the
    futures never complete; this one completes them: the goal is accepted and its result is SUCCEEDED."""
    context = Context()
    rclpy.init(context=context)
    server_node = Node("race_server", context=context)

    def execute(goal_handle: Any) -> RunActivations.Result:
        goal_handle.succeed()
        return RunActivations.Result(message="done")

    server = ActionServer(server_node, RunActivations, "/race_test", execute)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(server_node)
    spinner = BackgroundSpinner(executor).start()
    peer = RaceClient()
    client = peer.client
    try:
        assert client.wait_for_server(timeout_sec=30.0)
        for _ in range(3):
            sent = client.send_goal_async(RunActivations.Goal())
            assert wait_for_future(sent, 10.0), "the goal's response was dropped"
            goal = sent.result()
            assert goal.accepted
            result = goal.get_result_async()
            assert wait_for_future(result, 10.0), "the result's response was dropped"
            assert result.result().status == GoalStatus.STATUS_SUCCEEDED
            assert result.result().result.message == "done"
    finally:
        peer.close()
        spinner.stop()
        server.destroy()
        server_node.destroy_node()
        rclpy.shutdown(context=context)
