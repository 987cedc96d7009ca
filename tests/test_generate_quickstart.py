"""``platonic quickstart --photos DIR --generate``: a generator trained on a photo folder, judged and its samples
exported in one command (tiny sizes: 24² photos, 16³ volumes, 2 steps); the shipped recipe it uses; its refusals."""

import json

import pytest

from cli_runner import one_line, run_cli
from test_evaluate_photos import _photo

TINY = ["model.resolution=16", "model.width=4", "model.latent=8", "model.critic_width=4", "train.batch_size=2",
        "run.steps=2", "run.sample_every=2", "run.checkpoint_every=2", "run.threads=1", "data.split=0.6"]


def _folder(tmp_path, n):
    photos = tmp_path / "photos"
    photos.mkdir()
    for i in range(n):
        _photo(i).save(photos / f"p{i}.png")
    return photos


def test_the_generation_recipe_loads_as_a_generation_run_on_a_photo_folder():
    from mitsuba_platonic.config import load_config
    from mitsuba_platonic.quickstart.generate import GENERATE_CONFIG

    cfg = load_config("photos_generate", ["data.path=somewhere"])
    assert GENERATE_CONFIG.name == "photos_generate.yaml"
    assert (cfg.train.task, cfg.data.source, cfg.render.model) == ("generation", "folder", "ea")
    assert (cfg.model.resolution, cfg.run.steps) == (32, 2000)
    # the photo recipe's model and critic (configs/photos.yaml), none of its input-photo priors
    photos = load_config("photos", ["data.path=somewhere"])
    for key in ("norm", "upsample", "init", "critic_init", "critic_width", "latent", "width"):
        assert getattr(cfg.model, key) == getattr(photos.model, key), key
    for key in ("view_distribution", "elevation", "r1_weight", "ema", "d_augment", "lr_d", "d_gate"):
        assert getattr(cfg.train, key) == getattr(photos.train, key), key
    assert not cfg.model.photo_colour and cfg.train.depth_spread == cfg.train.solidity == cfg.train.turn == 0


def test_quickstart_generate_trains_judges_and_exports_samples(tmp_path):
    photos = _folder(tmp_path, 10)
    out = tmp_path / "g"
    code, stdout, err = run_cli(["quickstart", "--photos", str(photos), "--generate", "--out", str(out), "--quiet"]
                                + sum((["--set", s] for s in TINY), []))
    assert code == 0, err
    report = (out / "report.md").read_text()
    assert report in stdout and f"report: {out / 'report.md'}" in stdout
    assert "6 for training, 4 held out" in report and "2 steps at 16³" in report
    assert "two-sample accuracy, random views" in report and "two-sample accuracy, back (135–180°)" in report
    results = json.loads((out / "evaluation" / "results.json").read_text())
    entry = next(r for r in results if r.get("section") == "generation")
    means = entry["means"]
    assert entry["c2st"]["photos"] == 4
    # the report's first table's row is the evaluation's figures, as written there
    row = "| " + " | ".join(f"{means[f'c2st_{b}']:.3f}" for b in ("random", "front", "near", "side", "back")) + " |"
    assert row in report
    assert f"| {means['diversity_volumes']:.3f} | {means['diversity_renders']:.3f} |" in report
    assert "## Generation: run (generation, step 2)" in (out / "evaluation" / "report.md").read_text()
    samples = out / "samples"
    assert sorted(p.name for p in samples.glob("*.gif")) == [f"sample_{i:03d}.gif" for i in range(16)]
    assert all((samples / n).is_file() for n in ("samples.png", "turntables.png", "interpolation.png"))
    cfg = (out / "run" / "config.yaml").read_text()
    assert "task: generation" in cfg and str(photos.resolve()) in cfg


def test_quickstart_generate_without_photos_is_one_line(tmp_path):
    code, stdout, err = run_cli(["quickstart", "--generate", "--out", str(tmp_path / "g")])
    line = one_line(err, "quickstart")
    assert code == 2 and "--generate" in line and "--photos" in line and stdout == ""
    assert not (tmp_path / "g").exists()


@pytest.mark.parametrize("sets, words", [(["train.task=reconstruction"], "generation"),
                                         (["data.source=procedural"], "folder")])
def test_quickstart_generate_refuses_overrides_that_leave_generation_on_photos(tmp_path, sets, words):
    photos = _folder(tmp_path, 6)
    code, _, err = run_cli(["quickstart", "--photos", str(photos), "--generate", "--out", str(tmp_path / "g")]
                           + sum((["--set", s] for s in sets), []))
    line = one_line(err, "quickstart")
    assert code == 2 and "--generate" in line and words in line, line
    assert not (tmp_path / "g").exists()


def test_quickstart_generate_refuses_a_photo_folder_that_is_not_there(tmp_path):
    code, _, err = run_cli(["quickstart", "--photos", str(tmp_path / "nowhere"), "--generate",
                            "--out", str(tmp_path / "g")])
    assert code == 2 and "--photos" in one_line(err, "quickstart")
    assert not (tmp_path / "g").exists()
