"""Tracebacks become one-line errors and messages name what a user would change (issue 29):
``compare --resolution 1``, more marcher rays than a Dr.Jit launch holds, ``--help`` under an ASCII
terminal, ``--version``; a too-wide fov, too many ``--views``, fixes worded as the CLI's flags,
errors naming their config keys, settings that would be ignored, and an image Pillow only warns about."""

from __future__ import annotations

import os
import subprocess
import sys
import warnings

import pytest
from PIL import Image

from mitsuba_platonic.config import ConfigError, load_config
from mitsuba_platonic.errors import UserError
from cli_runner import one_line, run_cli
from tiny_shapes import TINY


def test_version():
    code, stdout, _ = run_cli(["--version"])
    assert code == 0 and stdout.startswith("platonic 0.")


def test_help_prints_under_an_ascii_terminal():
    env = dict(os.environ, PYTHONIOENCODING="ascii")
    r = subprocess.run([sys.executable, "-m", "mitsuba_platonic.cli", "make-dataset", "--help"], env=env,
                       capture_output=True, text=True, timeout=300, stdin=subprocess.DEVNULL)
    assert r.returncode == 0 and r.stderr == "", r.stderr
    assert "--elevation" in r.stdout


def test_compare_resolution_1_is_a_usage_error(tmp_path):
    code, _, stderr = run_cli(["compare", "--resolution", "1", "--out", str(tmp_path / "o")])
    assert code == 2 and "--resolution" in stderr and "at least 2" in stderr and "Traceback" not in stderr


def test_more_rays_than_one_launch_holds_is_said_up_front():
    from mitsuba_platonic import render
    from mitsuba_platonic.views import front_view
    from mitsuba_platonic.volume import test_volume

    with pytest.raises(UserError, match=r"spp: 100000000 .*2³² lanes.*spp ≤ 67,108,863"):
        render(test_volume(8), front_view(1), "ea", backend="mitsuba", spp=10 ** 8)


def test_a_too_wide_fov_is_reported_as_the_fov():
    from mitsuba_platonic.views import lens

    with pytest.raises(UserError, match=r"^fov: 120°? ?.*too wide") as e:
        lens("perspective", fov=120.0)
    assert "distance" in str(e.value)                                  # ... and how a distance would help
    assert lens("perspective", fov=120.0, distance=2.0)[1] == 2.0


def test_too_many_views_are_reported_against_views(monkeypatch, tmp_path):
    from mitsuba_platonic.bench import compare as C

    monkeypatch.setattr(C, "available_memory", lambda: (2 << 30, "MemAvailable in /proc/meminfo"))
    code, _, stderr = run_cli(["compare", "--views", "100000", "--out", str(tmp_path / "o")])
    assert code == 2
    err = one_line(stderr, "compare", "error")
    assert "--views 100000" in err and "view(s) fit at 32³ (--views)" in err, err


def test_fixes_are_worded_as_the_command_line_flags():
    from mitsuba_platonic.evaluate import metrics as M

    assert "--vgg-weights FILE" in M._VGG_HINT and "--fid-weights FILE" in M._FID_HINT


@pytest.mark.parametrize("overrides, key", [
    (["data.view_distribution=band", "data.elevation=[10]"], "data.elevation"),
    (["data.view_distribution=ring", "data.elevation=[10, 20]"], "data.elevation"),
    (["train.view_distribution=band", "train.elevation=[40, 10]"], "train.elevation"),
])
def test_elevation_errors_name_their_config_key(overrides, key):
    with pytest.raises(ConfigError, match=rf"^{key}: "):
        load_config(None, overrides)


def _tiny(tmp_path, *extra):
    overrides = [f"run.out_dir={tmp_path}/runs", "run.name=r", "run.steps=1", "run.log_every=1",
                 "run.sample_every=1000", "run.checkpoint_every=1", f"data.cache={tmp_path}/data",
                 f"data.shape_class={TINY}", "data.n_shapes=2", "data.views_per_shape=1", "model.resolution=16",
                 "model.width=4", "model.latent=8", "train.batch_size=2", *extra]
    return sum((["--set", o] for o in overrides), [])


def test_an_unknown_shape_class_names_data_shape_class(tmp_path, tiny_class):
    code, _, stderr = run_cli(["train", "--quiet", *_tiny(tmp_path, "data.shape_class=teapot")])
    assert code == 2
    err = one_line(stderr, "train", "error")
    assert "data.shape_class" in err and "teapot" in err, err


def test_resume_names_the_settings_that_differ(tmp_path, tiny_class):
    assert run_cli(["train", "--quiet", *_tiny(tmp_path)])[0] == 0
    code, _, stderr = run_cli(["train", "--quiet", "--resume", *_tiny(tmp_path, "run.steps=2", "data.n_shapes=3")])
    assert code == 2
    err = one_line(stderr, "train", "error")
    assert "data.n_shapes: 2 there, 3 now" in err, err


def test_settings_the_run_ignores_are_warned_about(tmp_path, tiny_class):
    code, _, stderr = run_cli(["train", "--quiet", *_tiny(tmp_path, "render.step=0.5", "data.elevation=10")])
    assert code == 0, stderr
    assert "platonic train: warning: render.step: only the Mitsuba marcher" in stderr, stderr
    assert "platonic train: warning: data.elevation: data.view_distribution 'sphere'" in stderr, stderr


@pytest.mark.parametrize("flags, named", [
    (["--lighting", "envmap", "--spp", "7"], "--lighting, --spp"),
    (["--max-depth", "3"], "--max-depth"),
    (["--elevation", "10"], "--elevation"),
    (["--side-width", "20"], "--side-width"),
])
def test_make_dataset_refuses_flags_it_would_ignore(tmp_path, flags, named):
    out = tmp_path / "d"
    code, _, stderr = run_cli(["make-dataset", "--class", "mushroom", "--shapes", "1", "--views", "1",
                               "--out", str(out), *flags])
    assert code == 2
    err = one_line(stderr, "make-dataset", "error")
    assert err.startswith(f"platonic make-dataset: error: {named}:"), err
    assert not out.exists()


def test_an_image_pillow_only_warns_about_is_refused_naming_the_file(tmp_path, monkeypatch):
    from mitsuba_platonic.data.photos import ImageRejected, decode_image

    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)               # 1000 < 40 × 40 < 2000: a warning only
    path = tmp_path / "big.png"
    Image.new("RGBA", (40, 40), (255, 0, 0, 255)).save(path)
    with warnings.catch_warnings():
        warnings.simplefilter("error")                                 # no warning escapes either
        with pytest.raises(ImageRejected) as e:
            decode_image(path)
    assert e.value.reason == "too_large" and str(path) in str(e.value)


# --------------------------------------------------------------------------- issue 46: flags and files misnamed


@pytest.mark.parametrize("command", [["generate", "--run", "r"], ["make-dataset"], ["compare"]])
def test_a_seed_past_64_bits_is_a_usage_error_not_an_overflow(command, tmp_path):
    code, _, stderr = run_cli([*command, "--seed", "99999999999999999999", "--out", str(tmp_path / "o")])
    assert code == 2 and "Traceback" not in stderr and "Overflow" not in stderr
    assert "argument --seed: expected a seed, an integer from 0 to 2⁶³ − 1" in stderr, stderr
    assert not (tmp_path / "o").exists()


def test_the_largest_seed_is_accepted():
    from mitsuba_platonic.cli.args import MAX_SEED, seed
    import torch
    assert seed(str(MAX_SEED)) == MAX_SEED
    torch.Generator().manual_seed(MAX_SEED)                               # what the seed is handed to


@pytest.mark.parametrize("content", [b"not an archive at all\n", b"PK\x03\x04 cut short"])
def test_a_npz_that_is_not_one_is_one_line_without_pickle_advice(tmp_path, content):
    bad = tmp_path / "v.npz"
    bad.write_bytes(content)
    code, _, stderr = run_cli(["compare", "--volume", str(bad), "--out", str(tmp_path / "o")])
    assert code == 2
    err = one_line(stderr, "compare", "error")
    assert f"'{bad}' is not a valid .npz volume" in err and "pickle" not in err, err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize("level", ["0", "1", "-0.5", "2"])
def test_reconstruct_names_level_outside_0_1(tmp_path, level):
    code, _, stderr = run_cli(["reconstruct", "--run", str(tmp_path / "no_run"), "--level", level,
                               str(tmp_path / "x.png")])
    assert code == 2
    err = one_line(stderr, "reconstruct", "error")
    assert err.startswith("platonic reconstruct: error: --level: expected the mesh's iso-level, a density between 0 "
                          "and 1"), err

