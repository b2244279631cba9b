"""The compiled steps' tests against deliberate changes: each must turn the tests red.

Usage::

    .venv/bin/python tools/kernel_mutations.py

Applies one change at a time to the source tree (restored afterwards, also on Ctrl-C), runs the
test that must catch it, and prints whether it failed. The changes: a sign in the pose ADM (the
compiled pose step against the independent references), two Newton steps per alpha-step (against
the Python ADM loop around one), a sign in the run's objective (against its formula in numpy)
and a run that keeps its last alternation instead of its best (against the Python alternation
loop). Each recompiles the kernels it touches (minutes on 2 cores).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CORE = REPO / "ros2_ws" / "src" / "pose_lifter" / "pose_lifter" / "core"

#: (what, file under core/, text, its replacement, the test that must fail)
MUTATIONS = [
    ("a sign in the pose ADM's d1", "solve/pose_kernel.py", "d1[i] = c[i] - gi + u1[i]",
     "d1[i] = c[i] - gi - u1[i]", "tests/core/solve/test_against_reference.py"),
    ("two Newton steps per alpha-step in the compiled pose step", "solve/pose_step.py",
     "alpha_max_iter=RIEMANNIAN_MAX_ITER,", "alpha_max_iter=2 * RIEMANNIAN_MAX_ITER,",
     "tests/core/solve/test_pose_step.py"),
    ("the sign of ||alpha||_1 in the run's objective", "solve/run_kernel.py",
     "obj = cobj + th * _sum_abs(alpha)", "obj = cobj - th * _sum_abs(alpha)",
     "tests/core/solve/test_run_kernel.py"),
    ("the compiled run keeps its last alternation, not its best", "solve/run_kernel.py",
     "if (b_idx < 0 and not continued) or obj < b_obj:",
     "if (b_idx < 0 and not continued) or obj < b_obj or True:", "tests/core/solve/test_run_kernel.py"),
]


def run_mutations(mutations: list[tuple[str, str, str, str, str]], base: Path) -> int:
    """Apply each ``(what, file under base, text, replacement, test)`` alone (every occurrence of
    the text; the file restored afterwards, also on Ctrl-C), run its test, print the verdict.
    Returns the process exit code: 0 when every change is caught, 2 when a text is missing."""
    caught = 0
    for what, name, old, new, test in mutations:
        path = base / name
        source = path.read_text()
        if old not in source:
            print(f"{what}: the text to change is not in {name}; update this tool")
            return 2
        path.write_text(source.replace(old, new))
        try:
            run = subprocess.run([sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", test],
                                 cwd=REPO, capture_output=True, text=True, check=False)
        finally:
            path.write_text(source)
        errors = [line for line in run.stdout.splitlines() if line.startswith("E ")]
        verdict = "caught" if run.returncode == 1 else f"NOT caught (pytest exit {run.returncode})"
        caught += run.returncode == 1
        print(f"{what}: {verdict} by {test}; {errors[0].strip()[:120] if errors else ''}", flush=True)
    print(f"{caught} of {len(mutations)} changes caught")
    return 0 if caught == len(mutations) else 1


def main() -> int:
    return run_mutations(MUTATIONS, CORE)


if __name__ == "__main__":
    sys.exit(main())
