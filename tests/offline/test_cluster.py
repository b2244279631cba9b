"""``pose-lifter lift --scheduler``: a collection lifted on a real Dask cluster (a scheduler and two
worker processes on localhost) equals the local run, message for message."""

from __future__ import annotations

import json
import os
import shutil
import time
from pathlib import Path
from typing import Any

import distributed
import pytest
from lift_compare import assert_same_lift
from pose_lifter import cli

BAGS = Path(__file__).resolve().parents[2] / "bags"
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


def _busy(client: distributed.Client) -> int:
    """Tasks the scheduler still holds plus tasks the workers are still executing."""
    held = int(client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks)))
    running = client.run(lambda dask_worker: dask_worker.state.executing_count)
    return held + sum(int(n) for n in running.values())


def test_on_dask_a_damaged_bag_fails_alone_a_stop_cancels_and_a_run_resumes(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]) -> None:
    """The cluster path as the local one (tests/offline/test_collection.py): a damaged bag is reported and
    the others lifted; Ctrl-C in the waiting client cancels the cluster's tasks and exits 130;
    the next run resumes (skips what the manifest records as done, reports the damaged bag again)
    and ends with every bag equal to the local lift's and no partial output."""
    src = tmp_path / "campaign"
    src.mkdir()
    for name, rel in (("two_people.mcap", "two.mcap"), ("walk_noisy.mcap", "walk.mcap"),
                      ("punch_outliers.mcap", "punch.mcap")):
        shutil.copy(BAGS / name, src / rel)
    (src / "broken.mcap").write_bytes((BAGS / "walk_clean.mcap").read_bytes()[:5000])
    local, out = tmp_path / "local", tmp_path / "dask"
    assert cli.main(["lift", str(src), "--out", str(local), "--workers", "1", *FAST]) == 1
    capsys.readouterr()
    original = distributed.as_completed

    def one_then_stop(futures: Any, *args: Any, **kwargs: Any) -> Any:
        """Ctrl-C while the client waits, after the first bag came back."""
        it = original(futures, *args, **kwargs)
        yield next(it)
        raise KeyboardInterrupt

    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                                  scheduler_port=0) as cluster, \
            distributed.Client(cluster.scheduler_address) as client:
        remote = ["lift", str(src), "--out", str(out), "--scheduler", cluster.scheduler_address, *FAST]
        monkeypatch.setattr(distributed, "as_completed", one_then_stop)
        assert cli.main(remote) == 130
        monkeypatch.setattr(distributed, "as_completed", original)
        # the stop cancelled the rest: the cluster drains (a task already running ends on its worker)
        deadline = time.monotonic() + 300
        while _busy(client) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert _busy(client) == 0
        entries = json.loads((out / "pose_lifter_manifest.json").read_text())["bags"]
        done = {rel for rel, e in entries.items() if e["status"] == "done"}
        assert 1 <= len(done) < 4 and "broken.mcap" not in done
        capsys.readouterr()
        assert cli.main(remote) == 1  # resumed on the cluster
        text = capsys.readouterr().out
        lifted = 3 - len(done)
        assert f"4 bags: {lifted} lifted, {len(done)} skipped (done already), 1 failed" in text
        assert "broken.mcap" in (out / "pose_lifter_errors.txt").read_text()
    assert not list(out.rglob(".bagwriter-*")) and not (out / "broken.mcap").exists()
    for rel in ("two.mcap", "walk.mcap", "punch.mcap"):
        assert assert_same_lift(local / rel, out / rel) > 6
