"""The RViz config and the Foxglove layout shipped in viz/ show what the node publishes, in the
frame of the committed bags."""

from __future__ import annotations

import json
import re
from pathlib import Path

import yaml
from pose_lifter.messages import names, typestore
from pose_lifter.mocap import scenes

VIZ = Path(__file__).resolve().parents[1] / "ros2_ws" / "src" / "pose_lifter" / "viz"


def test_rviz_config_shows_the_markers_in_the_bag_frame() -> None:
    cfg = yaml.safe_load((VIZ / "demo.rviz").read_text())
    manager = cfg["Visualization Manager"]
    assert manager["Global Options"]["Fixed Frame"] == scenes.CAMERA_FRAME
    (markers,) = [d for d in manager["Displays"] if d["Class"] == "rviz_default_plugins/MarkerArray"]
    assert markers["Topic"]["Value"] == names.TOPIC_MARKERS
    assert markers["Topic"]["Reliability Policy"] == "Reliable"  # the node's marker QoS
    assert set(markers["Namespaces"]) == {"pose_lifter/joints", "pose_lifter/bones"}


def test_foxglove_layout_topics_and_fields_exist() -> None:
    layout = json.loads((VIZ / "foxglove_layout.json").read_text())
    panels = layout["configById"]
    three_d = panels["3D!pose_lifter"]
    assert three_d["followTf"] == scenes.CAMERA_FRAME and names.TOPIC_MARKERS in three_d["topics"]
    assert panels["DiagnosticSummary!pose_lifter"]["topicToRender"] == "/diagnostics"
    fielddefs = typestore.pose_lifter_typestore().fielddefs["pose_lifter_msgs/msg/Skeleton3D"][1]
    fields = {name for name, _ in fielddefs}
    for panel in (p for k, p in panels.items() if k.startswith("Plot!")):
        for path in panel["paths"]:
            topic, rest = path["value"].split(".", 1)
            assert topic == names.TOPIC_SKELETONS
            used = set(re.findall(r"[a-z_]+", rest)) - {"skeletons"}
            assert used <= fields, used - fields
    # every panel named in the layout tree is configured
    panel_names = set(re.findall(r'"([A-Za-z0-9]+![a-z_]+)"', json.dumps(layout["layout"])))
    assert panel_names == set(panels)
