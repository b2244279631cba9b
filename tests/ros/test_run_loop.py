"""The one run loop of the package's executables (:func:`pose_lifter.ros.run.run_node`), driven in a
child process with a plain rclpy node (no colcon install, no graph peers): SIGINT and SIGTERM exit
with code 0 in every phase, at once while starting (also inside the loop, as a lifecycle configure
marks it), after the current callback while running; a node that cannot be built is one
``[FATAL]`` line and exit code 1."""

from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy  # noqa: F401  (required: in the lock)

PROBE = '''
import sys, time
from pose_lifter.ros.run import run_node

phase = sys.argv[1]

def make(signals):
    from rclpy.node import Node
    if phase == "bad":
        raise ValueError("theta must be\\n positive")
    if phase == "starting":
        print("starting", flush=True)
        time.sleep(30)
    node = Node("run_loop_probe")

    def busy():
        print("callback start", flush=True)
        time.sleep(1.0)
        print("callback end", flush=True)

    def configure():
        with signals.starting():
            print("configuring", flush=True)
            time.sleep(30)
        print("configured", flush=True)

    node.create_timer(0.2, configure if phase == "configure" else busy)
    return node

run_node(make, "probe", ["probe"])
print("run_node returned", flush=True)
'''

#: Seconds for a child to reach a phase (imports on a loaded machine), and to exit after a signal.
REACH_TIMEOUT = 60.0
EXIT_TIMEOUT = 10.0


def _start(tmp_path: Path, phase: str) -> subprocess.Popen[str]:
    script = tmp_path / "probe.py"
    script.write_text(PROBE)
    src = Path(__file__).resolve().parents[2] / "ros2_ws" / "src" / "pose_lifter"
    env = {**os.environ, "PYTHONPATH": f"{src}{os.pathsep}{os.environ.get('PYTHONPATH', '')}",
           "ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST",
           "ROS_DOMAIN_ID": str(random.SystemRandom().randint(1, 101))}
    return subprocess.Popen([sys.executable, str(script), phase], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)


def _wait_for(proc: subprocess.Popen[str], marker: str) -> list[str]:
    assert proc.stdout is not None
    lines: list[str] = []
    deadline = time.monotonic() + REACH_TIMEOUT
    while time.monotonic() < deadline:
        line = proc.stdout.readline()
        if not line:
            break
        lines.append(line.rstrip("\n"))
        if line.strip() == marker:
            return lines
    proc.kill()
    pytest.fail(f"the probe never printed {marker!r}: {lines}")


def _stop(proc: subprocess.Popen[str], sig: int) -> tuple[int, list[str]]:
    """Signal the child and wait for it to exit (killed after EXIT_TIMEOUT: a non-zero code);
    returns its exit code and the lines it printed after the signal."""
    proc.send_signal(sig)
    try:
        out, _ = proc.communicate(timeout=EXIT_TIMEOUT)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate(timeout=EXIT_TIMEOUT)  # killed: its pipe closes
    return proc.returncode, out.splitlines()


SIGNALS = pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])


@SIGNALS
def test_signal_while_starting_exits_0_without_waiting_for_the_start(tmp_path: Path, sig: int) -> None:
    proc = _start(tmp_path, "starting")
    _wait_for(proc, "starting")
    code, rest = _stop(proc, sig)
    # exit 0 within EXIT_TIMEOUT, far less than the 30 s start: the start is not waited for
    assert code == 0 and rest == [], rest


@SIGNALS
def test_signal_in_a_marked_start_up_phase_of_the_loop_exits_0(tmp_path: Path, sig: int) -> None:
    proc = _start(tmp_path, "configure")
    _wait_for(proc, "configuring")
    code, rest = _stop(proc, sig)
    assert code == 0 and rest == [], rest  # "configured" (after 30 s) never comes


@SIGNALS
def test_signal_while_running_finishes_the_callback_then_exits_0(tmp_path: Path, sig: int) -> None:
    proc = _start(tmp_path, "running")
    _wait_for(proc, "callback start")
    code, rest = _stop(proc, sig)
    assert code == 0, rest
    assert rest[0] == "callback end" and "callback start" not in rest, rest  # no new callback
    assert rest[-1] == "run_node returned" and not any("Traceback" in line for line in rest), rest


def test_a_node_that_cannot_be_built_is_one_fatal_line_and_exit_1(tmp_path: Path) -> None:
    proc = _start(tmp_path, "bad")
    out, _ = proc.communicate(timeout=REACH_TIMEOUT)
    lines = out.strip().splitlines()
    assert proc.returncode == 1, out
    assert len(lines) == 1 and lines[0].startswith("[FATAL]"), out
    assert lines[0].endswith("cannot start: theta must be positive"), out


def test_a_signal_while_the_node_is_imported_exits_0_at_once(tmp_path: Path) -> None:
    """A signal while the entry point imports the node (here the module signals itself; in the
    field it may land in rclpy's C-extension initialisation or in a callback of the import
    machinery, where a KeyboardInterrupt would come out as an ImportError or be swallowed) exits
    0 at once, the rest of the import and ``main`` never run; a broken import still fails."""
    (tmp_path / "signalled_node.py").write_text(
        "import os, signal, time\nos.kill(os.getpid(), signal.SIGTERM)\ntime.sleep(5)\n"
        "print('imported', flush=True)\ndef main():\n    print('ran', flush=True)\n")
    (tmp_path / "broken_node.py").write_text("raise ImportError('no such module')\n")
    env = {**os.environ, "PYTHONPATH": f"{tmp_path}{os.pathsep}{os.environ.get('PYTHONPATH', '')}"}
    code = "import sys\nfrom pose_lifter.ros import entry\nentry._run(sys.argv[1])"
    done = subprocess.run([sys.executable, "-c", code, "signalled_node"], env=env, capture_output=True,
                          text=True, timeout=REACH_TIMEOUT)
    assert done.returncode == 0 and done.stdout == "" and "Traceback" not in done.stderr, done
    broken = subprocess.run([sys.executable, "-c", code, "broken_node"], env=env, capture_output=True,
                            text=True, timeout=REACH_TIMEOUT)
    assert broken.returncode == 1 and "ImportError: no such module" in broken.stderr, broken
