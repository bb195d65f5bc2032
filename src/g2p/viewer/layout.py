"""The Foxglove layout shipped with the viewer (foxglove-sdk's layout types), written to layout.json.

    python -m g2p.viewer.layout > src/g2p/viewer/layout.json     # regenerate the shipped file

Left, the 3D scene in the treadmill frame; right, the joint angles desired vs actual, each attempt's
reward and best so far, its energy and tracking error and the exploitation sigma, and the last attempt's
figures. In Foxglove: Layouts -> Import from file -> layout.json.
"""

from __future__ import annotations

import json
from importlib import resources
from pathlib import Path

import foxglove.layouts as fl

from g2p.viewer.channels import ATTEMPTS_TOPIC, FRAME_ID, JOINTS_TOPIC, SCENE_TOPIC

_C0, _C1 = "#1f77b4", "#ff7f0e"  # matplotlib's first two colours, as in the report's figures


def _series(topic: str, field: str, label: str, color: str, dashed: bool = False) -> fl.PlotSeries:
    return fl.PlotSeries(
        value=f"{topic}.{field}",
        label=label,
        color=color,
        line_style="dashed" if dashed else "solid",
        timestamp_method="receiveTime",
    )


def _per_attempt(title: str, series: list[fl.PlotSeries]) -> fl.PlotPanel:
    """A plot of per-attempt values against the attempt number."""
    return fl.PlotPanel(
        title=title,
        config=fl.PlotConfig(
            paths=[
                fl.PlotSeries(
                    value=s.value, label=s.label, color=s.color, x_value_path=f"{ATTEMPTS_TOPIC}.attempt"
                )
                for s in series
            ],
            x_axis_val="custom",
            x_axis_path=fl.PlotXAxisPath(value=f"{ATTEMPTS_TOPIC}.attempt"),
            x_axis_label="attempt",
            show_legend=True,
        ),
    )


def layout() -> fl.Layout:
    """The viewer's layout."""
    scene = fl.ThreeDeePanel(
        title="leg",
        config=fl.ThreeDeeConfig(
            follow_tf=FRAME_ID,
            topics={SCENE_TOPIC: fl.BaseRendererSceneUpdateTopicSettings(visible=True)},
            # From the side (across the belt), level with the knee.
            camera_state=fl.ThreeDeeCameraState(
                distance=1.3, perspective=False, phi=90.0, theta_offset=90.0, target=(0.0, 0.0, 0.22)
            ),
        ),
    )
    angles = fl.PlotPanel(
        title="joint angles (rad): desired dashed",
        config=fl.PlotConfig(
            paths=[
                _series(JOINTS_TOPIC, "proximal_rad", "hip", _C0),
                _series(JOINTS_TOPIC, "proximal_desired_rad", "hip desired", _C0, dashed=True),
                _series(JOINTS_TOPIC, "distal_rad", "knee", _C1),
                _series(JOINTS_TOPIC, "distal_desired_rad", "knee desired", _C1, dashed=True),
            ],
            time_window_mode="sliding",
            following_view_width=5.0,
            show_legend=True,
        ),
    )
    rewards = _per_attempt(
        "reward (mm)",
        [
            _series(ATTEMPTS_TOPIC, "reward_mm", "reward", _C0),
            _series(ATTEMPTS_TOPIC, "best_reward_mm", "best so far", _C1),
        ],
    )
    costs = _per_attempt(
        "energy (J), tracking RMSE (rad), sigma",
        [
            _series(ATTEMPTS_TOPIC, "energy_j", "energy", _C0),
            _series(ATTEMPTS_TOPIC, "tracking_rmse_rad", "tracking RMSE", _C1),
            _series(ATTEMPTS_TOPIC, "sigma", "sigma", "#2ca02c"),
        ],
    )
    last = fl.RawMessagesPanel(title="last attempt", config=fl.RawMessagesConfig(topic_path=ATTEMPTS_TOPIC))
    right = fl.SplitContainer(
        direction="column",
        items=[
            fl.SplitItem(proportion=2, content=angles),
            fl.SplitItem(content=rewards),
            fl.SplitItem(content=costs),
            fl.SplitItem(content=last),
        ],
    )
    return fl.Layout(
        content=fl.SplitContainer(
            direction="row",
            items=[fl.SplitItem(proportion=3, content=scene), fl.SplitItem(proportion=2, content=right)],
        )
    )


def layout_json() -> str:
    """The layout as the shipped file holds it (indented JSON, newline-terminated)."""
    return json.dumps(json.loads(layout().to_json()), indent=2, sort_keys=True) + "\n"


def packaged_layout_path() -> Path:
    """Path of the shipped layout (g2p/viewer/layout.json)."""
    return Path(str(resources.files("g2p.viewer").joinpath("layout.json")))


if __name__ == "__main__":
    print(layout_json(), end="")
