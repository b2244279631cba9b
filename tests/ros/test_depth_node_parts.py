"""The lifter node's depth bookkeeping without ROS: the counts of frames with and without depth in
the stats line and /diagnostics, and the level a silent depth topic gives."""

from __future__ import annotations

from pose_lifter.ros.diagnostics import OK, WARN, status_level, values
from pose_lifter.ros.stats import FrameCounter


def test_depth_counts_in_the_stats_line_and_diagnostics() -> None:
    counter = FrameCounter()
    counter.open("report")
    assert counter.take("report").line() == ""
    for kind in (None, None, "depth: no partner", "depth: unsupported encoding", "depth: no partner"):
        counter.depth(kind)
    window = counter.take("report")
    assert window.with_depth == 2
    assert window.without_depth == {"depth: no partner": 2, "depth: unsupported encoding": 1}
    line = window.line()
    assert "2 frames with depth" in line and "depth: no partner 2" in line
    pairs = dict(values(window))
    assert pairs["frames with depth"] == "2"
    assert pairs["frames without depth: depth: unsupported encoding"] == "1"
    # a window without depth counts has no depth keys (a node without depth_topic)
    assert "frames with depth" not in dict(values(counter.take("report")))


def test_a_silent_depth_topic_warns() -> None:
    assert status_level(10, 10, 0) == (OK, "lifting")
    silent = "no depth image on /d for 1.5 s"
    assert status_level(10, 10, 0, 0, silent) == (WARN, silent)
    assert status_level(10, 10, 2, 0, silent) == (WARN, f"2 inputs skipped; {silent}")
    assert status_level(3, 0, 3, 0, silent)[0] == 2  # an ERROR stays one
