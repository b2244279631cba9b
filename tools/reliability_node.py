"""Long runs against the installed node (issue 10): ``fuzz`` and ``soak``.

Usage (``make fuzz`` / ``make soak`` source the workspace first)::

    .venv/bin/python tools/reliability_node.py fuzz [--messages 10000]
    .venv/bin/python tools/reliability_node.py soak [--seconds 600] [--rate 30]

fuzz
    Publishes malformed ``keypoints_2d`` / ``camera_info`` messages of many kinds into the
    installed ``lifter`` (a separate process on a private ROS domain), a good frame after every
    three bad ones; each good frame must be answered (lock step, matched by stamp), with the
    skeletons of that frame.
soak
    Replays ``bags/five_people.mcap`` (5 people) at ``--rate`` Hz in real time, input QoS
    overridden to reliable (``--depth``, default 20) on both sides; every frame must be answered. The node's
    RSS is sampled every 10 s.

Both print a table and exit 1 on any lost good frame, any non-finite value published, the
node's death, or RSS growth above ``--max-rss-growth`` MB (from the first sample after warm-up).
"""

from __future__ import annotations

import argparse
import math
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

REPO = Path(__file__).resolve().parents[1]
LIFTER = REPO / "ros2_ws" / "install" / "pose_lifter" / "lib" / "pose_lifter" / "lifter"
sys.path.insert(0, str(REPO / "tools"))
from bench_node import _memory_kb  # noqa: E402

RELIABLE_INPUT_YAML = """pose_lifter:
  ros__parameters:
    qos_overrides:
      /keypoints_2d:
        subscription:
          reliability: reliable
          depth: {depth}
"""


def _rss_mb(pid: int) -> float:
    return _memory_kb(pid).get("VmRSS", 0) / 1024


def _finite(msg: Any) -> bool:
    vals: list[float] = []
    for s in getattr(msg, "skeletons", []):
        vals += [c for p in s.joints for c in (p.x, p.y, p.z)]
        cam = s.camera
        vals += [*cam.projection, *cam.translation, cam.scale, s.objective, s.reprojection_error,
                 s.solve_time, cam.orientation.x, cam.orientation.y, cam.orientation.z, cam.orientation.w]
    for mk in getattr(msg, "markers", []):
        vals += [c for p in mk.points for c in (p.x, p.y, p.z)]
    return all(math.isfinite(v) for v in vals)


class Harness:
    """The lifter process and this process's client node."""

    def __init__(self, params: list[str], reliable_input: bool, depth: int = 20) -> None:
        import rclpy
        from pose_lifter.messages.convert import rclpy_types
        from rclpy.qos import QoSProfile, ReliabilityPolicy, qos_profile_sensor_data

        self.t = rclpy_types()
        domain = random.SystemRandom().randint(1, 101)
        env = {**os.environ, "ROS_DOMAIN_ID": str(domain), "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
               "PYTHONUNBUFFERED": "1", "RCUTILS_COLORIZED_OUTPUT": "0"}
        env.pop("ROS_LOCALHOST_ONLY", None)
        os.environ.update({k: env[k] for k in ("ROS_DOMAIN_ID", "ROS_AUTOMATIC_DISCOVERY_RANGE")})
        self.log = tempfile.NamedTemporaryFile("w+b", suffix=".log", delete=False)
        cmd = [str(LIFTER), "--ros-args", "-p", "stats_period:=10.0"]
        if reliable_input:
            qos = Path(tempfile.mkdtemp()) / "qos.yaml"
            qos.write_text(RELIABLE_INPUT_YAML.format(depth=depth))
            cmd += ["--params-file", str(qos)]
        for p in params:
            cmd += ["-p", p]
        self.proc = subprocess.Popen(cmd, env=env, stdout=self.log, stderr=subprocess.STDOUT)
        rclpy.init(domain_id=domain)
        self.node = rclpy.create_node("reliability_client")
        self.answers: dict[int, Any] = {}
        self.nonfinite = 0
        self.n_answers = 0
        self.n_markers = 0
        out_qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
        in_qos = QoSProfile(depth=depth, reliability=ReliabilityPolicy.RELIABLE) if reliable_input \
            else qos_profile_sensor_data
        self.pub = self.node.create_publisher(self.t.Skeleton2DArray, "keypoints_2d", in_qos)
        self.pub_info = self.node.create_publisher(self.t.CameraInfo, "camera_info", qos_profile_sensor_data)
        self.node.create_subscription(self.t.Skeleton3DArray, "skeletons_3d", self._on_answer, out_qos)
        self.node.create_subscription(self.t.MarkerArray, "skeleton_markers", self._on_markers, out_qos)

    def _on_answer(self, msg: Any) -> None:
        from pose_lifter.messages.convert import stamp_to_ns

        self.n_answers += 1
        if not _finite(msg):
            self.nonfinite += 1
        self.answers[stamp_to_ns(msg.header.stamp)] = msg

    def _on_markers(self, msg: Any) -> None:
        self.n_markers += 1
        if not _finite(msg):
            self.nonfinite += 1

    def spin(self, seconds: float) -> None:
        import rclpy

        end = time.monotonic() + seconds
        while True:
            rclpy.spin_once(self.node, timeout_sec=max(0.0, min(0.01, end - time.monotonic())))
            if time.monotonic() >= end:
                return

    def alive(self) -> bool:
        return self.proc.poll() is None

    def handshake(self) -> None:
        from pose_lifter.messages.convert import make_header

        deadline = time.monotonic() + 120.0
        probe = 1
        while not self.answers:
            if time.monotonic() > deadline or not self.alive():
                sys.exit(f"the lifter did not answer; log:\n{Path(self.log.name).read_text()}")
            if self.pub.get_subscription_count() > 0:
                self.pub.publish(self.t.Skeleton2DArray(header=make_header(probe, "handshake", self.t),
                                                        layout="coco17"))
                probe += 1
            self.spin(0.2)
        self.spin(0.5)
        self.answers.clear()

    def wait_answer(self, stamp: int, timeout: float) -> Any | None:
        end = time.monotonic() + timeout
        while stamp not in self.answers and time.monotonic() < end and self.alive():
            self.spin(0.005)
        return self.answers.get(stamp)

    def close(self) -> str:
        import rclpy

        if self.alive():
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
        self.node.destroy_node()
        rclpy.try_shutdown()
        return Path(self.log.name).read_text(errors="replace")


# --------------------------------------------------------------------------- fuzz

def _kinds(t: Any) -> dict[str, Callable[[int], Any]]:
    """Malformed messages by kind: each builds one from a stamp (ns)."""
    from pose_lifter.messages.convert import arrays_to_skeleton2d, camera_info, make_header
    from pose_lifter.messages.layouts import get_layout

    rng = np.random.default_rng(0)
    idx = list(get_layout("coco17").model_indices)
    base = np.zeros((17, 2))
    base[idx] = np.array([[320 + 30 * (j % 3), 100 + 25 * j] for j in range(12)], dtype=float)
    conf = np.zeros(17)
    conf[idx] = 0.9

    def arr(stamp: int, skels: list[tuple[int, np.ndarray, np.ndarray]], layout: str = "coco17",
            frame_id: str = "fuzz") -> Any:
        return t.Skeleton2DArray(header=make_header(stamp, frame_id, t), layout=layout,
                                 skeletons=[arrays_to_skeleton2d(k, c, i, t) for i, k, c in skels])

    def bad(**kw: Any) -> Callable[[int], Any]:
        def build(stamp: int) -> Any:
            kp = base.copy() + rng.normal(0, 2, base.shape)
            c = conf.copy()
            if "joint" in kw:
                kp[idx[3]] = kw["joint"]
            if "conf" in kw:
                c = np.where(conf > 0, kw["conf"], 0.0)
            if "scale" in kw:
                kp = kp * kw["scale"]
            n = kw.get("n_kp")
            if n is not None:
                kp, c = np.resize(kp, (n, 2)), np.resize(c, n)
            skels = [(kw.get("track", 0), kp, c)] * kw.get("copies", 1)
            return arr(stamp, skels, layout=kw.get("layout", "coco17"), frame_id=kw.get("frame", "fuzz"))
        return build

    def info(fx: float, w: int = 640) -> Callable[[int], Any]:
        return lambda stamp: camera_info(make_header(stamp, "fuzz", t), w, 480, fx, fx, 320.0, 240.0, t)

    return {
        "empty array": lambda s: arr(s, []),
        "unknown layout": bad(layout="coco18x"),
        "empty layout": bad(layout=""),
        "64 kB layout": bad(layout="L" * 65_536),
        "1 MB frame_id": bad(frame="f" * 1_000_000),
        "10 keypoints": bad(n_kp=10),
        "0 keypoints": bad(n_kp=0),
        "5000 keypoints": bad(n_kp=5000),
        "NaN keypoint": bad(joint=np.nan),
        "inf keypoint": bad(joint=np.inf),
        "-inf keypoint": bad(joint=-np.inf),
        "NaN confidence": bad(conf=np.nan),
        "negative confidence": bad(conf=-1.0),
        "confidence 3.4e38": bad(conf=3.4e38),
        "all-zero confidence": bad(conf=0.0),
        "coordinates 1e9": bad(scale=1e9),
        "denormal coordinates": bad(scale=1e-310),
        "one pixel": bad(scale=0.0),
        "duplicate track ids": bad(copies=3, track=7),
        "track id 2^63-1": bad(track=2**63 - 1),
        "track id -5": bad(track=-5),
        "200 skeletons": bad(copies=200, track=-1),
        "stamp 0": lambda s: bad()(0),
        "stamp out of order": lambda s: bad(track=0)(s - 500_000_000),
        "camera_info fx=0": info(0.0),
        "camera_info fx=NaN": info(float("nan")),
        "camera_info width 0": info(500.0, w=0),
        "camera_info fx=1e300": info(1e300),
    }


def fuzz(args: argparse.Namespace) -> int:
    from pose_lifter.messages.convert import arrays_to_skeleton2d, make_header
    from pose_lifter.messages.layouts import get_layout

    h = Harness([], reliable_input=False)
    t = h.t
    kinds = _kinds(t)
    names = list(kinds)
    sent: Counter[str] = Counter()
    good_sent = good_answered = good_wrong = 0
    idx = list(get_layout("coco17").model_indices)
    kp = np.zeros((17, 2))
    kp[idx] = np.array([[320 + 30 * (j % 3), 100 + 25 * j] for j in range(12)], dtype=float)
    c = np.zeros(17)
    c[idx] = 0.9
    rss: list[float] = []
    started = time.monotonic()
    try:
        h.handshake()
        rss.append(_rss_mb(h.proc.pid))
        stamp = 10**12
        i = 0
        while sum(sent.values()) < args.messages and h.alive():
            for _ in range(3):
                name = names[i % len(names)]
                i += 1
                stamp += 1_000_000
                msg = kinds[name](stamp)
                (h.pub_info if name.startswith("camera_info") else h.pub).publish(msg)
                sent[name] += 1
            stamp += 1_000_000
            good = t.Skeleton2DArray(header=make_header(stamp, "good", t), layout="coco17",
                                     skeletons=[arrays_to_skeleton2d(kp, c, 1, t)])
            h.pub.publish(good)
            good_sent += 1
            answer = h.wait_answer(stamp, 30.0)
            if answer is not None:
                good_answered += 1
                good_wrong += len(answer.skeletons) != 1 or answer.header.frame_id != "good"
            if good_sent % 200 == 0:
                rss.append(_rss_mb(h.proc.pid))
        h.spin(1.0)
        alive = h.alive()
        if alive:
            rss.append(_rss_mb(h.proc.pid))
    finally:
        log = h.close()
    elapsed = time.monotonic() - started
    print(f"fuzz: {sum(sent.values())} malformed messages of {len(sent)} kinds in {elapsed:.0f} s, "
          f"a good frame after every 3 (machine load average at the end {os.getloadavg()[0]:.2f})")
    print(f"{'kind':28s} {'sent':>6s}")
    for name in names:
        print(f"{name:28s} {sent[name]:6d}")
    # from the sample after the first 200 good frames (every kind sent ~20 times: DDS buffers for
    # the large ones are allocated) to the end
    base = rss[1] if len(rss) > 2 else (rss[0] if rss else float("nan"))
    growth = rss[-1] - base if rss else float("nan")
    rows = [
        ("node alive at the end", "yes" if alive else "NO", alive),
        ("good frames answered", f"{good_answered}/{good_sent}", good_answered == good_sent),
        ("good answers wrong", str(good_wrong), good_wrong == 0),
        ("messages with non-finite values", str(h.nonfinite), h.nonfinite == 0),
        ("answers / marker arrays received", f"{h.n_answers} / {h.n_markers}", True),
        ("node RSS start / warm / end (MB)", f"{rss[0]:.1f} / {base:.1f} / {rss[-1]:.1f}" if rss else "n/a",
         len(rss) > 1 and growth <= args.max_rss_growth),
        ("tracebacks in the node log", str(log.count("Traceback")), "Traceback" not in log),
    ]
    return _verdict(rows)


def _verdict(rows: list[tuple[str, str, bool]]) -> int:
    print(f"{'check':34s} {'value':>22s}  result")
    for name, value, ok in rows:
        print(f"{name:34s} {value:>22s}  {'ok' if ok else 'FAIL'}")
    failed = [n for n, _, ok in rows if not ok]
    print("PASS" if not failed else f"FAIL: {', '.join(failed)}")
    return 0 if not failed else 1


# --------------------------------------------------------------------------- soak

def soak(args: argparse.Namespace) -> int:
    from pose_lifter.messages.convert import ns_to_stamp, stamp_to_ns
    from pose_lifter.messages.names import TOPIC_KEYPOINTS
    from pose_lifter.messages.typestore import pose_lifter_typestore
    from pose_lifter.offline.bags import read_messages
    from rclpy.serialization import deserialize_message

    store = pose_lifter_typestore()
    h = Harness([], reliable_input=True, depth=args.depth)
    frames = [deserialize_message(bytes(store.serialize_cdr(x.msg, x.msgtype)), h.t.Skeleton2DArray)
              for x in read_messages(args.bag) if x.topic == TOPIC_KEYPOINTS]
    n_people = max(len(f.skeletons) for f in frames)
    period = 1.0 / args.rate
    span = stamp_to_ns(frames[-1].header.stamp) - stamp_to_ns(frames[0].header.stamp) + round(period * 1e9)
    samples: list[tuple[float, float, int, int, float]] = []  # (t, RSS MB, published, answered, load)
    sent: list[int] = []
    try:
        h.handshake()
        start = time.perf_counter()
        next_sample = 0.0
        i = 0
        while (now := time.perf_counter() - start) < args.seconds and h.alive():
            if now >= next_sample:
                samples.append((now, _rss_mb(h.proc.pid), len(sent), len(h.answers), os.getloadavg()[0]))
                next_sample += args.sample_every
            target = i * period
            while (now := time.perf_counter() - start) < target:
                h.spin(min(target - now, 0.005))
            loop, k = divmod(i, len(frames))
            msg = frames[k]
            original = msg.header.stamp
            stamp = stamp_to_ns(original) + loop * span
            msg.header.stamp = ns_to_stamp(stamp, h.t)
            h.pub.publish(msg)
            msg.header.stamp = original
            sent.append(stamp)
            i += 1
        end = time.monotonic() + 30.0
        while sent and sent[-1] not in h.answers and time.monotonic() < end and h.alive():
            h.spin(0.05)
        alive = h.alive()
        if alive:
            samples.append((time.perf_counter() - start, _rss_mb(h.proc.pid), len(sent), len(h.answers),
                            os.getloadavg()[0]))
    finally:
        log = h.close()
    answered = sum(1 for s in sent if s in h.answers)
    lifted = sum(len(h.answers[s].skeletons) for s in sent if s in h.answers)
    print(f"soak: {args.seconds:g} s at {args.rate:g} Hz, {n_people} people per frame, reliable input "
          f"(depth {args.depth}); RSS every {args.sample_every:g} s")
    print(f"{'t (s)':>7s} {'RSS (MB)':>9s} {'published':>10s} {'answered':>9s} {'load 1 min':>10s}")
    for t_s, r, p, a, load in samples:
        print(f"{t_s:7.0f} {r:9.2f} {p:10d} {a:9d} {load:10.2f}")
    base = samples[1][1] if len(samples) > 2 else (samples[0][1] if samples else float("nan"))
    growth = samples[-1][1] - base if samples else float("nan")
    rows = [
        ("node alive at the end", "yes" if alive else "NO", alive),
        ("frames answered", f"{answered}/{len(sent)}", answered == len(sent) and len(sent) > 0),
        ("person-frames lifted", f"{lifted}/{len(sent) * n_people}", True),
        ("messages with non-finite values", str(h.nonfinite), h.nonfinite == 0),
        ("RSS growth after warm-up (MB)", f"{growth:+.2f}", growth <= args.max_rss_growth),
        ("tracebacks in the node log", str(log.count("Traceback")), "Traceback" not in log),
    ]
    return _verdict(rows)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fuzz")
    f.add_argument("--messages", type=int, default=10_000, help="malformed messages to publish")
    f.add_argument("--max-rss-growth", type=float, default=5.0, help="MB allowed after warm-up")
    s = sub.add_parser("soak")
    s.add_argument("--seconds", type=float, default=600.0)
    s.add_argument("--rate", type=float, default=30.0)
    s.add_argument("--bag", default=str(REPO / "bags" / "five_people.mcap"))
    s.add_argument("--sample-every", type=float, default=10.0, help="seconds between RSS samples")
    s.add_argument("--max-rss-growth", type=float, default=5.0, help="MB allowed")
    s.add_argument("--depth", type=int, default=20,
                   help="queue depth of the reliable input, both sides (the README's override: 20)")
    args = ap.parse_args()
    try:
        import rclpy  # noqa: F401
        from pose_lifter_msgs.msg import Skeleton2DArray  # noqa: F401
    except ImportError as err:
        sys.exit(f"{err}: run `make ros` and `source ros2_ws/install/setup.bash` (make fuzz / soak do)")
    return fuzz(args) if args.cmd == "fuzz" else soak(args)


if __name__ == "__main__":
    sys.exit(main())
