"""Fault injection (issue 10): kill -9 at seeded points of ``make-dataset`` and ``train`` followed
by a resume, a full disk (a tiny tmpfs where the test may mount one, and a disk that fills up in
the middle of a write, injected in-process), corrupt checkpoints, and bad input files.

What each fault must leave: the command finishes when run again; every file it reports is whole
(checkpoints load with :mod:`mitsuba_platonic.files.checkpoint`, images and volumes load); a temporary
is never left looking like a real file; a resumed run goes on from a saved step; a full disk is
one line (exit code 2) and the previous files stay as they were.

Kill points are drawn from ``random.Random(SEED)``: a self-inflicted SIGKILL at the N-th
``os.replace`` (a temporary completely written, not yet renamed: the worst moment for an atomic
write) and an outside SIGKILL after a random amount of progress. Subprocesses are few (each one
pays for importing torch and Mitsuba) and everything is tiny (16³).
"""

from __future__ import annotations

import builtins
import contextlib
import errno
import io
import os
import random
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from mitsuba_platonic.files.checkpoint import (CHECKPOINT_VERSION, checkpoint_files, read_checkpoint,
                                         save_checkpoint)
from mitsuba_platonic.config import load_config
from mitsuba_platonic.data.render_collection import load_manifest
from mitsuba_platonic.files.fileio import atomic_write
from mitsuba_platonic.images import load_exr
from mitsuba_platonic.train import run as R
from mitsuba_platonic.train.data import load_training_data
from cli_runner import one_line, run_cli, set_flags
from tiny_shapes import TINY

SEED = 10                                   # issue 10
CLASS = "mushroom"                          # a built-in class: subprocesses see it too
N = 16


pytestmark = pytest.mark.usefixtures("tiny_class")


def temporaries(folder: Path):
    """Files an atomic write left behind (``.<stem>.tmp<pid><suffix>``), anywhere under ``folder``."""
    return sorted(p for p in folder.rglob(".*") if ".tmp" in p.name)


_set = set_flags


# --------------------------------------------------------------------------- subprocesses and kills

#: Runs the command line; with FAULT_KILL_AT=N it SIGKILLs itself at the N-th os.replace into
#: FAULT_ROOT, after the temporary is written and before it is renamed into place.
LAUNCHER = r"""
import os, signal, sys
kill_at, root = int(os.environ.get("FAULT_KILL_AT", "0")), os.environ.get("FAULT_ROOT", "")
if kill_at:
    real, calls = os.replace, [0]
    def replace(src, dst, *args, **kwargs):
        if os.path.abspath(dst).startswith(root):
            calls[0] += 1
            if calls[0] == kill_at:
                os.kill(os.getpid(), signal.SIGKILL)
        return real(src, dst, *args, **kwargs)
    os.replace = replace
from mitsuba_platonic.cli import main
sys.exit(main(sys.argv[1:]))
"""


class Child:
    """``platonic ARGS`` in a subprocess (stdout and stderr to files, one thread per library)."""

    def __init__(self, args, logs: Path, kill_at: int = 0, root: Path = Path("/")):
        env = dict(os.environ, PYTHONUNBUFFERED="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1",
                   DRJIT_NUM_THREADS="1", FAULT_KILL_AT=str(kill_at), FAULT_ROOT=str(root.resolve()))
        logs.mkdir(parents=True, exist_ok=True)
        n = len(list(logs.glob("*.err")))
        self.err_path = logs / f"{n}.err"
        with open(logs / f"{n}.out", "w") as out, open(self.err_path, "w") as err:
            self.p = subprocess.Popen([sys.executable, "-c", LAUNCHER, *args], stdout=out, stderr=err, env=env)

    @property
    def stderr(self) -> str:
        return self.err_path.read_text()

    def wait(self, timeout=240) -> int:
        try:
            return self.p.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.p.kill()
            raise

    def kill_when(self, ready, delay: float, what: str, timeout=240) -> None:
        """SIGKILL ``delay`` seconds after ``ready()`` first holds; fail if the process ended first."""
        deadline = time.monotonic() + timeout
        while not ready():
            assert self.p.poll() is None, f"ended (rc {self.p.returncode}) before {what}: {self.stderr}"
            assert time.monotonic() < deadline, f"timed out waiting for {what}"
            time.sleep(0.005)
        time.sleep(delay)
        self.p.send_signal(signal.SIGKILL)
        assert self.wait() == -signal.SIGKILL, f"ended before the kill ({what}): {self.stderr}"


def _vol_ok(path: Path, n: int) -> bool:
    """A whole Mitsuba .vol file: header 'VOL' 3, float32 encoding, n³ × 4 channels of data."""
    data = path.read_bytes()
    if data[:4] != b"VOL\x03" or len(data) < 48:
        return False
    enc, x, y, z, c = np.frombuffer(data[4:24], "<i4")
    return enc == 1 and (x, y, z, c) == (n, n, n, 4) and len(data) == 48 + 4 * n ** 3 * 4


def check_collection_files(out: Path) -> int:
    """Every file a collection shows under images/, exr/, volumes/ is whole (loads, right shape);
    temporaries are hidden names only. Returns how many images there are."""
    for p in (out / "images").glob("[!.]*"):
        with Image.open(p) as im:
            im.load()
            assert im.size == (N, N) and im.mode == "RGBA", p
    for p in (out / "exr").glob("[!.]*"):
        assert load_exr(p).shape == (N, N, 4), p
    for p in (out / "volumes").glob("[!.]*.npz"):
        with np.load(p) as z:
            assert z["volume"].shape == (4, N, N, N), p
    for p in (out / "volumes").glob("[!.]*.vol"):
        assert _vol_ok(p, N), p
    for sub in ("images", "exr", "volumes"):
        if (out / sub).is_dir():
            assert all(p.name.startswith(".") or p.suffix in (".png", ".exr", ".npz", ".vol")
                       for p in (out / sub).iterdir())
    return len(list((out / "images").glob("[!.]*.png")))


def _lines(path: Path) -> int:
    return len(path.read_text().splitlines()) if path.exists() else 0


def test_make_dataset_killed_twice_then_resumed(tmp_path):
    """SIGKILL at a seeded os.replace (a temporary whole, not yet renamed), then from outside after
    a seeded number of new images; the same command then finishes a collection that verifies."""
    rng = random.Random(SEED)
    out = tmp_path / "d"
    shapes_, views = 10, 2
    command = ["make-dataset", "--class", CLASS, "--shapes", str(shapes_), "--views", str(views),
               "--resolution", str(N), "--out", str(out), "--quiet"]
    # os.replace order: collection.json, then per shape: .npz, .vol, (.exr, .png) per view; manifest
    first = Child(command, tmp_path / "logs", kill_at=rng.randint(2, 31), root=out)
    assert first.wait() == -signal.SIGKILL, first.stderr
    assert not (out / "manifest.json").exists()
    check_collection_files(out)
    assert temporaries(out), "the self-kill at a rename leaves its temporary (hidden)"

    before = _lines(out / "records.jsonl")
    second = Child(command, tmp_path / "logs")
    second.kill_when(lambda: _lines(out / "records.jsonl") >= before + rng.randint(1, 4),
                     rng.uniform(0.0, 0.02), "new images")
    assert not (out / "manifest.json").exists()
    done = check_collection_files(out)
    assert before < done < shapes_ * views

    last = Child(command, tmp_path / "logs")
    assert last.wait() == 0, last.stderr
    assert "Traceback" not in last.stderr
    m = load_manifest(out)
    assert [r["id"] for r in m["images"]] == [f"{i:05d}_{k:02d}" for i in range(shapes_) for k in range(views)]
    assert all((out / r["image"]).is_file() and (out / r["exr"]).is_file() and (out / r["volume"]).is_file()
               for r in m["images"])
    assert check_collection_files(out) == shapes_ * views
    assert len(list((out / "volumes").glob("*.vol"))) == shapes_
    assert temporaries(out) == []                                    # the resumed run cleaned up


def _checkpoints(run_dir: Path):
    """{file name: step} of every checkpoint file the run shows, each read with files/checkpoint.py's
    reader (a torn one fails here); anything else in checkpoints/ must be a hidden temporary."""
    folder = run_dir / "checkpoints"
    listed = checkpoint_files(folder)
    steps = {p.name: read_checkpoint(p).step for p in listed}
    assert all(p in listed or p.name.startswith(".") for p in folder.iterdir()), sorted(folder.iterdir())
    return steps


def _inodes(run_dir: Path):
    return {p.name: p.stat().st_ino for p in (run_dir / "checkpoints").glob("step_*.pt")}


def test_train_killed_twice_then_resumed(tmp_path):
    """``train`` SIGKILLed at a seeded os.replace, then ``--resume`` SIGKILLed after a seeded number
    of new checkpoints; a last ``--resume`` finishes. After each kill every checkpoint loads; each
    resume goes on from the newest one (the older numbered checkpoints are never rewritten: no
    step was done twice); no temporary is left at the end."""
    rng = random.Random(SEED + 1)
    steps, every = 45, 3
    overrides = [f"run.out_dir={tmp_path}/runs", "run.name=r", f"run.steps={steps}", f"run.checkpoint_every={every}",
                 "run.keep_checkpoints=100", "run.log_every=1", "run.sample_every=100000",
                 f"data.cache={tmp_path}/data", f"data.shape_class={CLASS}", "data.n_shapes=2",
                 "data.views_per_shape=2", f"model.resolution={N}", "model.width=8", "model.latent=8",
                 "train.batch_size=2"]
    load_training_data(load_config(None, overrides), progress=False)      # the collection, rendered once here
    run_dir = tmp_path / "runs" / "r"
    command = ["train", "--quiet", *_set(overrides)]

    # os.replace order: config.yaml, then per checkpoint: last.pt, step_N.pt, scalars.csv
    first = Child(command, tmp_path / "logs", kill_at=rng.randint(3, 14), root=run_dir)
    assert first.wait() == -signal.SIGKILL, first.stderr
    saved = _checkpoints(run_dir)
    assert saved and temporaries(run_dir)
    kept = [_inodes(run_dir)]

    numbered = len(kept[0])
    second = Child(command + ["--resume"], tmp_path / "logs")
    second.kill_when(lambda: len(list((run_dir / "checkpoints").glob("step_*.pt"))) >= numbered + rng.randint(1, 3),
                     rng.uniform(0.0, 0.05), "new checkpoints")
    resumed_from = max(saved.values())
    saved = _checkpoints(run_dir)
    assert resumed_from < max(saved.values()) < steps
    kept.append(_inodes(run_dir))

    last = Child(command + ["--resume"], tmp_path / "logs")
    assert last.wait() == 0, last.stderr
    assert "Traceback" not in last.stderr
    final = _checkpoints(run_dir)
    assert final["last.pt"] == steps
    for inodes in kept:                                              # not redone: not rewritten
        assert {k: v for k, v in _inodes(run_dir).items() if k in inodes} == inodes
    after = max(saved.values())
    assert {s for s in range(after + every, steps + 1, every)} <= set(final.values())
    rows = (run_dir / "scalars.csv").read_text().splitlines()[1:]
    assert [int(r.split(",")[0]) for r in rows] == list(range(1, steps + 1))
    assert temporaries(run_dir) == [] and not (run_dir / "run.lock").exists()


# --------------------------------------------------------------------------- a disk that fills up (in-process)


class _FillsUp:
    """A file on a disk that fills up after ``room`` bytes: the write that crosses it stores what
    fits, then raises ENOSPC (as ``write(2)`` does)."""

    def __init__(self, f, room: int = 512):
        self._f, self._room = f, room

    def write(self, data):
        if len(data) <= self._room:
            self._room -= len(data)
            return self._f.write(data)
        self._f.write(data[: self._room])
        self._f.flush()
        self._room = 0
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    def __getattr__(self, name):
        return getattr(self._f, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self._f.close()


@contextlib.contextmanager
def disk_full(monkeypatch, full):
    """Files that ``full(path)`` selects, opened for writing (``open``, ``Path.write_text``, ...),
    fill the disk after their first 512 bytes."""
    real = io.open

    def fake_open(file, mode="r", *args, **kwargs):
        f = real(file, mode, *args, **kwargs)
        if isinstance(file, (str, Path)) and any(c in mode for c in "wax") and full(Path(file).resolve()):
            return _FillsUp(f)
        return f

    with monkeypatch.context() as m:
        m.setattr(builtins, "open", fake_open)
        m.setattr(io, "open", fake_open)
        yield


def test_a_full_disk_while_saving_a_checkpoint_keeps_the_old_one(tmp_path, monkeypatch):
    """torch.save reports a failed write as a RuntimeError about stream positions: the save
    raises the OSError itself, naming the checkpoint (not its temporary); the old file stays."""
    path = tmp_path / "last.pt"
    save_checkpoint(path, {"step": 1, "w": torch.zeros(10)})
    old = path.read_bytes()
    with disk_full(monkeypatch, lambda p: p.parent == tmp_path):
        with pytest.raises(OSError) as info:
            save_checkpoint(path, {"step": 2, "w": torch.ones(100_000)})
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(path)
    assert path.read_bytes() == old and temporaries(tmp_path) == []


def test_a_full_disk_at_the_checkpoint_write_says_what_is_kept_and_what_to_free(base_run, tmp_path, monkeypatch):
    """ENOSPC injected at the checkpoint's write (the temporary's ``open``): the run's one line names
    the file, the step the untouched last.pt still holds, the disk and what to free there, and how
    to go on; every checkpoint is as it was."""
    from mitsuba_platonic.files import checkpoint as C

    run_dir = _copy_run(base_run, tmp_path)
    checkpoints = _snapshot(run_dir / "checkpoints")
    real = C.atomic_write

    def no_room(path, write, durable=False):
        def full(tmp):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(tmp))
        return real(path, full, durable)

    monkeypatch.setattr(C, "atomic_write", no_room)
    argv = ["train", "--resume", "--quiet", *_set(_tiny_overrides(tmp_path / "runs", base_run[1], "run.steps=6"))]
    code, _, stderr = run_cli(argv)
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    last = run_dir / "checkpoints" / "last.pt"
    assert err.startswith(f"platonic train: error: step 6: the checkpoint could not be written ([Errno 28] No space left on device: "
                          f"'{last}'); nothing was saved: {last} still holds step 4; the disk holding "
                          f"{run_dir / 'checkpoints'} is full ("), err
    assert err.endswith("free now): free space on it (other runs and collections; run.keep_checkpoints=2 keeps "
                        "fewer step_*.pt), or write elsewhere; then run the same command with --resume to go on "
                        "from step 4"), err
    assert _snapshot(run_dir / "checkpoints") == checkpoints and read_checkpoint(run_dir).step == 4
    assert temporaries(run_dir) == []


def test_a_full_disk_no_command_explained_says_what_is_kept_and_what_to_free(tmp_path):
    """An ``OSError`` of a full disk reaching the command line (an export, a report): the file, that
    writes are whole or not at all, the disk of the file and what to do; other OS errors as they are."""
    import argparse

    from mitsuba_platonic.cli.exits import error_message

    args = argparse.Namespace(command="evaluate")
    path = tmp_path / "eval" / "report.md"
    line = error_message(args, OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path)))
    assert line.startswith(f"platonic evaluate: error: [Errno 28] No space left on device: '{path}'; {path} was not "
                           f"written (files are written whole or not at all: a copy there before is as it was, and "
                           f"the files written before it are complete); the disk holding {tmp_path} is full ("), line
    assert line.endswith("free now): free space on it, or write elsewhere; then run the same command again"), line
    quota = error_message(args, OSError(errno.EDQUOT, os.strerror(errno.EDQUOT), str(path)))
    assert f"{tmp_path}: its disk quota is used up (" in quota, quota
    denied = error_message(args, PermissionError(errno.EACCES, os.strerror(errno.EACCES), str(path)))
    assert denied == f"platonic evaluate: error: [Errno 13] Permission denied: '{path}'"


def test_atomic_write_names_the_file_of_a_failed_write(tmp_path):
    """A writer that reports a full disk as its own exception (Mitsuba's FileStream, OpenEXR) is an
    OSError naming the file; any other exception of a writer is a bug and keeps its type."""
    path = tmp_path / "v.vol"
    path.write_bytes(b"old")

    def mitsuba_like(tmp):
        tmp.write_bytes(b"par")
        raise RuntimeError(f'[FileStream] "{tmp}": I/O error while attempting to write 65536 bytes: '
                           f"No space left on device")

    with pytest.raises(OSError, match="No space left on device") as info:
        atomic_write(path, mitsuba_like)
    assert info.value.errno == errno.ENOSPC and info.value.filename == str(path)

    def bug(tmp):
        raise RuntimeError("index 3 is out of bounds")

    with pytest.raises(RuntimeError, match="out of bounds"):
        atomic_write(path, bug)
    assert path.read_bytes() == b"old" and temporaries(tmp_path) == []


def test_a_ctrl_c_whose_writer_fails_to_clean_up_is_still_an_interrupt(tmp_path):
    """numpy's savez, interrupted inside its zip entry, raises ValueError from closing the zip while
    handling the KeyboardInterrupt: atomic_write raises the interrupt (the CLI's one line, exit 130),
    keeps the old file and leaves no temporary; a ValueError that no interrupt caused stays one."""
    import numpy as np

    path = tmp_path / "v.npz"
    path.write_bytes(b"old")

    def interrupted(tmp):
        def torn():
            raise KeyboardInterrupt
        np.savez_compressed(tmp, volume=np.zeros(4))
        try:
            torn()
        finally:
            raise ValueError("Can't close the ZIP file while there is an open writing handle on it.")

    with pytest.raises(KeyboardInterrupt):
        atomic_write(path, interrupted)
    assert path.read_bytes() == b"old" and temporaries(tmp_path) == []

    def plain(tmp):
        raise ValueError("not an interrupt")

    with pytest.raises(ValueError, match="not an interrupt"):
        atomic_write(path, plain)


def _tiny_overrides(out: Path, data: Path, *extra):
    return [f"run.out_dir={out}", "run.name=r", "run.steps=2", "run.log_every=1", "run.sample_every=100000",
            "run.checkpoint_every=2", f"data.cache={data}", f"data.shape_class={TINY}", "data.n_shapes=2",
            "data.views_per_shape=1", f"model.resolution={N}", "model.width=4", "model.latent=8",
            "train.batch_size=2", *extra]


@pytest.fixture(scope="module")
def base_run(tmp_path_factory, tiny_class):
    """A finished tiny run (steps 2 and 4 saved) and its data cache, copied by the tests that break it."""
    root = tmp_path_factory.mktemp("base")
    R.train(load_config(None, _tiny_overrides(root / "runs", root / "data", "run.steps=4")), progress=False)
    return root / "runs" / "r", root / "data"


def _copy_run(base_run, tmp_path):
    run_dir = tmp_path / "runs" / "r"
    shutil.copytree(base_run[0], run_dir)
    return run_dir


def _snapshot(folder: Path):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir()) if p.is_file()}


@pytest.mark.parametrize("where", ["checkpoints", "config.yaml"])
def test_resume_on_a_disk_that_fills_up_is_one_line_and_keeps_the_run(base_run, tmp_path, monkeypatch, where):
    """The disk fills up while ``train --resume`` writes a checkpoint, or its config.yaml: one line
    naming the file, exit code 2, checkpoints and config.yaml as they were; once there is room
    again, ``--resume`` goes on from step 4."""
    run_dir = _copy_run(base_run, tmp_path)
    argv = ["train", "--resume", "--quiet", *_set(_tiny_overrides(tmp_path / "runs", base_run[1], "run.steps=6"))]
    checkpoints, files = _snapshot(run_dir / "checkpoints"), _snapshot(run_dir)
    full = ((lambda p: p.parent == run_dir / "checkpoints") if where == "checkpoints" else
            (lambda p: p.parent == run_dir and p.suffix == ".yaml"))
    with disk_full(monkeypatch, full):
        code, _, stderr = run_cli(argv)
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    assert "No space left on device" in err
    if where == "checkpoints":
        last = run_dir / "checkpoints" / "last.pt"
        assert f"'{last}'" in err and f"{last} still holds step 4" in err, err
        assert f"the disk holding {run_dir / 'checkpoints'} is full (" in err, err
        assert "free space on it (other runs and collections; run.keep_checkpoints=" in err, err
        assert err.endswith("then run the same command with --resume to go on from step 4"), err
    else:
        assert f"'{run_dir / 'config.yaml'}'" in err, err
        assert f"{run_dir / 'config.yaml'} was not written (files are written whole or not at all" in err, err
        assert f"the disk holding {run_dir} is full (" in err and "or write elsewhere" in err, err
        assert _snapshot(run_dir)["config.yaml"] == files["config.yaml"]
    assert _snapshot(run_dir / "checkpoints") == checkpoints
    assert temporaries(run_dir) == [] and not (run_dir / "run.lock").exists()

    code, _, stderr = run_cli(argv)
    assert code == 0, stderr
    assert read_checkpoint(run_dir).step == 6
    assert read_checkpoint(run_dir / "checkpoints" / "step_0000004.pt").step == 4


# --------------------------------------------------------------------------- a full tiny filesystem (root)


@pytest.fixture
def tiny_fs(tmp_path):
    """Mount a tmpfs (root on Linux only) → a function ``resize(size)``; its folder is tmp_path/fs."""
    if sys.platform != "linux" or os.geteuid() != 0:
        pytest.skip("a tiny filesystem needs root on Linux (mount -t tmpfs); CI runs as root")
    if shutil.which("mount") is None:
        pytest.skip("no mount command to make a tiny filesystem")
    mnt = tmp_path / "fs"
    mnt.mkdir()
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=2m", "tmpfs", str(mnt)], capture_output=True, text=True)
    if r.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {r.stderr.strip()}")

    def resize(size: str) -> Path:
        subprocess.run(["mount", "-o", f"remount,size={size}", str(mnt)], check=True)
        return mnt

    try:
        yield resize
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def _fill(folder: Path, leave: int) -> Path:
    """Fill ``folder``'s filesystem, then give back ``leave`` bytes (tmpfs counts 4 KiB pages)."""
    filler = folder / "filler"
    with open(filler, "wb", buffering=0) as f:
        for chunk in (1 << 16, 1 << 12):
            with contextlib.suppress(OSError):
                while True:
                    f.write(b"\0" * chunk)
    size = filler.stat().st_size
    os.truncate(filler, max(0, size - leave))
    return filler


@pytest.mark.parametrize("leave", [0, 16 << 10])
def test_resume_into_a_full_filesystem(base_run, tmp_path, tiny_fs, leave):
    """A run on a filesystem with no room (its run.lock cannot be written) or with a little (its
    checkpoint cannot): one line naming the file, exit code 2, every checkpoint as it was and
    loadable, no temporary; with room again, ``--resume`` goes on."""
    fs = tiny_fs("2m")
    out = fs / "runs"
    run_dir = out / "r"
    shutil.copytree(base_run[0], run_dir)
    filler = _fill(fs, leave)
    checkpoints = _snapshot(run_dir / "checkpoints")
    argv = ["train", "--resume", "--quiet", *_set(_tiny_overrides(out, base_run[1], "run.steps=6"))]
    code, _, stderr = run_cli(argv)
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    assert "No space left on device" in err and str(run_dir) in err, err
    if leave:
        assert "still holds step 4" in err, err
    assert _snapshot(run_dir / "checkpoints") == checkpoints
    assert read_checkpoint(run_dir).step == 4 and R.read_run_config(run_dir / "config.yaml")
    assert temporaries(run_dir) == []
    filler.unlink()
    code, _, stderr = run_cli(argv)
    assert code == 0, stderr
    assert read_checkpoint(run_dir).step == 6


def test_make_dataset_into_a_full_filesystem(tmp_path, tiny_fs, monkeypatch):
    """make-dataset on a 128 KiB filesystem: one line naming the file it could not write, exit code
    2, what is there is whole; with room again the same command finishes the collection. The disk
    fills after the up-front size check (test_size_checks tests that check), as when another writer
    takes the space: the check is told of ample room."""
    from mitsuba_platonic.runtime import budget

    monkeypatch.setattr(budget, "free_disk", lambda path: (1 << 40, "a stand-in"))
    out = tiny_fs("128k") / "d"
    command = ["make-dataset", "--class", TINY, "--shapes", "3", "--views", "2", "--resolution", str(N),
               "--out", str(out), "--quiet"]
    code, _, stderr = run_cli(command)
    assert code == 2
    err = one_line(stderr, "make-dataset", kind="error")
    assert "No space left on device" in err and f"'{out}/" in err, err
    check_collection_files(out)
    assert [p for p in temporaries(out) if p.parent != out] == []
    tiny_fs("2m")
    code, _, stderr = run_cli(command)
    assert code == 0, stderr
    assert check_collection_files(out) == 6 and len(load_manifest(out)["images"]) == 6


# --------------------------------------------------------------------------- corrupt checkpoints


def _garbage(path: Path):
    path.write_bytes(np.random.default_rng(SEED).bytes(4096))


CORRUPTIONS = {
    "zero bytes": lambda p: p.write_bytes(b""),
    "truncated": lambda p: p.write_bytes(p.read_bytes()[: p.stat().st_size // 2]),
    "random bytes": _garbage,
    "wrong version": lambda p: torch.save({**torch.load(p, weights_only=False), "version": CHECKPOINT_VERSION + 1}, p),
    "no version": lambda p: torch.save({k: v for k, v in torch.load(p, weights_only=False).items() if k != "version"}, p),
    "not a training checkpoint": lambda p: torch.save(torch.zeros(3), p),
    "a dict without the trainer": lambda p: torch.save({"version": CHECKPOINT_VERSION, "step": 4}, p),
    "a dangling symlink": lambda p: (p.unlink(), p.symlink_to(p.parent / "gone.pt")),
    "a symlink to garbage": lambda p: (_garbage(p.parent / "junk.bin"), p.unlink(), p.symlink_to("junk.bin")),
    "a folder": lambda p: (p.unlink(), p.mkdir()),
}


@pytest.mark.parametrize("kind", list(CORRUPTIONS))
def test_a_bad_last_checkpoint_falls_back_with_a_warning(base_run, tmp_path, kind):
    """A warning (the command line prints it as ``platonic <command>: warning: …``, one line)."""
    run_dir = _copy_run(base_run, tmp_path)
    last = run_dir / "checkpoints" / "last.pt"
    CORRUPTIONS[kind](last)
    with pytest.warns(UserWarning) as caught:
        ckpt = read_checkpoint(run_dir)
    assert ckpt.step == 4 and ckpt.path.name == "step_0000004.pt"
    assert len(caught) == 1
    warning = str(caught[0].message)
    assert "\n" not in warning and warning.startswith(f"could not load {last} ("), warning
    assert warning.endswith(f"using {ckpt.path} (step 4)"), warning


@pytest.mark.parametrize("kind", ["wrong version", "a dangling symlink"])
def test_reconstruct_generate_and_resume_use_the_newest_loadable_checkpoint(base_run, tmp_path, kind):
    run_dir = _copy_run(base_run, tmp_path)
    last = run_dir / "checkpoints" / "last.pt"
    CORRUPTIONS[kind](last)
    image = next(base_run[1].glob("*/images/*.png"))
    for argv in (["reconstruct", "--run", str(run_dir), str(image), "--out", str(tmp_path / "rec")],
                 ["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "gen")],
                 ["train", "--resume", "--quiet", *_set(_tiny_overrides(tmp_path / "runs", base_run[1], "run.steps=6"))]):
        code, stdout, stderr = run_cli(argv)
        assert code == 0, stderr
        assert f"warning: could not load {last}" in stderr and "step_0000004.pt (step 4)" in stderr, stderr
    assert (tmp_path / "rec" / f"{image.stem}.npz").is_file() and (tmp_path / "gen" / "samples.png").is_file()
    assert not last.is_symlink() and read_checkpoint(last).step == 6    # the resumed run wrote a real one


def test_no_loadable_checkpoint_names_each_file_and_why(base_run, tmp_path):
    """Every checkpoint unusable, each differently: one line naming each file with its reason."""
    run_dir = _copy_run(base_run, tmp_path)
    folder = run_dir / "checkpoints"
    CORRUPTIONS["random bytes"](folder / "last.pt")
    CORRUPTIONS["wrong version"](folder / "step_0000004.pt")
    CORRUPTIONS["zero bytes"](folder / "step_0000002.pt")
    image = next(base_run[1].glob("*/images/*.png"))
    for argv in (["reconstruct", "--run", str(run_dir), str(image)], ["generate", "--run", str(run_dir), "-n", "1"],
                 ["train", "--resume", "--quiet", *_set(_tiny_overrides(tmp_path / "runs", base_run[1], "run.steps=6"))]):
        code, _, stderr = run_cli(argv)
        assert code == 2
        err = one_line(stderr, argv[0], kind="error")
        assert f"no loadable checkpoint in {folder}" in err, err
        assert "step_0000004.pt (checkpoint format 2, this version reads 1)" in err, err
        assert "last.pt" in err and "step_0000002.pt" in err, err


def test_a_dangling_last_checkpoint_is_not_a_fresh_folder(base_run, tmp_path):
    """A ``last.pt`` symlink whose file is gone, and nothing else: ``train`` without ``--resume``
    does not start over in the folder, and ``generate`` names the link."""
    run_dir = _copy_run(base_run, tmp_path)
    folder = run_dir / "checkpoints"
    for p in folder.glob("step_*.pt"):
        p.unlink()
    CORRUPTIONS["a dangling symlink"](folder / "last.pt")
    code, _, stderr = run_cli(["train", "--quiet", *_set(_tiny_overrides(tmp_path / "runs", base_run[1]))])
    assert code == 2 and "already holds a run" in one_line(stderr, "train", kind="error")
    code, _, stderr = run_cli(["generate", "--run", str(run_dir), "-n", "1"])
    assert code == 2
    err = one_line(stderr, "generate", kind="error")
    assert f"no loadable checkpoint in {folder}" in err and "last.pt (no checkpoint at" in err, err


# --------------------------------------------------------------------------- bad files


@pytest.mark.parametrize("content, message", [
    (b"run: {steps: [1,\n", "not valid YAML (expected the node content, but found '<stream end>' at line 2"),
    (b"- a\n- b\n", "expected a mapping of sections"),
    (bytes(range(256)) * 4, "not a YAML text file"),
], ids=["syntax error", "a list", "binary"])
def test_a_bad_config_file_is_one_line_naming_it(tmp_path, content, message):
    config = tmp_path / "c.yaml"
    config.write_bytes(content)
    code, _, stderr = run_cli(["train", "--config", str(config), "--quiet"])
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    assert f"{config}: {message}" in err, err


def test_a_bad_override_is_one_line(tmp_path, kind="error"):
    code, _, stderr = run_cli(["train", "--quiet", "--set", "train.lr_g=[1,"])
    assert code == 2
    assert "train.lr_g: could not parse '[1,'" in one_line(stderr, "train", kind="error")


def test_resume_with_a_binary_config_yaml_names_it(base_run, tmp_path):
    run_dir = _copy_run(base_run, tmp_path)
    (run_dir / "config.yaml").write_bytes(np.random.default_rng(SEED).bytes(512))
    code, _, stderr = run_cli(["train", "--resume", "--quiet",
                               *_set(_tiny_overrides(tmp_path / "runs", base_run[1], "run.steps=6"))])
    assert code == 2
    err = one_line(stderr, "train", kind="error")
    assert f"{run_dir / 'config.yaml'} is not a text file" in err, err


@pytest.mark.parametrize("kind", ["a truncated EXR", "a folder", "missing"])
def test_make_dataset_envmap_that_cannot_be_used(tmp_path, kind):
    env = tmp_path / "sky.exr"
    if kind == "a truncated EXR":
        env.write_bytes(b"\x76\x2f\x31\x01" + bytes(12))            # the magic number, then no header
    elif kind == "a folder":
        env.mkdir()
    out = tmp_path / "d"
    code, _, stderr = run_cli(["make-dataset", "--class", TINY, "--shapes", "1", "--views", "1", "--resolution", "16",
                               "--formation", "physical", "--lighting", "envmap", "--envmap", str(env), "--spp", "1",
                               "--out", str(out), "--quiet"])
    assert code == 2
    err = one_line(stderr, "make-dataset", kind="error")
    assert f"--envmap '{env}'" in err, err
    assert not out.exists()


def test_unreadable_photos_are_skipped_by_train_and_refused_by_reconstruct(base_run, tmp_path):
    """A photo folder with a truncated PNG and random bytes among good images: ``train`` warns
    naming both and trains; with only bad files it refuses, naming each; ``reconstruct`` of a bad
    image is one line naming it."""
    photos = tmp_path / "photos"
    photos.mkdir()
    good = sorted(base_run[1].glob("*/images/*.png"))
    for p in good:
        shutil.copy(p, photos / p.name)
    (photos / "torn.png").write_bytes(good[0].read_bytes()[:200])
    _garbage(photos / "noise.png")
    overrides = [f"run.out_dir={tmp_path}/runs", "run.name=p", "run.steps=1", "run.sample_every=100000",
                 "data.source=folder", f"data.path={photos}", f"model.resolution={N}", "model.width=4",
                 "model.latent=8", "train.batch_size=2", "data.split=1.0"]
    code, _, stderr = run_cli(["train", "--quiet", *_set(overrides)])
    assert code == 0, stderr
    warned = [x for x in stderr.splitlines() if x.startswith("platonic train: warning: skipped ")]
    assert any(f"{photos / 'torn.png'}" in x for x in warned) and any(f"{photos / 'noise.png'}" in x for x in warned), stderr
    assert read_checkpoint(tmp_path / "runs" / "p").step == 1

    for p in good:
        (photos / p.name).unlink()
    code, _, stderr = run_cli(["train", "--quiet", *_set(overrides[:1] + ["run.name=q"] + overrides[2:])])
    assert code == 2 and "Traceback" not in stderr
    errors = [x for x in stderr.splitlines() if x.startswith("platonic train: error: ")]
    assert len(errors) == 1 and str(photos) in errors[0]
    assert "torn.png" in stderr and "noise.png" in stderr, stderr

    run_dir = _copy_run(base_run, tmp_path / "copy")
    for bad in ("torn.png", "noise.png"):
        code, _, stderr = run_cli(["reconstruct", "--run", str(run_dir), str(photos / bad)])
        assert code == 2
        assert str(photos / bad) in one_line(stderr, "reconstruct", kind="error")
