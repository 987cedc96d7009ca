"""Bad inputs that escaped as crashes or tracebacks (issue 27): each is now one line, exit code 2,
or (a damaged record the collection can rebuild) a warning naming it."""

from __future__ import annotations

import json
import subprocess
import sys

import pytest

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.render.mitsuba import sky
from cli_runner import one_line, run_cli
from tiny_shapes import TINY

pytestmark = pytest.mark.usefixtures("tiny_class")


# --------------------------------------------------------------------------- a truncated environment map


def _first_chunk(data: bytes) -> int:
    """Where a single-part EXR's pixel data begin: the first entry of the offset table that
    follows the header (magic, version, then ``name\\0 type\\0 size value`` attributes up to a 0 byte)."""
    at = 8
    while data[at] != 0:
        at = data.index(b"\0", data.index(b"\0", at) + 1) + 1           # past the name and the type
        at += 4 + int.from_bytes(data[at:at + 4], "little")               # the size, the value
    return int.from_bytes(data[at + 1:at + 9], "little")


@pytest.fixture(scope="module")
def whole_envmap(tmp_path_factory):
    return sky.bake_sky(tmp_path_factory.mktemp("envmaps") / "whole.exr", elevation=35.0, turbidity=3.0)


@pytest.mark.parametrize("cut", ["11 bytes into the pixels", "1571 bytes"])
def test_truncated_envmap_is_one_line_not_an_abort(whole_envmap, tmp_path, cut):
    """Cut 11 bytes into its first chunk, Mitsuba's loader threw EOFException on a worker thread:
    the process aborted (exit 134) with nothing said; cut later, a RuntimeError traceback (exit 1).
    Run as a user runs it, in its own process."""
    data = whole_envmap.read_bytes()
    truncated = tmp_path / "trunc.exr"
    truncated.write_bytes(data[:_first_chunk(data) + 11] if cut.startswith("11") else data[:1571])
    out = tmp_path / "d"
    done = subprocess.run(
        [sys.executable, "-m", "mitsuba_platonic.cli", "make-dataset", "--class", "mushroom", "--shapes", "1",
         "--views", "1", "--resolution", "16", "--formation", "physical", "--spp", "1", "--max-depth", "2",
         "--lighting", "envmap", "--envmap", str(truncated), "--out", str(out), "--quiet"],
        capture_output=True, text=True, stdin=subprocess.DEVNULL, timeout=300)
    assert done.returncode == 2, (done.returncode, done.stderr[-2000:])
    err = one_line(done.stderr, "make-dataset", kind="error")
    assert f"--envmap '{truncated}'" in err and "truncated or damaged" in err, err
    assert not out.exists()


def _envmap(path, kind: str):
    """A 8 × 16 lat-long map, grey 0.5, with what ``kind`` names wrong, written by Mitsuba."""
    import numpy as np
    from mitsuba_platonic.render.variant import ensure_variant

    pixels = np.full((8, 16, 3), 0.5, dtype=np.float32)
    if kind == "a NaN pixel":
        pixels[3, 5, 1] = np.nan
    elif kind == "an Inf pixel":
        pixels[2, 7] = np.inf
    elif kind == "all black":
        pixels[:] = 0.0
    elif kind == "all negative":
        pixels[:] = -1.0
    ensure_variant().Bitmap(pixels).write(str(path))
    return path


@pytest.mark.parametrize("kind, problem", [
    ("a NaN pixel", "1 pixel value(s) are NaN or Inf (NaN at row 3, column 5)"),
    ("an Inf pixel", "3 pixel value(s) are NaN or Inf (Inf at row 2, column 7)"),
    ("all black", "every pixel is black (0): it gives no light"),
    ("all negative", "384 pixel value(s) are negative (as low as -1)"),
])
def test_an_envmap_that_cannot_light_is_one_line_naming_the_file(tmp_path, kind, problem):
    envmap = _envmap(tmp_path / "bad.exr", kind)
    out = tmp_path / "d"
    code, _, stderr = run_cli(["make-dataset", "--class", TINY, "--shapes", "1", "--views", "1", "--resolution", "16",
                               "--formation", "physical", "--spp", "1", "--lighting", "envmap", "--envmap",
                               str(envmap), "--out", str(out), "--quiet"])
    assert code == 2
    err = one_line(stderr, "make-dataset", kind="error")
    assert f"--envmap '{envmap}' cannot light a scene: {problem}" in err, err
    assert not out.exists()


def test_a_good_envmap_passes_the_value_check(tmp_path):
    from mitsuba_platonic.data.envmaps import check_envmap
    check_envmap(_envmap(tmp_path / "good.exr", "good"))


# --------------------------------------------------------------------------- a manifest of the wrong shape


@pytest.mark.parametrize("manifest", ['{"spec": 5, "images": []}', "[1, 2]", '{"spec": {}, "images": 3}',
                                      '{"spec": {"n_shapes": 1}, "images": [7]}', "not JSON"])
def test_manifest_of_the_wrong_shape_is_named_and_rebuilt(tmp_path, manifest):
    args = ["make-dataset", "--class", TINY, "--shapes", "1", "--views", "2", "--resolution", "16",
            "--out", str(tmp_path), "--quiet"]
    assert run_cli(args)[0] == 0
    good = json.loads((tmp_path / "manifest.json").read_text())
    (tmp_path / "manifest.json").write_text(manifest)
    code, out, err = run_cli(args)
    assert code == 0, err
    warning = one_line(err, "make-dataset", kind="warning")
    assert f"{tmp_path / 'manifest.json'}" in warning and "rebuilt" in warning, warning
    rebuilt = json.loads((tmp_path / "manifest.json").read_text())
    assert {k: v for k, v in rebuilt.items() if k != "seconds"} == {k: v for k, v in good.items() if k != "seconds"}


@pytest.mark.parametrize("spec", ["5", "[1, 2]", "{}", "not JSON"])
def test_collection_json_of_the_wrong_shape_is_one_line(tmp_path, spec):
    """collection.json records the settings the images were made with: damaged, the collection
    cannot be resumed, and nothing is deleted."""
    args = ["make-dataset", "--class", TINY, "--shapes", "1", "--views", "1", "--resolution", "16",
            "--out", str(tmp_path), "--quiet"]
    assert run_cli(args)[0] == 0
    (tmp_path / "collection.json").write_text(spec)
    (tmp_path / "manifest.json").unlink()
    code, _, err = run_cli(args)
    assert code == 2
    err = one_line(err, "make-dataset", kind="error")
    assert f"{tmp_path / 'collection.json'}" in err and "damaged" in err, err
    assert (tmp_path / "images" / "00000_00.png").is_file()


# --------------------------------------------------------------------------- sizes that cannot fit


def test_a_latent_that_cannot_fit_is_refused_up_front(tmp_path):
    code, _, err = run_cli(["train", "--set", "model.latent=2000000000", "--set", f"run.out_dir={tmp_path}",
                            "--set", f"data.cache={tmp_path}/data", "--set", f"data.shape_class={TINY}",
                            "--set", "model.resolution=16", "--quiet"])
    assert code == 2
    err = one_line(err, "train", kind="error")
    assert err.startswith("platonic train: error: model.latent: 2000000000 ") and "GB" in err, err
    assert not (tmp_path / "data").exists() and not (tmp_path / "run").exists()


def test_quickstart_refuses_a_width_that_cannot_fit_before_rendering(tmp_path):
    code, _, err = run_cli(["quickstart", "--out", str(tmp_path / "q"), "--set", "model.width=1000000"])
    assert code == 2
    err = one_line(err, "quickstart", kind="error")
    assert "model.width: 1000000 " in err, err
    assert not (tmp_path / "q").exists()


def test_sizes_that_fit_pass():
    from mitsuba_platonic.train.memory_fit import check_model_fits
    check_model_fits(load_config("paper"))


# --------------------------------------------------------------------------- lighting the path tracer cannot use


@pytest.mark.parametrize("lighting", ["envmap", "mixed"])
def test_physical_backend_with_envmap_lighting_is_a_config_error(lighting):
    with pytest.raises(ConfigError, match=r"^render\.lighting: .*'sunsky'"):
        load_config(None, ["render.backend=physical", f"render.lighting={lighting}"])
    code, _, err = run_cli(["train", "--set", "render.backend=physical", "--set", f"render.lighting={lighting}"])
    assert code == 2
    assert one_line(err, "train", kind="error").startswith("platonic train: error: render.lighting: "), err


# --------------------------------------------------------------------------- files that are no regular files, sizes a file declares


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory, tiny_class):
    """A finished tiny reconstruction run (two steps at 16³)."""
    from mitsuba_platonic.train import run as R
    from tiny_shapes import tiny_run_overrides

    root = tmp_path_factory.mktemp("run")
    R.train(load_config(None, tiny_run_overrides(root / "runs", root / "data")), progress=False)
    return root / "runs" / "r"


def _fifo(path):
    """A FIFO at ``path``, and a thread that opens it for writing after a while and closes it (EOF):
    a reader that waits on it ends instead of hanging the test."""
    import os
    import threading
    import time

    os.mkfifo(path)

    def release():
        time.sleep(20)
        try:
            fd = os.open(path, os.O_WRONLY | os.O_NONBLOCK)
            os.close(fd)
        except OSError:                                   # no reader waits: nothing to release
            pass

    threading.Thread(target=release, daemon=True).start()
    return path


def test_reconstruct_of_a_fifo_is_one_line_and_reads_nothing(tiny_run, tmp_path):
    fifo = _fifo(tmp_path / "shot.png")
    code, _, err = run_cli(["reconstruct", "--run", str(tiny_run), str(fifo), "--out", str(tmp_path / "rec")])
    assert code == 2
    err = one_line(err, "reconstruct", kind="error")
    assert f"'{fifo}' is a FIFO (named pipe)" in err and "not a regular file" in err, err
    assert not (tmp_path / "rec").exists()


_READ_ZERO = """
import resource, sys
resource.setrlimit(resource.RLIMIT_AS, (2 << 30, 2 << 30))   # a reader without bound fails here, not the machine
from mitsuba_platonic.data.photos import ImageRejected, decode_image
try:
    decode_image(sys.argv[1])
except ImageRejected as e:
    print(e.reason, e)
"""


def test_an_image_that_links_to_dev_zero_is_refused_before_it_is_read(tmp_path):
    """``reconstruct --run R link-to-/dev/zero.png`` (and ``view --photo``) read it whole: all the memory."""
    link = tmp_path / "zero.png"
    link.symlink_to("/dev/zero")
    done = subprocess.run([sys.executable, "-c", _READ_ZERO, str(link)], capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith(f"unreadable '{link}' is a character device (through a link to '/dev/zero')"), \
        done.stdout


def test_a_volume_whose_header_declares_more_than_the_memory_is_refused_before_reading(tmp_path, monkeypatch):
    """A small ``.npz`` whose array header declares a large volume (here 4 × 256³ float32, 268 MB, its
    data cut short): refused by the size it declares against the memory free (64 MB, as this test
    says), before the data are read."""
    import io
    import zipfile

    import numpy as np

    from mitsuba_platonic.files import volume_io
    from mitsuba_platonic.runtime import budget
    from mitsuba_platonic.viewer.start import check_source          # platonic view SOURCE's reader

    header = io.BytesIO()
    np.lib.format.write_array_header_1_0(header, {"descr": "<f4", "fortran_order": False, "shape": (4, 256, 256, 256)})
    path = tmp_path / "declared.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        z.writestr("volume.npy", header.getvalue() + bytes(1024))            # magic, header, 1 kB of data
    monkeypatch.setattr(budget, "available_memory", lambda: (64 * 2 ** 20, "this test"))
    with pytest.raises(volume_io.VolumeFileError) as e:
        check_source(path)
    assert str(e.value).startswith(f"'{path}': its array 'volume' of shape (4, 256, 256, 256) needs at least "), e.value
    assert "this test" in str(e.value)
    monkeypatch.undo()                                   # with the memory there is: read, and cut short
    with pytest.raises(volume_io.VolumeFileError, match="could not read array 'volume'"):
        check_source(path)


def test_a_run_whose_config_asks_for_networks_that_cannot_fit_is_one_line(tiny_run, tmp_path):
    """``model.width: 100000`` in a run's checkpoint (its weights of width 4): ``generate`` refused
    before any network is allocated, naming the width."""
    import shutil

    import torch

    from mitsuba_platonic.files.checkpoint import save_checkpoint

    run = tmp_path / "r"
    shutil.copytree(tiny_run, run)
    for path in (run / "checkpoints").glob("*.pt"):
        state = torch.load(path, weights_only=True)
        state["config"]["model"]["width"] = 100000
        save_checkpoint(path, state)
    code, _, err = run_cli(["generate", "--run", str(run), "-n", "1", "--out", str(tmp_path / "g")])
    assert code == 2
    err = one_line(err, "generate", kind="error")
    assert "model.width: 100000" in err and "GB of memory" in err, err


def test_a_config_file_larger_than_any_config_is_refused_unread(tmp_path):
    from mitsuba_platonic.files.fileio import MAX_TEXT_BYTES

    big = tmp_path / "big.yaml"
    big.write_text("run:\n  name: " + "x" * (MAX_TEXT_BYTES + 1) + "\n")
    with pytest.raises(ValueError, match=rf"config file '{big}' is [0-9,]+ bytes, more than the "):
        load_config(big)


def test_quickstart_steps_and_a_set_of_run_steps_are_refused_naming_both(tmp_path):
    """--steps is run.steps: with a --set of it too, one of them would win without a word."""
    code, _, err = run_cli(["quickstart", "--steps", "5", "--set", "model.width=4", "--set", "run.steps=10",
                            "--out", str(tmp_path / "q")])
    assert code == 2
    assert one_line(err, "quickstart", kind="error") == ("platonic quickstart: error: run.steps: given twice, by "
                                                         "--steps 5 and by --set run.steps=10; expected one of them")
    assert not (tmp_path / "q").exists()


def test_a_run_name_longer_than_a_folder_name_is_refused_in_a_short_line():
    """A 10 MB ``run.name`` reached the file system, whose ``File name too long`` quoted it whole (a
    10 MB error line); a name of more than 255 bytes (UTF-8: 128 'ü' are 256) is refused by the
    config, quoted in a few dozen characters. 255 bytes is still a name."""
    load_config(None, ["run.name=" + "a" * 255])
    for name in ("a" * 10 ** 6, "ü" * 128):
        with pytest.raises(ConfigError) as e:
            load_config(None, [f"run.name={name}"])
        assert str(e.value).startswith("run.name: expected a folder name of at most 255 bytes") and len(str(e.value)) < 200


def test_an_os_error_on_a_huge_path_is_quoted_short_in_its_line():
    """An ``OSError`` that reaches the command line keeps Python's wording, its path cut to a few
    hundred characters (a path made of a user's long words was a line as long)."""
    import argparse
    import errno

    from mitsuba_platonic.cli.exits import error_message

    args = argparse.Namespace(command="train")
    line = error_message(args, OSError(errno.ENAMETOOLONG, "File name too long", "/tmp/" + "a" * 10 ** 6))
    assert line.startswith("platonic train: error: [Errno 36] File name too long: '/tmp/aaa") and len(line) < 300, line
    short = FileNotFoundError(errno.ENOENT, "No such file or directory", "x.yaml")
    assert error_message(args, short) == f"platonic train: error: {short}"
