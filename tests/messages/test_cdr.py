"""pose_lifter.messages.cdr: the offline lift's outputs, encoded straight from arrays, are the bytes that
rosbags gives for the messages the previous code built.

The reference (``_Reference`` below) is the message building of ``lift_bag`` as it was before
``pose_lifter.messages.cdr`` (commit 2a5a7f0): rosbags message classes filled field by field from the
typestore's field definitions, orientations from ``scipy.spatial.transform.Rotation``, then
``typestore.serialize_cdr``. It is kept here verbatim in behaviour, independent of
``pose_lifter.messages.convert`` and ``pose_lifter.messages.typestore.message_factory`` (both may change).
"""

from __future__ import annotations

import colorsys
import inspect
import itertools
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from lift_samples import random_frame
from pose_lifter.core.model.skeleton import BONES_FOR_DRAWING, JOINT_NAMES
from pose_lifter.messages import cdr, typestore
from pose_lifter.messages import convert as m
from pose_lifter.mocap import scenes
from pose_lifter.offline import bags
from pose_lifter.offline import lift as offline
from pose_lifter.offline.settings import LiftSettings
from rosbags.interfaces import Nodetype
from scipy.spatial.transform import Rotation

BAGS = Path(__file__).resolve().parents[2] / "bags"
_NUMPY = {"bool": "bool", "byte": "uint8", "char": "uint8", "int8": "int8", "uint8": "uint8",
          "int16": "int16", "uint16": "uint16", "int32": "int32", "uint32": "uint32", "int64": "int64",
          "uint64": "uint64", "float32": "float32", "float64": "float64"}


class _Reference:
    """The previous builders: ``bags._default_message`` and ``messages.convert.result_to_skeleton3d`` /
    ``skeleton_markers`` / ``skeletons3d_array`` of commit 2a5a7f0, with the node's marker book
    (DELETEALL first, DELETE for untracked positions no longer used) written out here again."""

    def __init__(self, store: Any) -> None:
        self.store = store

    def _default(self, desc: Any) -> Any:
        kind, sub = desc
        if kind == Nodetype.BASE:
            if sub[0] in ("string", "wstring"):
                return ""
            return False if sub[0] == "bool" else 0.0 if sub[0].startswith("float") else 0
        if kind == Nodetype.NAME:
            return self.msg(sub)
        inner, size = sub
        if inner[0] == Nodetype.BASE and inner[1][0] in _NUMPY:
            return np.zeros(size if kind == Nodetype.ARRAY else 0, dtype=_NUMPY[inner[1][0]])
        return [self._default(inner) for _ in range(size)] if kind == Nodetype.ARRAY else []

    def msg(self, msgtype: str, **fields: Any) -> Any:
        values = {}
        for name, (kind, sub) in self.store.fielddefs[msgtype][1]:
            if name not in fields:
                values[name] = self._default((kind, sub))
                continue
            value = fields[name]
            if (kind in (Nodetype.ARRAY, Nodetype.SEQUENCE) and isinstance(value, list | tuple)
                    and sub[0][0] == Nodetype.BASE and sub[0][1][0] in _NUMPY):
                value = np.asarray(value, dtype=_NUMPY[sub[0][1][0]])
            values[name] = value
        return self.store.types[msgtype](**values)

    def points(self, joints: np.ndarray) -> list[Any]:
        return [self.msg("geometry_msgs/msg/Point", x=float(a), y=float(b), z=float(c))
                for a, b, c in joints]

    def skeleton3d(self, result: Any, track_id: int, joints: np.ndarray, solve_time: float,
                   warm: bool, std: np.ndarray | None = None) -> Any:
        cam = result.camera
        q = np.asarray(Rotation.from_matrix(np.asarray(cam.rotation, dtype=np.float64)).as_quat())
        camera = self.msg(
            "pose_lifter_msgs/msg/CameraEstimate",
            projection=np.asarray(cam.projection, dtype=np.float64).reshape(6).copy(), scale=float(cam.scale),
            orientation=self.msg("geometry_msgs/msg/Quaternion", x=float(q[0]), y=float(q[1]), z=float(q[2]),
                                 w=float(q[3])),
            translation=np.asarray(cam.translation, dtype=np.float64).reshape(2).copy())
        weights = np.asarray(result.weights, dtype=np.float64)
        return self.msg(
            "pose_lifter_msgs/msg/Skeleton3D", track_id=int(track_id), joint_names=list(JOINT_NAMES),
            joints=self.points(joints), camera=camera, objective=float(result.objective),
            reprojection_error=float(result.reprojection_error), iterations=int(result.total_alternations),
            converged=bool(result.converged), solve_time=float(solve_time), warm_started=bool(warm),
            observed=[bool(w > 0) for w in weights], joint_weights=[float(w) for w in weights],
            joint_std=[] if std is None or not np.isfinite(std).all() else [
                self.msg("geometry_msgs/msg/Vector3", x=float(a), y=float(b), z=float(c)) for a, b, c in std])

    def markers(self, header: Any, tracks: list[tuple[int, np.ndarray]], ns: str, lifetime: float,
                deleted: list[int], clear: bool = False, deleted_untracked: range = range(0)) -> Any:
        out, untracked = [], 0
        if clear:
            for kind in ("joints", "bones"):
                out.append(self.msg("visualization_msgs/msg/Marker", header=header, ns=f"{ns}/{kind}", id=0,
                                    action=3))
        sec, nsec = divmod(max(0, round(float(lifetime) * 1e9)), 1_000_000_000)
        for track_id, joints in tracks:
            mid = track_id % (2**31 - 1) if track_id >= 0 else -1 - untracked
            untracked += track_id < 0
            pts = self.points(joints)
            r, g, b = (0.7, 0.7, 0.7) if track_id < 0 else \
                colorsys.hsv_to_rgb((0.12 + 0.618033988749895 * track_id) % 1.0, 0.85, 0.95)
            common = {
                "header": header, "id": mid, "action": 0,
                "pose": self.msg("geometry_msgs/msg/Pose", orientation=self.msg(
                    "geometry_msgs/msg/Quaternion", x=0.0, y=0.0, z=0.0, w=1.0)),
                "color": self.msg("std_msgs/msg/ColorRGBA", r=float(r), g=float(g), b=float(b), a=1.0),
                "lifetime": self.msg("builtin_interfaces/msg/Duration", sec=int(sec), nanosec=int(nsec)),
                "frame_locked": False}
            joint_scale = self.msg("geometry_msgs/msg/Vector3", x=0.05, y=0.05, z=0.05)
            out.append(self.msg("visualization_msgs/msg/Marker", ns=f"{ns}/joints", type=7, points=pts,
                                scale=joint_scale, **common))
            out.append(self.msg("visualization_msgs/msg/Marker", ns=f"{ns}/bones", type=5,
                                points=[pts[j] for bone in BONES_FOR_DRAWING for j in bone],
                                scale=self.msg("geometry_msgs/msg/Vector3", x=0.02, y=0.0, z=0.0), **common))
        for track_id in deleted:
            if track_id >= 0:
                for kind in ("joints", "bones"):
                    out.append(self.msg("visualization_msgs/msg/Marker", header=header, ns=f"{ns}/{kind}",
                                        id=track_id % (2**31 - 1), action=2))
        for position in deleted_untracked:
            for kind in ("joints", "bones"):
                out.append(self.msg("visualization_msgs/msg/Marker", header=header, ns=f"{ns}/{kind}",
                                    id=-1 - position, action=2))
        return self.msg("visualization_msgs/msg/MarkerArray", markers=out)

    def frame(self, header: Any, lifted: list[Any], results: list[Any], previous: set[int], ns: str,
              lifetime: float, first: bool = False,
              previous_untracked: int = 0) -> tuple[bytes, bytes, set[int]]:
        """The two serialised messages of one keypoint message (``lift_bag``'s ``record``)."""
        skels = [self.skeleton3d(r, f.track_id, f.joints_m, f.solve_time, f.warm_started, f.std_m)
                 for f, r in zip(lifted, results, strict=True)]
        now = {f.track_id for f in lifted if f.track_id >= 0}
        untracked = sum(1 for f in lifted if f.track_id < 0)
        markers = self.markers(header, [(f.track_id, f.joints_m) for f in lifted], ns, lifetime,
                               sorted(previous - now), first, range(untracked, previous_untracked))
        arr = self.msg("pose_lifter_msgs/msg/Skeleton3DArray", header=header, skeletons=skels)
        return (bytes(self.store.serialize_cdr(arr, cdr.SKELETON3D_ARRAY)),
                bytes(self.store.serialize_cdr(markers, cdr.MARKER_ARRAY)), now)


def _reference_outputs(monkeypatch: pytest.MonkeyPatch, lifetime: float) -> list[tuple[bytes, bytes]]:
    """Make ``lift_bag`` hand every message's lifts to the reference too; returns its bytes."""
    ref = _Reference(typestore.pose_lifter_typestore())
    expected: list[tuple[bytes, bytes]] = []
    previous: set[int] = set()
    previous_untracked = 0
    original = offline.lift_messages

    def spy(*args: Any, **kwargs: Any) -> Any:
        bound = inspect.signature(original).bind(*args, **kwargs)

        def reference(stamp: int, msg: Any, lifted: list[Any], results: list[Any]) -> None:
            nonlocal previous, previous_untracked
            a, b, previous = ref.frame(msg.header, lifted, results, previous, "pose_lifter", lifetime,
                                       first=not expected, previous_untracked=previous_untracked)
            previous_untracked = sum(1 for f in lifted if f.track_id < 0)
            expected.append((a, b))

        bound.arguments["on_frame"] = reference  # lift_bag writes what on_answer gets
        return original(*bound.args, **bound.kwargs)

    monkeypatch.setattr(offline, "lift_messages", spy)
    return expected


def _written(path: Path) -> list[tuple[bytes, bytes]]:
    raw = list(bags.read_raw(path, ["/skeletons_3d", "/skeleton_markers"]))
    skels = [r.data for r in raw if r.topic == "/skeletons_3d"]
    marks = [r.data for r in raw if r.topic == "/skeleton_markers"]
    assert len(skels) == len(marks)
    return list(zip(skels, marks, strict=True))


def _first_difference(a: bytes, b: bytes, msgtype: str) -> str:
    """Where two serialised messages differ, as a field path (for a readable failure)."""
    store = typestore.pose_lifter_typestore()

    def walk(x: Any, y: Any, path: str) -> str | None:
        if hasattr(x, "__dataclass_fields__"):
            for name in x.__dataclass_fields__:
                d = walk(getattr(x, name), getattr(y, name), f"{path}.{name}")
                if d:
                    return d
            return None
        if isinstance(x, list):
            if len(x) != len(y):
                return f"{path}: {len(x)} vs {len(y)} elements"
            pairs = enumerate(zip(x, y, strict=True))
            return next((d for i, (u, v) in pairs if (d := walk(u, v, f"{path}[{i}]"))), None)
        same = np.array_equal(x, y) if isinstance(x, np.ndarray) else x == y
        return None if same else f"{path}: {x!r} vs {y!r}"

    return walk(store.deserialize_cdr(a, msgtype), store.deserialize_cdr(b, msgtype), "msg") or "bytes only"


def _assert_same(got: list[tuple[bytes, bytes]], want: list[tuple[bytes, bytes]]) -> None:
    assert len(got) == len(want) > 0
    for i, ((gs, gm), (ws, wm)) in enumerate(zip(got, want, strict=True)):
        assert gs == ws, f"message {i}: {_first_difference(gs, ws, cdr.SKELETON3D_ARRAY)}"
        assert gm == wm, f"message {i}: {_first_difference(gm, wm, cdr.MARKER_ARRAY)}"


@pytest.mark.parametrize(("bag", "n_lifted"), [("five_people.mcap", 200), ("punch_outliers.mcap", 40)])
def test_lift_bag_writes_the_reference_bytes_on_a_committed_bag(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, bag: str, n_lifted: int) -> None:
    """A real lift (default hybrid mode) of committed bags (5 people; one person with missing
    and outlying joints, so some joint weights are 0): every /skeletons_3d and
    /skeleton_markers message is the reference's, byte for byte."""
    from pose_lifter.core import Lifter, LifterOptions, PoseBases

    settings = LiftSettings(max_messages=40, smoothing_s=0.0)  # the node's marker_lifetime
    expected = _reference_outputs(monkeypatch, settings.marker_lifetime)
    out = tmp_path / "out.mcap"
    summary, _ = offline.lift_bag(BAGS / bag, out, Lifter(PoseBases.load(), LifterOptions()), settings,
                                  progress=False)
    assert summary.n_lifted == n_lifted and len(expected) == 40
    _assert_same(_written(out), expected)
    if bag == "punch_outliers.mcap":
        weights = [w for x in bags.read_messages(out, ["/skeletons_3d"])
                   for w in x.msg.skeletons[0].joint_weights]
        assert 0.0 in weights
    # the orientations are not trivial (the quaternion path is exercised)
    s = next(bags.read_messages(out, ["/skeletons_3d"])).msg.skeletons[0]
    assert abs(s.camera.orientation.w) < 0.99


def test_lift_bag_writes_the_reference_bytes_with_vanishing_and_untracked_people(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """DELETE markers for a track that vanishes, untracked skeletons (ids -1, -2 by position),
    a marker lifetime, every other message lifted, and 2 worker processes."""
    from pose_lifter.core import Lifter, LifterOptions, PoseBases

    rng = np.random.default_rng(3)
    clip = rng.normal(scale=0.3, size=(8, 12, 3)) + np.array([0.0, 1.0, 0.0])
    sc = scenes.build_scene([clip, clip * 0.9, clip * 1.1], scenes.SceneOptions(), track_ids=[4, -1, 9])
    sc.confidence[2, 4:6, :] = 0.0  # track 9 has no joints in frames 4 and 5: DELETE markers
    sc.confidence[0, :, 2] = 0.0  # a missing joint: a weight of 0, observed false
    path = tmp_path / "in.mcap"
    bags.write_messages(path, scenes.scene_messages(sc))
    expected = _reference_outputs(monkeypatch, 0.25)
    out = tmp_path / "out.mcap"
    summary, _ = offline.lift_bag(path, out, Lifter(PoseBases.load(), LifterOptions(mode="learned")),
                                  LiftSettings(marker_lifetime=0.25, smoothing_s=0.0), progress=False,
                                  workers=2)
    assert (summary.n_lifted, summary.n_failed) == (22, 2)
    _assert_same(_written(out), expected)
    actions = [[(k.id, k.action) for k in x.msg.markers]
               for x in bags.read_messages(out, ["/skeleton_markers"])]
    assert actions[4][-2:] == [(9, 2), (9, 2)] and (-1, 0) in actions[0]


@pytest.mark.parametrize("frame_id", ["", "c", "ca", "cam", "came", "camer", "camera", "camera_",
                                      "virtual_camera_optical_frame", "kamera_ü"])
def test_encoders_equal_the_node_builders_for_every_alignment(frame_id: str) -> None:
    """The encoders against the node's builders (``messages.convert.result_to_skeleton3d``,
    ``skeleton_markers``) through rosbags: the frame id's length shifts every later field's
    alignment, so each length modulo 8 is a different layout."""
    rng = np.random.default_rng(len(frame_id))
    store = typestore.pose_lifter_typestore()
    types = m.rosbags_types(store)
    header = m.make_header(1_234_567_890_123, frame_id, types)
    track_ids = [3, -1, 7, -1, 2**31 + 5, 0]
    results, joints, times, warm = random_frame(rng, len(track_ids))
    for n in (0, 1, len(track_ids)):
        skels = [m.result_to_skeleton3d(r, t, j, types, s, w)
                 for r, t, j, s, w in zip(results[:n], track_ids[:n], joints[:n], times[:n], warm[:n],
                                          strict=True)]
        want = bytes(store.serialize_cdr(m.skeletons3d_array(header, skels, types), cdr.SKELETON3D_ARRAY))
        frame = cdr.SkeletonFrame.from_results(track_ids[:n], joints[:n], results[:n], times[:n], warm[:n])
        assert cdr.skeleton3d_array_cdr(cdr.message_header(header), frame) == want
        for lifetime, deleted in ((0.0, []), (1.5e-9, [11, -2]), (2.75, [1, 2])):
            tracks = list(zip(track_ids[:n], joints[:n], strict=True))
            mk = m.skeleton_markers(header, tracks, "ns", lifetime, types, deleted_track_ids=deleted)
            want = bytes(store.serialize_cdr(mk, cdr.MARKER_ARRAY))
            got = cdr.marker_array_cdr(cdr.message_header(header), track_ids[:n], frame.joints_m, "ns",
                                       lifetime, deleted)
            assert got == want, _first_difference(got, want, cdr.MARKER_ARRAY)


@pytest.mark.parametrize("frame_id", ["", "c", "ca", "cam", "came", "camer", "camera", "camera_"])
def test_joint_std_is_rosbags_bytes_filled_and_empty_for_every_alignment(frame_id: str) -> None:
    """``joint_std`` written from the columns is what rosbags serialises for the node's builder
    (:func:`~pose_lifter.messages.convert.result_to_skeleton3d` with ``std_m``): every skeleton
    with it, none, and a mix (an empty sequence between filled ones shifts the alignment of the
    next skeleton); rosbags reads the standard deviations back bit for bit, and
    :meth:`SkeletonFrame.of`, ``take`` and ``concat`` carry them."""
    from pose_lifter.messages.frame import LiftedSkeleton, SkeletonInput

    rng = np.random.default_rng(len(frame_id) + 20)
    store = typestore.pose_lifter_typestore()
    types = m.rosbags_types(store)
    header = m.make_header(1_234_567_890_123, frame_id, types)
    track_ids = [3, -1, 7, 11, 0]
    results, joints, times, warm = random_frame(rng, len(track_ids))
    filled = [rng.uniform(0.005, 0.4, size=(12, 3)) for _ in track_ids]
    for stds in (filled, [None] * len(filled), [filled[0], None, filled[2], filled[3], None],
                 [None, filled[1], None, None, filled[4]]):
        skels = [m.result_to_skeleton3d(r, t, j, types, s, w, std_m=sd)
                 for r, t, j, s, w, sd in zip(results, track_ids, joints, times, warm, stds, strict=True)]
        want = bytes(store.serialize_cdr(m.skeletons3d_array(header, skels, types), cdr.SKELETON3D_ARRAY))
        frame = cdr.SkeletonFrame.from_results(track_ids, joints, results, times, warm, std_m=stds)
        got = cdr.skeleton3d_array_cdr(cdr.message_header(header), frame)
        assert got == want, _first_difference(got, want, cdr.SKELETON3D_ARRAY)
        back = store.deserialize_cdr(got, cdr.SKELETON3D_ARRAY).skeletons
        for sk, sd in zip(back, stds, strict=True):
            if sd is None:
                assert len(sk.joint_std) == 0 and np.isnan(m.skeleton3d_to_std(sk)).all()
            else:
                assert np.array_equal(m.skeleton3d_to_std(sk), sd)
        lifted = [LiftedSkeleton(SkeletonInput(t, np.zeros((12, 2)), np.ones(12)), r, j, w, s, std_m=sd)
                  for r, t, j, s, w, sd in zip(results, track_ids, joints, times, warm, stds, strict=True)]
        of = cdr.SkeletonFrame.of(lifted)
        assert cdr.skeleton3d_array_cdr(cdr.message_header(header), of) == want
        rows = np.array([4, 0, 2])
        again = cdr.SkeletonFrame.concat([of.take(rows[:1]), of.take(rows[1:])])
        assert again.std_m is not None and frame.std_m is not None
        assert np.array_equal(again.std_m, frame.std_m[rows], equal_nan=True)


def test_joint_std_bad_input_is_refused_with_one_line() -> None:
    rng = np.random.default_rng(2)
    results, joints, times, warm = random_frame(rng, 2)
    good = rng.uniform(0.01, 0.1, size=(12, 3))
    negative, nan = good.copy(), good.copy()
    negative[3, 1] = -0.01
    nan[0, 2] = np.nan
    for stds, expected in [([good], "one joint std"), ([good, good[:, :2]], r"got shape \(12, 2\)"),
                           ([negative, None], "finite and non-negative"),
                           ([good, nan], "finite and non-negative")]:
        with pytest.raises(ValueError, match=expected) as err:
            cdr.SkeletonFrame.from_results([1, 2], joints, results, times, warm, std_m=stds)
        assert "\n" not in str(err.value)


def test_quaternions_are_scipys_bit_for_bit() -> None:
    rng = np.random.default_rng(0)
    special = [np.eye(3)]
    signed = itertools.product([1, -1], repeat=3)
    for perm, signs in itertools.product(itertools.permutations(range(3)), list(signed)):
        r = np.zeros((3, 3))
        r[range(3), perm] = signs
        if np.linalg.det(r) > 0:
            special.append(r)  # axis permutations: ties between the diagonal and the trace
    for angle, axis in itertools.product(np.deg2rad([45, 90, 180, 270]), np.eye(3)):
        special.append(Rotation.from_rotvec(angle * axis).as_matrix())
    rotations = Rotation.random(20000, random_state=rng).as_matrix()
    noisy = rotations + rng.normal(scale=1e-6, size=rotations.shape)  # not orthogonal: the SVD path
    for mats in (np.array(special), rotations, noisy):
        want = Rotation.from_matrix(mats).as_quat()
        got = m.quaternions_xyzw(mats)
        assert got.shape == want.shape and np.array_equal(got.view(np.uint64), want.view(np.uint64))
    assert m.quaternions_xyzw(rotations[0]).shape == (4,)
    with pytest.raises(ValueError, match="determinant"):
        m.quaternions_xyzw(np.diag([1.0, 1.0, -1.0]))


def test_check_definitions_refuses_another_skeleton3d_layout(tmp_path: Path) -> None:
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    cdr.check_definitions(typestore.pose_lifter_typestore())
    store = get_typestore(Stores.ROS2_JAZZY)
    d = typestore.msg_dir()
    for name in typestore.MSG_NAMES:
        text = (d / f"{name}.msg").read_text()
        if name == "Skeleton3D":
            text += "\nfloat64 confidence\n"
        store.register(get_types_from_msg(text, f"{typestore.MSG_PACKAGE}/msg/{name}"))
    with pytest.raises(RuntimeError, match="Skeleton3DArray"):
        cdr.check_definitions(store)


def test_message_factory_builds_what_the_previous_factory_built() -> None:
    """``typestore.message_factory`` (field plans read once per type) against the reference's
    field-by-field construction: every type of ``messages.convert.MESSAGE_TYPES`` with no fields and
    with list-valued numeric fields; defaults are fresh objects; an unknown field is refused."""
    store = typestore.pose_lifter_typestore()
    ref = _Reference(store)
    for name in m.MESSAGE_TYPES.values():
        make = typestore.message_factory(name, store)
        assert store.serialize_cdr(make(), name) == store.serialize_cdr(ref.msg(name), name)
    fields: dict[str, Any] = {"projection": [1.0, 2, 3, 4, 5, 6], "scale": 2.0, "translation": (7.0, 8.0)}
    a = typestore.message_factory("pose_lifter_msgs/msg/CameraEstimate", store)(**fields)
    assert a.projection.dtype == np.float64 and isinstance(a.translation, np.ndarray)
    assert store.serialize_cdr(a, "pose_lifter_msgs/msg/CameraEstimate") == \
        store.serialize_cdr(ref.msg("pose_lifter_msgs/msg/CameraEstimate", **fields),
                            "pose_lifter_msgs/msg/CameraEstimate")
    marker = typestore.message_factory("visualization_msgs/msg/Marker", store)
    one, two = marker(ns="x", id=3, action=2), marker(ns="x", id=3, action=2)
    assert store.serialize_cdr(one, "visualization_msgs/msg/Marker") == \
        store.serialize_cdr(ref.msg("visualization_msgs/msg/Marker", ns="x", id=3, action=2),
                            "visualization_msgs/msg/Marker")
    assert one.header is not two.header and one.texture.data is not two.texture.data
    assert one.points is not two.points
    with pytest.raises(TypeError, match="nosuch"):
        marker(ns="x", nosuch=1)


def _decoded_and_deserialised(bag: Path) -> list[tuple[Any, Any]]:
    store = typestore.pose_lifter_typestore()
    return [(cdr.decode_skeleton2d_array(r.data), store.deserialize_cdr(r.data, r.msgtype))
            for r in bags.read_raw(bag, ["/keypoints_2d"])]


def _same_input(decoded: Any, msg: Any) -> None:
    head = (decoded.header.stamp.sec, decoded.header.stamp.nanosec, decoded.header.frame_id, decoded.layout)
    assert head == (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id, msg.layout)
    assert [s.track_id for s in decoded.skeletons] == [s.track_id for s in msg.skeletons]
    for d, s in zip(decoded.skeletons, msg.skeletons, strict=True):
        want = np.array([[k.x, k.y, k.confidence] for k in s.keypoints], dtype=np.float64).reshape(-1, 3)
        assert d.xyc.dtype == np.float64 and np.array_equal(d.xyc, want, equal_nan=True)
        try:
            expected: Any = m.skeleton2d_to_arrays(s, msg.layout)
        except Exception as exc:  # the same refusal both ways
            with pytest.raises(type(exc)):
                m.skeleton2d_to_arrays(d, decoded.layout)
            continue
        got = m.skeleton2d_to_arrays(d, decoded.layout)
        for a, b in zip(got, expected, strict=True):
            assert a.dtype == b.dtype and np.array_equal(a, b)


@pytest.mark.parametrize("bag", sorted(p.name for p in BAGS.glob("*.mcap")))
def test_decoded_keypoints_equal_rosbags_on_every_committed_bag(bag: str) -> None:
    pairs = _decoded_and_deserialised(BAGS / bag)
    assert pairs
    for decoded, msg in pairs:
        assert decoded is not None
        _same_input(decoded, msg)


def test_decoder_on_awkward_input_agrees_or_hands_over_to_rosbags() -> None:
    store = typestore.pose_lifter_typestore()
    types = m.rosbags_types(store)
    rng = np.random.default_rng(5)

    def serialised(frame_id: str, layout: str, skeletons: list[Any]) -> bytes:
        arr = m.skeleton2d_array(m.make_header(7_000_000_123, frame_id, types), layout, skeletons, types)
        return bytes(store.serialize_cdr(arr, cdr.SKELETON2D_ARRAY))

    kp = rng.normal(300, 50, size=(17, 2))
    kp[3] = np.nan  # non-finite coordinates (missing with confidence 0, refused when visible)
    conf = rng.uniform(size=17).astype(np.float32).astype(np.float64)
    conf[3] = 0.0
    visible_nan = conf.copy()
    visible_nan[3] = 0.9
    cases = [
        serialised("", "coco17", []),
        serialised("kamera_ü", "coco17", [m.arrays_to_skeleton2d(kp, conf, -1, types)]),
        serialised("a", "coco17", [m.arrays_to_skeleton2d(kp, conf, 2**40, types),
                                   m.arrays_to_skeleton2d(kp[:5], conf[:5], 1, types),  # wrong length
                                   m.arrays_to_skeleton2d(kp[:0], conf[:0], 2, types),  # no keypoints
                                   m.arrays_to_skeleton2d(kp, visible_nan, 3, types)]),
        serialised("abc", "wang12", [m.arrays_to_skeleton2d(kp[:12], conf[:12], 0, types)]),
    ]
    for data in cases:
        decoded = cdr.decode_skeleton2d_array(data)
        assert decoded is not None
        _same_input(decoded, store.deserialize_cdr(data, cdr.SKELETON2D_ARRAY))
    good = cases[2]
    assert cdr.decode_skeleton2d_array(good[:-1]) is None  # truncated
    assert cdr.decode_skeleton2d_array(good[:40]) is None
    assert cdr.decode_skeleton2d_array(good + bytes(8)) is None  # trailing bytes
    assert cdr.decode_skeleton2d_array(b"\x00\x00" + good[2:]) is None  # big endian: rosbags reads it
    assert cdr.decode_skeleton2d_array(b"") is None


def test_read_messages_decodes_only_our_definition(tmp_path: Path) -> None:
    """The fast decoder is used for a bag with today's Skeleton2DArray definition, rosbags for
    a bag whose definition differs (the messages are read as before either way)."""
    fast = {cdr.SKELETON2D_ARRAY: cdr.decode_skeleton2d_array}
    msgs = list(bags.read_messages(BAGS / "two_people.mcap", ["/keypoints_2d"], decoders=fast))
    assert all(isinstance(x.msg, cdr.DecodedSkeleton2DArray) for x in msgs)
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    old = get_typestore(Stores.ROS2_JAZZY)
    d = typestore.msg_dir()
    for name in typestore.MSG_NAMES:
        text = (d / f"{name}.msg").read_text().replace("float32 confidence", "float64 confidence")
        old.register(get_types_from_msg(text, f"{typestore.MSG_PACKAGE}/msg/{name}"))
    path = tmp_path / "old.mcap"
    from rosbags.rosbag2 import StoragePlugin, Writer

    with Writer(tmp_path / "bag", version=9, storage_plugin=StoragePlugin.MCAP) as w:
        conn = w.add_connection("/keypoints_2d", cdr.SKELETON2D_ARRAY, typestore=old)
        types = m.rosbags_types(old)
        kp = np.arange(34, dtype=np.float64).reshape(17, 2)
        msg = m.skeleton2d_array(m.make_header(5, "f", types), "coco17",
                                 [m.arrays_to_skeleton2d(kp, np.full(17, 0.3), 4, types)], types)
        w.write(conn, 5, old.serialize_cdr(msg, cdr.SKELETON2D_ARRAY))
    next((tmp_path / "bag").glob("*.mcap")).rename(path)
    (x,) = bags.read_messages(path, ["/keypoints_2d"], decoders=fast)
    assert not isinstance(x.msg, cdr.DecodedSkeleton2DArray)
    assert x.msg.skeletons[0].keypoints[0].confidence == 0.3  # float64 in that definition
