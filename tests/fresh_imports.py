"""What importing some modules loads, seen from a fresh interpreter (the tests' own imports
do not count)."""

from __future__ import annotations

import json
import subprocess
import sys


def loaded_modules(*modules: str) -> set[str]:
    """The names in ``sys.modules`` of a new Python process after ``import`` of ``modules``."""
    code = f"import json, sys, {', '.join(modules)}; print(json.dumps(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    return set(json.loads(out))
