"""``pose-lifter play`` feeds the installed node from a committed bag, on the real graph."""

from __future__ import annotations

import subprocess
import sys
import time
from typing import Any

import pytest
from pose_lifter.messages import convert as m
from pose_lifter.offline import bags

from .conftest import REPO, GraphClient

pytestmark = pytest.mark.ros

BAG = REPO / "bags" / "walk_clean.mcap"


def test_play_feeds_the_lifter(graph: GraphClient, start_lifter: Any, lifter_env: dict[str, str]) -> None:
    # a reliable input with a deep queue (the override config/lifter.yaml documents): the first
    # frame takes ~0.3 s (cold solve + first publish), and the default sensor-data input (best
    # effort, depth 5) would drop the frames that arrive meanwhile, as with `ros2 bag play`
    lifter = start_lifter(params={
        "stats_period": 1.0, "qos_overrides./keypoints_2d.subscription.reliability": "reliable",
        "qos_overrides./keypoints_2d.subscription.depth": 100})
    graph.wait_for_lifter(lifter)
    stamps = [x.stamp_ns for x in bags.read_messages(BAG, ["/keypoints_2d"])]
    play = subprocess.Popen(
        [sys.executable, "-m", "pose_lifter.cli", "play", str(BAG), "--topics", "/keypoints_2d",
         "/camera_info", "--rate", "1", "--wait", "60"], env=lifter_env, cwd=REPO, stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    deadline = time.monotonic() + 180
    while play.poll() is None and time.monotonic() < deadline:
        graph.executor.spin_once(timeout_sec=0.05)
    out = play.communicate(timeout=30)[0]
    assert play.returncode == 0, out
    assert "play: 240 messages on 2 topics" in out  # 120 keypoint + 120 camera_info messages
    end = time.monotonic() + 10
    while len(graph.skeletons) < len(stamps) and time.monotonic() < end:
        graph.executor.spin_once(timeout_sec=0.05)
    answered = [m.stamp_to_ns(a.header.stamp) for a in graph.skeletons]
    missing = sorted(set(stamps) - set(answered))
    assert answered == stamps, (
        f"{len(answered)} answers, missing {[stamps.index(s) for s in missing]}; lifter log:\n{lifter.log()}")
    assert all(len(a.skeletons) == 1 and a.skeletons[0].track_id == 0 for a in graph.skeletons)
