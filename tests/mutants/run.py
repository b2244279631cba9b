"""``make mutants``: every planted regression of tests/mutants/plants.py must be caught.

Usage::

    .venv/bin/python tests/mutants/run.py [--only SUBSTRING] [--list]

For each plant: the package (ros2_ws/src/pose_lifter/pose_lifter) is copied to a temporary
directory, with its compiled-kernel caches and their files' times, so that only the planted
file's kernels compile again; the plant is applied to the copy (the checkout is never written);
its tests run with the copy first on ``PYTHONPATH``; the plant is caught when they fail (pytest's
exit status 1; an error collecting them is not a catch). Prints a line per plant and exits 0 when
every plant is caught, 1 when one survives, 2 when a plant's text is no longer in its file.
The kernel plants recompile their module's kernels: minutes each on 2 cores.
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from plants import PLANTS, Plant

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "ros2_ws" / "src" / "pose_lifter" / "pose_lifter"


def stale(plants: list[Plant]) -> list[str]:
    """The plants whose text is not in their file (a refactor moved the code)."""
    return [f"{p.what}: {p.text!r} is not in {p.file}" for p in plants
            if p.text not in (PACKAGE / p.file).read_text()]


def planted_copy(plant: Plant, into: Path) -> Path:
    """The package copied under ``into`` with ``plant`` applied: the directory to put first on
    ``PYTHONPATH``."""
    root = into / "src"
    shutil.copytree(PACKAGE, root / "pose_lifter", symlinks=True)  # copy2: times kept, caches valid
    path = root / "pose_lifter" / plant.file
    path.write_text(path.read_text().replace(plant.text, plant.replacement))
    return root


def run_plant(plant: Plant) -> tuple[bool, str]:
    """Whether ``plant``'s tests fail on a planted copy of the package, and the first error line
    (or why the run did not count)."""
    with tempfile.TemporaryDirectory(prefix="mutant-") as tmp:
        root = planted_copy(plant, Path(tmp))
        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join([str(root), env.get("PYTHONPATH", "")]).rstrip(os.pathsep)
        where = subprocess.run([sys.executable, "-c", "import pose_lifter; print(pose_lifter.__file__)"],
                               env=env, cwd=REPO, capture_output=True, text=True, check=False).stdout.strip()
        if not where.startswith(str(root)):
            return False, f"the tests would import pose_lifter from {where or '?'}, not the planted copy"
        cmd = [sys.executable, "-m", "pytest", "-q", "-x", "-p", "no:cacheprovider", plant.tests]
        if plant.select:
            cmd += ["-k", plant.select]
        run = subprocess.run(cmd, env=env, cwd=REPO, capture_output=True, text=True, check=False)
    errors = [line.strip() for line in run.stdout.splitlines() if line.startswith("E ")]
    if run.returncode == 1:
        return True, errors[0][:120] if errors else ""
    last = run.stdout.strip().splitlines()[-1:] or ["no output"]
    return False, f"pytest exit {run.returncode}: {last[0][:120]}"


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", default="", help="the plants whose description contains this")
    ap.add_argument("--list", action="store_true", help="list the plants and check their texts, run nothing")
    args = ap.parse_args(argv)
    plants = [p for p in PLANTS if args.only in p.what]
    missing = stale(plants)
    for line in missing:
        print(f"stale plant: {line}", flush=True)
    if args.list:
        for p in plants:
            print(f"{p.what}  [{p.file} -> {p.tests}{' -k ' + p.select if p.select else ''}]")
        return 2 if missing else 0
    if missing:
        return 2
    survived = []
    for p in plants:
        t0 = time.perf_counter()
        caught, detail = run_plant(p)
        print(f"{'caught  ' if caught else 'SURVIVED'} {p.what} ({p.tests}, {time.perf_counter() - t0:.0f} s)"
              f"{': ' + detail if detail else ''}", flush=True)
        if not caught:
            survived.append(p.what)
    print(f"{len(plants) - len(survived)} of {len(plants)} plants caught"
          + (f"; survived: {'; '.join(survived)}" if survived else ""))
    return 1 if survived else 0


if __name__ == "__main__":
    sys.exit(main())
