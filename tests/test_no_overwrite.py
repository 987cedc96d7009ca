"""Nothing a user already has is overwritten (issue 29): ``train`` writes only into a run folder
(one it created, or one its own records mark as a run) and never writes its ``--config`` file;
``reconstruct`` and ``generate`` give every result its own name inside ``--out`` and refuse to
replace an earlier call's results; the temporaries a killed ``make-dataset`` left are removed by
the next run."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
import yaml

from mitsuba_platonic.config import load_config
from mitsuba_platonic.train import run as R
from cli_runner import one_line, run_cli, set_flags
from tiny_shapes import TINY

N = 16


def _overrides(out: Path, data: Path, *extra):
    return [f"run.out_dir={out}", "run.name=r", "run.steps=2", "run.log_every=1", "run.sample_every=100000",
            "run.checkpoint_every=2", f"data.cache={data}", f"data.shape_class={TINY}", "data.n_shapes=2",
            "data.views_per_shape=1", f"model.resolution={N}", "model.width=4", "model.latent=8",
            "train.batch_size=2", *extra]


_set = set_flags


@pytest.fixture(scope="module")
def run(tmp_path_factory, tiny_class):
    """A finished tiny reconstruction run and its data cache."""
    root = tmp_path_factory.mktemp("run")
    R.train(load_config(None, _overrides(root / "runs", root / "data")), progress=False)
    return root / "runs" / "r", root / "data"


def _snapshot(folder: Path):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


# --------------------------------------------------------------------------- train: only into run folders


def _user_folder(folder: Path) -> None:
    folder.mkdir(parents=True)
    (folder / "config.yaml").write_text("# my notes\nrun: {steps: 1}\n")
    (folder / "scalars.csv").write_text("step,loss\n1,0.5\n2,0.25\n")
    (folder / "samples").mkdir()
    (folder / "samples" / "step_0000002.png").write_bytes(b"my picture")
    (folder / ".draft.tmp1.txt").write_text("draft")
    (folder / "run.lock").write_text("123\n")
    (folder / "notes.txt").write_text("notes")


def test_train_refuses_a_folder_that_is_not_a_run_and_changes_nothing_in_it(run, tmp_path):
    folder = tmp_path / "runs" / "userdir"
    _user_folder(folder)
    before = _snapshot(folder)
    code, stdout, stderr = run_cli(["train", "--quiet", *_set(_overrides(tmp_path / "runs", run[1],
                                                                         "run.name=userdir"))])
    assert code == 2, stderr
    err = one_line(stderr, "train", "error")
    assert str(folder) in err and "not a run folder" in err and "run.name" in err, err
    assert _snapshot(folder) == before
    assert sorted(p.name for p in folder.iterdir()) == sorted(
        [".draft.tmp1.txt", "config.yaml", "notes.txt", "run.lock", "samples", "scalars.csv"])


def test_train_into_a_new_or_empty_folder_marks_it_as_a_run(run, tmp_path):
    (tmp_path / "runs" / "r").mkdir(parents=True)                    # empty: fine
    assert run_cli(["train", "--quiet", *_set(_overrides(tmp_path / "runs", run[1]))])[0] == 0
    assert (tmp_path / "runs" / "r" / R.RUN_MARKER).is_file()


def test_a_run_from_before_the_marker_is_still_a_run(run, tmp_path):
    """A run folder written before the marker existed is recognised by its checkpoints."""
    run_dir = tmp_path / "runs" / "r"
    shutil.copytree(run[0], run_dir)
    (run_dir / R.RUN_MARKER).unlink()
    code, _, stderr = run_cli(["train", "--resume", "--quiet",
                               *_set(_overrides(tmp_path / "runs", run[1], "run.steps=3"))])
    assert code == 0, stderr


def test_train_never_writes_its_config_file(run, tmp_path):
    """``--config runs/r/config.yaml --resume``: the run's own config.yaml, with the user's comments,
    is the --config file and stays as it is."""
    run_dir = tmp_path / "runs" / "r"
    shutil.copytree(run[0], run_dir)
    config = run_dir / "config.yaml"
    saved = yaml.safe_load(config.read_text())
    saved["run"].update(out_dir=str(tmp_path / "runs"), steps=3)
    text = "# my comments\n" + yaml.safe_dump(saved, sort_keys=False)
    config.write_text(text)
    code, _, stderr = run_cli(["train", "--config", str(config), "--resume", "--quiet"])
    assert code == 0, stderr
    assert config.read_text() == text
    assert R.read_checkpoint(run_dir).step == 3


# --------------------------------------------------------------------------- reconstruct / generate: one name each


def _photo(path: Path, data: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    shutil.copy(sorted(data.glob("*/images/*.png"))[0], path)
    return path


def test_reconstruct_gives_each_input_its_own_name_inside_out(run, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    inputs = [_photo(tmp_path / p, run[1]) for p in ("same/a/x.png", "same/b/x.png", "shot.v1.png",
                                                        "shot.v2.png", "..png")]
    out = tmp_path / "rec"
    code, stdout, stderr = run_cli(["reconstruct", "--run", str(run[0]), *map(str, inputs), "--out", str(out)])
    assert code == 0, stderr
    stems = sorted({p.name[:-len(p.suffix)] for p in out.iterdir()})
    assert len(stems) == 5, stems
    assert {"x", "x_2", "shot.v1", "shot.v2"} <= set(stems), stems
    assert all((out / f"{s}.npz").is_file() and (out / f"{s}.gif").is_file() for s in stems)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["..png", "rec", "same", "shot.v1.png", "shot.v2.png"]
    for i in inputs:                                                  # each input is named with its results
        assert str(i) in stdout


def test_output_names_keep_the_letters_of_any_script():
    """Non-ASCII photo names stay readable (NFC: a decomposed ü is the typed one); what is no letter,
    mark or digit (a space, a bidirectional override, an undecodable byte) becomes ``_``."""
    import unicodedata

    from mitsuba_platonic.export import output_names

    decomposed = unicodedata.normalize("NFD", "Tür.jpg")
    assert output_names(["ñandú.png", "木の椅子.jpg", "हिन्दी.png", decomposed, "TÜR.png", "a b\u202e.png",
                         "bad\udcff.png"]) == ["ñandú", "木の椅子", "हिन्दी", "Tür", "TÜR_2", "a_b_", "bad_"]


def test_reconstruct_refuses_to_replace_an_earlier_calls_results(run, tmp_path):
    photo = _photo(tmp_path / "x.png", run[1])
    out = tmp_path / "rec"
    assert run_cli(["reconstruct", "--run", str(run[0]), str(photo), "--out", str(out)])[0] == 0
    before = _snapshot(out)
    code, _, stderr = run_cli(["reconstruct", "--run", str(run[0]), str(photo), "--out", str(out)])
    assert code == 2
    err = one_line(stderr, "reconstruct", "error")
    assert "x.npz" in err and "--overwrite" in err and "--out" in err, err
    assert _snapshot(out) == before
    assert run_cli(["reconstruct", "--run", str(run[0]), str(photo), "--out", str(out), "--overwrite"])[0] == 0


def _generation_run(run, tmp_path_factory):
    root = tmp_path_factory.mktemp("gen")
    R.train(load_config(None, _overrides(root / "runs", run[1], "train.task=generation")), progress=False)
    return root / "runs" / "r"


def test_generate_refuses_a_folder_holding_earlier_samples(run, tmp_path, tmp_path_factory):
    gen_run = _generation_run(run, tmp_path_factory)
    out = tmp_path / "gen" / "mix"
    assert run_cli(["generate", "--run", str(gen_run), "-n", "3", "--seed", "5", "--out", str(out)])[0] == 0
    before = _snapshot(out)
    code, _, stderr = run_cli(["generate", "--run", str(gen_run), "-n", "1", "--seed", "5", "--out", str(out)])
    assert code == 2
    err = one_line(stderr, "generate", "error")
    assert "sample_000" in err and "--overwrite" in err, err
    assert _snapshot(out) == before
    code, stdout, stderr = run_cli(["generate", "--run", str(gen_run), "-n", "1", "--seed", "5", "--out", str(out),
                                    "--overwrite"])
    assert code == 0, stderr
    assert sorted(p.stem for p in out.glob("sample_*")) == ["sample_000"] * 3   # npz, vol, gif of one sample


# --------------------------------------------------------------------------- make-dataset: a killed run's temporaries


def test_make_dataset_removes_the_temporaries_a_killed_run_left(tmp_path, tiny_class):
    out = tmp_path / "d"
    args = ["make-dataset", "--class", TINY, "--shapes", "2", "--views", "1", "--resolution", "16", "--out",
            str(out), "--quiet"]
    assert run_cli(args)[0] == 0
    stray = out / "images" / "..00000_00.tmp4242.tmp4242.png"      # a kill -9 inside save_png
    stray.write_bytes(b"")
    stray2 = out / "images" / ".00001_00.tmp4242.png"
    stray2.write_bytes(b"")
    code, _, stderr = run_cli(args)
    assert code == 0, stderr
    assert not stray.exists() and not stray2.exists()
    stray.write_bytes(b"")
    code, _, stderr = run_cli([*args, "--overwrite"])
    assert code == 0, stderr
    assert not stray.exists()
