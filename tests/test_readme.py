"""The README's core example runs as written, and what it tells a reader to run or read exists."""

from __future__ import annotations

import re
from pathlib import Path

import tolerances as tol

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text()


def test_readme_core_example_runs(capsys) -> None:  # type: ignore[no-untyped-def]
    section = README[README.index("## The core API (runnable)"):]
    code = re.search(r"```python\n(.*?)```", section, re.S)
    assert code is not None
    exec(compile(code.group(1), "README.md", "exec"), {})
    out = capsys.readouterr().out
    err = float(re.search(r"P-MPJPE ([0-9.]+)", out).group(1))  # type: ignore[union-attr]
    assert err < tol.README_EXAMPLE_P_MPJPE, out


def test_readme_make_targets_exist() -> None:
    targets = set(re.findall(r"^([a-z][\w-]*):", (ROOT / "Makefile").read_text(), re.M))
    named = {*re.findall(r"`make ([a-z][\w-]*)", README), *re.findall(r"^make ([a-z][\w-]*)", README, re.M)}
    assert named, "the README names no make target"
    assert named <= targets, sorted(named - targets)


def test_readme_package_modules_exist() -> None:
    """The layout and the walk of one frame name modules and folders of the package that exist."""
    package = ROOT / "ros2_ws" / "src" / "pose_lifter" / "pose_lifter"
    named = set(re.findall(r"`((?:core|messages|ros|offline|mocap)/[\w/.]*)`", README))
    assert named, "the README names no module of the package"
    missing = sorted(p for p in named if not (package / p).exists())
    assert not missing, missing


def test_readme_files_and_links_exist() -> None:
    links = re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", README)
    paths = re.findall(r"`((?:tools|docs|bags|tests|ros2_ws)/[\w./-]+)`", README)
    commands = re.findall(r"(?:^|[\s`(])(tools/\w+\.py)", README, re.M)
    named = {p for p in [*links, *paths, *commands] if not p.startswith("http")}
    assert named, "the README names no file"
    missing = sorted(p for p in named if not (ROOT / p).exists())
    assert not missing, missing
