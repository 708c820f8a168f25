"""Checked configs (stmpl/config.py): defaults, merging, and the messages every loader shares."""

import pytest

from stmpl import config

DEFAULTS = {"name": None, "epochs": 10, "parallel": {"backend": "serial", "workers": 1}}


def test_defaults_merge_and_name(tmp_path):
    f = tmp_path / "run_a.yaml"
    f.write_text("epochs: 3\nparallel: {workers: 2}\n")
    cfg = config.read(f, DEFAULTS, "test config", merge=("parallel",))
    assert cfg == {"name": "run_a", "epochs": 3, "parallel": {"backend": "serial", "workers": 2}}
    cfg = config.read({"parallel": {"workers": 2}}, DEFAULTS, "test config", name="x")
    assert cfg["parallel"] == {"workers": 2} and cfg["name"] == "x"  # replaced, not merged
    assert DEFAULTS["parallel"] == {"backend": "serial", "workers": 1}  # defaults untouched


@pytest.mark.parametrize(
    "text,message",
    [
        ("epochs: [1\n", "is not valid YAML"),
        ("- 1\n- 2\n", "must be a mapping"),
        ("epoch: 3\n", r"unknown test config keys \['epoch'\]"),
    ],
)
def test_bad_files_are_named(tmp_path, text, message):
    f = tmp_path / "c.yaml"
    f.write_text(text)
    with pytest.raises(ValueError, match=message):
        config.read(f, DEFAULTS, "test config")


def test_missing_file():
    with pytest.raises(FileNotFoundError, match="test config file not found"):
        config.read("no/such.yaml", DEFAULTS, "test config")


def test_value_checks_refuse_bools_and_ranges():
    assert config.integer(3, "n", 1) == 3
    assert config.number(0.5, "x", 0, 1) == 0.5
    for bad in (True, 1.5, "3", 0):
        with pytest.raises(ValueError, match="n must be an integer >= 1"):
            config.integer(bad, "n", 1)
    for bad in (True, float("nan"), float("inf"), 0, "1"):
        with pytest.raises(ValueError, match="x must be a number > 0"):
            config.number(bad, "x", 0, low_open=True)
    with pytest.raises(ValueError, match="must be one of"):
        config.one_of("step", "schedule", ("constant", "cosine"))
