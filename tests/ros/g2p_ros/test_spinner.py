"""g2p_ros.spinner.MultiThreadedExecutor: a callback waiting for a pool thread is handed over once."""

from __future__ import annotations

import threading
from collections.abc import Callable

import rclpy
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.context import Context
from rclpy.node import Node
from std_msgs.msg import Empty

from g2p_ros.spinner import MultiThreadedExecutor
from tests.ros.rosproc import wait_until


def test_a_callback_queued_behind_a_busy_pool_is_queued_once_and_then_runs() -> None:
    """Both pool threads held by timers' callbacks: a message's callback waits in the pool's queue while
    the executor spins 50 times. rclpy's own executor hands it over on every spin (ros2/rclpy#1452): 50
    futures, and a spinning thread that never waits. Ours hands it over once, and it runs once a pool
    thread is free."""
    context = Context()
    rclpy.init(context=context)
    node = Node("spinner_test", context=context)
    executor = MultiThreadedExecutor(num_threads=2, context=context)
    executor.add_node(node)
    group = ReentrantCallbackGroup()
    release, held, received = threading.Event(), [], []

    def holder(k: int) -> Callable[[], None]:
        def hold_a_pool_thread() -> None:
            timers[k].cancel()
            held.append(k)
            release.wait(30.0)

        return hold_a_pool_thread

    timers = [node.create_timer(0.01, holder(k), callback_group=group) for k in range(2)]
    node.create_subscription(Empty, "spinner_test", received.append, 10, callback_group=group)
    publisher = node.create_publisher(Empty, "spinner_test", 10)
    try:
        while len(held) < 2:
            executor.spin_once(timeout_sec=0.1)
        publisher.publish(Empty())
        for _ in range(50):
            executor.spin_once(timeout_sec=0.1)
        assert not received
        assert len(executor._futures) == 3  # the timers' callbacks, and the message's (once)
        release.set()
        wait_until(lambda: (executor.spin_once(timeout_sec=0.1), received)[1] != [], 10.0, "the message")
        assert len(received) == 1
    finally:
        release.set()
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
