"""Loading a checkpoint runs no code (issue 28), and a checkpoint that does not fit is one line (issue 29).

Every command that reads a checkpoint (``train --resume``, ``reconstruct``, ``generate``,
``evaluate``, ``Model.from_checkpoint``, ``load_run``) unpickles it with ``weights_only=True``:
a file whose pickle would run code is refused with one line naming it (exit code 2), the code
does not run, and no older checkpoint is used in its place. Checkpoints written the way the
package always wrote them load as they are; a trusted file holding other objects is converted
knowingly with ``platonic convert-checkpoint``. Bad contents under the right keys and a network
whose shapes differ from the saved weights are one line naming the file and what differs.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml

from mitsuba_platonic.files.checkpoint import (CHECKPOINT_VERSION, RunError, UnsafeCheckpoint, load_checkpoint,
                                         read_checkpoint, save_checkpoint)
from mitsuba_platonic.config import load_config
from mitsuba_platonic.model import Model
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.data import load_training_data
from mitsuba_platonic.train.trainer import Trainer
from cli_runner import one_line, run_cli, set_flags
from tiny_shapes import TINY


def _overrides(out: Path, data: Path, *extra: str):
    return [f"run.out_dir={out}", "run.name=r", "run.steps=4", "run.log_every=1", "run.sample_every=100000",
            "run.checkpoint_every=2", f"data.cache={data}", f"data.shape_class={TINY}", "data.n_shapes=2",
            "data.views_per_shape=1", "model.resolution=16", "model.width=4", "model.latent=8",
            "train.batch_size=2", *extra]


_set = set_flags


@pytest.fixture(scope="module")
def base_run(tmp_path_factory, tiny_class):
    """A finished tiny run (steps 2 and 4 saved) and its data cache; tests break copies of it."""
    root = tmp_path_factory.mktemp("base")
    R.train(load_config(None, _overrides(root / "runs", root / "data")), progress=False)
    return root / "runs" / "r", root / "data"


@pytest.fixture
def run_dir(base_run, tmp_path):
    """A copy of the base run in ``tmp_path/runs/r``."""
    copy = tmp_path / "runs" / "r"
    shutil.copytree(base_run[0], copy)
    return copy


class _RunsCode:
    """Unpickling this calls ``exec``: it creates ``marker`` (what a crafted checkpoint could do)."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return exec, (f"open({str(self.marker)!r}, 'w').close()",)


def _plant(path: Path, marker: Path, legacy: bool = False) -> None:
    """Rewrite the checkpoint at ``path`` as a whole training state plus an object whose unpickling
    would run code (torch's zip format, or its legacy plain-pickle format)."""
    state = torch.load(path, weights_only=True)
    state["trainer"]["extra"] = _RunsCode(marker)
    torch.save(state, path, _use_new_zipfile_serialization=not legacy)


def _commands(run_dir: Path, data: Path, tmp_path: Path):
    """Every command line that loads the checkpoints of ``run_dir``."""
    image = next(data.glob("*/images/*.png"))
    return {
        "train --resume": ["train", "--resume", "--quiet", *_set(_overrides(run_dir.parent, data, "run.steps=6"))],
        "reconstruct": ["reconstruct", "--run", str(run_dir), str(image), "--out", str(tmp_path / "rec")],
        "generate": ["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "gen")],
        "evaluate": ["evaluate", "--run", str(run_dir), "--out", str(tmp_path / "eval"), "--limit", "1",
                     "--views", "1", "--spp", "1", "--no-baselines", "--quiet"],
    }


COMMANDS = ["train --resume", "reconstruct", "generate", "evaluate"]


# --------------------------------------------------------------------------- a checkpoint that would run code


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_refuses_a_checkpoint_that_would_run_code(base_run, run_dir, tmp_path, command):
    """A crafted ``last.pt`` (good ``step_*.pt`` beside it): one line naming it and how to convert a
    trusted file, exit code 2, no fallback to ``step_0000004.pt``, and its code never ran."""
    last, marker = run_dir / "checkpoints" / "last.pt", tmp_path / "marker"
    _plant(last, marker)
    argv = _commands(run_dir, base_run[1], tmp_path)[command]
    code, stdout, stderr = run_cli(argv)
    assert code == 2, stderr
    err = one_line(stderr, argv[0], kind="error")
    assert f"{last} was refused" in err and "(exec)" in err and f"platonic convert-checkpoint {last}" in err, err
    assert "warning" not in err and "step_0000004" not in stdout + stderr
    assert not marker.exists()


@pytest.mark.parametrize("legacy", [False, True], ids=["zip", "legacy pickle"])
def test_model_from_checkpoint_and_load_run_refuse_a_checkpoint_that_would_run_code(run_dir, tmp_path, legacy):
    last, marker = run_dir / "checkpoints" / "last.pt", tmp_path / "marker"
    _plant(last, marker, legacy=legacy)
    for load in (lambda: Model.from_checkpoint(run_dir), lambda: Model.from_checkpoint(last),
                 lambda: R.load_run(run_dir), lambda: load_checkpoint(last)):
        with pytest.raises(UnsafeCheckpoint) as e:
            load()
        assert str(e.value).startswith(f"{last} was refused") and "\n" not in str(e.value)
        assert e.value.refused == "exec"
    assert not marker.exists()
    torch.load(last, weights_only=False)                       # the test's own check: the plant is live
    assert marker.exists()


def test_a_crafted_numbered_checkpoint_behind_a_torn_last_is_an_error_not_skipped(run_dir, tmp_path, capsys):
    """The fallback past a torn ``last.pt`` stops at a refused file: naming it, not using an older one."""
    folder, marker = run_dir / "checkpoints", tmp_path / "marker"
    (folder / "last.pt").write_bytes((folder / "last.pt").read_bytes()[:100])
    _plant(folder / "step_0000004.pt", marker)
    with pytest.raises(UnsafeCheckpoint, match=f"^{folder / 'step_0000004.pt'} was refused"):
        Model.from_checkpoint(run_dir)
    assert "warning" not in capsys.readouterr().err           # step_0000002.pt was not used
    assert not marker.exists()


# --------------------------------------------------------------------------- old checkpoints


def _old_save(path: Path, payload) -> None:
    """How checkpoints were written before loading was made safe (``torch.save`` of the dict)."""
    torch.save(payload, path)


def test_a_checkpoint_written_the_old_way_loads_safely_everywhere(base_run, run_dir, tmp_path, monkeypatch):
    """Old checkpoints hold tensors and plain data only: every command reads them as they are, and
    no command unpickles with ``weights_only=False``."""
    cfg = load_config(None, _overrides(run_dir.parent, base_run[1]))
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    for path in (run_dir / "checkpoints").glob("*.pt"):
        trainer.load_state_dict(torch.load(path, weights_only=True)["trainer"])
        _old_save(path, {"version": CHECKPOINT_VERSION, "step": 4 if path.name != "step_0000002.pt" else 2,
                         "config": cfg.to_dict(), "trainer": trainer.state_dict()})
    calls = []
    real_load = torch.load
    monkeypatch.setattr(torch, "load", lambda *a, **k: calls.append(k.get("weights_only")) or real_load(*a, **k))
    commands = _commands(run_dir, base_run[1], tmp_path)
    for name in ("generate", "reconstruct", "train --resume"):
        code, stdout, stderr = run_cli(commands[name])
        assert code == 0 and "warning" not in stderr, stderr
    assert Model.from_checkpoint(run_dir).step == 6            # the resumed run went on from step 4
    assert calls and set(calls) == {True}


def test_a_checkpoint_with_other_objects_is_refused_then_converted_knowingly(run_dir, tmp_path, monkeypatch):
    """A checkpoint holding numpy values (hand-made tooling): refused with the command to convert it;
    ``platonic convert-checkpoint RUN`` rewrites it (numpy → tensors and numbers) and leaves the
    files that already load safely alone, without unpickling them unsafely."""
    last = run_dir / "checkpoints" / "last.pt"
    state = torch.load(last, weights_only=True)
    state["step"] = np.int64(state["step"])
    state["trainer"]["nets"]["G.extra"] = np.zeros(3, dtype=np.float32)
    torch.save(state, last)
    code, _, stderr = run_cli(["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "g")])
    assert code == 2
    err = one_line(stderr, "generate", kind="error")
    assert f"{last} was refused" in err and "numpy" in err and f"platonic convert-checkpoint {last}" in err, err

    unsafe = []
    real_load = torch.load
    monkeypatch.setattr(torch, "load", lambda p, *a, **k: (unsafe.append(Path(p).name) if k.get("weights_only")
                                                           is False else None) or real_load(p, *a, **k))
    code, stdout, stderr = run_cli(["convert-checkpoint", "--yes", str(run_dir)])
    assert code == 0, stderr
    assert unsafe == ["last.pt"]                               # only the file that needed it
    assert f"{last}: converted (it held numpy" in stdout and "step_0000004.pt: loads safely already" in stdout
    converted = load_checkpoint(last)
    assert type(converted["step"]) is int and converted["trainer"]["nets"]["G.extra"].dtype == torch.float32
    del converted["trainer"]["nets"]["G.extra"]                 # no network has it: not a fitting checkpoint
    save_checkpoint(last, converted)
    assert read_checkpoint(run_dir).step == 4 and read_checkpoint(run_dir).path == last


def test_a_plain_pickle_checkpoint_is_converted_as_its_refusal_advises(run_dir, tmp_path):
    """A ``last.pt`` written by ``pickle.dump`` (not ``torch.save``) holding numpy values: the refusal
    advises ``platonic convert-checkpoint``, and that (with ``--yes``) converts it (torch.load cannot
    read a plain pickle: "Invalid magic number" was a traceback)."""
    import pickle

    last = run_dir / "checkpoints" / "last.pt"
    state = torch.load(last, weights_only=True)
    state["step"] = np.int64(state["step"])
    with open(last, "wb") as f:
        pickle.dump(state, f)
    code, _, stderr = run_cli(["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "g")])
    assert code == 2
    advice = f"platonic convert-checkpoint {last}"
    assert advice in one_line(stderr, "generate", kind="error"), stderr
    code, stdout, stderr = run_cli(["convert-checkpoint", "--yes", str(last)])
    assert code == 0, stderr
    assert f"{last}: converted (it held numpy" in stdout, stdout
    assert type(load_checkpoint(last)["step"]) is int and read_checkpoint(run_dir).step == 4


@pytest.mark.parametrize("message, refused", [
    ("Weights only load failed...\nUnsupported global: GLOBAL posix.system was not an allowed global", "posix.system"),
    ("Trying to load unsupported GLOBAL subprocess.Popen whose module subprocess is blocked.", "subprocess.Popen"),
    ("...\nTrying to call reduce for unrecognized function <built-in function exec>\n\nCheck", "<built-in function exec>"),
    ("Weights only load failed...\nUnsupported operand 95\n\nCheck the documentation", None),
], ids=["global", "blocked module", "reduce", "garbage"])
def test_a_refused_object_is_told_from_a_torn_file(message, refused):
    """What torch's safe unpickler says: an object it refused (an error, no fallback), or a torn file."""
    from mitsuba_platonic.files.checkpoint import _refused_object

    assert _refused_object(message) == refused


def test_save_checkpoint_refuses_what_the_safe_loader_could_not_read(tmp_path):
    with pytest.raises(TypeError, match=r"the payload\['step'\] \(numpy.int64\) is not plain data"):
        save_checkpoint(tmp_path / "c.pt", {"step": np.int64(3)})
    assert not (tmp_path / "c.pt").exists()


def test_convert_checkpoint_of_a_missing_path_is_one_line(tmp_path):
    code, _, stderr = run_cli(["convert-checkpoint", str(tmp_path / "nothing.pt")])
    assert code == 2
    assert "neither a checkpoint file nor a run folder" in one_line(stderr, "convert-checkpoint", kind="error")


# --------------------------------------------------------------------------- contents that do not fit (issue 29)


def test_the_right_keys_with_bad_contents_are_one_line_naming_the_file(run_dir, tmp_path):
    """A training state without ``nets`` (was ``KeyError: 'nets'``): the file and what is missing."""
    folder = run_dir / "checkpoints"
    for path in folder.glob("*.pt"):
        state = load_checkpoint(path)
        del state["trainer"]["nets"]
        save_checkpoint(path, state)
    code, _, stderr = run_cli(["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "g")])
    assert code == 2
    err = one_line(stderr, "generate", kind="error")
    assert f"no loadable checkpoint in {folder}" in err and "last.pt" in err, err
    assert "its trainer state's 'nets' is missing, expected a dict" in err, err
    with pytest.raises(RunError, match=f"^{folder / 'last.pt'} cannot be loaded: its trainer state's 'nets'"):
        Model.from_checkpoint(folder / "last.pt")


def test_weights_that_do_not_fit_their_saved_config_are_one_line(run_dir, tmp_path):
    """A weight of another shape than the saved config's network: the file and the tensor."""
    last = run_dir / "checkpoints" / "last.pt"
    state = load_checkpoint(last)
    name = next(k for k in state["trainer"]["nets"] if k.startswith("G.") and k.endswith("weight"))
    state["trainer"]["nets"][name] = torch.zeros(3, 3)
    save_checkpoint(last, state)
    code, _, stderr = run_cli(["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "g")])
    assert code == 2
    err = one_line(stderr, "generate", kind="error")
    assert err.startswith(f"platonic generate: error: {last}: its saved state does not fit the networks of the "
                          f"config saved with it: size mismatch for {name}: torch.Size([3, 3]) from checkpoint"), err


def test_resume_after_a_change_of_width_names_the_checkpoint_and_the_key(base_run, run_dir):
    """config.yaml edited to the new width too (was a ``load_state_dict`` size-mismatch traceback):
    one line naming the checkpoint and ``model.width``."""
    config = run_dir / "config.yaml"
    saved = yaml.safe_load(config.read_text())
    saved["model"]["width"] = 8
    config.write_text(yaml.safe_dump(saved, sort_keys=False))
    argv = ["train", "--resume", "--quiet", *_set(_overrides(run_dir.parent, base_run[1], "model.width=8",
                                                             "run.steps=6"))]
    code, _, stderr = run_cli(argv)
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    last = run_dir / "checkpoints" / "last.pt"
    assert f"--resume: {last} was saved with other settings (model.width: 4 in last.pt, 8 now)" in err, err


def test_resume_with_a_changed_setting_names_the_key_of_config_yaml(base_run, run_dir):
    argv = ["train", "--resume", "--quiet", *_set(_overrides(run_dir.parent, base_run[1], "model.width=8",
                                                             "run.steps=6"))]
    code, _, stderr = run_cli(argv)
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    assert (f"the model settings differ from {run_dir}/config.yaml (model.width: 4 there, 8 now)") in err, err


def test_resume_into_networks_that_do_not_fit_names_the_checkpoint(base_run, run_dir):
    """The saved weights do not fit the networks of the (matching) saved config: one line, the file."""
    last = run_dir / "checkpoints" / "last.pt"
    state = load_checkpoint(last)
    name = next(k for k in state["trainer"]["nets"] if k.startswith("D."))
    state["trainer"]["nets"][name] = torch.zeros(1)
    save_checkpoint(last, state)
    code, _, stderr = run_cli(["train", "--resume", "--quiet",
                               *_set(_overrides(run_dir.parent, base_run[1], "run.steps=6"))])
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    assert (f"--resume: {last}: its saved state does not fit this run's networks and optimisers: "
            f"size mismatch for {name}") in err, err
