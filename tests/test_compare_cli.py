"""`platonic compare` (cli/renderers.py + bench/compare.py) and the image helpers (images.py)."""

from __future__ import annotations

import contextlib
import io
import json

import numpy as np
import pytest
import torch
from PIL import Image

from mitsuba_platonic import render
from mitsuba_platonic.cli import main
from mitsuba_platonic.bench.compare import compare, format_table
from mitsuba_platonic.images import (composite, exr_channel_names, heatmap, load_exr, save_exr,
                                     save_png, to_hwc, to_uint8)
from mitsuba_platonic.views import front_view, sample_views
from mitsuba_platonic.volume import test_volume

N, VIEWS = 16, 2
MODELS = ("vh", "ao", "ea")


def run_cli(argv):
    """``main(argv)`` → (exit code, stdout, stderr)."""
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(list(argv))
    return code, out.getvalue(), err.getvalue()


def parse_table(stdout):
    """The printed table → {model: [max, mean, cf ms, mitsuba ms, ratio]}."""
    rows = {}
    for line in stdout.splitlines():
        cells = [c.strip() for c in line.split("|")]
        if len(cells) == 6 and cells[0] in MODELS:
            rows[cells[0]] = [float(c) for c in cells[1:]]
    return rows


def cli_views(n_views=VIEWS, seed=0):
    return torch.cat([front_view(1), sample_views(n_views - 1, seed=seed)])


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    out = tmp_path_factory.mktemp("compare")
    code, stdout, stderr = run_cli(["compare", "--resolution", str(N), "--views", str(VIEWS),
                                    "--out", str(out)])
    return code, stdout, stderr, out


# --------------------------------------------------------------------------- CLI: defaults


def independent_renders(model, views, **options):
    """Our own closed-form and Mitsuba renders of the CLI's default volume (builtin:figure at N,
    VH/AO on its density channel), one view per batch entry, with the CLI's Mitsuba options."""
    v = test_volume(N, "figure", "ea")
    v = (v if model == "ea" else v[:, 3:]).expand(len(views), -1, -1, -1, -1)
    options = {"step": 1.0, "spp": 1, "jitter": False, "seed": 0, **options}     # the CLI's defaults
    with torch.no_grad():
        return (render(v, views, model, "closed_form", filter="trilinear"),
                render(v, views, model, "mitsuba", filter="trilinear", **options))


def independent_diffs(model, views, **options):
    """max and mean |closed form − Mitsuba| over pixels, channels and views, computed here."""
    cf, mi = independent_renders(model, views, **options)
    d = (cf.double() - mi.double()).abs()
    return float(d.max()), float(d.mean())


def test_compare_table_agrees(default_run):
    """compare.json and the printed table report the max/mean |closed form − Mitsuba| we compute
    from our own renders of the same volume and views (float precision at step 1, trilinear), the
    printed cells are the JSON values rounded, and ratio = Mitsuba ms / closed-form ms."""
    code, stdout, stderr, out = default_run
    assert code == 0, stderr
    rows = parse_table(stdout)
    assert list(rows) == list(MODELS), stdout
    summary = json.loads((out / "compare.json").read_text())
    np.testing.assert_allclose(summary["view_vectors"], cli_views().numpy(), rtol=0, atol=1e-7)
    assert [r["model"] for r in summary["results"]] == list(MODELS)
    for r in summary["results"]:
        model = r["model"]
        assert r["resolution"] == N and r["views"] == VIEWS
        mx, mean = independent_diffs(model, cli_views())
        assert 0 < mx < 1e-4, model                       # step 1, trilinear: float precision
        assert r["max_abs_diff"] == pytest.approx(mx, rel=1e-6), model
        assert r["mean_abs_diff"] == pytest.approx(mean, rel=1e-6), model
        p_max, p_mean, p_cf, p_mi, p_ratio = rows[model]
        assert p_max == pytest.approx(mx, rel=6e-4) and p_mean == pytest.approx(mean, rel=6e-4), (model, stdout)
        assert r["ratio"] == pytest.approx(r["mitsuba_ms"] / r["closed_form_ms"], rel=1e-9)
        assert p_cf == pytest.approx(r["closed_form_ms"], abs=6e-4) and p_mi == pytest.approx(r["mitsuba_ms"], abs=6e-4)
        assert p_ratio == pytest.approx(r["ratio"], abs=6e-3)


def test_compare_writes_pngs_and_exrs(default_run):
    code, stdout, _, out = default_run
    assert code == 0
    for model in MODELS:
        png = out / f"compare_{model}.png"
        assert png.is_file() and str(png) in stdout
        with Image.open(png) as im:
            assert im.format == "PNG" and im.size[0] > 300 and im.size[1] > 300
        for i in range(VIEWS):
            exr = out / f"mitsuba_{model}_view{i}.exr"
            assert exr.is_file() and str(exr) in stdout
            names = exr_channel_names(exr)
            assert names == (("R", "G", "B", "A") if model == "ea" else ("Y", "A"))
            assert load_exr(exr).shape == (N, N, len(names))
    assert not list(out.glob(f"mitsuba_*_view{VIEWS}.exr"))


@pytest.mark.parametrize("model", MODELS)
def test_exr_alpha_is_the_mitsuba_alpha(default_run, model):
    _, _, _, out = default_run
    v = test_volume(N, "figure", model).expand(VIEWS, -1, -1, -1, -1)
    with torch.no_grad():
        image = render(v, cli_views(), model, "mitsuba", filter="trilinear")
    for i in range(VIEWS):
        exr = load_exr(out / f"mitsuba_{model}_view{i}.exr")
        alpha = image[i, -1].numpy()
        assert alpha.max() > 0.5                    # the figure is in frame
        np.testing.assert_allclose(load_exr(out / f"mitsuba_{model}_view{i}.exr", ("A",))[..., 0],
                                   alpha, rtol=0, atol=1e-6)
        if model == "ea":                           # premultiplied colour, as rendered
            np.testing.assert_allclose(exr[..., :3], to_hwc(image[i, :3]), rtol=0, atol=1e-6)
        else:                                       # Y = A: a white, premultiplied silhouette
            np.testing.assert_array_equal(exr[..., 0], exr[..., 1])


# --------------------------------------------------------------------------- CLI: .npz input


def test_npz_round_trip(tmp_path):
    v = test_volume(N, "figure", "ea")
    path = tmp_path / "figure.npz"
    np.savez(path, volume=v[0].numpy())                 # (C, N, N, N)
    code, stdout, stderr = run_cli(["compare", "--volume", str(path), "--views", "2", "--models", "ea",
                                    "--repeats", "1", "--out", str(tmp_path / "npz")])
    assert code == 0, stderr
    assert parse_table(stdout)["ea"][0] < 1e-4
    code, _, stderr = run_cli(["compare", "--resolution", str(N), "--views", "2", "--models", "ea",
                               "--repeats", "1", "--out", str(tmp_path / "builtin")])
    assert code == 0, stderr
    for i in range(2):
        a = load_exr(tmp_path / "npz" / f"mitsuba_ea_view{i}.exr")
        b = load_exr(tmp_path / "builtin" / f"mitsuba_ea_view{i}.exr")
        np.testing.assert_array_equal(a, b)


def test_npz_density_only_skips_ea(tmp_path):
    path = tmp_path / "density.npz"
    np.savez(path, volume=test_volume(N, "cloud", "vh").numpy())   # (1, 1, N, N, N)
    out = tmp_path / "out"
    code, stdout, stderr = run_cli(["compare", "--volume", str(path), "--views", "1", "--repeats", "1",
                                    "--out", str(out)])
    assert code == 0, stderr
    assert "skipping EA" in stderr
    assert set(parse_table(stdout)) == {"vh", "ao"}
    assert (out / "compare_vh.png").is_file() and not (out / "compare_ea.png").exists()
    code, _, stderr = run_cli(["compare", "--volume", str(path), "--models", "ea", "--out", str(out)])
    assert code == 2 and "nothing to compare" in stderr


def _bad_npz(tmp_path, kind):
    path = tmp_path / f"{kind}.npz"
    good = test_volume(8, "figure", "ea")[0].numpy()
    if kind == "missing_key":
        np.savez(path, density=good)
    elif kind == "wrong_shape":
        np.savez(path, volume=good[:3])                   # C = 3
    elif kind == "not_cubic":
        np.savez(path, volume=good[:, :, :, :6])
    elif kind == "out_of_range":
        bad = good.copy()
        bad[3, 4, 4, 4] = 1.5
        np.savez(path, volume=bad)
    elif kind == "nan":
        bad = good.copy()
        bad[0, 0, 0, 0] = np.nan
        np.savez(path, volume=bad)
    elif kind == "not_npz":
        path.write_text("not an archive")
    elif kind == "missing_file":
        pass
    return path


@pytest.mark.parametrize("kind, message", [
    ("missing_key", "no array named 'volume'"),
    ("wrong_shape", "(3, 8, 8, 8)"),
    ("not_cubic", "cubic"),
    ("out_of_range", "1.5] (1 value(s) outside, the first at index (3, 4, 4, 4)"),
    ("nan", "NaN"),
    ("not_npz", "is not a valid .npz volume"),
    ("missing_file", "does not exist"),
])
def test_bad_npz_exits_2(tmp_path, kind, message):
    path = _bad_npz(tmp_path, kind)
    code, stdout, stderr = run_cli(["compare", "--volume", str(path), "--out", str(tmp_path / "out")])
    assert code == 2
    assert message in stderr and str(path) in stderr, stderr
    assert "Traceback" not in stderr and stdout == ""
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("argv, message", [
    (["--volume", "builtin:teapot"], "unknown built-in volume"),
    (["--volume", "volume.vol"], ".npz"),
    (["--models", "vh,xray"], "unknown model 'xray'"),
    (["--spp", "2"], "perfect square"),
    (["--views", "0"], "positive integer"),
    (["--filter", "cubic"], "invalid choice"),
])
def test_bad_arguments_exit_2(tmp_path, argv, message):
    code, _, stderr = run_cli(["compare", "--resolution", "8", "--views", "1", "--repeats", "1",
                               "--out", str(tmp_path)] + argv)
    assert code == 2
    assert message in stderr and "Traceback" not in stderr, stderr


@pytest.mark.parametrize("argv, options", [(["--step", "2"], {"step": 2.0}),
                                           (["--jitter", "--spp", "2"], {"jitter": True, "spp": 2})])
def test_mitsuba_options_reach_the_renderer(tmp_path, argv, options):
    """With --step 2 / --jitter the CLI reports the max/mean |difference| of our own renders with
    those options (seed 0, the CLI's default) and writes that Mitsuba image to the EXR; the
    difference is far above the defaults' float precision, so the options changed the image."""
    code, stdout, stderr = run_cli(["compare", "--resolution", str(N), "--views", "2", "--models", "ao",
                                    "--repeats", "1", "--out", str(tmp_path)] + argv)
    assert code == 0, stderr
    views = cli_views(2)
    mx, mean = independent_diffs("ao", views, **options)
    assert mx > 1e-3
    (r,) = json.loads((tmp_path / "compare.json").read_text())["results"]
    assert r["max_abs_diff"] == pytest.approx(mx, rel=1e-6) and r["mean_abs_diff"] == pytest.approx(mean, rel=1e-6)
    assert parse_table(stdout)["ao"][:2] == pytest.approx([mx, mean], rel=6e-4)
    _, mi = independent_renders("ao", views, **options)
    for i in range(2):
        np.testing.assert_allclose(load_exr(tmp_path / f"mitsuba_ao_view{i}.exr", ("A",))[..., 0],
                                   mi[i, 0].numpy(), rtol=0, atol=1e-6)


def test_help_exits_0():
    code, stdout, _ = run_cli(["compare", "--help"])
    assert code == 0 and "--volume" in stdout


# --------------------------------------------------------------------------- compare() API


def test_compare_api_without_output():
    v = test_volume(8, "cloud", "ea")
    results = compare(v, cli_views(1), models=("ao",), filter="nearest", repeats=1)
    (r,) = results
    assert r["png"] is None and r["exrs"] == []
    assert r["closed_form"].shape == r["mitsuba"].shape == (1, 1, 8, 8)
    assert r["max_abs_diff"] < 1e-4
    assert "ao" in format_table(results)


def test_compare_api_rejects_bad_input():
    density = test_volume(8, "cloud", "vh")
    with pytest.raises(ValueError, match="needs 4 channels"):
        compare(density, cli_views(1), models=("ea",))
    with pytest.raises(ValueError, match="unknown Mitsuba option"):
        compare(density, cli_views(1), models=("vh",), options={"filter": "nearest"})
    with pytest.raises(ValueError, match="repeats"):
        compare(density, cli_views(1), models=("vh",), repeats=0)


# --------------------------------------------------------------------------- image helpers


def test_to_uint8_clips_and_rounds():
    img = np.array([[[-0.5], [0.0], [0.5 / 255], [0.499], [1.0], [2.0]]])
    assert to_uint8(img)[0, :, 0].tolist() == [0, 0, 0, 127, 255, 255]   # 0.5/255 → 0.5 rounds to even
    with pytest.raises(ValueError, match="NaN"):
        to_uint8(np.full((2, 2, 1), np.nan))
    with pytest.raises(ValueError, match=r"\(H, W, C\)"):
        to_uint8(np.zeros((2, 2)))


@pytest.mark.parametrize("channels, mode", [(1, "L"), (3, "RGB"), (4, "RGBA")])
def test_save_png_modes(tmp_path, channels, mode):
    img = np.random.default_rng(0).random((5, 7, channels))
    path = save_png(tmp_path / "sub" / "x.png", img)
    with Image.open(path) as im:
        assert im.mode == mode and im.size == (7, 5)
        back = np.asarray(im).reshape(5, 7, channels)
    np.testing.assert_array_equal(back, to_uint8(img))
    with pytest.raises(ValueError, match="1 or 3 or 4 channels"):
        save_png(tmp_path / "y.png", np.zeros((2, 2, 2)))


def test_exr_round_trip(tmp_path):
    rng = np.random.default_rng(1)
    rgba = rng.random((6, 4, 4)).astype(np.float32) * 3.0         # floats, not clipped
    save_exr(tmp_path / "rgba.exr", rgba)
    np.testing.assert_array_equal(load_exr(tmp_path / "rgba.exr"), rgba)
    opacity = rng.random((6, 4, 1)).astype(np.float32)
    save_exr(tmp_path / "a.exr", opacity)
    assert exr_channel_names(tmp_path / "a.exr") == ("Y", "A")
    np.testing.assert_array_equal(load_exr(tmp_path / "a.exr", ("A",)), opacity)
    save_exr(tmp_path / "named.exr", rgba[..., :2], channels=("Z", "A"))
    assert exr_channel_names(tmp_path / "named.exr") == ("A", "Z")
    with pytest.raises(ValueError, match="channel name"):
        save_exr(tmp_path / "bad.exr", rgba, channels=("R", "G"))
    with pytest.raises(ValueError, match="no channel"):
        load_exr(tmp_path / "a.exr", ("R",))
    with pytest.raises(FileNotFoundError):
        load_exr(tmp_path / "missing.exr")


def test_heatmap_and_composite():
    err = np.array([[0.0, 0.5], [1.0, 2.0]])
    rgb = heatmap(err)
    assert rgb.shape == (2, 2, 3) and rgb.min() >= 0 and rgb.max() <= 1
    np.testing.assert_array_equal(heatmap(err, vmax=1.0)[1], heatmap(err, vmax=1.0)[1, [1, 1]])  # clipped
    assert heatmap(np.zeros((3, 3))).shape == (3, 3, 3)
    with pytest.raises(ValueError, match="non-negative"):
        heatmap(-err)
    with pytest.raises(ValueError, match="vmax"):
        heatmap(err, vmax=0.0)
    premultiplied = np.array([[[0.2, 0.0, 0.0, 0.4]]])
    np.testing.assert_allclose(composite(premultiplied, 0.5), [[[0.2 + 0.3, 0.3, 0.3]]])
    np.testing.assert_allclose(composite(np.array([[[0.4]]]), 0.5), [[[0.7, 0.7, 0.7]]])


def test_an_interrupted_png_write_leaves_the_old_file_whole(tmp_path, monkeypatch):
    """save_png writes a temporary sibling and renames it: killed mid-write (here: the encoder raises
    after writing part of the file), the target keeps its old content and no temporary is left."""
    from pathlib import Path
    from PIL import Image
    path = save_png(tmp_path / "sample.png", np.full((4, 4, 3), 0.5))
    before = path.read_bytes()

    def torn(self, fp, format=None, **kw):
        Path(fp).write_bytes(b"\x89PNG\r\n")                    # the first bytes of a PNG, then the crash
        raise KeyboardInterrupt

    monkeypatch.setattr(Image.Image, "save", torn)
    with pytest.raises(KeyboardInterrupt):
        save_png(path, np.zeros((4, 4, 3)))
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["sample.png"]
