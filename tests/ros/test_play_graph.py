"""``pose-lifter play`` feeds the installed node from a committed bag, on the real graph."""

from __future__ import annotations

import dataclasses
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from pose_lifter.messages import convert as m
from pose_lifter.offline import bags

from .conftest import REPO, GraphClient

pytestmark = pytest.mark.ros

BAG = REPO / "bags" / "walk_clean.mcap"
SOURCE = REPO / "ros2_ws" / "src" / "pose_lifter"


def play(graph: GraphClient, args: list[str], env: dict[str, str]) -> tuple[str, str]:
    """Run ``pose-lifter play ARGS`` while the graph client spins; its stdout and stderr.

    The command is the working tree's (the venv's editable ``pose-lifter``), not the colcon
    install's copy that the sourced workspace puts first on the path (the message packages
    still come from the install)."""
    env = {**env, "PYTHONPATH": os.pathsep.join([str(SOURCE), env.get("PYTHONPATH", "")])}
    proc = subprocess.Popen([sys.executable, "-m", "pose_lifter.cli", "play", *args], env=env, cwd=REPO,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    deadline = time.monotonic() + 180
    while proc.poll() is None and time.monotonic() < deadline:
        graph.executor.spin_once(timeout_sec=0.05)
    out, err = proc.communicate(timeout=30)
    assert proc.returncode == 0, out + err
    return out, err


def test_play_feeds_the_lifter(graph: GraphClient, start_lifter: Any, lifter_env: dict[str, str]) -> None:
    # a reliable input with a deep queue (the override config/lifter.yaml documents) and as many
    # frames waiting for the lift: the first frame takes ~0.3 s (cold solve + first publish), and
    # the default sensor-data input (best effort, depth 5) and one waiting frame would drop the
    # frames that arrive meanwhile, as with `ros2 bag play`
    lifter = start_lifter(params={
        "stats_period": 1.0, "qos_overrides./keypoints_2d.subscription.reliability": "reliable",
        "qos_overrides./keypoints_2d.subscription.depth": 100, "max_waiting_frames": 100})
    graph.wait_for_lifter(lifter)
    stamps = [x.stamp_ns for x in bags.read_messages(BAG, ["/keypoints_2d"])]
    # every topic of the bag, no --wait: by default play waits for a subscriber on the topics a
    # lifter reads only (not on the ground truth, which nothing here reads), so the first frame
    # is not lost and the ground truth does not hold the start back
    out, err = play(graph, [str(BAG), "--rate", "1"], lifter_env)
    assert "play: 360 messages on 3 topics" in out  # 120 keypoint, camera_info and ground-truth messages
    assert err == "", err  # the wait did not give up
    end = time.monotonic() + 10
    while len(graph.skeletons) < len(stamps) and time.monotonic() < end:
        graph.executor.spin_once(timeout_sec=0.05)
    answered = [m.stamp_to_ns(a.header.stamp) for a in graph.skeletons]
    missing = sorted(set(stamps) - set(answered))
    assert answered == stamps, (
        f"{len(answered)} answers, missing {[stamps.index(s) for s in missing]}; lifter log:\n{lifter.log()}")
    assert all(len(a.skeletons) == 1 and a.skeletons[0].track_id == 0 for a in graph.skeletons)


def test_play_says_when_no_lifter_listens(graph: GraphClient, lifter_env: dict[str, str],
                                          tmp_path: Path) -> None:
    """Keypoints on a topic nobody reads: the bounded wait gives up with one line on stderr and plays."""
    renamed = tmp_path / "renamed.mcap"
    with bags.BagWriter(renamed, compress=False) as w:
        for raw in bags.read_raw(BAG, ["/keypoints_2d"]):
            w.write_raw(dataclasses.replace(raw, topic="/nobody/keypoints"))
    out, err = play(graph, [str(renamed), "--rate", "50", "--wait", "0.5"], lifter_env)
    assert err == "play: no subscriber after 0.5 s on ['/nobody/keypoints']; playing anyway " \
                  "(their first messages may be lost)\n"
    assert "play: 120 messages on 1 topics" in out
