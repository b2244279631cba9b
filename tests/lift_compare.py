"""Two lifted bags compared message for message (what a lift on other workers must reproduce)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import numpy as np
from pose_lifter.offline import bags

#: Fields that measure the run, not the result: the wall time of each skeleton's solve.
RUN_FIELDS = frozenset({"solve_time"})


def plain(value: Any) -> Any:
    """A rosbags message as nested tuples (arrays as lists of exact floats), run fields left out."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        return tuple((f.name, plain(getattr(value, f.name))) for f in dataclasses.fields(value)
                     if f.name not in RUN_FIELDS and not f.name.startswith("__"))
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, list | tuple):
        return [plain(v) for v in value]
    return value


def lifted_messages(path: Path) -> list[tuple[str, int, Any]]:
    """(topic, stamp, content) of every message of a bag, in order."""
    return [(m.topic, m.stamp_ns, plain(m.msg)) for m in bags.read_messages(path)]


def assert_same_lift(a: Path, b: Path) -> int:
    """Assert two bags hold the same messages (run fields aside); returns how many."""
    ma, mb = lifted_messages(a), lifted_messages(b)
    assert len(ma) == len(mb), (a, b, len(ma), len(mb))
    for x, y in zip(ma, mb, strict=True):
        assert x == y, (a, b, x[0], x[1], _first_difference(x[2], y[2]))
    assert any(t == "/skeletons_3d" for t, _, _ in ma)
    return len(ma)


def _first_difference(x: Any, y: Any, path: str = "") -> str:
    """Where two plain() values first differ, as a path with both values (for a readable failure)."""
    if isinstance(x, list | tuple) and isinstance(y, list | tuple):
        if len(x) != len(y):
            return f"{path}: length {len(x)} != {len(y)}"
        for i, (u, v) in enumerate(zip(x, y, strict=True)):
            if u != v:
                return _first_difference(u, v, f"{path}[{i}]")
    return f"{path}: {x!r} != {y!r}"
