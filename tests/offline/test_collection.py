"""``pose-lifter lift`` on a collection: layout, manifest and resume, damaged bags, stopped runs."""

from __future__ import annotations

import json
import multiprocessing
import shutil
import signal
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import pytest
from lift_compare import assert_same_lift
from pose_lifter import cli
from pose_lifter.offline import bags
from pose_lifter.offline import workers as workers_module
from pose_lifter.offline.bags import BagError
from pose_lifter.offline.collection import ERRORS_NAME, MANIFEST_NAME, expand_inputs, plan_jobs

REPO = Path(__file__).resolve().parents[2]
BAGS = REPO / "bags"
# short runs: the first messages of each bag (the behaviour, not the solver, is under test)
FAST = ["--max-messages", "6", "--quiet"]


def messages(path: Path) -> list[tuple[str, str, int, bytes]]:
    """Every message of a bag, serialised, in order: what two lifts must agree on."""
    return [(r.topic, r.msgtype, r.stamp_ns, r.data) for r in bags.read_raw(path)]


def collection(tmp: Path) -> Path:
    """A small campaign: two bags at the top, one in a sub-directory."""
    src = tmp / "campaign"
    (src / "robot_b").mkdir(parents=True)
    shutil.copy(BAGS / "walk_clean.mcap", src / "walk.mcap")
    shutil.copy(BAGS / "punch_clean.mcap", src / "punch.mcap")
    shutil.copy(BAGS / "two_people.mcap", src / "robot_b" / "two.mcap")
    return src


def outputs(out: Path) -> dict[str, int]:
    """Relative path -> mtime_ns of every .mcap under ``out``."""
    return {p.relative_to(out).as_posix(): p.stat().st_mtime_ns for p in sorted(out.rglob("*.mcap"))}


def manifest(out: Path) -> dict[str, dict[str, object]]:
    return dict(json.loads((out / MANIFEST_NAME).read_text())["bags"])


def test_inputs_files_directories_globs_and_the_output_directory_left_out(tmp_path: Path) -> None:
    src = collection(tmp_path)
    files, root = expand_inputs([str(src)])
    assert [f.relative_to(root).as_posix() for f in files] == ["punch.mcap", "robot_b/two.mcap", "walk.mcap"]
    files, root = expand_inputs([str(src / "*.mcap"), str(src / "robot_b" / "two.mcap")])
    assert root == src.resolve() and len(files) == 3
    files, _ = expand_inputs([str(src / "**" / "two.mcap")])
    assert [f.name for f in files] == ["two.mcap"]
    (src / "lifted").mkdir()
    shutil.copy(BAGS / "walk_clean.mcap", src / "lifted" / "walk.mcap")  # an earlier run's output
    jobs = plan_jobs([str(src)], src / "lifted")
    assert sorted(j.rel for j in jobs) == ["punch.mcap", "robot_b/two.mcap", "walk.mcap"]
    with pytest.raises(BagError, match="bag not found"):
        expand_inputs([str(src / "nope.mcap")])
    with pytest.raises(BagError, match=r"no \.mcap file matches"):
        expand_inputs([str(src / "*.bag")])
    with pytest.raises(BagError, match="would overwrite"):
        plan_jobs([str(src / "walk.mcap"), str(src / "punch.mcap")], src)


def test_collection_keeps_the_layout_and_equals_one_bag_at_a_time(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    src = collection(tmp_path)
    out = tmp_path / "out"
    assert cli.main(["lift", str(src), "--out", str(out), "--workers", "2", *FAST]) == 0
    text = capsys.readouterr().out
    assert "3 bags: 3 lifted, 0 skipped" in text and "0 failed" in text and "poses/s" in text
    assert list(outputs(out)) == ["punch.mcap", "robot_b/two.mcap", "walk.mcap"]
    single = tmp_path / "single.mcap"
    assert cli.main(["lift", str(src / "robot_b" / "two.mcap"), "--out", str(single), "--workers", "1",
                     *FAST]) == 0
    assert assert_same_lift(out / "robot_b" / "two.mcap", single) > 12
    entries = manifest(out)
    assert entries["robot_b/two.mcap"]["poses"] == 12 and entries["walk.mcap"]["status"] == "done"
    # several bags are never written into one file
    two = [str(src / "walk.mcap"), str(src / "punch.mcap")]
    assert cli.main(["lift", *two, "--out", str(tmp_path / "x.mcap")]) == 2
    assert "names a .mcap file" in capsys.readouterr().err and not (tmp_path / "x.mcap").exists()


def test_a_damaged_bag_is_reported_and_the_others_lifted(tmp_path: Path,
                                                         capsys: pytest.CaptureFixture[str]) -> None:
    src = collection(tmp_path)
    (src / "robot_b" / "broken.mcap").write_bytes((BAGS / "walk_clean.mcap").read_bytes()[:5000])
    out = tmp_path / "out"
    assert cli.main(["lift", str(src), "--out", str(out), "--workers", "2", *FAST]) == 1
    text = capsys.readouterr().out
    assert "4 bags: 3 lifted, 0 skipped (done already), 1 failed" in text
    assert "broken.mcap" in text and str(out / ERRORS_NAME) in text
    assert list(outputs(out)) == ["punch.mcap", "robot_b/two.mcap", "walk.mcap"]
    errors = (out / ERRORS_NAME).read_text()
    assert "broken.mcap" in errors and "cannot read" in errors and "Traceback" in errors
    assert manifest(out)["robot_b/broken.mcap"]["status"] == "failed"
    # a second run skips the lifted bags and tries the failed one again (it failed again)
    assert cli.main(["lift", str(src), "--out", str(out), *FAST]) == 1
    assert "3 skipped (done already), 1 failed" in capsys.readouterr().out


def test_a_resumed_run_skips_what_is_done_and_redoes_what_changed(tmp_path: Path,
                                                                  capsys: pytest.CaptureFixture[str]) -> None:
    src = collection(tmp_path)
    out = tmp_path / "out"
    assert cli.main(["lift", str(src), "--out", str(out), "--workers", "1", *FAST]) == 0
    first = outputs(out)
    assert cli.main(["lift", str(src), "--out", str(out), *FAST]) == 0
    assert "3 bags: 0 lifted, 3 skipped" in capsys.readouterr().out
    assert outputs(out) == first
    # an input changed (another recording under the same name): only that bag is lifted again
    shutil.copy(BAGS / "run_orbit.mcap", src / "walk.mcap")
    assert cli.main(["lift", str(src), "--out", str(out), *FAST]) == 0
    assert "3 bags: 1 lifted, 2 skipped" in capsys.readouterr().out
    now = outputs(out)
    assert now["walk.mcap"] != first["walk.mcap"] and now["punch.mcap"] == first["punch.mcap"]
    assert messages(out / "walk.mcap")[0][2] == messages(BAGS / "run_orbit.mcap")[0][2]
    # other settings: every bag again
    assert cli.main(["lift", str(src), "--out", str(out), "--max-messages", "4", "--quiet"]) == 0
    assert "3 bags: 3 lifted, 0 skipped" in capsys.readouterr().out
    assert manifest(out)["robot_b/two.mcap"]["poses"] == 8
    # --overwrite: every bag again with the same settings
    again = ["lift", str(src), "--out", str(out), "--max-messages", "4", "--quiet", "--overwrite"]
    assert cli.main(again) == 0
    assert "3 bags: 3 lifted, 0 skipped" in capsys.readouterr().out
    # an output deleted by hand is lifted again
    (out / "punch.mcap").unlink()
    assert cli.main(["lift", str(src), "--out", str(out), "--max-messages", "4", "--quiet"]) == 0
    assert "3 bags: 1 lifted, 2 skipped" in capsys.readouterr().out


class Stop(KeyboardInterrupt):
    """Ctrl-C in the middle of writing a bag."""


@pytest.mark.parametrize("workers", ["1", "2"])
def test_a_stopped_run_leaves_no_partial_output_and_resumes(workers: str, tmp_path: Path,
                                                            monkeypatch: pytest.MonkeyPatch,
                                                            capsys: pytest.CaptureFixture[str]) -> None:
    src = collection(tmp_path)
    out = tmp_path / "out"
    write_cdr = bags.BagWriter.write_cdr
    written: list[str] = []

    def stop_in_two(self: bags.BagWriter, topic: str, stamp_ns: int, data: bytes, msgtype: str) -> None:
        written.append(self.path.name)
        if written.count("two.mcap") > 5:  # half way through the two-person bag's 12 answers
            raise Stop
        write_cdr(self, topic, stamp_ns, data, msgtype)

    monkeypatch.setattr(bags.BagWriter, "write_cdr", stop_in_two)
    assert cli.main(["lift", str(src), "--out", str(out), "--workers", workers, *FAST]) == 130
    done = {rel for rel, e in manifest(out).items() if e["status"] == "done"}
    assert "robot_b/two.mcap" not in done
    # every output the manifest records exists; with several workers a bag finished in another
    # process may be complete under its final name and not yet recorded when the stop lands (it is
    # lifted again on resume); every output under a final name is complete (it reads to its end)
    finished = set(outputs(out))
    assert done <= finished and "robot_b/two.mcap" not in finished
    assert not list(out.rglob(".bagwriter-*"))  # no temporary left either
    assert not multiprocessing.active_children()  # the stopped pool's workers are gone
    for rel in finished:
        assert messages(out / rel)
    monkeypatch.setattr(bags.BagWriter, "write_cdr", write_cdr)
    capsys.readouterr()
    assert cli.main(["lift", str(src), "--out", str(out), "--workers", workers, *FAST]) == 0
    assert f"{3 - len(done)} lifted, {len(done)} skipped" in capsys.readouterr().out
    assert list(outputs(out)) == ["punch.mcap", "robot_b/two.mcap", "walk.mcap"]


def _deaf_to_sigterm() -> None:
    signal.signal(signal.SIGTERM, signal.SIG_IGN)


def test_stopping_a_pool_ends_workers_that_outlive_sigterm(monkeypatch: pytest.MonkeyPatch) -> None:
    # A worker may survive SIGTERM (here it ignores it; a task that turns it into an exception is
    # kept alive by the executor's worker loop): the stop must still end, every worker with it.
    monkeypatch.setattr(workers_module, "STOP_TIMEOUT", 0.5)
    ex = ProcessPoolExecutor(2, mp_context=multiprocessing.get_context("fork"), initializer=_deaf_to_sigterm)
    running = [ex.submit(time.sleep, 3600) for _ in range(3)]
    while not any(f.running() for f in running):
        time.sleep(0.01)
    workers = list(ex._processes.values())
    workers_module.stop_workers(ex)
    # each reaped once, by one thread: none left marked alive (the executor's manager thread joins
    # the same workers; had both waited at once, the loser's wait would find no child and leave
    # its process marked alive)
    assert workers and not any(p.is_alive() for p in workers)
    assert not multiprocessing.active_children()


def test_the_collection_path_loads_neither_dask_nor_the_solver_until_it_lifts() -> None:
    import subprocess
    import sys

    code = ("import sys, pose_lifter.cli, pose_lifter.offline.collection; "
            "print(sorted(m for m in ('dask', 'distributed', 'numba', 'pose_lifter.core.lift.lifter') "
            "if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
    from pose_lifter.core.track import defaults as track_defaults
    from pose_lifter.messages.frame import FrameSettings
    from pose_lifter.offline.settings import LiftSettings

    s = LiftSettings()
    assert s.frame.track_timeout == track_defaults.DEFAULT_TRACK_TIMEOUT_S == FrameSettings().track_timeout
    assert s.frame.reinit_ratio == track_defaults.DEFAULT_REINIT_RATIO == FrameSettings().reinit_ratio
    assert s.digest() == LiftSettings().digest() != LiftSettings(every=2).digest()
