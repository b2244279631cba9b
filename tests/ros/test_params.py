"""The node's parameter table (pose_lifter.ros.params): option parameters come from the options'
metadata, config/lifter.yaml is written from it, and an offline read knows every node name."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import yaml
from pose_lifter.core.options import EXPERIMENT_OPTIONS, NODE_OPTIONS, OPTION_META, LifterOptions
from pose_lifter.ros.params import NODE_ONLY, PARAMS, SPECS, NodeSettings, params_yaml, read_params_file

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
    assert headings == ["# ---- fit", "# ---- prior", "# ---- track", "# ---- output", "# ---- the node"]
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


def test_offline_read_of_the_node_yaml_ignores_no_node_parameter() -> None:
    params = read_params_file(CONFIG)
    assert params.ignored == ()  # every node-only name is known (it listed five before)
    assert params.options == {n: DEFAULTS[n] for n in NODE_OPTIONS}
    assert NODE_ONLY >= {"diagnostics_period", "max_keypoints", "strict_parameters", "publish_markers"}
    assert not NODE_ONLY & set(OPTION_META)


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
