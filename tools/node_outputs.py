"""What the lifter node publishes for the committed bags, to prove that a refactor of the node
changes no published message.

Usage (ROS sourced: ``source ros2_ws/install/setup.bash``)::

    .venv/bin/python tools/node_outputs.py dump OUT.pkl [--src DIR] [--frames 40]
    .venv/bin/python tools/node_outputs.py compare A.pkl B.pkl

``dump`` runs :class:`pose_lifter.node.LifterNode` in-process (``--src``: the directory that holds
the ``pose_lifter`` package to import, e.g. an old commit's ``ros2_ws/src/pose_lifter`` from
``git archive``), feeds it the first ``--frames`` keypoint frames (and the camera_info) of every
committed bag in ``mode`` hybrid and paper through its callbacks, and pickles every
``Skeleton3DArray`` and ``MarkerArray`` it publishes (``solve_time`` zeroed: a timing).
``compare`` walks two dumps field by field, floats by bit pattern (-0.0 is not 0.0), and prints
the first differences. (The serialised CDR bytes are no proof: rclpy leaves the alignment
padding uninitialised, so two runs of one build differ there.)
"""

from __future__ import annotations

import argparse
import glob
import pickle
import struct
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def dump(out: Path, src: Path | None, frames: int) -> None:
    if src is not None:
        sys.path.insert(0, str(src))
    import rclpy
    from pose_lifter import bags
    from pose_lifter.messages import rclpy_types
    from pose_lifter.node import LifterNode
    from rclpy.parameter import Parameter
    from rclpy.serialization import deserialize_message

    rclpy.init()
    types = rclpy_types()
    published: list[tuple[str, str, Any]] = []
    for path in sorted(glob.glob(str(REPO / "bags" / "*.mcap"))):
        for mode in ("hybrid", "paper"):
            node = LifterNode(parameter_overrides=[Parameter("mode", value=mode),
                                                   Parameter("stats_period", value=0.0),
                                                   Parameter("diagnostics_period", value=0.0)])
            where = f"{Path(path).stem} {mode}"

            class Capture:
                def publish(self, msg: Any, where: str = where) -> None:
                    published.append((where, type(msg).__name__, msg))

            node._pub_skeletons = node._pub_markers = Capture()
            n = 0
            for raw in bags.read_raw(path):
                if raw.msgtype == "sensor_msgs/msg/CameraInfo":
                    node.on_camera_info(deserialize_message(raw.data, types.CameraInfo))
                elif raw.msgtype == "pose_lifter_msgs/msg/Skeleton2DArray":
                    if n == frames:
                        break
                    node.on_keypoints(deserialize_message(raw.data, types.Skeleton2DArray))
                    n += 1
            node.destroy_node()
    for _, kind, msg in published:
        for skel in msg.skeletons if kind == "Skeleton3DArray" else ():
            skel.solve_time = 0.0
    out.write_bytes(pickle.dumps(published))
    print(f"{len(published)} messages -> {out}")
    rclpy.shutdown()


def _first_difference(a: Any, b: Any, path: str) -> str | None:
    if hasattr(a, "get_fields_and_field_types"):
        for name in a.get_fields_and_field_types():
            found = _first_difference(getattr(a, name), getattr(b, name), f"{path}.{name}")
            if found:
                return found
        return None
    if isinstance(a, list | tuple) or type(a).__name__ in ("array", "ndarray"):
        a, b = list(a), list(b)
        if len(a) != len(b):
            return f"{path}: {len(a)} items vs {len(b)}"
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            found = _first_difference(x, y, f"{path}[{i}]")
            if found:
                return found
        return None
    if isinstance(a, float) or type(a).__name__.startswith("float"):
        same = struct.pack("<d", float(a)) == struct.pack("<d", float(b))
    else:
        same = type(a) is type(b) and a == b
    return None if same else f"{path}: {a!r} vs {b!r}"


def compare(a_path: Path, b_path: Path) -> int:
    a, b = pickle.loads(a_path.read_bytes()), pickle.loads(b_path.read_bytes())
    differences = 0
    if [(w, k) for w, k, _ in a] != [(w, k) for w, k, _ in b]:
        print("the two dumps hold different message sequences")
        return 1
    for (where, kind, x), (_, _, y) in zip(a, b, strict=True):
        found = _first_difference(x, y, kind)
        if found:
            differences += 1
            if differences <= 10:
                print(f"{where}: {found}")
    print(f"{len(a)} messages, {differences} differ")
    return 1 if differences else 0


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="command", required=True)
    d = sub.add_parser("dump")
    d.add_argument("out", type=Path)
    d.add_argument("--src", type=Path, help="directory holding the pose_lifter package to run")
    d.add_argument("--frames", type=int, default=40, help="keypoint frames per bag and mode")
    c = sub.add_parser("compare")
    c.add_argument("a", type=Path)
    c.add_argument("b", type=Path)
    args = ap.parse_args()
    if args.command == "dump":
        dump(args.out, args.src, args.frames)
        return 0
    return compare(args.a, args.b)


if __name__ == "__main__":
    sys.exit(main())
