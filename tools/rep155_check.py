"""How well the REP-155 outputs reproduce the lifted joints, on a lifted bag.

Usage::

    .venv/bin/pose-lifter lift bags/walk_noisy.mcap --out out/walk_noisy.mcap
    .venv/bin/python tools/rep155_check.py out/walk_noisy.mcap [--topic /skeletons_3d]

For every skeleton of ``--topic`` (tracked ones), prints the largest distance between a joint
and its TF link composed up to the camera frame (:func:`pose_lifter.messages.body.body_frames`,
what the node broadcasts on /tf), and the distance between the joints and the forward
kinematics of the published joint angles through the body's URDF (dimensioned from the track's
first skeleton, as the node publishes it): mean, p95 and max, per joint group.
"""

from __future__ import annotations

import argparse

import numpy as np
from pose_lifter.core.model.skeleton import JOINT_NAMES
from pose_lifter.messages import body
from pose_lifter.messages.convert import skeleton3d_to_joints
from pose_lifter.offline.bags import read_messages


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag")
    ap.add_argument("--topic", default="/skeletons_3d")
    args = ap.parse_args()
    poses: dict[int, list[np.ndarray]] = {}
    for m in read_messages(args.bag, [args.topic]):
        for s in m.msg.skeletons:
            if int(s.track_id) >= 0:
                poses.setdefault(int(s.track_id), []).append(skeleton3d_to_joints(s))
    links = body.joint_link_names()
    tf_err, fk_err = 0.0, []
    for track in poses.values():
        dims = body.body_dimensions(track[0])
        for joints in track:
            composed = body.compose(body.body_frames(joints))
            got = np.array([composed[links[n]][0] for n in JOINT_NAMES])
            tf_err = max(tf_err, float(np.abs(got - joints).max()))
            origin, rotation = composed["body"]
            fk = body.forward_kinematics(dims, body.joint_angles(joints)) @ rotation.T + origin
            fk_err.append(np.linalg.norm(fk - joints, axis=1))
    err = np.array(fk_err) * 1e3
    print(f"{args.bag} {args.topic}: {len(poses)} tracks, {len(err)} skeletons")
    print(f"  TF composed to the camera frame: max {tf_err * 1e3:.2e} mm from the joints")
    for name, idx in (("all joints", slice(None)), ("arms", slice(0, 6)), ("legs", slice(6, 12))):
        e = err[:, idx]
        print(f"  URDF forward kinematics, {name:10s}: mean {e.mean():5.1f}  p95 {np.percentile(e, 95):5.1f}"
              f"  max {e.max():5.1f} mm")


if __name__ == "__main__":
    main()
