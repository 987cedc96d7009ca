"""Evaluation on real photos (mitsuba_platonic.evaluate.photos): the front-card check, the held-out
photos of a folder run, the scores at and away from the input view, and ``platonic evaluate`` on a
tiny folder run. Tiny sizes only: 16² photos, 16³ volumes, a 2-step training."""

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from PIL import Image

from cli_runner import one_line, run_cli
from mitsuba_platonic.config import load_config
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.evaluate import photos as P
from mitsuba_platonic.evaluate.metrics import half_opacity_depth
from mitsuba_platonic.evaluate.protocol import billboard
from mitsuba_platonic.render import RenderSettings, render
from mitsuba_platonic.views import front_view
from mitsuba_platonic.volume import voxel_centres

N = 16


def _ball(n, radius=0.5, centre=(0.0, 0.0, 0.0)):
    """A solid RGBA ball (density 1 inside), orange."""
    p = voxel_centres(n)
    inside = ((p - p.new_tensor(centre)).norm(dim=-1) <= radius).float()
    rgb = torch.tensor([0.8, 0.4, 0.1])[:, None, None, None] * inside
    return torch.cat([rgb, inside[None]]).float()


def _card(n, layers=1, density=0.9):
    """A front card: a painted square in the first ``layers`` depth layers, nothing behind."""
    v = torch.zeros(4, n, n, n)
    lo, hi = n // 4, 3 * n // 4
    v[:3, :layers, lo:hi, lo:hi] = torch.tensor([0.2, 0.6, 0.3])[:, None, None, None]
    v[3, :layers, lo:hi, lo:hi] = density
    return v


# -- the front-card check --------------------------------------------------------------------

def test_card_flag_on_a_front_card_and_a_centred_ball():
    for layers, density, depth in ((1, 0.9, 0.0), (2, 0.9, 0.0), (2, 0.4, 1.0)):
        check = P.card_check(_card(32, layers, density))          # T after layer 1 at 0.4: 0.6² = 0.36 < ½
        assert check["card"] and not check["empty"]
        assert check["half_opacity_depth"] == depth
    for n in (16, 32, 64):
        # the docstring's claims: ball of radius r → ≈ (1 − r/√2)·N/2; radius ½ → about N/3
        for r in (0.4, 0.5, 0.7, 1.0):
            depth = P.card_check(_ball(n, r))["half_opacity_depth"]
            assert abs(depth - (1 - r / math.sqrt(2)) * n / 2) <= 1.0, (n, r, depth)
            assert not P.card_check(_ball(n, r))["card"], (n, r)       # every centred ball passes
        assert abs(P.card_check(_ball(n, 0.5))["half_opacity_depth"] - n / 3) <= 1.0
    empty = P.card_check(torch.zeros(4, N, N, N))
    assert empty["empty"] and not empty["card"] and empty["half_opacity_depth"] is None
    with pytest.raises(UserError, match=r"\(C, N, N, N\)"):
        P.card_check(torch.zeros(N, N, N))


def test_card_summary_counts_and_the_three_of_four_target():
    solid, card, empty = (P.card_check(v) for v in (_ball(N), _card(N), torch.zeros(4, N, N, N)))
    s = P.card_summary([solid, solid, solid, card], N)
    assert (s["not_cards"], s["n"], s["cards"], s["target_met"]) == (3, 4, 1, True)
    assert s["threshold_voxels"] == N / 8
    s = P.card_summary([solid, solid, card, empty], N)            # an empty reconstruction does not pass
    assert (s["not_cards"], s["cards"], s["empty"], s["target_met"]) == (2, 1, 1, False)
    assert s["median_depth"] == float(np.median([solid["half_opacity_depth"]] * 2 + [0.0]))


def test_novel_views_follow_the_angle_convention():
    names, views = P.novel_views()
    assert names == ["above_10", "above_20", "above_30", "beside_10", "beside_20", "beside_30"]
    s, c = math.sin(math.radians(30)), math.cos(math.radians(30))
    assert torch.allclose(views[2], torch.tensor([0.0, s, c]), atol=1e-6)      # raised towards +y
    assert torch.allclose(views[5], torch.tensor([s, 0.0, c]), atol=1e-6)      # turned towards +x
    # the depth seen from a view is the volume's own depth at the input view
    ball = _ball(N, 0.5)
    assert P.view_depth(ball, front_view()) == half_opacity_depth(ball)
    assert all(abs(P.view_depth(ball, w) - half_opacity_depth(ball)) <= 1.0 for w in views)


# -- scoring held-out photos -----------------------------------------------------------------

def _centroid(img):
    a = img[-1]
    rows, cols = torch.meshgrid(torch.arange(a.shape[0]).float(), torch.arange(a.shape[1]).float(), indexing="ij")
    return float((a * rows).sum() / a.sum()), float((a * cols).sum() / a.sum())


def test_score_photos_at_and_away_from_the_input_view():
    settings = RenderSettings(backend="closed_form", model="ea")
    ball, card = _ball(N, 0.6), _card(N)
    photos = render(torch.stack([ball, card]), front_view(2))                 # each volume's own photo
    row = P.score_photos("exact", torch.stack([ball, card]), photos, ["ball.png", "card.png"], settings,
                         n_examples=2)
    b, c = row.photos
    for p in (b, c):                                                          # the input view reproduces the photo
        assert p["input_view_mae"] == pytest.approx(0.0, abs=1e-6) and p["input_view_iou"] == 1.0
        assert p["input_view_dssim"] == pytest.approx(0.0, abs=1e-6)
    assert not b["card"] and c["card"] and row.summary["not_cards"] == 1 and not row.summary["target_met"]
    names, _ = P.novel_views()
    for name in names:                                                        # a centred ball looks the same
        assert b[f"coverage_ratio_{name}"] == pytest.approx(1.0, abs=0.1)
        assert abs(b[f"depth_{name}"] - b["half_opacity_depth"]) <= 1.0
        assert c[f"depth_{name}"] < N / 8                                     # a card stays in front
    # the card sits at the front face: raising the camera moves it down, turning it right moves it left
    renders = row.examples[1][2]
    (r0, c0), (r_up, _), (_, c_side) = _centroid(renders[0]), _centroid(renders[3]), _centroid(renders[6])
    assert r_up > r0 + 2 and c_side < c0 - 2
    # the scores use the given renderer: a pinhole camera's render differs from the orthographic photo
    pinhole = RenderSettings(backend="closed_form", model="ea", camera="perspective", fov=60.0)
    persp = P.score_photos("pinhole", ball[None], photos[:1], ["ball.png"], pinhole)
    expected = render(ball[None], front_view(1), camera="perspective", fov=60.0)
    assert persp.photos[0]["input_view_mae"] > 1e-3
    assert persp.photos[0]["input_view_mae"] == pytest.approx(float((expected - photos[:1]).abs().mean()), rel=1e-6)
    with pytest.raises(UserError, match="files"):
        P.score_photos("x", ball[None], photos, ["a.png"], settings)


def test_billboard_is_perfect_at_the_input_view_and_a_card():
    settings = RenderSettings(backend="closed_form", model="ea")
    photos = render(torch.stack([_ball(N, 0.6), _ball(N, 0.5, (0.2, 0.1, 0.0))]), front_view(2))
    boards = torch.stack([billboard(x) for x in photos])
    row = P.score_photos("billboard", boards, photos, ["a.png", "b.png"], settings)
    assert row.mean("input_view_mae") < 1e-3 and row.mean("input_view_iou") == 1.0
    assert row.summary["cards"] == 2 and row.summary["not_cards"] == 0


# -- a folder run ----------------------------------------------------------------------------

def _photo(seed, size=24):
    """An RGBA photo: an opaque ellipse of a random colour and size on transparency."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:size, 0:size] + 0.5
    ry, rx = rng.uniform(0.25, 0.45, 2) * size
    inside = ((x - size / 2) / rx) ** 2 + ((y - size / 2) / ry) ** 2 <= 1.0
    arr = np.zeros((size, size, 4), np.uint8)
    arr[inside, :3] = rng.integers(30, 230, 3)
    arr[inside, 3] = 255
    arr[0, 0, :3] = seed                                        # distinct bytes per seed
    return Image.fromarray(arr, "RGBA")


@pytest.fixture(scope="module")
def folder_run(tmp_path_factory):
    """8 generated photos, half held out (data.split 0.5 → 4 train, 2 val, 2 test), trained 2 steps at 16³."""
    root = tmp_path_factory.mktemp("folder_run")
    photos = root / "photos"
    photos.mkdir()
    (photos / "more").mkdir()
    for i in range(8):                                          # a sub-folder may repeat a file name
        _photo(i).save(photos / ("more" if i % 2 else "") / f"p{i // 2}.png")
    overrides = [f"run.out_dir={root}/runs", "run.name=shapes", "run.steps=2", "run.threads=1",
                 "run.sample_every=2", "run.checkpoint_every=2", "data.source=folder", f"data.path={photos}",
                 "data.split=0.5", "model.resolution=16", "model.width=4", "model.latent=8",
                 "render.backend=closed_form", "render.model=ea", "train.task=reconstruction", "train.batch_size=2"]
    code, _, err = run_cli(["train", "--quiet"] + sum((["--set", o] for o in overrides), []))
    assert code == 0, err
    return root, photos, root / "runs" / "shapes", load_config(None, overrides)


def test_held_out_photos_are_the_runs_held_out_split(folder_run):
    from mitsuba_platonic.train.data import load_training_data

    _, photos, _, cfg = folder_run
    images, files = P.held_out_photos(cfg)
    data = load_training_data(cfg, progress=False)
    assert images.shape == (4, 4, 16, 16) and torch.equal(images, data.held_out)
    assert len(files) == 4 and all(f.parent in (photos, photos / "more") for f in files)
    assert not any(torch.equal(x, t) for x in images for t in data.images)    # never trained on
    with pytest.raises(UserError, match="--data-path"):
        P.held_out_photos(cfg, photos.parent / "elsewhere")


def test_platonic_evaluate_on_a_folder_run_writes_the_photo_section(folder_run, tmp_path):
    from mitsuba_platonic.model import Model
    from mitsuba_platonic.render import render_with

    root, photos, run_dir, cfg = folder_run
    out = tmp_path / "eval"
    code, _, err = run_cli(["evaluate", "--run", str(run_dir), "--out", str(out), "--quiet"])
    assert code == 0, err
    text = (out / "report.md").read_text()
    assert "## Real photos: shapes (platonic, step 2)" in text
    assert "| Method | IF | MAE (input view) | silhouette IoU (input view) |" in text
    assert "no ground truth" in text and "DSSIM VOL" not in text            # no Table 2 without ground truth
    results = json.loads((out / "results.json").read_text())
    assert [r["method"] for r in results] == ["shapes (platonic, step 2)", "shapes: untrained", "shapes: billboard"]
    trained = results[0]
    assert trained["section"] == "photos" and len(trained["pairs"]) == 4
    s = trained["card_check"]
    assert f"**Front-card check** (shapes (platonic, step 2)): {s['not_cards']} of 4 reconstructions are not cards" in text
    # the input-view MAE is the run's reconstruction rendered with its renderer, against the held-out photos
    images, files = P.held_out_photos(cfg)
    model = Model.from_checkpoint(run_dir)
    rendered = render_with(model.reconstruct(images), front_view(4), model.render)
    assert trained["means"]["input_view_mae"] == pytest.approx(float((rendered - images).abs().mean()), rel=1e-5)
    assert [p["file"] for p in trained["pairs"]] == [str(f) for f in files]
    for p in trained["pairs"]:                                  # named relative to the folder in the report
        rel = Path(p["file"]).relative_to(photos).as_posix()
        assert f"| {rel} | {p['input_view_mae']:.4f} |" in text
    assert results[2]["card_check"]["cards"] == 4                            # the billboard is a card
    # the shape priors: the default config has no round prior, so no warning; the evidence reads all 8 photos
    assert "### Shape priors this run used" in text and "**Warning:" not in text
    priors = trained["shape_priors"]
    assert [p["key"] for p in priors["priors"]] == ["train.view_distribution"] and priors["warnings"] == []
    assert priors["round_evidence"]["photos"] == 8 and "shape_priors" not in results[1]
    figure = out / "figures" / "shapes_platonic_step_2_photos.png"
    assert f"![shapes (platonic, step 2): photo | input view | novel views](figures/{figure.name})" in text
    with Image.open(figure) as im:
        assert im.width > 400 and im.height > 200                          # 8 columns, 4 photos
    # the judge: every row judged from every band, on the run's held-out photos
    assert "### Judged from every side: shapes (platonic, step 2)" in text
    for r in results:
        j = r["judge"]
        assert set(j["c2st"]["accuracy"]) == {"input", "near", "side", "back"} and j["c2st"]["photos"] == 4
        assert all(0.0 <= a <= 1.0 for a in j["c2st"]["accuracy"].values())
        assert [p["file"] for p in j["photos"]] == [str(f) for f in files]
    assert results[1]["judge"]["c2st_side"] >= 0.9          # the untrained blob never passes for a photo
    turntable = out / "figures" / "shapes_platonic_step_2_turntable.png"
    assert f"](figures/{turntable.name})" in text and turntable.is_file()
    # --judge-steps 0 skips it; a negative count is refused
    code, _, err = run_cli(["evaluate", "--run", str(run_dir), "--out", str(tmp_path / "nj"), "--quiet",
                            "--no-baselines", "--judge-steps", "0"])
    assert code == 0, err
    assert "judge" not in json.loads((tmp_path / "nj" / "results.json").read_text())[0]
    code, _, err = run_cli(["evaluate", "--run", str(run_dir), "--out", str(tmp_path / "nj"), "--judge-steps", "-1"])
    assert code == 2 and "--judge-steps" in one_line(err, "evaluate")

    # a photo folder that moved: one line naming --data-path; then --data-path finds it
    moved = root / "moved"
    shutil.move(str(photos), str(moved))
    try:
        code, _, err = run_cli(["evaluate", "--run", str(run_dir), "--out", str(tmp_path / "e2"), "--quiet"])
        assert code == 2 and "--data-path" in one_line(err, "evaluate")
        code, _, err = run_cli(["evaluate", "--run", str(run_dir), "--out", str(tmp_path / "e2"), "--quiet",
                                "--no-baselines", "--data-path", str(moved), "--limit", "2"])
        assert code == 0, err
        again = json.loads((tmp_path / "e2" / "results.json").read_text())
        assert len(again) == 1 and len(again[0]["pairs"]) == 2
        assert again[0]["pairs"][0]["input_view_mae"] == pytest.approx(trained["pairs"][0]["input_view_mae"])
    finally:
        shutil.move(str(moved), str(photos))
