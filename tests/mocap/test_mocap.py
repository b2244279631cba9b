"""pose_lifter.mocap.cmu against the check numbers of shared/data/README.md (real CMU data)."""

from __future__ import annotations

import itertools
import warnings
from pathlib import Path

import numpy as np
import pytest
import tolerances as tol
from cmu_data import DATA, needs_data
from pose_lifter.core.model.skeleton import limb_lengths
from pose_lifter.mocap import cmu as mocap

# (trial, format, frames, L upper arm, L forearm, L thigh, L shin) from the data README
CHECKS = [
    ("01_03", "amc", 4510, 0.281, 0.197, 0.404, 0.423),
    ("02_05", "amc", 1854, 0.275, 0.189, 0.429, 0.411),
    ("09_01", "bvh", 148, 0.312, 0.202, 0.426, 0.436),
]


def test_missing_data_dir_is_a_clear_error(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    with pytest.raises(mocap.MocapDataError, match="POSE_LIFTER_CMU_DATA"):
        mocap.resolve_data_dir(tmp_path / "nope")
    monkeypatch.setenv(mocap.DATA_ENV_VAR, str(tmp_path))
    with pytest.raises(mocap.MocapDataError):
        mocap.load_trial("01_03")
    with pytest.raises(FileNotFoundError):  # MocapDataError is a FileNotFoundError too
        mocap.read_manifest()


def test_bvh_parser_and_fk_on_a_tiny_file(tmp_path: Path) -> None:
    # two-bone chain: rotating the root 90 degrees about Z swings the chain from +x to +y;
    # channel order "Zrotation Xrotation" with a 90-degree X rotation of the child must act
    # in the child's frame after Z (intrinsic), not before.
    text = """HIERARCHY
ROOT A
{
  OFFSET 0 0 0
  CHANNELS 6 Xposition Yposition Zposition Zrotation Yrotation Xrotation
  JOINT B
  {
    OFFSET 1 0 0
    CHANNELS 2 Zrotation Xrotation
    JOINT C
    {
      OFFSET 0 1 0
      CHANNELS 1 Zrotation
      End Site
      {
        OFFSET 0 0 1
      }
    }
  }
}
MOTION
Frames: 2
Frame Time: 0.5
0 0 0 0 0 0 0 0 0
1 2 3 90 0 0 90 90 0
"""
    p = tmp_path / "t.bvh"
    p.write_text(text)
    bvh = mocap.parse_bvh(p)
    assert bvh.names == ["A", "B", "C"] and bvh.parents == [-1, 0, 1] and bvh.frame_time == 0.5
    pos = mocap.bvh_positions(bvh, ["A", "B", "C"])
    np.testing.assert_allclose(pos[0], [[0, 0, 0], [1, 0, 0], [1, 1, 0]], atol=tol.ROUND_OFF)
    # frame 1: root at (1,2,3) turned 90 deg about z: B at root + (0,1,0). B's channels
    # Z=90, X=90 mean Rz @ Rx (X acts first): C's offset (0,1,0) -> (0,0,1) -> unchanged by
    # the two z turns, so C = B + (0,0,1). The reversed order would give B + (0,-1,0).
    np.testing.assert_allclose(pos[1], [[1, 2, 3], [1, 3, 3], [1, 3, 4]], atol=tol.ROUND_OFF)


@needs_data
def test_manifest() -> None:
    rows = mocap.read_manifest(DATA)
    assert {r.paper_split for r in rows} == {"train", "test", "other"}
    train = {r.trial for r in rows if r.paper_split == "train"}
    assert train and all(t.startswith("01_") for t in train)
    assert mocap.find_trial("07_01", DATA).format == "amc"  # AMC preferred over the BVH copy
    assert mocap.find_trial("09_01", DATA).format == "bvh"
    with pytest.raises(mocap.MocapDataError):
        mocap.find_trial("99_99", DATA)


@needs_data
@pytest.mark.parametrize(("trial", "fmt", "frames", *"abcd"), CHECKS)
def test_readme_check_numbers(trial: str, fmt: str, frames: int, a: float, b: float, c: float,
                              d: float) -> None:
    assert mocap.find_trial(trial, DATA).format == fmt
    x = mocap.load_trial(trial, DATA)
    assert x.shape == (frames, 12, 3)
    lengths = limb_lengths(x)
    np.testing.assert_allclose(lengths[0, [0, 1, 4, 5]], [a, b, c, d], atol=0.0006)
    assert np.ptp(lengths, axis=0).max() < tol.ROUND_OFF_ACCUMULATED  # rigid bones
    # Y-up: ankles below hips below shoulders, feet near the floor
    assert np.all(x[:, [8, 11], 1].mean(axis=1) < x[:, [6, 9], 1].mean(axis=1))
    assert np.all(x[:, [6, 9], 1].mean(axis=1) < x[:, [0, 3], 1].mean(axis=1))


@needs_data
def test_amc_and_bvh_agree_to_micrometres() -> None:
    amc = mocap.load_amc(DATA / "asf_amc" / "07_01.amc")
    bvh = mocap.load_bvh(DATA / "bvh" / "07" / "07_01.bvh")
    assert amc.shape == bvh.shape == (316, 12, 3)
    assert np.abs(amc - bvh).max() < tol.MOCAP_FORMAT_AGREEMENT
    # the thorax trap: without the vector the upper body sits ~12 cm too low
    low = mocap.load_bvh(DATA / "bvh" / "07" / "07_01.bvh", thorax=np.zeros(3), max_frames=50)
    drop = (amc[:50, :6] - low[:, :6])[..., 1]
    assert 0.10 < np.median(drop) < 0.13
    np.testing.assert_allclose(low[:, 6:], amc[:50, 6:], atol=tol.MOCAP_FORMAT_AGREEMENT)  # legs unaffected
    # the table value equals the ASF's thorax (the default reads the .asf)
    table = mocap.load_bvh(DATA / "bvh" / "07" / "07_01.bvh",
                           thorax=np.array(mocap.THORAX_VECTORS["07"]), max_frames=50)
    np.testing.assert_allclose(table, amc[:50], atol=tol.MOCAP_FORMAT_AGREEMENT)


@needs_data
def test_step_and_max_frames() -> None:
    full = mocap.load_trial("09_01", DATA)
    sub = mocap.load_trial("09_01", DATA, step=4, max_frames=10)
    np.testing.assert_array_equal(sub, full[::4][:10])
    amc = mocap.load_trial("02_03", DATA)
    np.testing.assert_array_equal(mocap.load_trial("02_03", DATA, step=3), amc[::3])
    with pytest.raises(ValueError):
        mocap.load_trial("02_03", DATA, step=0)


@needs_data
def test_unknown_subject_thorax_estimate_warns() -> None:
    with pytest.warns(UserWarning, match="thorax"):
        x = mocap.load_trial("08_01", DATA, max_frames=5)
    assert x.shape == (5, 12, 3) and np.all(np.isfinite(x))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mocap.load_trial("09_02", DATA, max_frames=5)  # known subject: no warning


@needs_data
def test_amc_fast_and_fallback_parsers_agree(tmp_path: Path) -> None:
    lines = (DATA / "asf_amc" / "02_05.amc").read_text().splitlines()
    head = lines.index(":DEGREES") + 1
    frame_starts = [i for i in range(head, len(lines)) if lines[i].strip().isdigit()][:4]
    frames = [lines[a:b] for a, b in itertools.pairwise(frame_starts)]  # 3 frames
    regular = tmp_path / "regular.amc"
    regular.write_text("\n".join(lines[:head] + [ln for f in frames for ln in f]) + "\n")
    shuffled = [frames[0], frames[1], [frames[2][0], *frames[2][1:][::-1]]]  # bone order changes
    irregular = tmp_path / "irregular.amc"
    irregular.write_text("\n".join(lines[:head] + [ln for f in shuffled for ln in f]) + "\n")
    a, b = mocap.parse_amc(regular), mocap.parse_amc(irregular)
    assert a.keys() == b.keys() and a["root"].shape == (3, 6)
    for k in a:
        np.testing.assert_array_equal(a[k], b[k])
    np.testing.assert_array_equal(a["rfemur"], mocap.parse_amc(DATA / "asf_amc" / "02_05.amc")["rfemur"][:3])
