"""Config files and overrides a user gets wrong (issue 46): an empty file, negative loss weights, a
YAML alias bomb (named by its beginning, not printed whole) and the ``--set`` error's own example."""

from __future__ import annotations

import pytest

from mitsuba_platonic.config import OVERRIDE_EXAMPLE, ConfigError, apply_overrides, load_config
from mitsuba_platonic.settings_checks import QUOTE_LIMIT, quoted
from mitsuba_platonic.config.train_settings import LOSS_WEIGHTS
from cli_runner import one_line, run_cli


@pytest.mark.parametrize("bad", ["steps500", "steps=500"])
def test_the_set_errors_example_is_itself_accepted(bad):
    with pytest.raises(ConfigError) as e:
        apply_overrides({}, [bad])
    assert f"e.g. {OVERRIDE_EXAMPLE}" in str(e.value)
    key, value = OVERRIDE_EXAMPLE.split("=")
    cfg = load_config(None, [OVERRIDE_EXAMPLE])
    section, name = key.split(".")
    assert getattr(getattr(cfg, section), name) == int(value)


@pytest.mark.parametrize("key", LOSS_WEIGHTS)
def test_a_negative_loss_weight_is_refused_naming_its_key(key):
    with pytest.raises(ConfigError, match=rf"^train\.{key}: expected a non-negative value, got -5"):
        load_config(None, [f"train.{key}=-5"])


def test_a_negative_weight_on_the_command_line_starts_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, _, stderr = run_cli(["train", "--quiet", "--set", "train.rec_weight=-10"])
    assert code == 2
    assert "train.rec_weight: expected a non-negative value, got -10" in one_line(stderr, "train", "error")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("text", ["", "\n", "# nothing but a comment\n"])
def test_an_empty_config_file_is_refused_naming_the_file(tmp_path, monkeypatch, text):
    config = tmp_path / "empty.yaml"
    config.write_text(text)
    monkeypatch.chdir(tmp_path)
    code, _, stderr = run_cli(["train", "--quiet", "--config", str(config)])
    assert code == 2
    err = one_line(stderr, "train", "error")
    assert f"{config}: the config file is empty" in err and "leave --config out" in err, err
    assert [p.name for p in tmp_path.iterdir()] == ["empty.yaml"]         # no run started


def test_a_yaml_alias_bomb_is_named_by_its_beginning(tmp_path, monkeypatch):
    lines = ["a: &a [" + ", ".join(["x"] * 9) + "]"]
    for i, name in enumerate("bcdefg"):                                   # 9⁷ ≈ 4.8 million items if expanded
        previous = "abcdefg"[i]
        lines.append(f"{name}: &{name} [" + ", ".join([f"*{previous}"] * 9) + "]")
    lines.append("train:\n  batch_size: *g")
    config = tmp_path / "bomb.yaml"
    config.write_text("\n".join(lines) + "\n")
    monkeypatch.chdir(tmp_path)
    code, _, stderr = run_cli(["train", "--quiet", "--config", str(config)])
    assert code == 2
    err = one_line(stderr, "train", "error")
    assert err.startswith("platonic train: error: train.batch_size: expected int, got [[[[")
    assert len(err) < 100 + QUOTE_LIMIT, err


def test_quoted_keeps_short_values_whole_and_cuts_long_ones():
    assert quoted("eight") == "'eight'" and quoted([1, 2]) == "[1, 2]"
    long = quoted("x" * 1000)
    assert len(long) == QUOTE_LIMIT and long.endswith("…")
