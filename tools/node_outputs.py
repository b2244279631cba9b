"""What the lifter node publishes for the committed bags, to prove that a refactor of the node
changes no published message.

Usage (ROS sourced: ``source ros2_ws/install/setup.bash``)::

    .venv/bin/python tools/node_outputs.py dump OUT.json [--src DIR] [--frames 40]
    .venv/bin/python tools/node_outputs.py compare A.json B.json

``dump`` runs :class:`pose_lifter.ros.node.LifterNode` in-process (``--src``: the directory that
holds the ``pose_lifter`` package to import, e.g. an old commit's ``ros2_ws/src/pose_lifter`` from
``git archive``), feeds it the first ``--frames`` keypoint frames (serialised, as its
subscription hands them over; and the camera_info) of every committed bag in ``mode`` hybrid and
paper through its callbacks, and writes every ``Skeleton3DArray`` and ``MarkerArray`` it
publishes as JSON, field by field, floats as exact hex strings (``solve_time`` zeroed: a timing).
``compare`` walks two dumps field by field, floats by bit pattern (-0.0 is not 0.0), prints the
first differences and the largest float difference.
(The serialised CDR bytes are no proof: rclpy leaves the alignment padding uninitialised, so two
runs of one build differ there.)
"""

from __future__ import annotations

import argparse
import glob
import json
import sys
import time
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[1]


def dump(out: Path, src: Path | None, frames: int) -> None:
    if src is not None:
        sys.path.insert(0, str(src))
    import rclpy
    from pose_lifter.messages.convert import rclpy_types
    from pose_lifter.offline import bags
    from pose_lifter.ros.node import LifterNode
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
                """A publisher that keeps what it is given (serialised messages read back as ``cls``)."""

                def __init__(self, cls: Any) -> None:
                    self.cls = cls

                def publish(self, msg: Any, where: str = where) -> None:
                    if isinstance(msg, bytes):
                        msg = deserialize_message(msg, self.cls)
                    published.append((where, type(msg).__name__, msg))

            node._pub_skeletons = Capture(types.Skeleton3DArray)
            node._pub_markers = Capture(types.MarkerArray)
            n = 0
            for raw in bags.read_raw(path):
                if raw.msgtype == "sensor_msgs/msg/CameraInfo":
                    node.on_camera_info(deserialize_message(raw.data, types.CameraInfo))
                elif raw.msgtype == "pose_lifter_msgs/msg/Skeleton2DArray":
                    if n == frames:
                        break
                    # the serialised frame, as the subscription hands it to a node that reads it
                    # (LifterNode.read_frame); else the rclpy message it subscribes to
                    data = bytes(raw.data)
                    frame = (data if hasattr(node, "read_frame")
                             else deserialize_message(data, types.Skeleton2DArray))
                    node.lift_frame(frame, time.perf_counter())
                    n += 1
            node.destroy_node()
    for _, kind, msg in published:
        for skel in msg.skeletons if kind == "Skeleton3DArray" else ():
            skel.solve_time = 0.0
    out.write_text(json.dumps([(w, k, _plain(m)) for w, k, m in published]))
    print(f"{len(published)} messages -> {out}")
    rclpy.shutdown()


def _plain(x: Any) -> Any:
    """A message as JSON data: fields as a dict, sequences as lists, floats as ``float.hex``."""
    if hasattr(x, "get_fields_and_field_types"):
        return {name: _plain(getattr(x, name)) for name in x.get_fields_and_field_types()}
    if isinstance(x, list | tuple) or type(x).__name__ in ("array", "ndarray"):
        return [_plain(v) for v in x]
    if isinstance(x, float) or type(x).__name__.startswith("float"):
        return {"f": float(x).hex()}
    return x.decode("latin-1") if isinstance(x, bytes) else x


def _first_difference(a: Any, b: Any, path: str, largest: list[float]) -> str | None:
    if isinstance(a, dict) and set(a) == {"f"}:  # a float, by bit pattern
        fa, fb = float.fromhex(a["f"]), float.fromhex(b["f"])
        largest[0] = max(largest[0], abs(fa - fb))
        return None if a == b else f"{path}: {fa!r} vs {fb!r}"
    if isinstance(a, dict):
        first = None
        for name in a:
            found = _first_difference(a[name], b[name], f"{path}.{name}", largest)
            first = first or found
        return first
    if isinstance(a, list):
        if len(a) != len(b):
            return f"{path}: {len(a)} items vs {len(b)}"
        first = None
        for i, (x, y) in enumerate(zip(a, b, strict=True)):
            found = _first_difference(x, y, f"{path}[{i}]", largest)
            first = first or found
        return first
    return None if type(a) is type(b) and a == b else f"{path}: {a!r} vs {b!r}"


def compare(a_path: Path, b_path: Path) -> int:
    a, b = json.loads(a_path.read_text()), json.loads(b_path.read_text())
    differences = 0
    largest = [0.0]
    if [(w, k) for w, k, _ in a] != [(w, k) for w, k, _ in b]:
        print("the two dumps hold different message sequences")
        return 1
    for (where, kind, x), (_, _, y) in zip(a, b, strict=True):
        found = _first_difference(x, y, kind, largest)
        if found:
            differences += 1
            if differences <= 10:
                print(f"{where}: {found}")
    print(f"{len(a)} messages, {differences} differ; largest float difference {largest[0]:.3g}")
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
