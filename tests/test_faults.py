"""Faults that used to lose data (issue 10): ``make-dataset --overwrite`` in a folder it did not
make, a failing training step saving its broken state over good checkpoints, two runs in one run
folder, run names that leave ``out_dir``, and a truncated ``last.pt``."""

import subprocess
import sys
import threading

import pytest
import torch

from mitsuba_platonic.cli import main
from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.data.render_collection import CollectionSpec, load_manifest, make_collection
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.trainer import Trainer
from cli_runner import one_line
from tiny_shapes import TINY

CLASS = "mushroom"


pytestmark = pytest.mark.usefixtures("tiny_class")


# --------------------------------------------------------------------------- make-dataset --overwrite


def _make(out, *extra):
    return main(["make-dataset", "--class", CLASS, "--shapes", "1", "--views", "1", "--resolution", "16",
                 "--out", str(out), "--quiet", *extra])


def test_overwrite_keeps_files_in_a_folder_that_is_no_collection(tmp_path, capsys):
    """The issue's reproduction: OUT/images/my_photo.jpg survives ``--overwrite``."""
    photo = tmp_path / "u" / "images" / "my_photo.jpg"
    photo.parent.mkdir(parents=True)
    photo.write_text("x")
    assert _make(tmp_path / "u", "--overwrite") == 2
    assert photo.read_text() == "x"
    err = one_line(capsys.readouterr().err, "make-dataset", kind="error")
    assert str(tmp_path / "u") in err and "images/my_photo.jpg" in err and "not a collection" in err


def test_overwrite_keeps_files_the_collection_did_not_write(tmp_path, capsys):
    out = tmp_path / "c"
    assert _make(out) == 0
    mine = sorted(p.relative_to(out) for p in out.rglob("*") if p.is_file())
    (out / "exr" / "notes.txt").write_text("keep me")
    (out / "volumes" / "hand_made.npz").write_bytes(b"keep me too")
    capsys.readouterr()
    assert _make(out, "--overwrite", "--seed", "3") == 2
    err = one_line(capsys.readouterr().err, "make-dataset", kind="error")
    assert str(out) in err and "exr/notes.txt" in err and "volumes/hand_made.npz" in err
    assert (out / "exr" / "notes.txt").read_text() == "keep me"
    assert (out / "volumes" / "hand_made.npz").read_bytes() == b"keep me too"
    # nothing was deleted, the collection's own files included
    assert all((out / p).exists() for p in mine)
    assert load_manifest(out)["spec"]["seed"] == 0


def test_overwrite_starts_its_own_collection_over(tmp_path):
    """--overwrite still works where the folder holds only what a collection wrote: finished, or
    half-written (a shape's volume and images written, its record lines not yet), or empty."""
    out = tmp_path / "c"
    spec = CollectionSpec(shape_class=CLASS, n_shapes=2, views_per_shape=2, resolution=16)
    make_collection(out, spec, progress=False)
    (out / "manifest.json").unlink()
    lines = (out / "records.jsonl").read_text().splitlines()
    (out / "records.jsonl").write_text(lines[0] + "\n")                 # a crash after the first record
    (out / "images" / ".00001_01.tmp99.png").write_bytes(b"partial")  # and a temporary it left
    small = CollectionSpec(shape_class=CLASS, n_shapes=1, views_per_shape=1, resolution=16, seed=4)
    make_collection(out, small, overwrite=True, progress=False)
    assert sorted(p.name for p in (out / "images").iterdir()) == ["00000_00.png"]
    assert sorted(p.name for p in (out / "volumes").iterdir()) == ["00000.npz", "00000.vol"]
    assert load_manifest(out)["spec"]["seed"] == 4
    assert _make(tmp_path / "fresh", "--overwrite") == 0                 # nothing there yet: fine


# --------------------------------------------------------------------------- training runs


def _overrides(tmp_path, *extra):
    return [f"run.out_dir={tmp_path}/runs", "run.name=r", "run.steps=4", "run.log_every=1",
            "run.sample_every=1000", "run.checkpoint_every=2", f"data.cache={tmp_path}/data",
            f"data.shape_class={TINY}", "data.n_shapes=2", "data.views_per_shape=2", "model.resolution=16",
            "model.width=4", "model.latent=8", "train.batch_size=2", *extra]


def _cfg(tmp_path, *extra):
    return load_config(None, _overrides(tmp_path, *extra))


def _finite(state):
    return all(torch.isfinite(v).all() for v in state["trainer"]["nets"].values() if v.is_floating_point())


def _poison(trainer):
    with torch.no_grad():
        for p in trainer.nets["G"].parameters():
            p.fill_(float("nan"))


def test_a_failing_step_keeps_the_good_checkpoints(tmp_path, monkeypatch):
    """Step 4 of 6 turns G into NaN and raises (as rendering a NaN volume does): the checkpoint of
    step 2 stays last.pt and is not rotated out (keep_checkpoints 1), and the error says so, in
    one line (a diverged run is the settings' doing, not a bug)."""
    real = Trainer.step

    def failing(self, step):
        if step == 3:
            _poison(self)
            raise ValueError("volume contains NaN")
        return real(self, step)

    monkeypatch.setattr(Trainer, "step", failing)
    with pytest.raises(R.RunError) as info:
        R.train(_cfg(tmp_path, "run.steps=6", "run.keep_checkpoints=1"), progress=False)
    message = str(info.value)
    assert "volume contains NaN" in message and "step 4" in message and "not finite" in message
    assert "nothing was saved" in message and "step 2" in message
    ckpts = tmp_path / "runs" / "r" / "checkpoints"
    assert sorted(p.name for p in ckpts.iterdir()) == ["last.pt", "step_0000002.pt"]
    last = R.load_checkpoint(ckpts / "last.pt")
    assert last["step"] == 2 and _finite(last)


def test_a_run_whose_parameters_went_non_finite_saves_nothing(tmp_path, monkeypatch):
    """A step that leaves NaN parameters without raising: the final checkpoint is refused."""
    real = Trainer.step

    def silent(self, step):
        out = real(self, step)
        if step == 3:
            _poison(self)
        return out

    monkeypatch.setattr(Trainer, "step", silent)
    with pytest.raises(R.RunError, match="not finite.*nothing was saved.*step 2"):
        R.train(_cfg(tmp_path), progress=False)
    ckpts = tmp_path / "runs" / "r" / "checkpoints"
    assert sorted(p.name for p in ckpts.iterdir()) == ["last.pt", "step_0000002.pt"]
    assert _finite(R.load_checkpoint(ckpts / "last.pt"))


@pytest.mark.parametrize("name", ["../../x", "a/b", "ABSOLUTE", "..", ".", ""])
def test_run_names_are_one_folder_name(tmp_path, name, capsys):
    name = str(tmp_path / "x") if name == "ABSOLUTE" else name
    setting = f"run.name={name}" if name else "run.name=''"
    with pytest.raises(ConfigError, match="^run.name"):
        _cfg(tmp_path, setting)
    args = sum((["--set", a] for a in _overrides(tmp_path, setting, f"run.out_dir={tmp_path}/o/runs")), [])
    assert main(["train", "--quiet", *args]) == 2
    assert "run.name" in one_line(capsys.readouterr().err, "train", kind="error")
    assert not (tmp_path / "x").exists() and not (tmp_path / "o").exists()


def test_a_second_run_in_a_busy_run_folder_is_refused(tmp_path, monkeypatch, capsys):
    """While run A is in its first step, run B with the same run.name (the command line, in a
    thread) is refused with one line; A then finishes with its own checkpoints."""
    real = Trainer.step
    second = {}

    def first_step_runs_b(self, step):
        if not second:
            second["running"] = True
            args = sum((["--set", a] for a in _overrides(tmp_path, "run.steps=2")), [])
            t = threading.Thread(target=lambda: second.update(rc=main(["train", "--quiet", *args])))
            t.start()
            t.join()
        return real(self, step)

    monkeypatch.setattr(Trainer, "step", first_step_runs_b)
    run_dir = R.train(_cfg(tmp_path), progress=False)
    assert second["rc"] == 2
    err = one_line(capsys.readouterr().err, "train", kind="error")
    assert str(run_dir) in err and "in use" in err
    assert R.load_checkpoint(run_dir / "checkpoints" / "last.pt")["step"] == 4
    assert not (run_dir / "run.lock").exists()                           # released at the end


def test_a_stale_lock_of_a_dead_process_is_taken_over(tmp_path):
    dead = subprocess.Popen([sys.executable, "-c", "pass"])
    dead.wait()
    run_dir = tmp_path / "runs" / "r"
    run_dir.mkdir(parents=True)
    (run_dir / R.RUN_MARKER).write_text("{}\n")                          # a run killed before its first step
    (run_dir / "run.lock").write_text(f"{dead.pid}\n")
    assert R.train(_cfg(tmp_path, "run.steps=2"), progress=False) == run_dir
    assert R.load_checkpoint(run_dir / "checkpoints" / "last.pt")["step"] == 2
    assert not (run_dir / "run.lock").exists()


# --------------------------------------------------------------------------- truncated checkpoints


def test_a_truncated_last_checkpoint_falls_back_to_the_newest_loadable_one(tmp_path, capsys):
    """Past two broken checkpoints in a row (a truncated last.pt, an empty step_0000004.pt) to step 2,
    and the resumed run's scalars.csv holds each step once. One broken file of each kind, and no
    loadable one at all, are test_fault_injection.py's."""
    run_dir = R.train(_cfg(tmp_path), progress=False)
    ckpts = run_dir / "checkpoints"
    last = ckpts / "last.pt"
    last.write_bytes(last.read_bytes()[: last.stat().st_size // 2])
    (ckpts / "step_0000004.pt").write_bytes(b"")                 # the newest numbered one is broken too

    with pytest.warns(UserWarning) as caught:                    # `platonic <command>: warning: …` on the CLI
        cfg, trainer, step = R.load_run(run_dir)
    assert step == 2
    err = " ".join(str(w.message) for w in caught)
    assert "could not load" in err and str(last) in err and str(ckpts / "step_0000002.pt") in err

    assert main(["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "gen")]) == 0
    assert "step 2" in capsys.readouterr().out

    R.train(_cfg(tmp_path, "run.steps=6"), resume=True, progress=False)   # continues from step 2
    state = R.load_checkpoint(last)
    assert state["step"] == 6 and _finite(state)
    rows = (run_dir / "scalars.csv").read_text().splitlines()
    assert [int(r.split(",")[0]) for r in rows[1:]] == [1, 2, 3, 4, 5, 6]
