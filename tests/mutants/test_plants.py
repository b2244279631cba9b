"""The plants of ``make mutants`` still plant: each text is in its module, and changes it.

``make mutants`` (tests/mutants/run.py, minutes) is not part of ``make test``; this check is, so a
refactor that moves the code a plant changes fails here, and the plant is rewritten, not lost."""

from __future__ import annotations

from pathlib import Path

import pytest
from plants import PLANTS, Plant

REPO = Path(__file__).resolve().parents[2]
PACKAGE = REPO / "ros2_ws" / "src" / "pose_lifter" / "pose_lifter"


@pytest.mark.parametrize("plant", PLANTS, ids=[p.what for p in PLANTS])
def test_each_plant_changes_its_module_and_names_an_existing_test(plant: Plant) -> None:
    source = (PACKAGE / plant.file).read_text()
    assert plant.text in source, f"{plant.file} no longer holds {plant.text!r}: rewrite the plant"
    assert source.replace(plant.text, plant.replacement) != source
    assert (REPO / plant.tests).is_file()
    if plant.select:
        assert plant.select in (REPO / plant.tests).read_text()


def test_the_plants_are_distinct() -> None:
    assert len({p.what for p in PLANTS}) == len(PLANTS)
    assert len({(p.file, p.text) for p in PLANTS}) == len(PLANTS)
