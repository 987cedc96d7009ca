"""User errors are one line on the command line (issue 10): a corrupt run config, an envmap that is
no EXR, a marching step float32 cannot take, a CUDA variant without CUDA, Ctrl-C while data is
prepared, a comparison that cannot fit in memory, a photo too thin to train on, a collection with a
missing volume, an empty or meta batch; and a bug is not dressed up as one (it keeps its traceback)."""

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest
import torch
from PIL import Image

import mitsuba_platonic
from mitsuba_platonic.views import front_view
from mitsuba_platonic.volume import test_volume
from cli_runner import one_line, run_cli
from tiny_shapes import TINY

CLASS = "mushroom"


pytestmark = pytest.mark.usefixtures("tiny_class")


def _train_args(tmp_path):
    overrides = [f"run.out_dir={tmp_path}/runs", "run.name=r", "run.steps=2", "run.log_every=1",
                 "run.sample_every=1000", "run.checkpoint_every=2", f"data.cache={tmp_path}/data",
                 f"data.shape_class={TINY}", "data.n_shapes=2", "data.views_per_shape=1", "model.resolution=16",
                 "model.width=4", "model.latent=8", "train.batch_size=2"]
    return sum((["--set", a] for a in overrides), [])


# --------------------------------------------------------------------------- 1. a corrupt run config


@pytest.mark.parametrize("text, message", [
    ("run: [unclosed\n  foo: {", "not valid YAML"),
    ("- a\n- b\n", "expected a mapping"),
    ("bogus: 1\n", "bogus: unknown key"),
    ("train: {batch_size: eight}\n", "train.batch_size"),
])
def test_resume_with_a_corrupt_config_yaml_names_the_file(tmp_path, text, message):
    args = _train_args(tmp_path)
    assert run_cli(["train", "--quiet", *args])[0] == 0
    config = tmp_path / "runs" / "r" / "config.yaml"
    config.write_text(text)
    code, _, stderr = run_cli(["train", "--resume", "--quiet", *args])
    assert code == 2
    err = one_line(stderr, "train")
    assert str(config) in err and message in err, err


def test_a_checkpoint_whose_saved_config_is_bad_names_the_file(tmp_path):
    """reconstruct and generate read the config saved in the checkpoint (config.yaml is only what
    --resume compares against): a bad key there is one line naming the checkpoint."""
    args = _train_args(tmp_path)
    assert run_cli(["train", "--quiet", *args])[0] == 0
    run_dir = tmp_path / "runs" / "r"
    (run_dir / "config.yaml").write_text("run: [unclosed")           # not read by generate
    assert run_cli(["generate", "--run", str(run_dir), "-n", "1", "--out", str(tmp_path / "g")])[0] == 0
    for ckpt in (run_dir / "checkpoints").glob("*.pt"):
        state = torch.load(ckpt, weights_only=False)
        state["config"]["train"]["bogus"] = 1
        torch.save(state, ckpt)
    img = next((tmp_path / "data").glob("*/images/*.png"))
    for command in (["generate", "--run", str(run_dir), "-n", "1"], ["reconstruct", "--run", str(run_dir), str(img)]):
        code, _, stderr = run_cli(command)
        assert code == 2
        err = one_line(stderr, command[0])
        assert "last.pt" in err and "train.bogus: unknown key" in err, err


# --------------------------------------------------------------------------- 2. --envmap that is no EXR


def test_make_dataset_envmap_that_is_not_an_exr(tmp_path):
    fake = tmp_path / "sky.exr"
    fake.write_text("not an EXR file")
    out = tmp_path / "d"
    code, _, stderr = run_cli(["make-dataset", "--class", CLASS, "--shapes", "1", "--views", "1", "--resolution", "16",
                               "--formation", "physical", "--lighting", "envmap", "--envmap", str(fake),
                               "--spp", "1", "--out", str(out), "--quiet"])
    assert code == 2
    err = one_line(stderr, "make-dataset")
    assert str(fake) in err and "OpenEXR" in err, err
    assert not (out / "images").exists()                             # refused before rendering


def test_collection_spec_checks_envmaps_are_exr(tmp_path):
    from mitsuba_platonic.data.render_collection import CollectionSpec
    from mitsuba_platonic.errors import UserError
    fake = tmp_path / "sky.exr"
    fake.write_bytes(b"\x89PNG\r\n\x1a\n" + bytes(32))
    with pytest.raises(UserError, match="sky.exr.*not an OpenEXR file"):
        CollectionSpec(CLASS, formation="physical", lighting="envmap", envmaps=(str(fake),)).validate()


# --------------------------------------------------------------------------- 3. compare --step 1e-12


def test_compare_step_float32_cannot_march_names_the_flag(tmp_path):
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(["compare", "--step", "1e-12", "--resolution", "8", "--views", "1",
                                    "--repeats", "1", "--out", str(out)])
    assert code == 2 and stdout == ""
    err = one_line(stderr, "compare")
    assert "--step" in err and "1/64" in err and "1e-12" in err, err
    assert not out.exists()                                          # refused before rendering


# --------------------------------------------------------------------------- 4. a CUDA variant without CUDA


@pytest.mark.skipif(bool(mitsuba_platonic.BACKEND.get("cuda")), reason="CUDA works here")
def test_cuda_variant_without_cuda_says_what_to_do(tmp_path):
    env = dict(os.environ, MITSUBA_PLATONIC_VARIANT="cuda_ad_rgb")
    r = subprocess.run([sys.executable, "-m", "mitsuba_platonic.cli", "compare", "--resolution", "8", "--views", "1",
                        "--repeats", "1", "--models", "vh", "--out", str(tmp_path / "out")],
                       env=env, capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    err = one_line(r.stderr, "compare")
    assert "MITSUBA_PLATONIC_VARIANT=cuda_ad_rgb" in err and "llvm_ad_rgb" in err and "unset" in err, err


# --------------------------------------------------------------------------- 5. Ctrl-C while data is prepared


def _interrupt_when(command, ready, timeout=240, preexec_fn=None):
    """Start ``python -m mitsuba_platonic.cli COMMAND``, send SIGINT once ``ready()``; → (rc, stdout, stderr)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    p = subprocess.Popen([sys.executable, "-m", "mitsuba_platonic.cli", *command], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, env=env, text=True, preexec_fn=preexec_fn)
    deadline = time.time() + timeout
    while not ready() and time.time() < deadline and p.poll() is None:
        time.sleep(0.1)
    assert p.poll() is None, p.communicate()
    time.sleep(0.3)                                                  # a few more images
    p.send_signal(signal.SIGINT)
    out, err = p.communicate(timeout=timeout)
    return p.returncode, out, err


def test_ctrl_c_during_make_dataset_is_one_line(tmp_path):
    out = tmp_path / "d"
    rc, stdout, stderr = _interrupt_when(
        ["make-dataset", "--class", CLASS, "--shapes", "5000", "--views", "1", "--resolution", "16",
         "--out", str(out), "--quiet"],
        lambda: any((out / "images").glob("*.png")) if (out / "images").is_dir() else False)
    assert rc == -signal.SIGINT, stderr                             # ends by the signal, as a shell expects
    err = one_line(stderr, "make-dataset")
    assert "interrupted" in err and "of 5000 images" in err and str(out) in err and "same command" in err, err
    saved = int(err.split(" of 5000 images")[0].rsplit(" ", 1)[1])
    assert 0 < saved <= len(list((out / "images").glob("*.png")))
    assert not (out / "manifest.json").exists()


def test_ctrl_c_while_train_prepares_its_data_is_one_line(tmp_path):
    cfg_file = tmp_path / "c.yaml"
    cfg_file.write_text(f"""
run: {{out_dir: {tmp_path}/runs, name: r, steps: 10}}
data: {{cache: {tmp_path}/data, shape_class: {CLASS}, n_shapes: 5000, views_per_shape: 1}}
model: {{resolution: 16, width: 4, latent: 8}}
train: {{batch_size: 2}}
""")
    data = tmp_path / "data"
    rc, stdout, stderr = _interrupt_when(["train", "--config", str(cfg_file), "--quiet"],
                                         lambda: any(data.glob("*/images/*.png")))
    images = len(list(data.glob("*/images/*.png")))
    assert rc == -signal.SIGINT, f"exit {rc} with {images} of 5000 images on disk; stdout {stdout!r}, stderr {stderr!r}"
    err = one_line(stderr, "train")
    assert "preparing the training data" in err and "of 5000 images" in err and "no training step" in err, err
    assert not (tmp_path / "runs" / "r" / "checkpoints").exists()
    assert not (tmp_path / "runs" / "r" / "run.lock").exists()


def test_ctrl_c_interrupts_a_command_whose_parent_blocked_sigint(tmp_path):
    """The signal mask is inherited: a command started with SIGINT blocked unblocks it."""
    out = tmp_path / "d"
    rc, _, stderr = _interrupt_when(
        ["make-dataset", "--class", CLASS, "--shapes", "5000", "--views", "1", "--resolution", "16",
         "--out", str(out), "--quiet"],
        lambda: any((out / "images").glob("*.png")) if (out / "images").is_dir() else False,
        preexec_fn=lambda: signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}))
    assert rc == -signal.SIGINT, f"exit {rc}; stderr {stderr!r}"
    assert "interrupted" in one_line(stderr, "make-dataset")


def test_a_ctrl_c_a_library_swallows_still_interrupts_the_collection(tmp_path, monkeypatch):
    """A compiled library can clear the KeyboardInterrupt raised in Python code it calls; within
    the command line's handler the press is noted and the next shape raises it again."""
    from mitsuba_platonic.data import render_collection as C
    from mitsuba_platonic.errors import Interrupted, remembering_ctrl_c
    real = C.save_exr
    swallowed = []

    def save_exr_swallowing_ctrl_c(path, img):
        if not swallowed:
            try:
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(5)                                 # the handler raises in here
            except KeyboardInterrupt:
                swallowed.append(True)                        # ... and the "library" clears it
        return real(path, img)

    monkeypatch.setattr(C, "save_exr", save_exr_swallowing_ctrl_c)
    spec = C.CollectionSpec(shape_class=CLASS, n_shapes=4, views_per_shape=1, resolution=16, formation="ea",
                            renderer="closed_form")
    with remembering_ctrl_c():
        with pytest.raises(Interrupted, match="1 of 4 images"):
            C.make_collection(tmp_path / "c", spec, progress=False)
    assert swallowed == [True]
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler      # restored


# --------------------------------------------------------------------------- 6. compare at 1000³


def test_compare_refuses_a_resolution_that_cannot_fit_in_memory(monkeypatch, tmp_path):
    from mitsuba_platonic.bench import compare as C
    monkeypatch.setattr(C, "available_memory", lambda: (8 << 30, "MemAvailable in /proc/meminfo"))
    assert C.memory_estimate(1000, 4, builtin=True) > 24e9           # the float64 grid alone is 24 GB
    out = tmp_path / "out"
    t0 = time.perf_counter()
    code, stdout, stderr = run_cli(["compare", "--resolution", "1000", "--out", str(out)])
    assert time.perf_counter() - t0 < 5.0                            # refused up front, nothing allocated
    assert code == 2 and stdout == ""
    err = one_line(stderr, "compare")
    assert "--resolution 1000" in err and "GB" in err and "8.6 GB" in err and "MemAvailable" in err, err
    assert not out.exists()
    C.check_memory(32, 4, builtin=True)                              # the default fits


# --------------------------------------------------------------------------- 7. an 8 × 2000 photo


def test_an_extremely_thin_photo_is_rejected_and_reported(tmp_path):
    from mitsuba_platonic.data.photos import ImageRejected, PhotoCollection, PhotoCollectionWarning, decode_image, \
        prepare_image
    good = np.zeros((40, 40, 4), np.uint8)
    good[10:30, 12:28] = [200, 120, 40, 255]
    Image.fromarray(good, "RGBA").save(tmp_path / "good.png")
    thin = np.zeros((2000, 8, 4), np.uint8)                          # 8 wide, 2000 tall
    thin[5:1995, 2:6] = [90, 160, 60, 255]                           # a pole, transparent around it
    Image.fromarray(thin, "RGBA").save(tmp_path / "thin.png")
    with pytest.warns(PhotoCollectionWarning, match="thin.png"):
        photos = PhotoCollection(tmp_path, 16, "all")
    assert len(photos) == 1
    (skipped,) = photos.report.skipped
    assert skipped.path.name == "thin.png" and skipped.reason == "extreme_aspect"
    assert "thin.png" in skipped.message and "250" in skipped.message and "8" in skipped.message
    assert "thin.png" in photos.report.summary()
    with pytest.raises(ImageRejected, match="thin.png"):
        prepare_image(decode_image(tmp_path / "thin.png"), 16, name=str(tmp_path / "thin.png"))


# --------------------------------------------------------------------------- 8. a missing .npz volume


@pytest.mark.parametrize("missing", ["volumes/00000.npz", "volumes/00000.vol"])
def test_a_collection_with_a_missing_volume_is_not_finished(tmp_path, missing):
    out = tmp_path / "d"
    command = ["make-dataset", "--class", CLASS, "--shapes", "2", "--views", "2", "--resolution", "16",
               "--out", str(out), "--quiet"]
    assert run_cli(command)[0] == 0
    png = out / "images" / "00000_00.png"
    stamp = png.stat().st_mtime_ns
    reference = (out / missing).read_bytes()
    (out / missing).unlink()
    code, stdout, stderr = run_cli(command)
    assert code == 0, stderr
    assert (out / missing).read_bytes() == reference                 # re-made, the same bytes
    assert png.stat().st_mtime_ns == stamp                           # the images were not re-rendered


# --------------------------------------------------------------------------- 9. B = 0 and meta tensors


@pytest.mark.parametrize("backend", ["closed_form", "mitsuba"])
def test_render_rejects_an_empty_batch_and_meta_tensors(backend):
    from mitsuba_platonic.views import validate_views
    from mitsuba_platonic.volume import validate_volume
    with pytest.raises(ValueError, match="volume has batch size 0"):
        mitsuba_platonic.render(torch.zeros(0, 4, 8, 8, 8), torch.zeros(0, 3), "ea", backend)
    with pytest.raises(ValueError, match="volume is on the 'meta' device"):
        mitsuba_platonic.render(torch.zeros(1, 4, 8, 8, 8, device="meta"), front_view(1), "ea", backend)
    with pytest.raises(ValueError, match="views are on the 'meta' device"):
        mitsuba_platonic.render(test_volume(8), front_view(1).to("meta"), "ea", backend)
    with pytest.raises(ValueError, match="views hold no view"):
        validate_views(torch.zeros(0, 3))
    with pytest.raises(ValueError, match="batch size 0"):
        validate_volume(torch.zeros(0, 1, 8, 8, 8), "vh")


# --------------------------------------------------------------------------- user errors vs bugs


def test_a_bug_keeps_its_traceback_and_a_user_error_is_one_line(monkeypatch, tmp_path):
    from mitsuba_platonic.bench import compare as C
    from mitsuba_platonic.errors import Interrupted, UserError
    argv = ["compare", "--resolution", "8", "--views", "1", "--repeats", "1", "--out", str(tmp_path / "out")]

    def bug(*args, **kwargs):
        raise ValueError("operands could not be broadcast together")    # an internal bug, not the user's

    monkeypatch.setattr(C, "compare", bug)
    with pytest.raises(ValueError, match="broadcast"):
        run_cli(argv)

    def user(*args, **kwargs):
        raise UserError("--views 1: something the user can fix")

    monkeypatch.setattr(C, "compare", user)
    code, _, stderr = run_cli(argv)
    assert code == 2 and one_line(stderr, "compare") == "platonic compare: error: --views 1: something the user can fix"

    def ctrl_c(*args, **kwargs):
        raise Interrupted("3 of 9 images are saved")

    monkeypatch.setattr(C, "compare", ctrl_c)
    code, _, stderr = run_cli(argv)
    assert code == 130 and one_line(stderr, "compare") == "platonic compare: interrupted: 3 of 9 images are saved"


def test_a_bug_inside_a_training_step_keeps_its_traceback(monkeypatch, tmp_path):
    """A ValueError from the code of a step (not the user's input, the weights still finite) is a
    bug: ``platonic train`` does not turn it into a one-line error with exit code 2, it propagates
    with a note saying which step failed and what is kept."""
    from mitsuba_platonic.errors import UserError
    from mitsuba_platonic.train.trainer import Trainer

    def bug(self, step):
        raise ValueError("operands could not be broadcast together")     # an internal bug, not the user's

    monkeypatch.setattr(Trainer, "step", bug)
    with pytest.raises(ValueError, match="broadcast") as info:
        run_cli(["train", "--quiet", *_train_args(tmp_path)])
    assert not isinstance(info.value, UserError)
    assert any("training failed in step 1" in note and "nothing was saved" in note
               for note in getattr(info.value, "__notes__", [])), getattr(info.value, "__notes__", None)
    assert not (tmp_path / "runs" / "r" / "checkpoints").exists()


def test_warnings_on_the_command_line_are_one_line_each(tmp_path):
    """A skipped photo warns with one line per file (``platonic train: warning: skipped …``), not
    Python's warning format with its file name and source line; the error that follows when no
    photo is usable is still the one-line summary first."""
    photos = tmp_path / "photos"
    photos.mkdir()
    (photos / "a.png").write_text("not an image")
    (photos / "b.jpg").write_bytes(b"")
    code, _, err = run_cli(["train", "--config", "configs/photos_tree_ea.yaml", "--set", f"data.path={photos}",
                            "--set", f"run.out_dir={tmp_path / 'runs'}", "--set", "run.steps=1"])
    assert code == 2
    lines = err.strip().splitlines()
    warned = [x for x in lines if x.startswith("platonic train: warning: skipped ")]
    assert len(warned) == 2 and any("a.png" in x for x in warned) and any("b.jpg" in x for x in warned)
    assert not any("dataset.py" in x or "collection.py" in x or x.lstrip().startswith("full = ") for x in lines), err
    errors = [x for x in lines if x.startswith("platonic train: error: ")]
    assert len(errors) == 1 and "no usable images" in errors[0]
