"""Hostile and careless input on the real graph (issue 10): the installed ``lifter`` process is
given hostile basis files live, oversized strings, misspelt and out-of-range start-up parameters
and signals at start-up; it must refuse with a reason, stay alive and keep answering."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tolerances as tol
from hostile_bases import HOSTILE

from .conftest import LIFTER_EXE, SHUTDOWN_TIMEOUT, GraphClient, all_finite
from .test_lifter_graph import CHEAP, STANDING, coco_keypoints, frame

pytestmark = pytest.mark.ros


def _joints(answer: Any) -> np.ndarray:
    return np.array([[(p.x, p.y, p.z) for p in s.joints] for s in answer.skeletons.skeletons])


def test_live_bases_file_change_with_hostile_files_is_refused(start_lifter: Any, graph: GraphClient,
                                                              tmp_path: Path) -> None:
    lifter = start_lifter(params={**CHEAP, "warm_start": False})
    graph.wait_for_lifter(lifter)
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    before = graph.send(frame(t, 10**9, [(-1, kp, c)]))
    refused = []
    for i, (name, (build, reason)) in enumerate(HOSTILE.items()):
        folder = tmp_path / f"f{i}"
        folder.mkdir()
        (r,) = graph.set_parameters(bases_file=str(build(folder)))
        assert not r.successful and reason in r.reason, (name, r.reason)
        refused.append(name)
        assert lifter.alive(), f"the lifter died on {name}; log:\n{lifter.log()[-2000:]}"
    # the package's own py.typed (an empty file) as basis file
    typed = Path(__import__("pose_lifter").__file__).parent / "py.typed"
    (r,) = graph.set_parameters(bases_file=str(typed))
    assert not r.successful and "not an .npz" in r.reason
    # nothing stuck: same parameter, same solver, same answer
    assert graph.get_parameters("bases_file") == {"bases_file": ""}
    after = graph.send(frame(t, 2 * 10**9, [(-1, kp, c)]))
    np.testing.assert_allclose(_joints(after), _joints(before), atol=tol.ROUND_OFF_ACCUMULATED)
    assert len(refused) == len(HOSTILE) >= 18
    assert "Traceback" not in lifter.log()


def test_megabyte_frame_id_is_skipped_not_amplified(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params=CHEAP)
    graph.wait_for_lifter(lifter)
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    huge = frame(t, 10**9, [(i, kp + 3.0 * i, c) for i in range(64)], frame_id="x" * 1_000_000)
    # a best-effort reader may lose a 1 MB sample (fragments): publish until the lifter warns
    def warned(text: str, message: Any) -> bool:
        graph.pub_keypoints.publish(message)
        end = time.monotonic() + 0.2
        while time.monotonic() < end:
            graph.executor.spin_once(timeout_sec=0.05)
        return text in lifter.log()
    assert any(warned("header.frame_id of 1000000 characters", huge) for _ in range(30)), lifter.log()
    good = graph.send(frame(t, 2 * 10**9, [(0, kp, c)]))  # answers come in order: none for `huge`
    assert [len(a.header.frame_id) for a in graph.skeletons] == [len("camera_optical")]
    assert all(len(mk.header.frame_id) < 100 for a in graph.markers for mk in a.markers)
    assert len(good.skeletons.skeletons) == 1 and all_finite(good.skeletons)
    # a 1 MB layout name: skipped too, and never logged whole
    long_layout = frame(t, 3 * 10**9, [(0, kp, c)], layout="L" * 1_000_000)
    assert any(warned("layout name of 1000000 characters", long_layout) for _ in range(30)), lifter.log()
    graph.send(frame(t, 4 * 10**9, [(0, kp, c)]))
    assert len(graph.skeletons) == 2
    assert max(len(line) for line in lifter.log().splitlines()) < 1000


def test_each_kind_is_warned_and_huge_confidences_are_clipped(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params=CHEAP)
    graph.wait_for_lifter(lifter)
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    # another kind first (its warning must not silence the next kind), then out-of-order stamps
    graph.send(frame(t, 10**9, [(0, np.zeros((3, 2)), np.ones(3))]))
    graph.send(frame(t, 5 * 10**9, [(3, kp, c)]))
    for i in range(40):
        answer = graph.send(frame(t, 5 * 10**9 - (i + 1) * 10_000_000, [(3, kp, c)]))
        assert answer.skeletons.skeletons == []
    huge = np.where(c > 0, np.float32(3.4e38), 0.0)
    answer = graph.send(frame(t, 6 * 10**9, [(-1, kp, huge)]))
    assert len(answer.skeletons.skeletons) == 1 and all_finite(answer.skeletons)
    graph.spin_until(lambda: "older than its last frame" in lifter.log()
                     and "outside [0, 1]" in lifter.log(), 10.0, "the warnings")
    warnings = [line for line in lifter.log().splitlines() if line.startswith("[WARN]")]
    assert len(warnings) == 3, warnings  # one per kind: wrong keypoint count, out of order, clipped


def _run_lifter(env: dict[str, str], *ros_args: str, timeout: float = 60.0) -> tuple[int, str]:
    proc = subprocess.run([str(LIFTER_EXE), "--ros-args", "-p", "stats_period:=0.0", *ros_args], env=env,
                          capture_output=True, text=True, timeout=timeout)
    return proc.returncode, proc.stdout + proc.stderr


@pytest.mark.parametrize(("args", "reason"), [
    (("-p", "theta:=-1"), "theta"),
    (("-p", "n_starts:=0"), "n_starts out of range"),
    (("-p", "theta:=abc"), "expecting type 'DOUBLE'"),
    (("-p", "n_start:=1", "-p", "strict_parameters:=true"),
     "unknown parameter: n_start (did you mean n_starts?)"),
    (("-p", "bases_file:=EMPTY"), "not an .npz"),
    (("-p", "bases_file:=K0"), "k >= 1"),
], ids=["theta=-1", "n_starts=0", "theta=abc", "misspelt+strict", "empty bases", "k=0 bases"])
def test_startup_refusal_is_one_fatal_line(lifter_env: dict[str, str], tmp_path: Path,
                                           args: tuple[str, ...], reason: str) -> None:
    files = {"EMPTY": HOSTILE["empty file"][0](tmp_path), "K0": HOSTILE["k = 0"][0](tmp_path)}
    args = tuple(next((a.replace(k, str(v)) for k, v in files.items() if a.endswith(k)), a) for a in args)
    code, out = _run_lifter(lifter_env, *args)
    lines = out.strip().splitlines()
    assert code == 1, out
    assert len(lines) == 1 and lines[0].startswith("[FATAL]") and reason in lines[0], out


def test_misspelt_parameter_is_warned(start_lifter: Any, graph: GraphClient) -> None:
    lifter = start_lifter(params={"n_start": 1})
    graph.wait_for_lifter(lifter)
    assert "[WARN]" in lifter.log() and "unknown parameter: n_start (did you mean n_starts?)" in lifter.log()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
@pytest.mark.parametrize("delay", [0.3, 1.5])
def test_signal_during_startup_exits_0(lifter_env: dict[str, str], sig: int,
                                                        delay: float) -> None:
    proc = subprocess.Popen([str(LIFTER_EXE)], env=lifter_env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    time.sleep(delay)  # importing, or loading and compiling the kernels
    proc.send_signal(sig)
    try:  # exit 0 on its own: a start that ignored the signal would run on and be killed here
        out, _ = proc.communicate(timeout=SHUTDOWN_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate(timeout=SHUTDOWN_TIMEOUT)  # killed: its pipe closes
    assert proc.returncode == 0 and "Traceback" not in out, out


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_signal_while_busy_finishes_the_frame_and_exits(start_lifter: Any, graph: GraphClient,
                                                        sig: int) -> None:
    lifter = start_lifter(params={"warm_start": False, "n_starts": 30})
    graph.wait_for_lifter(lifter)
    t = graph.types
    kp, c = coco_keypoints(STANDING, 30.0)
    graph.send(frame(t, 10**9, [(-1, kp, c)]))
    # 64 cold 30-start solves: about half a second of work, or more on a loaded machine
    busy = frame(t, 2 * 10**9, [(-1, kp + 2.0 * i, c) for i in range(64)])
    graph.pub_keypoints.publish(busy)
    end = time.monotonic() + 0.3
    while time.monotonic() < end:
        graph.executor.spin_once(timeout_sec=0.05)
    lifter.proc.send_signal(sig)
    assert lifter.proc.wait(SHUTDOWN_TIMEOUT) == 0  # the frame in progress is finished first
    log = lifter.log()
    assert "Traceback" not in log and "unexpected" not in log, log
