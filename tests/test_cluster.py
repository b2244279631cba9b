"""``pose-lifter lift --scheduler``: a collection lifted on a real Dask cluster (a scheduler and two
worker processes on localhost) equals the local run, message for message."""

from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

import distributed
import pytest
from lift_compare import assert_same_lift
from pose_lifter import cli

BAGS = Path(__file__).resolve().parents[1] / "bags"
FAST = ["--max-messages", "6", "--quiet"]


def test_the_dask_path_equals_the_local_path_on_three_bags(tmp_path: Path,
                                                           capsys: pytest.CaptureFixture[str]) -> None:
    src = tmp_path / "campaign"
    (src / "cam2").mkdir(parents=True)
    for name, rel in (("two_people.mcap", "two.mcap"), ("walk_noisy.mcap", "walk.mcap"),
                      ("punch_outliers.mcap", "cam2/punch.mcap")):
        shutil.copy(BAGS / name, src / rel)
    local, remote = tmp_path / "local", tmp_path / "dask"
    assert cli.main(["lift", str(src), "--out", str(local), "--workers", "1", *FAST]) == 0
    # two worker processes, one thread each: a scheduler of its own and workers that import
    # pose_lifter themselves (spawned, not forked from this process)
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  scheduler_port=0) as cluster:
        assert cli.main(["lift", str(src), "--out", str(remote), "--scheduler", cluster.scheduler_address,
                         *FAST]) == 0
        with distributed.Client(cluster.scheduler_address) as client:
            assert len(client.scheduler_info()["workers"]) == 2
    text = capsys.readouterr().out
    assert "3 bags: 3 lifted, 0 skipped (done already), 0 failed" in text
    for rel in ("two.mcap", "walk.mcap", "cam2/punch.mcap"):
        assert assert_same_lift(local / rel, remote / rel) > 6
    # the manifest says which process lifted each bag: the cluster's workers, not this one
    entries = json.loads((remote / "pose_lifter_manifest.json").read_text())["bags"]
    assert {e["status"] for e in entries.values()} == {"done"}
    assert all(not e["worker"].endswith(f":{os.getpid()}") for e in entries.values())
