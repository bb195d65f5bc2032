"""`ros2 run g2p_learner learn`: a full G2P learning run against the rig on the learner's topics.

Hosts the learner node, sends it one `learn` goal through its own action interface, prints progress as
feedback arrives and a summary at the end. `--serve` only hosts the actions (for other clients).

    ros2 run g2p_learner learn [--serve] [--dataset-bag DIR] [--ros-args -p search.threshold_mm:=64.0 ...]
    ros2 run g2p_learner learn --resume bags/<run>    # continue a run after its last completed attempt
    ros2 run g2p_learner learn --control closed       # every attempt in closed loop (g2p.rig.closed_loop)
"""

from __future__ import annotations

import argparse
import importlib
import math
import os
import sys
import threading
import time
from typing import NoReturn

from action_msgs.msg import GoalStatus
from rclpy.executors import Executor
from rclpy.parameter import Parameter
from rclpy.utilities import remove_ros_args

from g2p.rig.closed_loop import ControlMode
from g2p_interfaces.action import Learn
from g2p_learner.learner_node import LearnerNode
from g2p_learner.learner_node import node_parameters as node_parameters  # bringup reads it here
from g2p_ros.action_client import ActionClient
from g2p_ros.contract import ServerWatch, action_name, wait_all
from g2p_ros.executable import run_node
from g2p_ros.spinner import BackgroundSpinner, MultiThreadedExecutor, wait_for_future

# While the rig or the recorder is not on the graph yet, how often to say so (s).
WAIT_REPORT_S = 5.0
# On exit, how long to wait for the recorder to acknowledge the last events and maps (s).
EVENT_FLUSH_TIMEOUT_S = 5.0


def _parse(argv: list[str]) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="learn", description=__doc__.splitlines()[0])
    parser.add_argument("--serve", action="store_true", help="only host the actions; run no learning run")
    parser.add_argument(
        "--dataset-bag", default="", help="build the initial map from this recorded run instead of babbling"
    )
    parser.add_argument(
        "--resume",
        default="",
        metavar="BAG",
        help="continue the run recorded in BAG from its last completed attempt (same run id)",
    )
    parser.add_argument(
        "--control",
        choices=[m.value for m in ControlMode],
        help="play attempts open loop (the paper's G2P) or closed loop; sets the learner.control parameter "
        "(default: the parameter's value, open)",
    )
    options = parser.parse_args(remove_ros_args(argv)[1:])
    if options.resume and options.dataset_bag:
        parser.error("--resume and --dataset-bag exclude each other")
    return options


class _Progress:
    """Prints learn feedback: babbling progress in 10% steps, then a line per attempt.

    On a terminal, babbling progress updates one line in place.
    """

    def __init__(self) -> None:
        self._tty = sys.stdout.isatty()
        self._babbling_shown = -1

    def __call__(self, msg: Learn.Impl.FeedbackMessage) -> None:
        fb = msg.feedback
        if fb.phase == "babbling":
            step = int(10 * fb.babbling_progress)
            if step > self._babbling_shown:
                self._babbling_shown = step
                start, end = ("\r", "" if step < 10 else "\n") if self._tty else ("", "\n")
                print(f"{start}babbling {10 * step:3d}%", end=end, flush=True)
            return
        sigma = f"  sigma {fb.sigma:.3f}" if fb.sigma > 0 else ""
        print(
            f"attempt {fb.attempt:3d}  {fb.phase:<12s} reward {fb.reward_mm:7.1f} mm  "
            f"best {fb.best_reward_mm:7.1f} mm{sigma}",
            flush=True,
        )


def _summary(result: Learn.Result, status_ok: bool, threshold_mm: float) -> str:
    lines = [
        "",
        f"| run | crossed {threshold_mm:g} mm | exploration attempts | exploitation attempts "
        "| best reward (mm) |",
        "| --- | --- | --- | --- | --- |",
        f"| {result.run_id} | {'yes' if result.crossed_threshold else 'no'} | {result.exploration_attempts} "
        f"| {result.exploitation_attempts} | {result.best_reward_mm:.1f} |",
    ]
    if len(result.best_features) and all(math.isfinite(f) for f in result.best_features):
        lines.append("best features: " + " ".join(f"{f:.3f}" for f in result.best_features))
    if result.bag_path:
        lines.append(f"recorded in {result.bag_path}")
    if not status_ok:
        lines.append(f"the run did not complete: {result.message}")
    return "\n".join(lines)


def run_learning(node: LearnerNode, client: ActionClient, goal: Learn.Goal, stop: threading.Event) -> int:
    """Send one learn goal to the node's own action server through `client` and report; the exit code.

    When `stop` is set (Ctrl-C, SIGTERM) the goal is cancelled, which drops the rig to baseline; a
    stop is a clean end, exit code 0 (`ros2 launch` reports any other code as a process that died).
    """
    # The learner's own server, the rig and the recorder are discovered and settle together; the rig's
    # side may start later (another host): say what is awaited every few seconds.
    watches = [ServerWatch("learn", client.server_is_ready), *node.watches]
    deadline = time.monotonic() + node.config.rig_timeout_s
    while missing := wait_all(watches, min(WAIT_REPORT_S, max(0.0, deadline - time.monotonic())), stop):
        if stop.is_set() or time.monotonic() >= deadline:
            break
        print(f"learn: waiting for {', '.join(missing)} (is the rig's side up?)", flush=True)
    if stop.is_set():
        return 0
    if missing:
        print(
            f"learn: not on the graph after {node.config.rig_timeout_s:g} s: {', '.join(missing)}",
            file=sys.stderr,
        )
        return 1
    return _run_goal(client, goal, stop, node.config.search.threshold_mm)


def _run_goal(client: ActionClient, goal: Learn.Goal, stop: threading.Event, threshold_mm: float) -> int:
    send = client.send_goal_async(goal, feedback_callback=_Progress())
    if not wait_for_future(send, math.inf, stop):
        return 0
    handle = send.result()
    if handle is None or not handle.accepted:
        print("learn: goal rejected (see the log above for the reason)", file=sys.stderr)
        return 1
    result_future = handle.get_result_async()
    if not wait_for_future(result_future, math.inf, stop):
        print("\nlearn: stopping: cancelling the run (the rig drops to baseline)", file=sys.stderr)
        wait_for_future(handle.cancel_goal_async(), math.inf)
        wait_for_future(result_future, math.inf)
        print("learn: stopped; the bag holds every attempt completed so far", file=sys.stderr)
        return 0
    response = result_future.result()
    ok = response.status == GoalStatus.STATUS_SUCCEEDED
    print(_summary(response.result, ok, threshold_mm), flush=True)
    return 0 if ok else 1


class _Learn:
    """What `learn` does with its node: spin it in the background, send it one goal (or serve), stop it.

    Args:
        options: the command line.
    """

    def __init__(self, options: argparse.Namespace) -> None:
        self._options = options
        self._client: ActionClient | None = None
        self._spinner: BackgroundSpinner | None = None
        # Torch takes a second or more to import and is needed from the first fit on: imported while the
        # graph is discovered and settles, rather than before the node exists (a stop meanwhile: _exit_now).
        self.warm_up = threading.Thread(target=importlib.import_module, args=("g2p.inverse_map.training",))

    def make_node(self) -> LearnerNode:
        """The learner node, with `--control` as its `learner.control` parameter."""
        control = self._options.control
        return LearnerNode([] if control is None else [Parameter("learner.control", value=control)])

    def run(self, node: LearnerNode, executor: Executor, stop: threading.Event) -> int:
        """Spin in the background; run one learn goal until it ends or `stop` (or serve until `stop`)."""
        # Before spinning starts: rclpy's ActionClient joins the node half-built (ros2/rclpy#1589).
        self._client = None if self._options.serve else ActionClient(node, Learn, action_name(node, "learn"))
        self._spinner = BackgroundSpinner(executor).start()
        self.warm_up.start()
        if self._client is None:
            stop.wait()
            return 0
        goal = Learn.Goal(dataset_bag=self._options.dataset_bag, resume_bag=self._options.resume)
        return run_learning(node, self._client, goal, stop)

    def stop(self, node: LearnerNode) -> None:
        """End the goals while the executor still spins (cancels reach the rig), flush, stop spinning."""
        node.stop_goals(timeout_s=10.0)
        if not node.flush_events(timeout_s=EVENT_FLUSH_TIMEOUT_S):  # the recorder may be remote
            print("learn: the recorder did not acknowledge the last events", file=sys.stderr)
        if self._spinner is not None:
            self._spinner.stop()
        if self._client is not None:
            self._client.destroy()


def main(args: list[str] | None = None) -> None:
    """Entry point of `ros2 run g2p_learner learn`."""
    argv = sys.argv if args is None else args
    learn = _Learn(_parse(argv))
    code = run_node(
        "learn",
        learn.make_node,
        argv,
        executor=lambda: MultiThreadedExecutor(num_threads=4),
        run=learn.run,
        stop_node=learn.stop,
    )
    if learn.warm_up.is_alive():
        _exit_now(code)
    sys.exit(code)


def _exit_now(code: int) -> NoReturn:
    """End the process without finalizing the interpreter: a stop while torch is still being imported.

    Waiting for the import can outlast the 5 s that `ros2 launch` grants (seconds more on a loaded machine
    with a cold page cache), and finalizing while an import runs fails it ("dictionary changed size during
    iteration" in weakref's exit hook). The node is destroyed and rclpy shut down: nothing is left to
    finalize but the output streams.
    """
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


if __name__ == "__main__":
    main()
