"""The options (pose_lifter.core.options): each field's metadata is the one table its validation
follows, and the user options stand apart from the experiment options."""

from __future__ import annotations

import dataclasses
import math
import re
import typing
from typing import Any

import pytest
from pose_lifter.core.errors import OptionsError
from pose_lifter.core.options import (
    EXPERIMENT_OPTIONS,
    MODE_OPTIONS,
    NODE_OPTIONS,
    OPTION_META,
    OPTION_PARTS,
    ExperimentOptions,
    FitOptions,
    LifterOptions,
    OptionMeta,
    OutputOptions,
    PaperOptions,
    PriorOptions,
    TrackOptions,
    UserOptions,
)

FIELDS = {f.name: f for f in dataclasses.fields(LifterOptions)}
NUMBERS = [n for n, f in FIELDS.items() if type(f.default) in (int, float)]


def in_its_mode(name: str) -> LifterOptions:
    """The default options in a mode that reads ``name``."""
    modes = OPTION_META[name].modes
    return LifterOptions(mode=modes[0]) if modes else LifterOptions()  # type: ignore[arg-type]


def accepted(name: str, value: Any) -> bool:
    try:
        in_its_mode(name).replace(**{name: value})
    except OptionsError:
        return False
    return True


def outside(meta: OptionMeta, kind: type) -> tuple[Any, Any]:
    """The values just below ``low`` and just above ``high``."""
    assert meta.low is not None and meta.high is not None
    if kind is int:
        return int(meta.low) - 1, int(meta.high) + 1
    return math.nextafter(meta.low, -math.inf), math.nextafter(meta.high, math.inf)


def test_every_field_has_metadata_and_its_default_is_valid() -> None:
    assert list(OPTION_META) == list(FIELDS)
    for name, f in FIELDS.items():
        meta = f.metadata["option"]
        assert meta is OPTION_META[name] and meta.doc and "\n" not in meta.doc, name
        kind = type(f.default)
        if kind in (int, float):
            assert meta.low is not None and meta.high is not None, name
            assert meta.accepts(f.default), name
        else:
            assert meta.low is None and meta.high is None, name
    LifterOptions().validate()


@pytest.mark.parametrize("name", NUMBERS)
def test_numbers_refuse_just_outside_the_range_and_take_the_closed_bounds(name: str) -> None:
    meta, kind = OPTION_META[name], type(FIELDS[name].default)
    assert meta.low is not None and meta.high is not None
    below, above = outside(meta, kind)
    assert not accepted(name, below) and not accepted(name, above)
    assert accepted(name, kind(meta.low)) is not meta.open_low
    assert accepted(name, kind(meta.high)) is not meta.open_high
    inner = (meta.low + meta.high) / 2
    assert accepted(name, int(inner) if kind is int else inner)
    assert not accepted(name, True)  # a bool is not a number here
    assert not accepted(name, "1")
    if kind is float:
        assert not accepted(name, math.nan) and not accepted(name, math.inf)
        assert accepted(name, int(meta.high)) is not meta.open_high  # ints pass as floats (YAML)
    else:
        assert not accepted(name, float(meta.low + 1))  # an int field takes no float
    with pytest.raises(OptionsError, match=f"{name} must be an? [a-z]+ in {re.escape(meta.range_text())}"):
        in_its_mode(name).replace(**{name: above})


def test_the_tolerances_are_open_intervals() -> None:
    for name in ("alternation_tol", "pose_tol", "inner_tol", "camera_tol", "newton_tol"):
        meta = OPTION_META[name]
        assert (meta.low, meta.high, meta.open_low, meta.open_high) == (0.0, 1.0, True, True), name
        assert meta.range_text() == "(0, 1)"
        assert "open bound" in meta.constraint_text()


def test_choices_are_the_literal_types_and_nothing_else_passes() -> None:
    hints = typing.get_type_hints(LifterOptions)
    literal = {n for n, h in hints.items() if typing.get_origin(h) is typing.Literal}
    assert literal == {"mode", "camera_solver", "pose_solver", "limb_proportions"}
    for name in literal:
        meta = OPTION_META[name]
        assert meta.choices == typing.get_args(hints[name]), name
        assert FIELDS[name].default == meta.choices[0]
        for choice in meta.choices:
            assert accepted(name, choice), (name, choice)
        assert not accepted(name, "nope") and not accepted(name, meta.choices[0].upper())
        assert meta.constraint_text() == "one of " + ", ".join(meta.choices)


def test_variant_names_are_case_insensitive() -> None:
    assert accepted("variant", "l2nans") and accepted("variant", "FULL")
    assert not accepted("variant", "L3XXXX") and not accepted("variant", 1)


def test_bools_and_paths() -> None:
    for name, f in FIELDS.items():
        if type(f.default) is bool:
            assert accepted(name, True) and accepted(name, False), name
            assert not accepted(name, 1) and not accepted(name, "true"), name
    for name in ("prior_file", "temporal_prior_file"):
        meta = OPTION_META[name]
        assert meta.max_length == 4096
        assert accepted(name, "x" * 4096) and not accepted(name, "x" * 4097) and not accepted(name, None)


def test_experiment_options_stand_apart_from_the_user_options() -> None:
    for name in ("camera_solver", "pose_solver", "newton_tol", "inner_max_iter", "inner_tol", "eta", "delta",
                 "tau", "eta_growth"):
        assert name in EXPERIMENT_OPTIONS, name
    assert "theta" not in EXPERIMENT_OPTIONS and "mode" not in EXPERIMENT_OPTIONS
    # every field is a user option (a node parameter) or an experiment option, the users' first
    assert list(FIELDS) == [*NODE_OPTIONS, *EXPERIMENT_OPTIONS]
    assert NODE_OPTIONS == tuple(f.name for f in dataclasses.fields(UserOptions))
    assert EXPERIMENT_OPTIONS == tuple(f.name for f in dataclasses.fields(ExperimentOptions))
    # each part validates its own fields
    with pytest.raises(OptionsError, match="theta"):
        UserOptions(theta=-1.0)
    with pytest.raises(OptionsError, match="eta"):
        ExperimentOptions(eta=0.0)
    assert LifterOptions(eta=0.5, theta=0.2).method == UserOptions(theta=0.2).method


def test_replace_keeps_refusing_unknown_names_and_bad_types() -> None:
    with pytest.raises(OptionsError, match="unknown option"):
        LifterOptions().replace(no_such_option=1)
    with pytest.raises(OptionsError, match="theta must be a number in \\[0, 1e\\+06\\]"):
        LifterOptions().replace(theta=-1.0)
    with pytest.raises(OptionsError, match="n_starts must be an integer in \\[1, 100000\\]"):
        LifterOptions(mode="paper", n_starts=0)


def test_the_user_options_are_thirty_at_most_in_five_parts_in_order() -> None:
    """A user holds the node's solver parameters by part: the fit, the paper mode's own, the
    prior, a track, the published pose; the YAML and docs/node.md list them so."""
    assert list(OPTION_PARTS) == ["fit", "paper", "prior", "track", "output"]
    listed = [name for names in OPTION_PARTS.values() for name in names]
    assert listed == list(NODE_OPTIONS) and len(listed) <= 30
    assert not set(listed) & set(EXPERIMENT_OPTIONS)


@pytest.mark.parametrize(("part", "cls", "bad"), [
    ("fit", FitOptions, {"min_visible_joints": 2}),
    ("paper", PaperOptions, {"n_starts": 0}),
    ("prior", PriorOptions, {"mode": "guess"}),
    ("track", TrackOptions, {"fill_missing_frames": -1}),
    ("output", OutputOptions, {"correction_smoothing": 1.0}),
])
def test_each_part_is_an_options_class_that_validates_itself(part: str, cls: type, bad: dict[str, Any]
                                                             ) -> None:
    """A part holds exactly its fields of :data:`OPTION_PARTS`, refuses a bad value of its own
    alone, and :meth:`UserOptions.part` gives it with the user's values."""
    assert tuple(f.name for f in dataclasses.fields(cls)) == OPTION_PARTS[part]
    assert cls.__doc__ and len(cls.__doc__.split()) >= 10
    (name,) = bad
    with pytest.raises(OptionsError, match=name):
        cls(**bad)
    with pytest.raises(OptionsError, match=name):
        LifterOptions(**bad)
    changed = LifterOptions(theta=0.2, mode="paper", n_starts=5, outlier_gate=0.5, measurement_depth=0.25)
    got = changed.part(part)
    assert type(got) is cls
    assert all(getattr(got, n) == getattr(changed, n) for n in OPTION_PARTS[part])


def test_the_paper_modes_own_options_are_refused_in_another_mode_unless_at_their_default() -> None:
    """Every option is read in the mode that runs: one only the paper mode reads (n_starts,
    max_alternations, pose_max_iter; the experiments' n_refine) is grouped as such (its part,
    its metadata, its doc) and refused with the reason in the hybrid and learned modes."""
    assert MODE_OPTIONS == {"max_alternations": ("paper",), "pose_max_iter": ("paper",),
                            "n_starts": ("paper",), "n_refine": ("paper",)}
    assert set(OPTION_PARTS["paper"]) == set(MODE_OPTIONS) - {"n_refine"}
    changed = {"n_starts": 5, "max_alternations": 3, "pose_max_iter": 7, "n_refine": 2}
    for name, value in changed.items():
        assert OPTION_META[name].doc.startswith("Paper mode only: "), name
        assert getattr(LifterOptions(mode="paper", **{name: value}), name) == value
        for mode in ("hybrid", "learned"):
            with pytest.raises(OptionsError, match=f"{name} = {value} is read only in paper mode, not in "
                               f"'{mode}' mode: leave it at its default"):
                LifterOptions(mode=mode, **{name: value})  # type: ignore[arg-type]
            # at its default it is accepted (the node declares every parameter)
            assert LifterOptions(mode=mode).replace(**{name: getattr(LifterOptions(), name)})  # type: ignore[arg-type]
    # a change of mode is refused too while a paper option is set, and a part alone has no mode
    with pytest.raises(OptionsError, match="n_starts = 5 is read only in paper mode"):
        LifterOptions(mode="paper", n_starts=5).replace(mode="hybrid")
    assert PaperOptions(n_starts=5).n_starts == 5
