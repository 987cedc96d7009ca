"""Config files that extend another (``extends:``, mitsuba_platonic/config/files.py): the merge by
section, the order of what overrides what, the errors of a cycle, a missing parent and a chain too
deep, and every shipped config resolving to exactly the values it had before the configs shared
their blocks (``tests/resolved_configs.json``, written from the configs as they were without
``extends:``; after a deliberate change to a shipped config or a default, rewrite it with
``python tests/test_config_files.py --write`` and review its diff)."""

import json
import sys
from pathlib import Path

import pytest

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.config.files import MAX_DEPTH, merge_sections, read_config_file
from mitsuba_platonic.files.resources import config_names, configs_folder

ROOT = Path(__file__).resolve().parents[1]
RESOLVED = Path(__file__).with_name("resolved_configs.json")
UNSET = "<unset>"                                  # photos.yaml and photos64.yaml: templates for the user's folder


def resolved(name: str) -> dict:
    """The shipped config ``name`` fully resolved (every key, defaults included), as JSON data;
    a photo template's missing ``data.path`` as :data:`UNSET`."""
    try:
        return load_config(name).to_dict()
    except ConfigError as e:
        assert "data.path" in str(e), e
        out = load_config(name, ["data.path=PHOTOS"]).to_dict()
        out["data"]["path"] = UNSET
        return out


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def test_every_shipped_config_resolves_to_its_recorded_values():
    recorded = json.loads(RESOLVED.read_text())
    assert sorted(recorded) == config_names()
    for name in config_names():
        assert json.loads(json.dumps(resolved(name))) == recorded[name], name


def test_the_shipped_configs_extend_where_they_share_their_blocks():
    """The pairs that differ in a few keys state only those (issue 57): the Table-2 rows, the
    64³ photo config, the procedural collections."""
    parents = {"baseline_platonic_vh": "baseline_platonic_ea", "baseline_platonic_ao": "baseline_platonic_ea",
               "baseline_prgan": "baseline_platonic_vh", "baseline_platonic3d": "baseline_platonic_ea",
               "baseline_gan3d": "baseline_platonic3d", "photos64": "photos",
               "procedural_ea_closed_form": "procedural_ea", "procedural_ao": "procedural_ea",
               "procedural_vh": "procedural_ea", "procedural_physical": "procedural_ea", "platonic3d": "procedural_ea"}
    import yaml
    for child, parent in parents.items():
        assert yaml.safe_load((configs_folder() / f"{child}.yaml").read_text())["extends"] == parent, child


def test_a_child_replaces_the_keys_it_sets_and_keeps_the_rest(tmp_path):
    write(tmp_path / "base.yaml", "run: {name: base, steps: 7}\nmodel: {width: 8, norm: instance}\n"
                                  "train: {d_augment: [flip, cutout]}\n")
    child = write(tmp_path / "child.yaml", "extends: base.yaml\nmodel: {width: 4}\ntrain: {d_augment: [flip]}\n"
                                           "data: {n_shapes: 3}\n")
    assert read_config_file(child) == {"run": {"name": "base", "steps": 7}, "model": {"width": 4, "norm": "instance"},
                                       "train": {"d_augment": ["flip"]}, "data": {"n_shapes": 3}}
    cfg = load_config(child)
    assert (cfg.run.name, cfg.run.steps, cfg.model.width, cfg.model.norm, cfg.data.n_shapes) == ("base", 7, 4, "instance", 3)
    assert cfg.train.d_augment == ["flip"]                    # a list is replaced whole, not extended


def test_the_nearest_file_wins_and_the_command_line_over_all(tmp_path):
    """grandparent < parent < child < --set, key by key."""
    write(tmp_path / "a.yaml", "run: {name: a, steps: 1, log_every: 1, sample_every: 1}\n")
    write(tmp_path / "sub" / "b.yaml", "extends: ../a.yaml\nrun: {name: b, steps: 2, log_every: 2}\n")
    c = write(tmp_path / "c.yaml", "extends: sub/b.yaml\nrun: {name: c, steps: 3}\n")
    cfg = load_config(c, ["run.steps=4"])
    assert (cfg.run.name, cfg.run.steps, cfg.run.log_every, cfg.run.sample_every) == ("c", 4, 2, 1)


def test_a_packaged_config_is_found_by_name_from_any_folder(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    mine = write(tmp_path / "mine.yaml", f"extends: photos\ndata: {{path: {tmp_path}}}\nmodel: {{resolution: 16}}\n")
    cfg, photos = load_config(mine), load_config("photos", [f"data.path={tmp_path}", "model.resolution=16"])
    assert cfg == photos
    # a file beside the child is preferred to a packaged config of the same name
    write(tmp_path / "quickstart.yaml", "run: {name: local}\n")
    assert load_config(write(tmp_path / "q.yaml", "extends: quickstart.yaml\n")).run.name == "local"


def test_an_empty_section_changes_nothing():
    assert merge_sections({"run": {"steps": 3}}, {"run": None}) == {"run": {"steps": 3}}


def test_a_cycle_names_the_files(tmp_path):
    write(tmp_path / "a.yaml", "extends: b.yaml\nrun: {steps: 1}\n")
    write(tmp_path / "b.yaml", "extends: a.yaml\n")
    with pytest.raises(ConfigError, match=r"a\.yaml: extends: the chain comes back .*a\.yaml → .*b\.yaml → .*a\.yaml"):
        load_config(tmp_path / "a.yaml")
    with pytest.raises(ConfigError, match=r"self\.yaml → .*self\.yaml"):
        load_config(write(tmp_path / "self.yaml", "extends: self.yaml\n"))


def test_a_missing_parent_names_the_file_and_the_name(tmp_path):
    child = write(tmp_path / "child.yaml", "extends: nope\n")
    with pytest.raises(ConfigError, match=r"child\.yaml: extends: 'nope' is neither a file in .* nor a packaged "
                                          r"config \(packaged: .*quickstart"):
        load_config(child)
    with pytest.raises(ConfigError, match=r"bad\.yaml: extends: expected the name of a packaged config or a path"):
        load_config(write(tmp_path / "bad.yaml", "extends: [a, b]\n"))
    empty = write(tmp_path / "empty.yaml", "# nothing\n")
    with pytest.raises(ConfigError, match=r"empty\.yaml: the config file is empty"):
        load_config(write(tmp_path / "c2.yaml", "extends: empty.yaml\n"))
    assert empty.is_file()


def test_a_chain_is_bounded(tmp_path):
    for i in range(MAX_DEPTH):
        write(tmp_path / f"c{i}.yaml", f"extends: c{i + 1}.yaml\n" if i + 1 < MAX_DEPTH else "run: {steps: 5}\n")
    assert load_config(tmp_path / "c0.yaml").run.steps == 5          # MAX_DEPTH files: allowed
    write(tmp_path / f"c{MAX_DEPTH - 1}.yaml", f"extends: c{MAX_DEPTH}.yaml\n")
    write(tmp_path / f"c{MAX_DEPTH}.yaml", "run: {steps: 5}\n")
    with pytest.raises(ConfigError, match=rf"c0\.yaml: extends: more than {MAX_DEPTH} files deep"):
        load_config(tmp_path / "c0.yaml")


def test_a_run_saves_its_config_resolved(tmp_path):
    """The run folder's config.yaml holds every key (``Config.to_dict``), never ``extends:``: a run
    does not depend on the files its config extended."""
    import yaml

    from mitsuba_platonic.train.folder import prepare_run_folder, read_run_config
    cfg = load_config("baseline_platonic_vh", [f"run.out_dir={tmp_path}"])
    run_dir = tmp_path / cfg.run.name
    prepare_run_folder(run_dir, cfg, resume=False)
    saved = yaml.safe_load((run_dir / "config.yaml").read_text())
    assert "extends" not in saved and saved["data"]["formation"] == "vh" and saved["model"]["width"] == 16
    assert read_run_config(run_dir / "config.yaml") == cfg


if __name__ == "__main__" and sys.argv[1:] == ["--write"]:
    RESOLVED.write_text(json.dumps({name: resolved(name) for name in config_names()}, indent=1, sort_keys=True) + "\n")
    print(f"wrote {RESOLVED}")
