"""The CMU mocap data of the tests that read it: :data:`DATA`, its directory (None when it is not
found), and :data:`needs_data`, the mark that skips a test without it."""

from __future__ import annotations

import pytest
from pose_lifter.mocap import cmu as mocap

try:
    DATA = mocap.resolve_data_dir()
except mocap.MocapDataError:
    DATA = None
needs_data = pytest.mark.skipif(DATA is None, reason="CMU data not found (../shared/data/cmu or "
                                "$POSE_LIFTER_CMU_DATA); the raw files are never committed")
