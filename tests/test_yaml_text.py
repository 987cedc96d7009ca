"""YAML as the configs read it (config/files.load_yaml): a key given twice, nesting thousands deep and
huge values are one-line errors, in a config file, a --set value and a run folder's config.yaml."""

import pytest
import yaml

from mitsuba_platonic.config import ConfigError, load_config, load_yaml
from mitsuba_platonic.config.files import MAX_NESTING
from mitsuba_platonic.files.checkpoint import RunError
from mitsuba_platonic.settings_checks import QUOTE_LIMIT
from mitsuba_platonic.train.folder import read_run_config


def _one_line(e: Exception, limit: int = 4 * QUOTE_LIMIT) -> str:
    text = str(e)
    assert "\n" not in text and len(text) <= limit, text[:300]
    return text


def test_a_setting_given_twice_is_refused_naming_it_and_its_line(tmp_path):
    path = tmp_path / "twice.yaml"
    path.write_text("run:\n  steps: 10\n  steps: 20\n")
    with pytest.raises(ConfigError) as e:
        load_config(path)
    text = _one_line(e.value)
    assert "'steps'" in text and "twice" in text and "line 3" in text


def test_a_section_given_twice_is_refused(tmp_path):
    path = tmp_path / "sections.yaml"
    path.write_text("run: {steps: 10}\ntrain: {batch_size: 4}\nrun: {seed: 3}\n")
    with pytest.raises(ConfigError) as e:
        load_config(path)
    assert "'run'" in _one_line(e.value) and "line 3" in str(e.value)


def test_the_same_key_in_two_mappings_and_a_merge_override_are_accepted():
    assert load_yaml("a: {k: 1}\nb: {k: 2}\n") == {"a": {"k": 1}, "b": {"k": 2}}
    # '<<' merges a mapping whose keys the merging mapping may override: YAML's own rule, not a duplicate
    assert load_yaml("base: &b {k: 1, j: 2}\nc:\n  <<: *b\n  k: 3\n")["c"] == {"k": 3, "j": 2}


@pytest.mark.parametrize("depth", [MAX_NESTING + 1, 3000, 5000])
def test_nesting_too_deep_in_a_file_is_one_line(tmp_path, depth):
    path = tmp_path / "deep.yaml"
    path.write_text("train:\n  elevation: " + "[" * depth + "]" * depth + "\n")
    with pytest.raises(ConfigError) as e:              # not RecursionError
        load_config(path)
    assert f"more than {MAX_NESTING} levels" in _one_line(e.value)


def test_nesting_too_deep_in_a_set_value_is_one_line():
    with pytest.raises(ConfigError) as e:
        load_config(None, ["train.elevation=" + "[" * 4000 + "]" * 4000])
    assert f"more than {MAX_NESTING} levels" in _one_line(e.value)


def test_nesting_a_config_needs_is_accepted():
    assert load_yaml("train: {elevation: [-10.0, 40.0]}\n") == {"train": {"elevation": [-10.0, 40.0]}}
    nested = "[" * MAX_NESTING + "]" * MAX_NESTING
    assert load_yaml(nested) is not None


def test_a_huge_value_is_quoted_short(tmp_path):
    name = "x/" + "n" * 5_000_000
    with pytest.raises(ConfigError) as e:
        load_config(None, [f"run.name={name}"])
    assert "run.name" in _one_line(e.value)
    with pytest.raises(ConfigError) as e:
        load_config(None, ["n" * 1_000_000])                # no '=': the override itself quoted short
    _one_line(e.value)


def test_a_run_folders_config_with_a_key_twice_is_a_run_error(tmp_path):
    path = tmp_path / "config.yaml"
    path.write_text("run: {steps: 10}\nrun: {steps: 20}\n")
    with pytest.raises(RunError) as e:
        read_run_config(path)
    assert "'run'" in _one_line(e.value)


def test_load_yaml_errors_are_yaml_errors():
    with pytest.raises(yaml.YAMLError):
        load_yaml("a: 1\na: 2\n")
