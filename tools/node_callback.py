"""CPU cost of the lifter node's frame callback, in process, without transport or queueing.

    source ros2_ws/install/setup.bash
    .venv/bin/python tools/node_callback.py [--bag out/crowd30.mcap] [--passes 4]
        [--profile N [--sort tottime]] [--param NAME:=VALUE ...]

Builds :class:`pose_lifter.ros.node.LifterNode` in this process, gives it the bag's first
``camera_info`` and lifts every ``/keypoints_2d`` message as its callback does
(``lift_frame``), pass after pass
(each pass's stamps shifted by the bag's duration, so the tracks stay warm). The first two passes
warm the tracks up; the others are timed: per frame, from its serialised bytes (what the
middleware hands the node) to the frame's answers published (reading the frame, the solve, the
messages, the markers and the REP-155 outputs; a node without ``read_frame``, which subscribes to
rclpy messages, is timed with rclpy's deserialisation of the same bytes). With ``--profile N``,
prints the N entries of the largest cumulative time (``--sort tottime``: time in the function
itself) of a cProfile of the timed passes too.
Run it from two checkouts (``PYTHONPATH=<checkout>/ros2_ws/src/pose_lifter``) to compare them.
"""

from __future__ import annotations

import argparse
import cProfile
import pstats
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bag", default=str(REPO / "bags" / "five_people.mcap"))
    ap.add_argument("--passes", type=int, default=4, help="passes over the bag, 2 of them warm-up")
    ap.add_argument("--profile", type=int, default=0, metavar="N", help="print a profile's top N")
    ap.add_argument("--sort", choices=("cumtime", "tottime"), default="cumtime",
                    help="the profile's order: time with callees, or in the function itself")
    ap.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE")
    args = ap.parse_args()
    if args.passes < 3:
        ap.error("--passes must be at least 3: the first two warm the tracks up")
    try:
        import rclpy
        from pose_lifter_msgs.msg import Skeleton2DArray
        from rclpy.parameter import Parameter
        from rclpy.serialization import deserialize_message, serialize_message
        from sensor_msgs.msg import CameraInfo
    except ImportError as err:
        sys.exit(f"{err}: run `make ros` and `source ros2_ws/install/setup.bash`")
    from pose_lifter.messages.convert import ns_to_stamp, stamp_to_ns
    from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_KEYPOINTS
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import read_messages
    from pose_lifter.ros.node import LifterNode

    store = pose_lifter_typestore()
    recorded = [x for x in read_messages(args.bag) if x.topic in (TOPIC_KEYPOINTS, TOPIC_CAMERA_INFO)]

    def rclpy_msg(x: Any, cls: Any) -> Any:
        return deserialize_message(bytes(store.serialize_cdr(x.msg, x.msgtype)), cls)

    frames = [rclpy_msg(x, Skeleton2DArray) for x in recorded if x.topic == TOPIC_KEYPOINTS]
    infos = [rclpy_msg(x, CameraInfo) for x in recorded if x.topic == TOPIC_CAMERA_INFO]
    stamps = [stamp_to_ns(f.header.stamp) for f in frames]
    span = stamps[-1] - stamps[0] + (stamps[-1] - stamps[0]) // max(len(stamps) - 1, 1)
    overrides = []
    for p in args.param:
        name, _, value = p.partition(":=")
        overrides.append(Parameter(name, value=_parse(value)))
    rclpy.init()
    node = LifterNode(parameter_overrides=overrides)
    if infos:
        node.on_camera_info(infos[0])

    reads_bytes = hasattr(node, "read_frame")

    def one_pass(k: int) -> list[float]:
        times = []
        for f, s in zip(frames, stamps, strict=True):
            f.header.stamp = ns_to_stamp(s + k * span, node._types)
            data = serialize_message(f)
            t0 = time.perf_counter()
            node.lift_frame(data if reads_bytes else deserialize_message(data, Skeleton2DArray),
                            time.perf_counter())
            times.append(time.perf_counter() - t0)
        return times

    one_pass(0)
    one_pass(1)
    profiler = cProfile.Profile() if args.profile else None
    if profiler is not None:
        profiler.enable()
    times = [t for k in range(2, args.passes) for t in one_pass(k)]
    if profiler is not None:
        profiler.disable()
        pstats.Stats(profiler).sort_stats(args.sort).print_stats(args.profile)
    people = max(len(f.skeletons) for f in frames)
    ms = 1e3 * np.asarray(times)
    print(f"{Path(args.bag).name}: {people} people, {ms.size} frames timed: callback median "
          f"{np.median(ms):.1f} ms, p95 {np.percentile(ms, 95):.1f} ms, per person-frame "
          f"{np.median(ms) / people:.2f} ms{' (profiled)' if profiler else ''}")
    node.destroy_node()
    rclpy.shutdown()


def _parse(value: str) -> Any:
    """A parameter value as the command line would type it: bool, int, float or string."""
    if value in ("true", "false"):
        return value == "true"
    for cast in (int, float):
        try:
            return cast(value)
        except ValueError:
            pass
    return value


if __name__ == "__main__":
    main()
