"""The README's core example runs as written."""

from __future__ import annotations

import re
from pathlib import Path

import tolerances as tol


def test_readme_core_example_runs(capsys) -> None:  # type: ignore[no-untyped-def]
    text = (Path(__file__).resolve().parents[1] / "README.md").read_text()
    section = text[text.index("## The core API (runnable)"):]
    code = re.search(r"```python\n(.*?)```", section, re.S)
    assert code is not None
    exec(compile(code.group(1), "README.md", "exec"), {})
    out = capsys.readouterr().out
    err = float(re.search(r"P-MPJPE ([0-9.]+)", out).group(1))  # type: ignore[union-attr]
    assert err < tol.README_EXAMPLE_P_MPJPE, out
