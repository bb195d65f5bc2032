"""The live view of a run in Foxglove: the leg, the belt, the foot paths, the joint angles and each attempt.

- state: what is shown, from the rig's ticks and the learner's events (pure, numpy);
- channels: the Foxglove channels and messages (foxglove-sdk);
- server: `LegViewer`, the WebSocket server the Foxglove app connects to;
- replay: a recorded run shown at a chosen rate;
- layout: the Foxglove layout shipped as layout.json.

Needs the `view` extra (`pip install -e .[view]`).

May import: g2p.description, g2p.rig, g2p.learning, g2p.bags.
"""
