"""Short CI versions of ``make fuzz`` and ``make soak`` (tools/reliability_node.py, issue 10):
the same drivers against the installed node, about a minute each. They exit 1 on a lost good
frame, a non-finite value published, the node's death or RSS growth above the limit."""

from __future__ import annotations

import re
import subprocess
import sys

import pytest

from .conftest import REPO

pytestmark = [pytest.mark.ros, pytest.mark.slow]

TOOL = REPO / "tools" / "reliability_node.py"


def _run(lifter_env: dict[str, str], *args: str) -> str:
    proc = subprocess.run([sys.executable, str(TOOL), *args], env=lifter_env, capture_output=True, text=True,
                          timeout=300, cwd=REPO)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0 and out.rstrip().endswith("PASS"), out
    return out


def test_short_fuzz(lifter_env: dict[str, str]) -> None:
    out = _run(lifter_env, "fuzz", "--messages", "1200")
    assert "1200 malformed messages of 28 kinds" in out
    assert "400/400" in out  # a good frame after every three bad ones, each answered


def test_short_soak(lifter_env: dict[str, str]) -> None:
    # frames flow: every frame published is answered, through a reliable queue deeper than the
    # run (300 for 15 s at 10 Hz), so a slow or starved machine delays answers but loses none;
    # a crash, leak or non-finite value still fails the run. The rate (30 Hz, 10 min) is make soak's.
    out = _run(lifter_env, "soak", "--seconds", "15", "--rate", "10", "--sample-every", "5", "--depth", "300")
    (answered, published), = re.findall(r"frames answered\s+(\d+)/(\d+)", out)
    assert answered == published and int(published) > 0, out
