"""Basis-file validation (issue 10): every hostile or careless file is refused with the reason,
as a BasisFileError and nothing else, and without reading more than the headers of a bomb."""

from __future__ import annotations

import resource
from pathlib import Path

import numpy as np
import pytest
from hostile_bases import HOSTILE, write_npz
from pose_lifter.core import BasisFileError, Lifter, PoseBases


@pytest.mark.parametrize("name", list(HOSTILE))
def test_hostile_basis_file_is_refused_with_the_reason(name: str, tmp_path: Path) -> None:
    build, reason = HOSTILE[name]
    path = build(tmp_path)
    with pytest.raises(BasisFileError) as info:
        PoseBases.load(path)
    assert reason in str(info.value) and str(path) in str(info.value), str(info.value)


def test_bomb_is_refused_from_its_header_without_expanding_it(tmp_path: Path) -> None:
    build, _ = HOSTILE["lying header (1.25 M starts)"]
    path = build(tmp_path)
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    with pytest.raises(BasisFileError, match="1250000 start poses"):
        PoseBases.load(path)
    assert resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before < 50_000  # kB: no 2 GB array


def test_a_saved_basis_file_round_trips_and_lifts(tmp_path: Path) -> None:
    b = PoseBases.load()
    b.save(tmp_path / "copy.npz")
    c = PoseBases.load(tmp_path / "copy.npz")
    np.testing.assert_array_equal(c.components, b.components)
    np.testing.assert_array_equal(c.start_alphas, b.start_alphas)
    # a file written member by member with the same arrays (no compression) is as good
    d = PoseBases.load(write_npz(tmp_path / "plain.npz", {
        "mean": b.mean, "components": b.components, "start_alphas": b.start_alphas,
        "limb_proportions": b.limb_proportions, "metadata": np.array('{"method": "sparse"}')}))
    assert d.method == "sparse" and Lifter(d).bases.n_bases == b.n_bases


def test_constructor_refuses_degenerate_bases_too() -> None:
    b = PoseBases.load()
    with pytest.raises(BasisFileError, match="limb_proportions"):
        PoseBases(b.mean, b.components, "x", b.start_alphas, -b.limb_proportions)
    with pytest.raises(BasisFileError, match="at least one start"):
        PoseBases(b.mean, b.components, "x", np.zeros((0, b.n_bases)), b.limb_proportions)
