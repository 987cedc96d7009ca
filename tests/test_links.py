"""A folder someone else made never redirects a write (issue 46): a run folder, a collection or an
output folder copied from a colleague or an archive may hold symbolic links, and no command writes,
truncates, appends to, locks or deletes anything through one. Each writer is tried with a part of
its folder linked to an outside file or folder: the command refuses with one line naming the link,
and the outside target is byte for byte as it was."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

import pytest

from mitsuba_platonic.files import fileio
from mitsuba_platonic.config import load_config
from mitsuba_platonic.train import run as R
from cli_runner import one_line, run_cli, set_flags
from tiny_shapes import TINY, tiny_run_overrides


def _snapshot(path: Path):
    """Every file under ``path`` (or ``path`` itself) with its bytes, and the names of its folders."""
    if path.is_file():
        return {"": path.read_bytes()}
    return {str(p.relative_to(path)): (p.read_bytes() if p.is_file() else "folder") for p in sorted(path.rglob("*"))}


def _outside(tmp_path: Path, kind: str) -> Path:
    """A user's file or folder outside every folder the project writes: what a link points to."""
    if kind == "file":
        target = tmp_path / "outside" / "profile.sh"
        target.parent.mkdir(parents=True, exist_ok=True)
        target.write_text("export PATH=$HOME/bin:$PATH\n")
        return target
    target = tmp_path / "outside" / "mine"
    target.mkdir(parents=True)
    (target / "step_0000000.pt").write_text("my notes, not a checkpoint\n")
    (target / "step_0000001.pt").write_text("more notes\n")
    (target / "events.txt").write_text("keep me\n")
    return target


def _refused(stderr: str, command: str, link: Path) -> str:
    err = one_line(stderr, command, "error")
    assert str(link) in err and "symbolic link" in err, err
    return err


# --------------------------------------------------------------------------- the mechanism (fileio)


def test_confined_refuses_every_write_through_a_link_and_leaves_the_target_alone(tmp_path):
    root = tmp_path / "run"
    (root / "real").mkdir(parents=True)
    file_target, folder_target = _outside(tmp_path, "file"), _outside(tmp_path, "folder")
    (root / "lock").symlink_to(file_target)
    (root / "linked").symlink_to(folder_target)
    before = _snapshot(tmp_path / "outside")
    with fileio.confined(root):
        for attempt in (lambda: fileio.open_file(root / "lock", os.O_RDWR | os.O_CREAT),
                        lambda: fileio.write_text(root / "linked" / "events.txt", "x"),
                        lambda: fileio.remove(root / "linked" / "step_0000000.pt"),
                        lambda: fileio.remove_temporaries(root / "linked"),
                        lambda: fileio.make_folder(root / "linked" / "sub")):
            with pytest.raises(fileio.LinkRefused, match="symbolic link"):
                attempt()
        fileio.write_text(root / "real" / "a.txt", "fine")              # a real folder inside: written
        (root / "real" / "b.txt").symlink_to(file_target)
        fileio.write_text(root / "real" / "b.txt", "replaced")          # a link as the last part: replaced,
        fileio.remove(root / "lock")                                    # or removed, itself; never followed
    assert _snapshot(tmp_path / "outside") == before
    assert not (root / "real" / "b.txt").is_symlink() and (root / "real" / "b.txt").read_text() == "replaced"
    assert not (root / "lock").exists() and not (root / "lock").is_symlink()
    assert (root / "real" / "a.txt").read_text() == "fine"
    with pytest.raises(fileio.LinkRefused, match=str(root / "linked")):  # the layout, checked on entry
        with fileio.confined(root, ("real", "linked")):
            pass


def test_the_confined_folder_itself_may_be_a_link(tmp_path):
    """The user named it; what lies inside it may not be a link."""
    real = tmp_path / "scratch" / "runs"
    real.mkdir(parents=True)
    (tmp_path / "runs").symlink_to(real)
    with fileio.confined(tmp_path / "runs"):
        fileio.write_text(tmp_path / "runs" / "a" / "b.txt", "ok")
    assert (real / "a" / "b.txt").read_text() == "ok"


def test_outside_a_confined_folder_nothing_is_checked(tmp_path):
    target = _outside(tmp_path, "folder")
    (tmp_path / "link").symlink_to(target)
    fileio.write_text(tmp_path / "link" / "new.txt", "library use, no folder claimed")
    assert (target / "new.txt").is_file()


# --------------------------------------------------------------------------- train


def _overrides(out: Path, data: Path, *extra):
    return tiny_run_overrides(out, data, "run.sample_every=1", "run.checkpoint_every=1", "run.keep_checkpoints=1", *extra)


@pytest.fixture(scope="module")
def run(tmp_path_factory, tiny_class):
    """A finished tiny reconstruction run (samples and checkpoints at every step) and its data cache."""
    root = tmp_path_factory.mktemp("run")
    R.train(load_config(None, _overrides(root / "runs", root / "data")), progress=False)
    return root / "runs" / "r", root / "data"


def _linked_run(run, tmp_path: Path, part: str, kind: str) -> Path:
    """A copy of the run whose ``part`` is a link to an outside file or folder (its target returned)."""
    run_dir = tmp_path / "runs" / "r"
    shutil.copytree(run[0], run_dir)
    target = _outside(tmp_path, kind)
    link = run_dir / part
    if link.is_dir():
        shutil.rmtree(link)
    elif link.exists():
        link.unlink()
    link.symlink_to(target)
    return target


@pytest.mark.parametrize("part, kind", [("checkpoints", "folder"), ("run.lock", "file"), ("samples", "folder"),
                                        ("tb", "folder"), ("scalars.csv", "file"), ("config.yaml", "file"),
                                        ("run.json", "file")])
def test_train_resume_refuses_a_run_folder_whose_part_is_a_link(run, tmp_path, part, kind):
    target = _linked_run(run, tmp_path, part, kind)
    before = _snapshot(target)
    code, _, stderr = run_cli(["train", "--resume", "--quiet",
                               *set_flags(_overrides(tmp_path / "runs", run[1], "run.steps=4"))])
    assert code == 2, stderr
    _refused(stderr, "train", tmp_path / "runs" / "r" / part)
    assert _snapshot(target) == before
    if part != "checkpoints":
        assert R.read_checkpoint(tmp_path / "runs" / "r").step == 2      # nothing trained


def test_a_link_among_the_checkpoints_is_rotated_out_itself_never_its_target(run, tmp_path):
    """keep_checkpoints deletes the oldest step file: where that is a link, the link goes, not its target."""
    run_dir = tmp_path / "runs" / "r"
    shutil.copytree(run[0], run_dir)
    target = _outside(tmp_path, "file")
    before = target.read_bytes()
    (run_dir / "checkpoints" / "step_0000000.pt").symlink_to(target)
    code, _, stderr = run_cli(["train", "--resume", "--quiet",
                               *set_flags(_overrides(tmp_path / "runs", run[1], "run.steps=3"))])
    assert code == 0, stderr
    assert target.read_bytes() == before
    assert not (run_dir / "checkpoints" / "step_0000000.pt").is_symlink()


# --------------------------------------------------------------------------- make-dataset


def _dataset_args(out: Path):
    return ["make-dataset", "--class", TINY, "--shapes", "2", "--views", "1", "--resolution", "16", "--out",
            str(out), "--quiet"]


@pytest.mark.parametrize("part, kind", [(".lock", "file"), ("records.jsonl", "file"), ("collection.json", "file"),
                                        ("manifest.json", "file"), ("images", "folder"), ("exr", "folder"),
                                        ("volumes", "folder")])
def test_make_dataset_refuses_a_collection_whose_part_is_a_link(tmp_path, tiny_class, part, kind):
    out = tmp_path / "data"
    out.mkdir()
    target = _outside(tmp_path, kind)
    (out / part).symlink_to(target)
    before = _snapshot(target)
    for extra in ([], ["--overwrite"]):
        code, _, stderr = run_cli([*_dataset_args(out), *extra])
        assert code == 2, stderr
        _refused(stderr, "make-dataset", out / part)
        assert _snapshot(target) == before
    assert sorted(p.name for p in out.iterdir()) == [part]                # nothing written beside it either


def test_make_dataset_resume_refuses_a_linked_image_folder_of_a_half_written_collection(tmp_path, tiny_class):
    out = tmp_path / "data"
    assert run_cli(_dataset_args(out))[0] == 0
    (out / "manifest.json").unlink()                                       # unfinished: it would resume
    target = _outside(tmp_path, "folder")
    shutil.rmtree(out / "images")
    (out / "images").symlink_to(target)
    before = _snapshot(target)
    code, _, stderr = run_cli(_dataset_args(out))
    assert code == 2
    _refused(stderr, "make-dataset", out / "images")
    assert _snapshot(target) == before


# --------------------------------------------------------------------------- output folders


@pytest.mark.parametrize("part, kind", [("report.md", "file"), ("results.json", "file"), ("figures", "folder"),
                                        ("platonic.json", "file"), ("platonic.lock", "file")])
def test_evaluate_refuses_an_out_folder_whose_part_is_a_link(tmp_path, part, kind):
    out = tmp_path / "eval"
    out.mkdir()
    target = _outside(tmp_path, kind)
    (out / part).symlink_to(target)
    before = _snapshot(target)
    code, _, stderr = run_cli(["evaluate", "--run", str(tmp_path / "no-run"), "--out", str(out), "--overwrite"])
    assert code == 2
    _refused(stderr, "evaluate", out / part)
    assert _snapshot(target) == before


@pytest.mark.parametrize("photos", [False, True])
@pytest.mark.parametrize("part, kind", [("report.md", "file"), ("run", "folder"), ("data", "folder"),
                                        ("reconstructions", "folder")])
def test_quickstart_refuses_an_out_folder_whose_part_is_a_link(tmp_path, part, kind, photos):
    out = tmp_path / "qs"
    out.mkdir()
    target = _outside(tmp_path, kind)
    (out / part).symlink_to(target)
    before = _snapshot(target)
    extra = ["--photos", str(_photo_folder(tmp_path))] if photos else []
    code, _, stderr = run_cli(["quickstart", *extra, "--out", str(out), "--quiet", "--overwrite",
                               "--set", "model.resolution=16"])
    assert code == 2, stderr
    _refused(stderr, "quickstart", out / part)
    assert _snapshot(target) == before


def _photo_folder(tmp_path: Path) -> Path:
    """Ten small cut-out photos (distinct): enough for the photo quickstart's split."""
    import numpy as np
    from PIL import Image

    folder = tmp_path / "photos"
    folder.mkdir()
    rng = np.random.default_rng(0)
    for i in range(10):
        rgba = np.zeros((32, 32, 4), np.uint8)
        rgba[8:24, 8 + i % 4:24, :3] = rng.integers(0, 255, 3)
        rgba[8:24, 8 + i % 4:24, 3] = 255
        Image.fromarray(rgba, "RGBA").save(folder / f"p{i}.png")
    return folder


@pytest.mark.parametrize("part, kind", [("compare.json", "file"), ("compare_vh.png", "file")])
def test_compare_writes_nothing_through_a_link_in_out(tmp_path, part, kind):
    out = tmp_path / "cmp"
    out.mkdir()
    target = _outside(tmp_path, kind)
    (out / part).symlink_to(target)
    before = _snapshot(target)
    code, _, stderr = run_cli(["compare", "--resolution", "8", "--views", "1", "--repeats", "1", "--models", "vh",
                               "--out", str(out), "--overwrite"])
    assert code == 2, stderr
    _refused(stderr, "compare", out / part)
    assert _snapshot(target) == before


def test_reconstruct_replaces_a_link_in_out_never_its_target(run, tmp_path):
    """A result file that is a link (--overwrite) is replaced by the rename, not written through; and
    --out itself may be a link, the user's choice."""
    photo = tmp_path / "x.png"
    shutil.copy(sorted(run[1].glob("*/images/*.png"))[0], photo)
    target = _outside(tmp_path, "file")
    before = target.read_bytes()
    out = tmp_path / "rec"
    out.mkdir()
    (out / "x.npz").symlink_to(target)
    code, _, stderr = run_cli(["reconstruct", "--run", str(run[0]), str(photo), "--out", str(out), "--overwrite"])
    assert code == 0, stderr
    assert not (out / "x.npz").is_symlink() and target.read_bytes() == before
    folder = _outside(tmp_path / "more", "folder")
    (tmp_path / "linked-out").symlink_to(folder)
    code, _, stderr = run_cli(["reconstruct", "--run", str(run[0]), str(photo), "--out", str(tmp_path / "linked-out")])
    assert code == 0, stderr
    assert (folder / "x.npz").is_file()


def test_make_dataset_preview_replaces_a_link_never_its_target(tmp_path):
    """matplotlib's savefig opened the sheet's path, following a link there; now it is written beside and renamed."""
    out = tmp_path / "previews"
    out.mkdir()
    target = _outside(tmp_path, "file")
    before = target.read_bytes()
    (out / "preview_mushroom.png").symlink_to(target)
    code, _, stderr = run_cli(["make-dataset", "--preview", "--class", "mushroom", "--preview-shapes", "1",
                               "--resolution", "16", "--out", str(out)])
    assert code == 0, stderr
    assert target.read_bytes() == before and not (out / "preview_mushroom.png").is_symlink()


def test_generate_overwrite_removes_a_linked_sample_itself_never_its_target(tmp_path):
    """--overwrite deletes an earlier call's sample_* files: one that is a link goes, its target stays."""
    import torch
    from types import SimpleNamespace

    from mitsuba_platonic.export import export_samples

    model = SimpleNamespace(generate=lambda n, seed: torch.rand(n, 4, 8, 8, 8), formation="ea", channels=4, resolution=8)
    out = tmp_path / "gen"
    out.mkdir()
    target = _outside(tmp_path, "file")
    before = target.read_bytes()
    (out / "sample_007.npz").symlink_to(target)
    (out / "linked").symlink_to(_outside(tmp_path / "more", "folder"))
    with fileio.confined(out):
        export_samples(model, 1, out, overwrite=True)
        with pytest.raises(fileio.LinkRefused, match="linked"):             # a folder on the way: refused
            export_samples(model, 1, out / "linked", overwrite=True)
    assert target.read_bytes() == before
    assert not (out / "sample_007.npz").exists() and not (out / "sample_007.npz").is_symlink()
    assert (out / "sample_000.npz").is_file() and (out / "samples.png").is_file()
