"""Checkpoint files a user points at by mistake, or that are broken, each said in one line that names
the file and what to do (issue 46): a missing run folder, a config given as --run, a truncated or empty
``last.pt`` (also when a command falls back past it, as a ``platonic <command>: warning:``), weights
that hold NaN, a plain pickle that would run code (never skipped for an older file), and
``convert-checkpoint`` naming what a file would call before it unpickles anything."""

from __future__ import annotations

import os
import pickle
import shutil
from pathlib import Path

import pytest
import torch

from mitsuba_platonic.files.checkpoint import UnsafeCheckpoint, load_checkpoint, objects_to_convert
from mitsuba_platonic.config import load_config
from mitsuba_platonic.files.pickle_scan import foreign_objects, pickled_globals
from mitsuba_platonic.train import run as R
from cli_runner import one_line, run_cli
from tiny_shapes import tiny_run_overrides


def _overrides(out: Path, data: Path):
    return tiny_run_overrides(out, data, "run.steps=4")


@pytest.fixture(scope="module")
def base_run(tmp_path_factory, tiny_class):
    root = tmp_path_factory.mktemp("base")
    R.train(load_config(None, _overrides(root / "runs", root / "data")), progress=False)
    return root / "runs" / "r"


@pytest.fixture
def run_dir(base_run, tmp_path):
    copy = tmp_path / "runs" / "r"
    shutil.copytree(base_run, copy)
    return copy


class _System:
    """Unpickling this calls ``os.system`` (``posix.system``), which would create ``marker``."""

    def __init__(self, marker: Path):
        self.marker = marker

    def __reduce__(self):
        return os.system, (f"touch {self.marker}",)


def _generate(run: Path, tmp_path: Path):
    return run_cli(["generate", "--run", str(run), "-n", "1", "--out", str(tmp_path / "gen"), "--quiet"])


def test_a_missing_run_folder_is_said_not_to_exist(tmp_path):
    missing = tmp_path / "no_such_run"
    code, _, stderr = run_cli(["evaluate", "--run", str(missing), "--out", str(tmp_path / "e")])
    assert code == 2
    err = one_line(stderr, "evaluate", "error")
    assert f"{missing} does not exist" in err and "not started" not in err, err
    assert not (tmp_path / "e").exists()


def test_a_config_given_as_run_is_not_a_checkpoint(tmp_path):
    config = tmp_path / "quick.yaml"
    config.write_text("run: {steps: 10}\n")
    code, _, stderr = _generate(config, tmp_path)
    assert code == 2
    err = one_line(stderr, "generate", "error")
    assert f"{config} is not a checkpoint: --run takes a run folder" in err and "Weights only" not in err, err
    assert not (tmp_path / "gen").exists()


@pytest.mark.parametrize("keep", [0, 100])
def test_a_truncated_last_pt_is_named_and_the_fallback_is_a_prefixed_warning(run_dir, tmp_path, keep):
    last = run_dir / "checkpoints" / "last.pt"
    last.write_bytes(last.read_bytes()[:keep])
    code, _, stderr = _generate(last, tmp_path)                       # the file itself: an error
    assert code == 2
    err = one_line(stderr, "generate", "error")
    assert str(last) in err and ("is empty" if keep == 0 else "is truncated or damaged") in err, err
    assert "Errno" not in err and "miniz" not in err
    code, stdout, stderr = _generate(run_dir, tmp_path)               # the run: the older file, with a warning
    assert code == 0, stderr
    warning = one_line(stderr, "generate", "warning")
    assert f"could not load {last} ({'empty' if keep == 0 else 'truncated or damaged'}); using" in warning
    assert "step_0000004.pt (step 4)" in warning, warning


def test_weights_that_hold_nan_are_said_to_be_the_checkpoints(run_dir, tmp_path):
    last = run_dir / "checkpoints" / "last.pt"
    state = torch.load(last, weights_only=True)
    name = next(k for k in state["trainer"]["nets"] if k.startswith("G."))
    state["trainer"]["nets"][name].fill_(float("nan"))
    state["trainer"].pop("ema", None)
    torch.save(state, last)
    code, _, stderr = _generate(last, tmp_path)
    assert code == 2
    err = one_line(stderr, "generate", "error")
    assert f"{last}: the checkpoint's weights hold NaN (first at " in err and "earlier checkpoint" in err, err
    assert not (tmp_path / "gen").exists()


@pytest.mark.parametrize("protocol", [2, 4, pickle.HIGHEST_PROTOCOL])
def test_a_plain_pickle_last_pt_is_refused_not_skipped(run_dir, tmp_path, protocol):
    last, marker = run_dir / "checkpoints" / "last.pt", tmp_path / "marker"
    with open(last, "wb") as f:
        pickle.dump({"step": 9, "trainer": _System(marker)}, f, protocol=protocol)
    with pytest.raises(UnsafeCheckpoint) as e:
        load_checkpoint(last)
    assert e.value.refused == "posix.system"
    code, stdout, stderr = _generate(run_dir, tmp_path)
    assert code == 2
    err = one_line(stderr, "generate", "error")
    assert f"{last} was refused" in err and "(posix.system)" in err and "step_0000004" not in stdout + stderr, err
    assert not marker.exists() and not (tmp_path / "gen").exists()


def test_the_scan_names_globals_without_unpickling(tmp_path):
    marker = tmp_path / "marker"
    plain = tmp_path / "plain.pkl"
    plain.write_bytes(pickle.dumps([1, {"a": _System(marker)}], protocol=5))
    assert pickled_globals(plain) == ["posix.system"] and foreign_objects(plain) == ["posix.system"]
    safe = tmp_path / "safe.pt"
    torch.save({"w": torch.zeros(2), "n": 3}, safe)
    torch.save({"w": torch.zeros(2)}, tmp_path / "legacy.pt", _use_new_zipfile_serialization=False)
    assert foreign_objects(safe) == [] and foreign_objects(tmp_path / "legacy.pt") == []
    assert not marker.exists()


def test_convert_checkpoint_names_the_callable_and_needs_yes_without_a_terminal(run_dir, tmp_path, monkeypatch):
    last, marker = run_dir / "checkpoints" / "last.pt", tmp_path / "marker"
    state = torch.load(last, weights_only=True)
    state["trainer"]["extra"] = _System(marker)
    torch.save(state, last)
    before = last.read_bytes()
    assert objects_to_convert(last) == ["posix.system"]
    monkeypatch.setattr("sys.stdin.isatty", lambda: False, raising=False)
    code, stdout, stderr = run_cli(["convert-checkpoint", str(last)])
    assert code == 2
    err = one_line(stderr, "convert-checkpoint", "error")
    assert f"{last} names posix.system" in err and "--yes" in err and "nothing was converted" in err, err
    assert not marker.exists() and last.read_bytes() == before        # named before anything ran


def test_convert_checkpoint_asks_on_a_terminal_and_a_no_converts_nothing(run_dir, tmp_path, monkeypatch):
    last, marker = run_dir / "checkpoints" / "last.pt", tmp_path / "marker"
    state = torch.load(last, weights_only=True)
    state["trainer"]["extra"] = _System(marker)
    torch.save(state, last)
    before = last.read_bytes()
    import sys
    monkeypatch.setattr(sys.stdin, "isatty", lambda: True, raising=False)
    asked = []
    monkeypatch.setattr("builtins.input", lambda prompt: asked.append(prompt) or "n")
    code, stdout, _ = run_cli(["convert-checkpoint", str(last)])
    assert code == 1 and asked == ["Convert? [y/N] "]
    assert f"{last} names posix.system" in stdout and "nothing was converted" in stdout
    assert not marker.exists() and last.read_bytes() == before


def test_a_checkpoint_past_the_size_bound_is_refused_before_a_byte_is_read(run_dir, tmp_path, monkeypatch):
    """A last.pt larger than MAX_CHECKPOINT_BYTES (sparse here: no disk used) is refused in one line,
    torch.load never called on it; the run falls back to its newest numbered checkpoint with a warning."""
    from mitsuba_platonic.files import checkpoint as C
    from mitsuba_platonic.files.fileio import MAX_CHECKPOINT_BYTES

    last = run_dir / "checkpoints" / "last.pt"
    os.truncate(last, MAX_CHECKPOINT_BYTES + 1)
    real, loaded = torch.load, []

    def watched(path, *args, **kwargs):
        loaded.append(Path(path).name)
        return real(path, *args, **kwargs)

    monkeypatch.setattr(C.torch, "load", watched)
    with pytest.raises(C.RunError) as info:
        load_checkpoint(last)
    assert str(info.value) == (f"checkpoint {str(last)!r} is {MAX_CHECKPOINT_BYTES + 1:,} bytes, more than the "
                               f"{MAX_CHECKPOINT_BYTES:,} such a file may be; nothing was read from it: expected a "
                               f"checkpoint platonic train wrote (tens to hundreds of MB)")
    assert loaded == []
    code, _, stderr = _generate(run_dir, tmp_path)
    assert code == 0, stderr
    warning = one_line(stderr, "generate", "warning")
    assert warning.startswith(f"platonic generate: warning: could not load {last} ({MAX_CHECKPOINT_BYTES + 1:,} "
                              f"bytes, more than the {MAX_CHECKPOINT_BYTES:,} a checkpoint may be); using"), warning
    assert "step_0000004.pt (step 4)" in warning and "last.pt" not in loaded, warning


def test_a_fifo_as_last_pt_is_passed_over_without_blocking(run_dir, tmp_path):
    last = run_dir / "checkpoints" / "last.pt"
    last.unlink()
    os.mkfifo(last)
    code, _, stderr = _generate(run_dir, tmp_path)
    assert code == 0, stderr
    warning = one_line(stderr, "generate", "warning")
    assert f"could not load {last} (not a checkpoint file); using" in warning, warning
    with pytest.raises(R.RunError, match=r"no checkpoint at .*last.pt: checkpoint '.*last.pt' is a FIFO"):
        load_checkpoint(last)
