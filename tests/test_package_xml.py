"""package.xml declares what the node's code imports, with rosdep keys that need no pip."""

from __future__ import annotations

import ast
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

PKG = Path(__file__).resolve().parents[1] / "ros2_ws" / "src" / "pose_lifter"
#: What the installed executables (lifter, lifter_lifecycle, adapter) run.
NODE_MODULES = [*(f"ros/{p.name}" for p in (PKG / "pose_lifter" / "ros").glob("*.py")
                  if p.name not in ("play.py", "action_recognition.py")),
                "messages/adapters.py", "messages/convert.py", "messages/hri.py", "messages/body.py",
                "messages/cdr.py", "messages/names.py",
                *(f"core/{p.name}" for p in (PKG / "pose_lifter" / "core").glob("*.py"))]
#: Imported only by offline functions the node never calls (basis learning), or optional
#: (threadpoolctl: without it the node runs, with BLAS's own thread count; core/numeric/threads.py).
OPTIONAL = {"sklearn", "threadpoolctl"}
KEYS = {"numpy": "python3-numpy", "scipy": "python3-scipy", "yaml": "python3-yaml"}


def imported_roots(path: Path) -> set[str]:
    roots: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            roots |= {a.name.split(".")[0] for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            roots.add(node.module.split(".")[0])
    return roots


def test_every_import_of_the_node_is_an_exec_depend() -> None:
    depends = {e.text for e in ET.parse(PKG / "package.xml").getroot().iter("exec_depend")}
    roots = set().union(*(imported_roots(PKG / "pose_lifter" / m) for m in NODE_MODULES))
    needed = {KEYS.get(r, r) for r in roots
              if r not in sys.stdlib_module_names and r not in OPTIONAL and r != "pose_lifter"}
    needed.discard("__future__")
    assert needed <= depends, f"missing from package.xml: {sorted(needed - depends)}"
    assert "rclpy" in needed and "diagnostic_msgs" in depends and "lifecycle_msgs" in depends
    # imported by name (ros/hri.py message_classes): the REP-155 outputs' packages
    assert {"hri_msgs", "tf2_msgs", "sensor_msgs", "std_msgs"} <= depends
    # no pip-only keys (rosdep on Ubuntu 24.04 refuses system pip installs)
    assert not [d for d in depends if d and d.endswith("-pip")]
    # the offline tools' libraries are not the node's dependencies
    assert not depends & {"python3-sklearn", "python3-tqdm", "python3-matplotlib", "python3-numba"}


def test_a_workspace_holding_the_repository_lists_only_the_project_s_packages(tmp_path: Path) -> None:
    """``colcon build`` in a workspace with this repository under src builds pose_lifter and
    pose_lifter_msgs only: the vendored message copies (ros2_ws/vendor) and the test copies
    (tests/ros/msgs) carry a COLCON_IGNORE, so they never shadow a system's packages."""
    import subprocess

    (tmp_path / "src").mkdir()
    (tmp_path / "src" / "pose_lifter_repo").symlink_to(PKG.parents[2])
    colcon = Path(sys.executable).parent / "colcon"
    out = subprocess.run([str(colcon), "list", "--names-only"], cwd=tmp_path, check=True,
                         capture_output=True, text=True).stdout
    assert sorted(out.split()) == ["pose_lifter", "pose_lifter_msgs"]
