"""Careless command lines and broken bags (issue 10): one ``pose-lifter <cmd>: error:`` line, the
documented exit code (2 usage, 1 data, 130 interrupted, 143 terminated), no traceback and no output
file, and no worker process left behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from pose_lifter import cli

REPO = Path(__file__).resolve().parents[1]
BAG = REPO / "bags" / "two_people.mcap"
FIVE = REPO / "bags" / "five_people.mcap"


def _broken(tmp_path: Path, kind: str) -> Path:
    p = tmp_path / f"{kind}.mcap"
    if kind == "truncated":
        p.write_bytes(BAG.read_bytes()[:20_000])
    elif kind == "random":
        p.write_bytes(os.urandom(5000))
    else:
        p.write_bytes(b"")
    return p


@pytest.mark.parametrize("kind", ["truncated", "random", "empty"])
def test_broken_bag_is_a_data_error(kind: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out.mcap"
    assert cli.main(["lift", str(_broken(tmp_path, kind)), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("pose-lifter lift: error: cannot read "), err
    assert not out.exists() and list(tmp_path.glob(".bagwriter-*")) == []


@pytest.mark.parametrize("option", ["--workers=0", "--workers=-1", "--every=0", "--max-messages=0",
                                    "--lower-leg-length=-1", "--lower-leg-length=nan", "--n-starts=0",
                                    "--max-keypoints=0", "--workers=x"])
def test_out_of_range_option_is_a_usage_error(option: str, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "out.mcap"
    with pytest.raises(SystemExit) as exc:
        cli.main(["lift", str(BAG), "--out", str(out), option])
    assert exc.value.code == 2
    last = capsys.readouterr().err.strip().splitlines()[-1]
    assert last.startswith("pose-lifter lift: error: argument " + option.split("=")[0]), last
    assert not out.exists()


def test_out_naming_a_directory_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert cli.main(["lift", str(BAG), "--out", str(tmp_path), "--overwrite"]) == 2
    assert "is a directory" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_bad_basis_file_is_a_data_error(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    empty = tmp_path / "empty.npz"
    empty.write_bytes(b"")
    assert cli.main(["lift", str(BAG), "--out", str(tmp_path / "o.mcap"), "--bases-file", str(empty)]) == 1
    assert "not an .npz" in capsys.readouterr().err
    assert not (tmp_path / "o.mcap").exists()


def test_workers_are_capped_by_tracks_and_cores(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from concurrent import futures

    sizes: list[int] = []
    real = futures.ProcessPoolExecutor

    class Counting(real):  # type: ignore[misc, valid-type]
        def __init__(self, n: int, *args: object, **kwargs: object) -> None:
            sizes.append(n)
            super().__init__(n, *args, **kwargs)

    monkeypatch.setattr(futures, "ProcessPoolExecutor", Counting)
    out = tmp_path / "o.mcap"
    assert cli.main(["lift", str(FIVE), "--out", str(out), "--workers", "1000", "--max-messages", "2",
                     "--quiet"]) == 0
    assert sizes == [min(5, os.cpu_count() or 1)] and out.is_file()


def _children(pid: int) -> list[int]:
    """Process ids whose parent is ``pid`` (from /proc)."""
    out = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.append(int(stat.parent.name))
    return out


def test_ctrl_c_exits_130_with_one_line(tmp_path: Path) -> None:
    out = tmp_path / "o.mcap"
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    # SIGINT at its default in the child whatever this process inherited: a shell ignores it in
    # background jobs, and Python then never raises KeyboardInterrupt (the lift would run on)
    proc = subprocess.Popen([sys.executable, "-m", "pose_lifter.cli", "lift", str(FIVE), "--out", str(out),
                             "--workers", "2", "--solver", "cvxpy", "--quiet"],
                            stderr=subprocess.PIPE, text=True, env=env,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    # interrupt while lifting: once the two workers are forked (the slow reference solver),
    # however long the imports and the reading take on a loaded machine
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline and proc.poll() is None and not _children(proc.pid):
        time.sleep(0.1)
    time.sleep(1.0)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 130, err
    assert err.strip().splitlines() == ["pose-lifter lift: interrupted"], err
    assert not out.exists() and list(tmp_path.glob(".bagwriter-*")) == []


def _alive(pid: int) -> bool:
    """Whether process ``pid`` runs (not gone, not a zombie waiting to be reaped)."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _lifting(tmp_path: Path) -> tuple[subprocess.Popen[str], list[int], Path]:
    """``pose-lifter lift`` of the five-person bag on two workers (the slow reference solver), once
    its workers are forked: the process, the workers' ids, the output it would write."""
    out = tmp_path / "o.mcap"
    proc = subprocess.Popen([sys.executable, "-m", "pose_lifter.cli", "lift", str(FIVE), "--out", str(out),
                             "--workers", "2", "--solver", "cvxpy", "--quiet"],
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONUNBUFFERED": "1"})
    deadline = time.monotonic() + 120.0
    while time.monotonic() < deadline and proc.poll() is None and len(_children(proc.pid)) < 2:
        time.sleep(0.1)
    time.sleep(1.0)
    workers = _children(proc.pid)
    assert proc.poll() is None and len(workers) >= 2, workers
    return proc, workers, out


def _gone(pids: list[int], within_s: float) -> bool:
    deadline = time.monotonic() + within_s
    while time.monotonic() < deadline and any(_alive(p) for p in pids):
        time.sleep(0.1)
    return not any(_alive(p) for p in pids)


def test_sigterm_exits_143_with_one_line_and_stops_the_workers(tmp_path: Path) -> None:
    """SIGTERM to the command alone (a supervisor's, ``timeout``'s) unwinds it as Ctrl-C does: its
    workers stopped, no output, one line, exit 143 (128 + SIGTERM)."""
    proc, workers, out = _lifting(tmp_path)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == 143, err
    assert err.strip().splitlines() == ["pose-lifter lift: terminated"], err
    assert _gone(workers, 30.0)
    assert not out.exists() and list(tmp_path.glob(".bagwriter-*")) == []


def test_the_workers_end_with_a_killed_command(tmp_path: Path) -> None:
    """A command killed outright (SIGKILL: no handler runs) takes its workers with it: each was
    told to end with its parent (``die_with_parent``), not to wait for its pool's next task."""
    proc, workers, _ = _lifting(tmp_path)
    proc.kill()
    proc.communicate(timeout=30)
    assert _gone(workers, 30.0), [p for p in workers if _alive(p)]
