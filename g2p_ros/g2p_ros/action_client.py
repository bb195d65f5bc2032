"""rclpy's ActionClient, safe to call from a thread other than the one spinning its executor.

rclpy's on Jazzy (7.1.6; ros2/rclpy#1123) sends a goal, cancel or result request and only then stores the
future its response completes. A response taken by the spinning thread in between is dropped ("Ignoring
unexpected goal response. There may be more than one action server"), and the future never completes:
the driver's trajectory test waited 30 s for a goal's response from a healthy rig (1 of 34 runs beside the
core suite), and a RigClient, called from the learner's threads, is exposed alike. Kilted's rclpy (9.x)
sends and stores under a lock that its `take_data` also holds; this class does the same on every
distribution (on Kilted the second lock is redundant, and harmless: both paths take the two locks in the
same order).
"""

from __future__ import annotations

import threading
from typing import Any

from rclpy import action


class ActionClient(action.ActionClient):
    """rclpy's ActionClient whose requests are sent and registered before any response can be taken."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self._requests_lock = threading.Lock()
        super().__init__(*args, **kwargs)

    def take_data(self) -> Any:
        """rclpy's, once no request is between its sending and its registration."""
        with self._requests_lock:
            return super().take_data()

    def send_goal_async(self, *args: Any, **kwargs: Any) -> Any:
        """rclpy's, the request sent and its future registered as one step."""
        with self._requests_lock:
            return super().send_goal_async(*args, **kwargs)

    def _cancel_goal_async(self, goal_handle: Any) -> Any:
        with self._requests_lock:
            return super()._cancel_goal_async(goal_handle)

    def _get_result_async(self, goal_handle: Any) -> Any:
        with self._requests_lock:
            return super()._get_result_async(goal_handle)
