"""The Foxglove layout that opens a session's recording (or its live scene) ready to watch:
``docs/foxglove-layout.json`` (``swarm-sitl layout`` writes it; a test checks the committed file is what this builds).

A 3D panel in the world frame with every ``foxglove.SceneUpdate`` topic shown (the arena, the robots in their LED
colours with their headings, the radio links coloured by RSSI, a study's own scenes such as a global controller's
regions), looking down on the demo's 10 x 20 m arena; beside it the log (``/log``: every robot's and service's log
record, the session's events as warnings) over the session's events as raw messages.
"""

from __future__ import annotations

import foxglove.layouts as fl

SCENE_TOPICS = ("/scene/arena", "/scene/robots")


def layout() -> fl.Layout:
    three_d = fl.ThreeDeePanel(
        title="swarm",
        config=fl.ThreeDeeConfig(
            follow_tf="world",
            topics={t: fl.BaseRendererSceneUpdateTopicSettings(visible=True) for t in SCENE_TOPICS},
            camera_state=fl.ThreeDeeCameraState(distance=28.0, perspective=True, phi=25.0, theta_offset=90.0,
                                                target=(5.0, 10.0, 0.0)),
        ),
    )
    log = fl.LogPanel(title="log", config=fl.LogConfig(topic_to_render="/log", show_name=True, show_time=True,
                                                       min_log_level=1))
    events = fl.RawMessagesPanel(title="events", config=fl.RawMessagesConfig(topic_path="/session/events"))
    right = fl.SplitContainer(direction="column", items=[fl.SplitItem(proportion=0.65, content=log),
                                                          fl.SplitItem(proportion=0.35, content=events)])
    return fl.Layout(content=fl.SplitContainer(direction="row", items=[fl.SplitItem(proportion=0.65, content=three_d),
                                                                       fl.SplitItem(proportion=0.35, content=right)]))


def layout_json() -> str:
    """The layout as the file holds it (indented, one trailing newline)."""
    import json

    return json.dumps(json.loads(layout().to_json()), indent=1, sort_keys=True) + "\n"
