"""The settings table (pose_lifter.ros.params): option parameters come from the options'
metadata, config/lifter.yaml is written from it, and an offline read of a params file honours
every key it keeps and refuses, by name, every key it cannot honour."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import Any

import pytest
import yaml
from pose_lifter.core.errors import OptionsError
from pose_lifter.core.options import (
    EXPERIMENT_OPTIONS,
    MODE_OPTIONS,
    NODE_OPTIONS,
    OPTION_META,
    LifterOptions,
)
from pose_lifter.ros.params import (
    OFFLINE_PARAMS,
    PARAMS,
    SPECS,
    NodeSettings,
    params_yaml,
    read_params_file,
)

REPO = Path(__file__).resolve().parents[2]
CONFIG = REPO / "ros2_ws" / "src" / "pose_lifter" / "config" / "lifter.yaml"
DEFAULTS = {f.name: f.default for f in dataclasses.fields(LifterOptions)}


def test_option_parameters_are_the_metadata() -> None:
    options = [p for p in PARAMS if p.option]
    assert [p.name for p in options] == list(NODE_OPTIONS)
    for p in options:
        meta = OPTION_META[p.name]
        assert p.default == DEFAULTS[p.name] and type(p.default) is type(DEFAULTS[p.name]), p.name
        assert (p.description, p.low, p.high) == (meta.doc, meta.low, meta.high), p.name
        assert p.constraints == meta.constraint_text(), p.name
        assert not p.read_only, p.name
    assert len(SPECS) == len(PARAMS)  # no name twice


def test_the_yaml_states_each_range_and_default() -> None:
    text = params_yaml()
    values = yaml.safe_load(text)["/**"]["ros__parameters"]
    assert list(values) == [p.name for p in PARAMS]
    headings = [line.strip() for line in text.splitlines() if line.startswith("    # ---- ")]
    assert headings == ["# ---- fit", "# ---- paper (read only in paper mode: another value than the default "
                        "is refused in another mode)", "# ---- prior", "# ---- track", "# ---- output",
                        "# ---- the node"]
    paper = text[text.index("# ---- paper"):text.index("# ---- prior")]
    assert sorted(re.findall(r"^    ([a-z_]+):", paper, re.M)) == sorted(set(MODE_OPTIONS) & set(SPECS))
    described = [line.strip() for line in text.splitlines()
                 if line.startswith("    # ") and not line.startswith("    # ---- ")]
    comments = dict(zip([p.name for p in PARAMS], described, strict=False))
    for p in PARAMS:
        assert values[p.name] == p.default and type(values[p.name]) is type(p.default), p.name
        assert comments[p.name].startswith(f"# {p.description}"), p.name
        if p.range_text():
            assert p.range_text() in comments[p.name], p.name
    assert "theta: 0.1" in text and "[0, 1e+06]" in comments["theta"]
    assert "(0, 1)" in comments["alternation_tol"]  # open: the bounds are refused


def test_the_committed_yaml_is_the_generated_one() -> None:
    assert CONFIG.read_text() == params_yaml(), (
        "config/lifter.yaml is stale: python -m pose_lifter.ros.node --params-yaml > config/lifter.yaml")


def test_offline_read_of_the_node_yaml_keeps_every_parameter_it_honours() -> None:
    assert read_params_file(CONFIG) == {p.name: p.default for p in OFFLINE_PARAMS}
    live = {p.name for p in PARAMS if p.live_only}
    assert live == {"solver_threads", "max_waiting_frames", "stats_period", "frame_id", "diagnostics_period",
                    "strict_parameters"}
    assert not live & set(OPTION_META)
    # the caps are honoured offline (they were dropped before)
    assert {"max_skeletons", "max_coordinate", "max_frame_id_length", "max_layout_length",
            "max_keypoints"} <= {p.name for p in OFFLINE_PARAMS}


def write(tmp_path: Path, values: dict[str, Any], section: str = "/**") -> Path:
    path = tmp_path / "params.yaml"
    path.write_text(yaml.safe_dump({section: {"ros__parameters": values}}))
    return path


@pytest.mark.parametrize("name", sorted(p.name for p in PARAMS if p.live_only))
def test_a_key_the_offline_lift_cannot_honour_is_an_error_naming_it(tmp_path: Path, name: str) -> None:
    """A parameter of the live node only, at another value than its default, is refused by name
    with the reason (at its default it is what the offline lift does anyway)."""
    spec = SPECS[name]
    other = {bool: not spec.default, str: "other_frame", int: 2, float: 2.5}[type(spec.default)]
    with pytest.raises(OptionsError, match=f"{name} = {other!r} cannot be honoured offline "
                                           f"\\({re.escape(spec.live_only)}\\)"):
        read_params_file(write(tmp_path, {"theta": 0.2, name: other}))
    assert read_params_file(write(tmp_path, {"theta": 0.2, name: spec.default})) == {"theta": 0.2}


def test_a_params_file_refuses_unknown_names_and_bad_values_and_keeps_rcl_s_own(tmp_path: Path) -> None:
    with pytest.raises(OptionsError, match=r"unknown parameter: n_start \(did you mean n_starts\?\)"):
        read_params_file(write(tmp_path, {"n_start": 3}))
    with pytest.raises(OptionsError, match=r"max_keypoints must be an int in \[1, 100000\], got 0"):
        read_params_file(write(tmp_path, {"max_keypoints": 0}))
    with pytest.raises(OptionsError, match="theta must be a number"):
        read_params_file(write(tmp_path, {"theta": "big"}))
    got = read_params_file(write(tmp_path, {"use_sim_time": True, "track_timeout": 2, "max_keypoints": 50},
                                 section="pose_lifter"))
    assert got == {"track_timeout": 2.0, "max_keypoints": 50} and type(got["track_timeout"]) is float
    # an option of the paper mode alone is read: whether the mode reads it is checked with the flags
    assert read_params_file(write(tmp_path, {"n_starts": 5})) == {"n_starts": 5}


def test_node_settings_read_every_field_with_its_type() -> None:
    values = {p.name: p.default for p in PARAMS}
    settings = NodeSettings.read(values.__getitem__)
    read = [(settings.frame, f) for f in dataclasses.fields(settings.frame)]
    read += [(settings, f) for f in dataclasses.fields(NodeSettings) if f.name != "frame"]
    for owner, f in read:
        value = getattr(owner, f.name)
        assert value == values[f.name] and type(value).__name__ == f.type, f.name


def test_the_node_docs_list_every_parameter_and_the_experiment_toggles() -> None:
    text = (REPO / "docs" / "node.md").read_text()
    section = text[text.index("Parameters (all declared with ranges"):text.index("The YAML is keyed `/**:`")]
    listed = set(re.findall(r"`([a-z_0-9]+)`", section))
    named_apart = {"camera_solver", "pose_solver"}  # named as not parameters
    assert listed & set(OPTION_META) - set(SPECS) <= named_apart
    assert set(SPECS) <= listed
    assert "`ExperimentOptions`" in section and "are not node parameters" in section
    assert not set(EXPERIMENT_OPTIONS) & set(SPECS)
