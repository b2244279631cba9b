"""Speed of the live node (issue 5): the installed ``lifter`` fed a committed bag at camera rate.

Usage (``make bench-node`` sources the workspace first)::

    source ros2_ws/install/setup.bash
    .venv/bin/python tools/bench_node.py [--bag bags/five_people.mcap] [--rate 30] [--loops 3]
        [--checkout ../before]

Starts ``ros2_ws/install/pose_lifter/lib/pose_lifter/lifter`` (what ``ros2 run`` executes) as a
separate process on a private ROS domain, publishes the bag's ``/keypoints_2d`` (and
``/camera_info``, and its depth image when the bag has one: the node then reads it as
``depth_topic``; ``--no-depth`` leaves it out) at ``--rate`` Hz in real time -- not in lock
step: a frame the node cannot take in time is dropped by its sensor-data (keep-last)
subscription, as behind a real camera -- and collects ``skeletons_3d``. Each loop over the bag is
shifted by the bag's duration so the stamps keep increasing (tracks stay warm across loops; the
people jump back to their first pose). Prints:

* frames answered / published;
* per person-frame solve time inside the node (``Skeleton3D.solve_time``), warm and cold, median
  / p95 / max;
* per frame, callback in -> answer published, from the node's own statistics log lines;
* per frame, publish -> answer received in this process (adds transport and queueing);
* the node's peak and current resident memory (``/proc/<pid>/status``).
"""

from __future__ import annotations

import argparse
import gc
import os
import random
import re
import shlex
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace
from typing import Any, NamedTuple

import numpy as np

REPO = Path(__file__).resolve().parents[1]
LIFTER = REPO / "ros2_ws" / "install" / "pose_lifter" / "lib" / "pose_lifter" / "lifter"


#: How long before its keypoints a frame's depth image is published, seconds: the detector's
#: latency (the camera publishes the depth with the colour image the detector then reads).
DEPTH_LEAD_S = 0.015
#: The frames of a loop's start that :func:`_report` counts apart.
LOOP_START_FRAMES = 3


def _percentiles(values_ms: list[float]) -> str:
    if not values_ms:
        return "n/a"
    a = np.asarray(values_ms)
    return (f"median {np.median(a):7.2f} ms  p95 {np.percentile(a, 95):7.2f} ms  max {a.max():7.2f} ms"
            f"  (n={a.size})")


def _memory_kb(pid: int) -> dict[str, int]:
    out: dict[str, int] = {}
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        key, _, value = line.partition(":")
        if key in ("VmHWM", "VmRSS"):
            out[key] = int(value.split()[0])
    return out


def _parser() -> argparse.ArgumentParser:
    """The command line (the module docstring)."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bag", default=str(REPO / "bags" / "five_people.mcap"))
    ap.add_argument("--rate", type=float, default=30.0, help="publishing rate, Hz")
    ap.add_argument("--loops", type=int, default=3, help="passes over the bag")
    ap.add_argument("--no-depth", action="store_true",
                    help="do not publish the bag's depth images (the node lifts from the 2D alone)")
    ap.add_argument("--param", action="append", default=[], metavar="NAME:=VALUE",
                    help="extra lifter parameter (repeatable), e.g. n_starts:=10")
    ap.add_argument("--checkout", type=Path, default=REPO,
                    help="the checkout whose installed lifter runs (its ros2_ws/install, with the "
                         "environment its setup.bash gives): another commit measured by this same "
                         "client, for figures side by side (default: this one)")
    return ap


def _ros() -> SimpleNamespace:
    """rclpy and the message classes the benchmark uses; exits with how to get them when missing."""
    try:
        import rclpy
        from pose_lifter_msgs.msg import Skeleton2DArray, Skeleton3DArray
        from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data
        from rclpy.serialization import deserialize_message
        from sensor_msgs.msg import CameraInfo, Image
    except ImportError as err:
        sys.exit(f"{err}: run `make ros` and `source ros2_ws/install/setup.bash` (make bench-node does)")
    return SimpleNamespace(rclpy=rclpy, Skeleton2DArray=Skeleton2DArray, Skeleton3DArray=Skeleton3DArray,
                           QoSProfile=QoSProfile, ReliabilityPolicy=ReliabilityPolicy,
                           qos_profile_sensor_data=qos_profile_sensor_data,
                           deserialize_message=deserialize_message, CameraInfo=CameraInfo, Image=Image)


class _Bag(NamedTuple):
    """The bag's keypoint frames as rclpy messages, its first camera info (if any), each frame's
    depth image of the same stamp (None: none, or not wanted), the most people in a frame, and the
    stamp shift of one loop over the bag (ns)."""

    kp_msgs: list[Any]
    info_msg: Any
    depth_msgs: list[Any]
    n_people: int
    span_ns: int


def _load_bag(path: str, rate: float, ros: SimpleNamespace, depth: bool) -> _Bag:
    """The ``/keypoints_2d``, ``/camera_info`` and (``depth``) depth image messages of the bag at
    ``path``, replayed at ``rate`` Hz."""
    from pose_lifter.messages.names import TOPIC_CAMERA_INFO, TOPIC_DEPTH, TOPIC_KEYPOINTS
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import read_messages

    store = pose_lifter_typestore()
    topics = (TOPIC_KEYPOINTS, TOPIC_CAMERA_INFO) + ((TOPIC_DEPTH,) if depth else ())
    recorded = [x for x in read_messages(path) if x.topic in topics]
    frames = [x for x in recorded if x.topic == TOPIC_KEYPOINTS]
    infos = [x for x in recorded if x.topic == TOPIC_CAMERA_INFO]
    span_ns = frames[-1].stamp_ns - frames[0].stamp_ns + round(1e9 / rate)

    def rclpy_msg(x: Any, cls: Any) -> Any:
        return ros.deserialize_message(bytes(store.serialize_cdr(x.msg, x.msgtype)), cls)

    kp_msgs = [rclpy_msg(x, ros.Skeleton2DArray) for x in frames]
    info_msg = rclpy_msg(infos[0], ros.CameraInfo) if infos else None
    images = {x.stamp_ns: x for x in recorded if x.topic == TOPIC_DEPTH}
    depth_msgs = [rclpy_msg(images[x.stamp_ns], ros.Image) if x.stamp_ns in images else None for x in frames]
    n_people = max(len(m.skeletons) for m in kp_msgs)
    return _Bag(kp_msgs, info_msg, depth_msgs, n_people, span_ns)


def _checkout_env(checkout: Path) -> dict[str, str]:
    """The environment ``checkout``'s lifter runs in: this one's for this checkout, else what
    sourcing that checkout's ``ros2_ws/install/setup.bash`` gives (its packages, its venv's
    paths)."""
    if checkout.resolve() == REPO:
        return dict(os.environ)
    setup = checkout / "ros2_ws" / "install" / "setup.bash"
    if not setup.is_file():
        sys.exit(f"{setup} is missing: run `make ros` in {checkout}")
    out = subprocess.run(["bash", "-c", f"source {shlex.quote(str(setup))} && env -0"], check=True,
                         capture_output=True, env=dict(os.environ)).stdout
    return dict(line.split("=", 1) for line in out.decode().split("\0") if "=" in line)


def _start_lifter(params: list[str], checkout: Path) -> tuple[subprocess.Popen[bytes], Any, int]:
    """Start ``checkout``'s installed lifter (extra ``params``) on a random private ROS domain,
    which this process joins too; returns the process, its log file (stdout and stderr) and the
    domain."""
    domain = random.SystemRandom().randint(1, 101)
    env = {**_checkout_env(checkout), "ROS_DOMAIN_ID": str(domain),
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST", "PYTHONUNBUFFERED": "1",
           "RCUTILS_COLORIZED_OUTPUT": "0"}
    env.pop("ROS_LOCALHOST_ONLY", None)
    os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
    log = tempfile.NamedTemporaryFile("w+b", suffix=".log", delete=False)
    lifter = checkout / LIFTER.relative_to(REPO)
    if not lifter.is_file():
        sys.exit(f"{lifter} is missing: run `make ros` in {checkout}")
    cmd = [str(lifter), "--ros-args", "-p", "stats_period:=1.0"]
    for p in params:
        cmd += ["-p", p]
    proc = subprocess.Popen(cmd, env=env, stdout=log, stderr=subprocess.STDOUT)
    return proc, log, domain


def _handshake(ros: SimpleNamespace, node: Any, pub: Any, answers: dict[int, tuple[float, Any]],
               proc: subprocess.Popen[bytes], log: Any, types: Any) -> None:
    """Discovery, then empty frames until one is answered (the node's reader matched); the answers
    are then cleared."""
    from pose_lifter.messages.convert import make_header

    deadline = time.monotonic() + 120.0
    probe = 1
    while not answers:
        if time.monotonic() > deadline or proc.poll() is not None:
            sys.exit(f"the lifter did not answer; log:\n{Path(log.name).read_text()}")
        if pub.get_subscription_count() > 0:
            pub.publish(ros.Skeleton2DArray(header=make_header(probe, "handshake", types), layout="coco17"))
            probe += 1
        ros.rclpy.spin_once(node, timeout_sec=0.2)
    answers.clear()


def _replay(ros: SimpleNamespace, node: Any, pub: Any, pub_info: Any, pub_depth: Any, bag: _Bag, rate: float,
            loops: int, types: Any) -> dict[int, float]:
    """Publish the bag's frames (each after the camera info, and :data:`DEPTH_LEAD_S` after its
    depth image) at ``rate`` Hz in real time, ``loops``
    times, each loop's stamps shifted by the bag's span; returns each stamp's publishing time
    (``time.perf_counter``)."""
    from pose_lifter.messages.convert import ns_to_stamp, stamp_to_ns

    period = 1.0 / rate
    sent: dict[int, float] = {}

    def wait(until: float) -> None:
        while (now := time.perf_counter()) < until:
            ros.rclpy.spin_once(node, timeout_sec=max(0.0, min(until - now, 0.005)))

    start = time.perf_counter()
    i = 0
    for loop in range(loops):
        for msg, image in zip(bag.kp_msgs, bag.depth_msgs, strict=True):
            target = start + i * period
            stamp = stamp_to_ns(msg.header.stamp) + loop * bag.span_ns
            msg.header.stamp = ns_to_stamp(stamp, types)
            if image is not None:  # the camera's image, a detector's latency before its keypoints
                wait(target - DEPTH_LEAD_S)
                image.header.stamp = msg.header.stamp
                pub_depth.publish(image)
            wait(target)
            if bag.info_msg is not None:
                bag.info_msg.header.stamp = msg.header.stamp
                pub_info.publish(bag.info_msg)
            pub.publish(msg)
            sent[stamp] = time.perf_counter()
            msg.header.stamp = ns_to_stamp(stamp - loop * bag.span_ns, types)
            i += 1
    return sent


def _stop(proc: subprocess.Popen[bytes], node: Any, ros: SimpleNamespace) -> None:
    """SIGINT to the lifter (killed if it has not ended in 10 s); this process leaves ROS."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGINT)
        try:
            proc.wait(10)
        except subprocess.TimeoutExpired:
            proc.kill()
    node.destroy_node()
    ros.rclpy.try_shutdown()


def _report(args: argparse.Namespace, bag: _Bag, answers: dict[int, tuple[float, Any]],
            sent: dict[int, float], log: Any, mem: dict[str, int]) -> None:
    """Print the frames answered, the solve times, the latencies and the node's memory."""
    text = Path(log.name).read_text(errors="replace")
    # the bag's frames only (a lagged node, output_lag, answers late handshake probes too)
    answers = {k: v for k, v in answers.items() if k in sent}
    warm = [s.solve_time * 1e3 for _, a in answers.values() for s in a.skeletons if s.warm_started]
    cold = [s.solve_time * 1e3 for _, a in answers.values() for s in a.skeletons if not s.warm_started]
    e2e = [(t - sent[k]) * 1e3 for k, (t, _) in answers.items()]
    stats = [line for line in text.splitlines() if "frames (" in line]
    cb = [float(v) for line in stats for v in re.findall(r"latency median ([\d.]+) ms", line)]
    n_depth = sum(m is not None for m in bag.depth_msgs)
    print(f"bag {Path(args.bag).name}: {len(bag.kp_msgs)} frames x {args.loops} loops at {args.rate:g} Hz, "
          f"{bag.n_people} people per frame, {n_depth} with a depth image; "
          f"lifter params {args.param or 'defaults'}; "
          f"the lifter of {args.checkout}")
    print(f"frames answered: {len(answers)} of {len(sent)} published "
          f"({len(warm) + len(cold)} person-frames lifted)")
    # where the unanswered frames fall: a loop's first frames follow the people's jump back to
    # where the bag starts, a jump no camera shows (those frames take longer to lift)
    places = [i % len(bag.kp_msgs) for i, k in enumerate(sent) if k not in answers]
    if places:
        first = sum(p < LOOP_START_FRAMES for p in places)
        print(f"frames not answered: {first} within the first {LOOP_START_FRAMES} frames of a loop, "
              f"{len(places) - first} elsewhere")
    print(f"solve per person-frame, warm:  {_percentiles(warm)}")
    print(f"solve per person-frame, cold:  {_percentiles(cold)}")
    print(f"publish -> answer received:    {_percentiles(e2e)}")
    print(f"node stats lines (callback in -> published), per-second medians: "
          f"{', '.join(f'{v:.0f}' for v in cb) or 'n/a'} ms")
    for line in stats[-2:]:
        print("  " + line.split("]: ", 1)[-1])
    print(f"node memory: peak RSS {mem.get('VmHWM', 0) / 1024:.0f} MB, RSS at the end "
          f"{mem.get('VmRSS', 0) / 1024:.0f} MB")


def main() -> None:
    args = _parser().parse_args()
    ros = _ros()
    from pose_lifter.messages.convert import rclpy_types, stamp_to_ns

    types = rclpy_types()
    bag = _load_bag(args.bag, args.rate, ros, not args.no_depth)
    with_depth = any(m is not None for m in bag.depth_msgs)
    params = args.param + (["depth_topic:=depth"] if with_depth else [])
    proc, log, domain = _start_lifter(params, args.checkout)

    ros.rclpy.init(domain_id=domain)
    node = ros.rclpy.create_node("bench_node_client")
    answers: dict[int, tuple[float, Any]] = {}

    def on_answer(msg: Any) -> None:
        answers[stamp_to_ns(msg.header.stamp)] = (time.perf_counter(), msg)

    pub = node.create_publisher(ros.Skeleton2DArray, "keypoints_2d", ros.qos_profile_sensor_data)
    pub_info = node.create_publisher(ros.CameraInfo, "camera_info", ros.qos_profile_sensor_data)
    pub_depth = node.create_publisher(ros.Image, "depth",
                                      ros.QoSProfile(depth=2, reliability=ros.ReliabilityPolicy.RELIABLE))
    node.create_subscription(ros.Skeleton3DArray, "skeletons_3d", on_answer,
                             ros.QoSProfile(depth=100, reliability=ros.ReliabilityPolicy.RELIABLE))
    try:
        _handshake(ros, node, pub, answers, proc, log, types)
        # this process keeps every answer: a full collection walking them paused the publisher
        # ~100 ms now and then, and the frames it then sent in a burst were dropped by the node
        # (as it should: the newest frame wins). The collector stays off while it publishes.
        gc.freeze()
        gc.disable()
        try:
            sent = _replay(ros, node, pub, pub_info, pub_depth, bag, args.rate, args.loops, types)
        finally:
            gc.enable()
        # the last frames in flight
        end = time.perf_counter() + 30.0
        last = max(sent)
        while last not in answers and time.perf_counter() < end:
            ros.rclpy.spin_once(node, timeout_sec=0.05)
        time.sleep(1.5)  # one more statistics line
        ros.rclpy.spin_once(node, timeout_sec=0.05)
        mem = _memory_kb(proc.pid)
    finally:
        _stop(proc, node, ros)
    _report(args, bag, answers, sent, log, mem)


if __name__ == "__main__":
    main()
