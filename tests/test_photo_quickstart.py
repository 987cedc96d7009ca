"""``platonic quickstart --photos DIR``: a photo folder trained, judged and exported in one command
(tiny sizes: 16² photos, 16³ volumes, 2 steps)."""

import json

from cli_runner import one_line, run_cli
from test_evaluate_photos import _photo


def test_quickstart_on_a_photo_folder_trains_judges_and_exports(tmp_path):
    photos = tmp_path / "photos"
    photos.mkdir()
    for i in range(10):
        _photo(i).save(photos / f"p{i}.png")
    out = tmp_path / "q"
    sets = ["model.resolution=16", "model.width=4", "model.latent=8", "model.critic_width=4", "train.batch_size=2",
            "run.steps=2", "run.sample_every=2", "run.checkpoint_every=2", "run.threads=1", "data.split=0.6"]
    code, stdout, err = run_cli(["quickstart", "--photos", str(photos), "--out", str(out), "--quiet"]
                                + sum((["--set", s] for s in sets), []))
    assert code == 0, err
    report = (out / "report.md").read_text()
    assert report in stdout and f"report: {out / 'report.md'}" in stdout
    assert "6 for training, 4 held out" in report and "2 steps at 16³" in report
    assert "| run (platonic, step 2) |" in report and "| run: billboard |" in report     # the judge's table
    # the shape priors of photos.yaml, and no warning: ellipses are their own mirror images
    assert "## Shape priors this run used" in report and "| `train.turn` | 1 |" in report
    assert "consistent with a round class" in report and "**Warning:" not in report
    assert stdout.rstrip().splitlines()[-1] == f"report: {out / 'report.md'}"
    results = json.loads((out / "evaluation" / "results.json").read_text())
    assert results[0]["judge"]["c2st"]["photos"] == 4
    assert (out / "evaluation" / "report.md").is_file()
    assert sorted(p.name for p in (out / "reconstructions").glob("*_input.png")) == \
        [f"heldout_{i}_input.png" for i in range(4)]
    assert len(list((out / "reconstructions").glob("*.gif"))) == 4
    # the config of the run is configs/photos.yaml's, with the folder and the overrides
    cfg = (out / "run" / "config.yaml").read_text()
    assert "d_augment:" in cfg and str(photos.resolve()) in cfg


def test_quickstart_refuses_a_photo_folder_that_is_not_there(tmp_path):
    code, _, err = run_cli(["quickstart", "--photos", str(tmp_path / "nowhere"), "--out", str(tmp_path / "q")])
    assert code == 2 and "--photos" in one_line(err, "quickstart")
    assert not (tmp_path / "q").exists()


def test_quickstart_on_photos_stops_when_training_is_interrupted(tmp_path, monkeypatch):
    from mitsuba_platonic.errors import Interrupted
    from mitsuba_platonic.evaluate import report as E
    from mitsuba_platonic.train import run as R

    photos = tmp_path / "photos"
    photos.mkdir()
    for i in range(6):
        _photo(i).save(photos / f"p{i}.png")
    judged = []
    monkeypatch.setattr(E, "evaluate_runs", lambda *a, **k: judged.append(a))

    def train(cfg, resume=False, progress=True):
        raise Interrupted("after step 3 of 2000", saved="quickstart-photos/run/checkpoints/last.pt holds step 3")

    monkeypatch.setattr(R, "train", train)
    out = tmp_path / "qp"
    code, stdout, stderr = run_cli(["quickstart", "--photos", str(photos), "--out", str(out), "--quiet",
                                    "--set", "model.resolution=16"])
    assert code == 130, stderr
    err = stderr.strip()
    assert "\n" not in err and "while training" in err and "holds step 3" in err, err
    assert f"platonic quickstart --photos {photos} --out {out} --set model.resolution=16" in err
    assert judged == [] and not (out / "report.md").exists() and stdout == ""
