"""tools/lift_hash.py: the hash that proves a refactor changes no result."""

from __future__ import annotations

import re
from pathlib import Path
from types import ModuleType

import numpy as np
import pytest
from tool_modules import load_tool

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def lift_hash() -> ModuleType:
    return load_tool("lift_hash")


def _digest(mod: ModuleType, *values: float) -> str:
    d = mod.Digest(9)
    d.floats(np.array(values))
    return str(d.hexdigest())


def test_digest_ignores_round_off_below_the_rounding_and_sees_changes_above_it(lift_hash: ModuleType) -> None:
    base = _digest(lift_hash, 0.25, -1.5, 0.0)
    assert _digest(lift_hash, 0.25 + 1e-13, -1.5 - 1e-13, -0.0) == base  # last bits, signed zero
    assert _digest(lift_hash, 0.25 + 1e-7, -1.5, 0.0) != base
    assert _digest(lift_hash, -1.5, 0.25, 0.0) != base  # order matters


def test_two_runs_print_the_same_hashes(lift_hash: ModuleType, capsys: pytest.CaptureFixture[str]) -> None:
    argv = ["--bags", str(REPO / "bags" / "two_people.mcap"), "--max-messages", "3", "--starts", "3",
            "--record", "2", "--record-every", "3"]
    outs = []
    for _ in range(2):
        assert lift_hash.main(argv) == 0
        outs.append(capsys.readouterr().out)
    assert outs[0] == outs[1]
    hashes = dict(re.findall(r"^(lifts paper|lifts hybrid|metrics|pose_step|total)\s+([0-9a-f]{64})", outs[0],
                             re.M))
    assert len(hashes) == 5
    assert len(set(hashes.values())) == 5  # each section hashes something of its own
    assert "(6 skeletons" in outs[0] and "(4 recorded calls, 12 solves)" in outs[0]
