"""A frame's depth image through the frame pipeline's placement (pose_lifter.messages.frame
``place_lifted``): the people of one camera and one depth image fused in one call, with their
labelled 2D, confidences, poses, scales and centres; their joints and std_m the fusion's; a person
the fusion gives no finite joints placed as without depth; and without depth the monocular
placement, unchanged. The fusion is replaced here by a recording double (its maths is
pose_lifter.core.depth's, tested there)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
from pose_lifter.core.track.policy import TrackedLift
from pose_lifter.messages.frame import FrameSettings, LiftedSkeleton, SkeletonInput, place_lifted
from scipy.spatial.transform import Rotation
from test_convert import fake_result

FX, FY, CX, CY = 600.0, 580.0, 320.0, 240.0
CAMERA = ((FX, FY), (CX, CY))
SETTINGS = FrameSettings()


def _people(n: int, swapped_first: bool = False) -> list[tuple[SkeletonInput, TrackedLift]]:
    rng = np.random.default_rng(3)
    out = []
    for i in range(n):
        res = fake_result(Rotation.random(random_state=i).as_matrix(), float(rng.uniform(60, 150)),
                          rng.uniform(100, 500, size=2), seed=i)
        inp = SkeletonInput(i, rng.uniform(0, 640, size=(12, 2)), rng.uniform(0.3, 1.0, size=12))
        swapped = np.array([True, False]) if swapped_first and i == 0 else None
        out.append((inp, TrackedLift(res, False, False, swapped=swapped)))
    return out


@pytest.fixture
def fusion(monkeypatch: pytest.MonkeyPatch) -> list[dict[str, Any]]:
    """``pose_lifter.core.depth.place.place_people`` with a depth image replaced by a double that
    records each call and puts every joint at z = 2 m (std 0.05 m), the second person's NaN;
    without depth, the real (monocular) placement."""
    from pose_lifter.core.depth import place
    from pose_lifter.core.depth.fuse import DepthReadings

    calls: list[dict[str, Any]] = []
    real = place.place_people

    def place_people(results: Any, points: Any, intrinsics: Any, leg: float, distance: float, *,
                     poses: Any = None, depth: Any = None, readings: Any = None) -> Any:
        if depth is None and readings is None:
            return real(results, points, intrinsics, leg, distance, poses=poses)
        calls.append(dict(depth=depth, intrinsics=intrinsics, points=points, results=results))
        n = len(results)
        joints = np.zeros((n, 12, 3))
        joints[..., 2] = 2.0
        if n > 1:
            joints[1] = np.nan
        return place.Placed(joints, np.full((n, 12, 3), 0.05), DepthReadings(np.full((n, 12), 2.0),
                                                                             np.full((n, 12), 1e-4)))

    monkeypatch.setattr(place, "place_people", place_people)
    return calls


def test_without_depth_the_placement_is_the_monocular_one(fusion: list[dict[str, Any]]) -> None:
    people = _people(3)
    solved = [(SETTINGS, CAMERA, inp, t) for inp, t in people]
    plain = place_lifted(solved)
    for out in (place_lifted(solved, None), place_lifted(solved, [None] * 3)):
        for a, b in zip(plain, out, strict=True):
            assert isinstance(a, LiftedSkeleton) and isinstance(b, LiftedSkeleton)
            np.testing.assert_array_equal(a.joints_m, b.joints_m)
            assert a.std_m is not None and b.std_m is not None and a.depth is None and b.depth is None
            np.testing.assert_array_equal(a.std_m, b.std_m)  # the monocular uncertainty
    assert not fusion
    # a depth image without intrinsics: nothing to fuse it with
    depth = np.full((480, 640), 2.0, dtype=np.float32)
    no_camera = place_lifted([(SETTINGS, None, inp, t) for inp, t in people], [depth] * 3)
    assert not fusion and all(isinstance(x, LiftedSkeleton) and x.depth is None for x in no_camera)


def test_one_fusion_per_camera_and_depth_image(fusion: list[dict[str, Any]]) -> None:
    people = _people(4, swapped_first=True)
    depth = np.full((480, 640), 2.0, dtype=np.float32)
    other = np.full((480, 640), 3.0, dtype=np.float32)
    solved = [(SETTINGS, CAMERA, inp, t) for inp, t in people]
    mono = place_lifted(solved)
    out = place_lifted(solved, [depth, depth, depth, other])
    assert len(fusion) == 2  # people 0-2 on one image, person 3 on the other
    first = fusion[0]
    assert first["depth"] is depth and first["intrinsics"] == CAMERA
    # the 2D as the track labelled the 3D joints (person 0's arms swapped back), and their lifts
    inp0 = people[0][0]
    swapped = inp0.points.copy()
    swapped[[0, 1, 2, 3, 4, 5]] = inp0.points[[3, 4, 5, 0, 1, 2]]
    np.testing.assert_array_equal(first["points"][0], swapped)
    np.testing.assert_array_equal(first["points"][1], people[1][0].points)
    assert [r is t.result for r, (_, t) in zip(first["results"], people[:3], strict=True)] == [True] * 3
    for k in (0, 2, 3):  # placed on the depth with its uncertainty and its readings
        x = out[k]
        assert isinstance(x, LiftedSkeleton) and x.std_m is not None and x.depth is not None
        np.testing.assert_array_equal(x.joints_m[:, 2], 2.0)
        np.testing.assert_array_equal(x.std_m, 0.05)
    # person 1: no finite joints from the fusion, placed as without depth
    x1, m1 = out[1], mono[1]
    assert isinstance(x1, LiftedSkeleton) and isinstance(m1, LiftedSkeleton) and x1.depth is None
    np.testing.assert_array_equal(x1.joints_m, m1.joints_m)
    assert m1.std_m is not None and x1.std_m is not None
    np.testing.assert_array_equal(x1.std_m, m1.std_m)
