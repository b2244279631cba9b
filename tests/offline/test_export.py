"""``Skeleton3D.joint_std`` through the offline readers: ``pose-lifter export`` (CSV, NPZ, JSON)
and ``evaluate`` of bags with the field filled, empty, and of bags written before the field
existed (the committed bags under ``bags/``, and a lifted bag of the older definition)."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tolerances as tol
from lift_samples import random_frame
from pose_lifter.core.model.metrics import mpjpe
from pose_lifter.core.model.skeleton import JOINT_NAMES
from pose_lifter.messages import convert as m
from pose_lifter.messages import typestore
from pose_lifter.messages.names import SKELETON3D_ARRAY, TOPIC_GROUND_TRUTH, TOPIC_SKELETONS
from pose_lifter.offline import bags
from pose_lifter.offline.evaluate import evaluate_bag
from pose_lifter.offline.export import export_skeletons

BAGS = Path(__file__).resolve().parents[2] / "bags"
#: Where the field's comment starts in Skeleton3D.msg: the definition before it ends there.
_JOINT_STD_COMMENT = "\n# Per joint (order of joint_names): standard deviation"


def _exported(bag: Path, tmp_path: Path, name: str, topic: str = TOPIC_SKELETONS
              ) -> tuple[list[dict[str, str]], Any, dict[str, Any]]:
    """``bag``'s ``topic`` exported to the three formats: CSV rows, NPZ arrays, JSON document."""
    for fmt in ("csv", "npz", "json"):
        export_skeletons(bag, tmp_path / f"{name}.{fmt}", topic)
    with open(tmp_path / f"{name}.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    return rows, np.load(tmp_path / f"{name}.npz", allow_pickle=False), \
        json.loads((tmp_path / f"{name}.json").read_text())


def _csv_std(rows: list[dict[str, str]]) -> np.ndarray:
    """The CSV's std columns as (skeletons, 12, 3), NaN for an empty cell (as pandas reads it)."""
    values = [[float(r[c]) if r[c] else np.nan for c in ("std_x_m", "std_y_m", "std_z_m")] for r in rows]
    return np.array(values).reshape(-1, len(JOINT_NAMES), 3)


def test_export_writes_each_skeletons_joint_std_in_the_three_formats(tmp_path: Path) -> None:
    """Skeletons with a std, without one, and one whose message lists its joints in another
    order: each format gives the std in the core joint order, bit for bit (CSV through ``repr``),
    and NaN / an empty cell / null where the skeleton has none; an empty message is kept."""
    rng = np.random.default_rng(11)
    types = m.rosbags_types()
    results, joints, times, warm = random_frame(rng, 3)
    std = [rng.uniform(0.005, 0.5, size=(12, 3)) for _ in range(3)]
    first = [m.result_to_skeleton3d(results[0], 1, joints[0], types, times[0], warm[0], std_m=std[0]),
             m.result_to_skeleton3d(results[1], 2, joints[1], types, times[1], warm[1])]
    shuffled = m.result_to_skeleton3d(results[2], 1, joints[2], types, times[2], warm[2], std_m=std[2])
    perm = rng.permutation(12)
    shuffled.joint_names = [shuffled.joint_names[i] for i in perm]
    shuffled.joints = [shuffled.joints[i] for i in perm]
    shuffled.joint_std = [shuffled.joint_std[i] for i in perm]
    frames = [first, [], [shuffled]]
    bag = tmp_path / "std.mcap"
    stamps = [10**9 * (k + 1) for k in range(len(frames))]
    bags.write_messages(bag, [
        (TOPIC_SKELETONS, t, m.skeletons3d_array(m.make_header(t, "cam", types), skels, types),
         SKELETON3D_ARRAY) for t, skels in zip(stamps, frames, strict=True)])
    want = np.stack([std[0], np.full((12, 3), np.nan), std[2]])

    rows, npz, document = _exported(bag, tmp_path, "e")
    assert npz["joint_std"].shape == (3, 12, 3) and npz["joint_std"].dtype == np.float64
    np.testing.assert_array_equal(npz["joint_std"], want)  # NaN where NaN, equal elsewhere
    np.testing.assert_array_equal(npz["joints"][2], joints[2])
    assert len(rows) == 3 * 12 and [r["joint"] for r in rows[24:]] == list(JOINT_NAMES)
    np.testing.assert_array_equal(_csv_std(rows), want)
    assert {r["std_x_m"] for r in rows[12:24]} == {""}
    skeletons = [s for fr in document["frames"] for s in fr["skeletons"]]
    assert [len(fr["skeletons"]) for fr in document["frames"]] == [2, 0, 1]
    assert skeletons[1]["joint_std"] is None
    np.testing.assert_array_equal(np.array(skeletons[0]["joint_std"]), std[0])
    np.testing.assert_array_equal(np.array(skeletons[2]["joint_std"]), std[2])
    assert document["units"]["joint_std"].startswith("metres")


def _older_store() -> Any:
    """A typestore with ``Skeleton3D`` as it was before ``joint_std``."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    old = get_typestore(Stores.ROS2_JAZZY)
    texts = {n: (typestore.msg_dir() / f"{n}.msg").read_text() for n in typestore.MSG_NAMES}
    texts["Skeleton3D"] = texts["Skeleton3D"].split(_JOINT_STD_COMMENT)[0] + "\n"
    assert "joint_std" not in texts["Skeleton3D"] and "joint_weights" in texts["Skeleton3D"]
    types: dict[str, Any] = {}
    for n, text in texts.items():
        types.update(get_types_from_msg(text, f"{typestore.MSG_PACKAGE}/msg/{n}"))
    old.register(types)
    return old


def test_a_lifted_bag_written_before_joint_std_reads_exports_and_evaluates(tmp_path: Path) -> None:
    """Estimates and ground truth in the definition before ``joint_std``: read (deserialised or
    raw) they are upgraded to today's definition (an empty ``joint_std``: NaN stds);
    export writes NaN / empty cells / null; evaluate matches them and reports NaN stds."""
    old = _older_store()
    types = m.rosbags_types(old)
    rng = np.random.default_rng(5)
    truth = [rng.normal(size=(12, 3)) + np.array([0.0, 0.0, 4.0]) for _ in range(4)]
    shift = rng.normal(scale=0.03, size=(12, 3))  # the estimates' error, per joint
    msgdef = old.generate_msgdef(SKELETON3D_ARRAY, ros_version=2)[0]
    rihs01 = old.hash_rihs01(SKELETON3D_ARRAY)
    assert rihs01 != typestore.pose_lifter_typestore().hash_rihs01(SKELETON3D_ARRAY)
    bag = tmp_path / "older.mcap"
    with bags.BagWriter(bag) as w:
        for k, joints in enumerate(truth):
            header = m.make_header(10**8 * (k + 1), "cam", types)
            for topic, j in ((TOPIC_GROUND_TRUTH, joints), (TOPIC_SKELETONS, joints + shift)):
                msg = m.skeletons3d_array(header, [m.skeleton3d_from_joints(7, j, types)], types)
                w.write_raw(bags.RawMessage(topic, SKELETON3D_ARRAY, 10**8 * (k + 1),
                                            bytes(old.serialize_cdr(msg, SKELETON3D_ARRAY)), msgdef, rihs01))
    read = [x.msg.skeletons[0] for x in bags.read_messages(bag, [TOPIC_SKELETONS])]
    assert len(read) == 4 and len(read[0].joint_std) == 0
    np.testing.assert_array_equal(m.skeleton3d_to_joints(read[2]), truth[2] + shift)
    assert np.isnan(m.skeleton3d_to_std(read[2])).all()
    store = typestore.pose_lifter_typestore()
    raw = list(bags.read_raw(bag, [TOPIC_SKELETONS]))
    assert {r.rihs01 for r in raw} == {store.hash_rihs01(SKELETON3D_ARRAY)}
    assert all(len(store.deserialize_cdr(r.data, r.msgtype).skeletons[0].joint_std) == 0 for r in raw)

    rows, npz, document = _exported(bag, tmp_path, "old")
    assert npz["joint_std"].shape == (4, 12, 3) and np.isnan(npz["joint_std"]).all()
    np.testing.assert_array_equal(npz["joints"], np.array(truth) + shift)
    assert {r[c] for r in rows for c in ("std_x_m", "std_y_m", "std_z_m")} == {""}
    assert {str(s["joint_std"]) for fr in document["frames"] for s in fr["skeletons"]} == {"None"}

    ev = evaluate_bag(bag)
    assert ev.n_matched == 4 and ev.joint_std_m.shape == (4, 12, 3) and np.isnan(ev.joint_std_m).all()
    np.testing.assert_allclose(ev.mpjpe_mm, 1e3 * mpjpe(np.array(truth) + shift, np.array(truth)),
                               rtol=tol.ROUND_OFF_ACCUMULATED)
    assert ev.mpjpe_mm.min() > 10.0


@pytest.mark.parametrize("bag", sorted(p.name for p in BAGS.glob("*.mcap")))
def test_the_committed_bags_have_no_joint_std_and_still_export(bag: str, tmp_path: Path) -> None:
    """The committed bags' ground truth was written before ``joint_std``: it exports with NaN
    standard deviations (the joints as the reader reads them)."""
    first = next(bags.read_messages(BAGS / bag, [TOPIC_GROUND_TRUTH])).msg
    assert len(first.skeletons[0].joint_std) == 0  # the older definition, read as today's
    export_skeletons(BAGS / bag, tmp_path / "gt.npz", TOPIC_GROUND_TRUTH)
    data = np.load(tmp_path / "gt.npz", allow_pickle=False)
    assert data["joint_std"].shape == data["joints"].shape and np.isnan(data["joint_std"]).all()
    np.testing.assert_array_equal(data["joints"][0], m.skeleton3d_to_joints(first.skeletons[0]))
    assert np.isfinite(data["joints"]).all()
