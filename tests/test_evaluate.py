"""Evaluation (mitsuba_platonic.evaluate): metrics, the re-rendering protocol, the report.

Tiny sizes only: 16³ volumes, 16² images, 1–4 samples per pixel.
"""

import json
from types import SimpleNamespace

import numpy as np
import pytest
import torch
import torch.nn.functional as F

from mitsuba_platonic.errors import UserError
from mitsuba_platonic.evaluate import metrics as M
from mitsuba_platonic.evaluate import protocol as P
from mitsuba_platonic.evaluate import report as R
from mitsuba_platonic.render import render
from mitsuba_platonic.views import front_view, sample_views
from mitsuba_platonic.volume import test_volume, voxel_centres, voxel_size

N = 16


def _box(n=N, lo=(4, 5, 3), hi=(10, 11, 8)):
    """A binary box of ones, [lo, hi) in (d, h, w)."""
    v = torch.zeros(n, n, n)
    v[lo[0]:hi[0], lo[1]:hi[1], lo[2]:hi[2]] = 1.0
    return v


def _sphere(n=N, centre=(0.25, 0.15, -0.1), radius=0.55):
    """An off-centre anti-aliased sphere, RGBA, colour varying along x (so flips show)."""
    p = voxel_centres(n)
    sdf = (p - p.new_tensor(centre)).norm(dim=-1) - radius
    density = torch.sigmoid(-sdf / (voxel_size(n) / 4.0))
    rgb = torch.stack([0.2 + 0.3 * (p[..., 0] + 1.0), torch.full_like(density, 0.5), torch.full_like(density, 0.3)])
    return torch.cat([rgb, density[None]]).float()


# -- metrics ---------------------------------------------------------------------------------

def test_identical_volumes_and_images_score_perfectly():
    v = test_volume(N, "figure", "ea")[0]
    binary = v.clone()
    binary[3] = (v[3] >= 0.5).float()
    assert M.volume_iou(v, v) == 1.0
    assert M.volume_rmse(v, v) == 0.0
    assert M.chamfer_distance(binary, binary) == 0.0          # every output voxel with density lies in O
    img = render(v[None], front_view(1))[0]
    assert M.dssim(img, img) == pytest.approx(0.0, abs=1e-12)
    assert M.image_rmse(img, img) == 0.0
    other = render(v[None], sample_views(1, seed=3))[0]
    assert M.dssim(img, other) > 0.01                          # a different view is not "identical"
    assert M.volume_iou(v, torch.flip(v, dims=[3])) < 0.9      # the figure is asymmetric in x


@pytest.mark.parametrize("k", [1, 2, 3])
def test_chamfer_distance_of_a_shifted_box(k):
    """Output = target box moved k voxels along +x: the k-voxel slab beyond the box is at distances
    Δ, 2Δ, …, kΔ from the nearest target voxel (straight across); the overlap is at 0."""
    target = _box()
    output = torch.roll(target, shifts=k, dims=2)              # w grows with +x; the box has room
    delta = 2.0 / N
    face = (10 - 4) * (11 - 5)                                  # voxels in a (d, h) cross-section
    expected = sum(face * (s * delta) ** 2 for s in range(1, k + 1)) / N ** 3
    assert M.chamfer_distance(output, target) == pytest.approx(expected, rel=1e-12)
    # directional, as in the paper: a target that covers the output costs nothing
    assert M.chamfer_distance(_box(hi=(10, 11, 6)), target) == 0.0
    # weighted by the output's density
    assert M.chamfer_distance(0.5 * output, target) == pytest.approx(0.5 * expected, rel=1e-12)
    inter = face * (8 - 3 - k)
    assert M.volume_iou(output, target) == pytest.approx(inter / (2 * face * (8 - 3) - inter))


def test_metrics_reject_bad_input_with_what_was_expected():
    v = torch.rand(4, N, N, N)
    with pytest.raises(UserError, match="same resolution"):
        M.volume_iou(v, torch.rand(4, 8, 8, 8))
    bad = v.clone()
    bad[0, 0, 0, 0] = float("nan")
    with pytest.raises(UserError, match="NaN"):
        M.volume_rmse(bad, v)
    with pytest.raises(UserError, match=r"\[0, 1\]"):
        M.chamfer_distance(v * 2.0, v)
    with pytest.raises(UserError, match="cubic"):
        M.volume_rmse(torch.rand(4, 8, 8, 9), torch.rand(4, 8, 8, 9))
    with pytest.raises(UserError, match="no voxel with density"):
        M.chamfer_distance(v, torch.zeros(N, N, N))
    with pytest.raises(UserError, match="threshold"):
        M.volume_iou(v, v, threshold=0.0)
    with pytest.raises(UserError, match=r"\(C, H, W\)"):
        M.dssim(torch.rand(3, N, N), torch.rand(3, N, N))
    with pytest.raises(UserError, match="at least"):
        M.dssim(torch.rand(4, 8, 8), torch.rand(4, 8, 8))
    with pytest.raises(UserError, match="same shape"):
        M.dssim(torch.rand(4, N, N), torch.rand(1, N, N))


# -- feature metrics: weights from the user --------------------------------------------------

def _tiny_vgg_state():
    """A VGG-shaped state dict: conv 0, conv 2, pool, conv 5 (torchvision's indexing)."""
    g = torch.Generator().manual_seed(0)
    state = {}
    for i, (cin, cout) in {0: (3, 4), 2: (4, 4), 5: (4, 6)}.items():
        state[f"features.{i}.weight"] = torch.randn(cout, cin, 3, 3, generator=g) * 0.3
        state[f"features.{i}.bias"] = torch.randn(cout, generator=g) * 0.1
    state["classifier.0.weight"] = torch.zeros(2, 2)          # ignored, as in torchvision's file
    return state


def test_feature_metrics_need_weights_and_say_so(tmp_path):
    a, b = torch.rand(2, 4, N, N), torch.rand(2, 4, N, N)
    with pytest.raises(UserError, match="weights"):
        M.vgg_distance(a, b)
    with pytest.raises(UserError, match="weights"):
        M.fid(a, b)
    with pytest.raises(UserError, match="does not exist"):
        M.vgg_distance(a, b, weights=tmp_path / "missing.pth")
    junk = tmp_path / "junk.pth"
    junk.write_bytes(b"not a torch file")
    with pytest.raises(UserError, match="neither a TorchScript file nor a torch state dict"):
        M.fid(a, b, weights=junk)
    notvgg = tmp_path / "notvgg.pth"
    torch.save({"w": torch.zeros(1)}, notvgg)
    with pytest.raises(UserError, match="features.N.weight"):
        M.vgg_distance(a, b, weights=notvgg)


def test_vgg_distance_with_weights_the_test_makes(tmp_path):
    state = _tiny_vgg_state()
    path = tmp_path / "tiny_vgg.pth"
    torch.save(state, path)
    net = M.load_feature_network(path)
    x = torch.rand(1, 3, N, N)
    xn = (x - torch.tensor(M.IMAGENET_MEAN).view(1, 3, 1, 1)) / torch.tensor(M.IMAGENET_STD).view(1, 3, 1, 1)
    h = F.relu(F.conv2d(F.relu(F.conv2d(xn, state["features.0.weight"], state["features.0.bias"], padding=1)),
                        state["features.2.weight"], state["features.2.bias"], padding=1))
    h2 = F.relu(F.conv2d(F.max_pool2d(h, 2), state["features.5.weight"], state["features.5.bias"], padding=1))
    feats = net(x)
    assert len(feats) == 2
    torch.testing.assert_close(feats[0], h)
    torch.testing.assert_close(feats[1], h2)

    img = render(test_volume(N, "figure", "ea"), front_view(1))
    other = render(test_volume(N, "figure", "ea"), sample_views(1, seed=5))
    assert M.vgg_distance(img, img, weights=path) == 0.0
    d = M.vgg_distance(img, other, weights=path)
    assert np.isfinite(d) and 0.0 < d <= 4.0


def test_fid_with_weights_the_test_makes(tmp_path):
    torch.manual_seed(1)
    net = torch.jit.script(torch.nn.Sequential(torch.nn.Conv2d(3, 3, 3, padding=1), torch.nn.Tanh()))
    path = tmp_path / "tiny_features.pt"
    torch.jit.save(net, str(path))
    real = torch.rand(8, 4, N, N)
    real[:, :3] *= real[:, 3:]                                 # premultiplied
    assert M.fid(real, real, weights=path) == pytest.approx(0.0, abs=1e-6)
    fake = real.clone()
    fake[:, :3] = fake[:, :3] * 0.3                            # darker: a shifted feature distribution
    # by hand: the same network, spatial means, Fréchet distance of two Gaussians
    from scipy import linalg

    def feats(x):
        rgb = torch.from_numpy(np.stack([M.display_image(i) for i in x])).permute(0, 3, 1, 2).float()
        return net(rgb).mean(dim=(2, 3)).double().detach().numpy()

    fr, ff = feats(real), feats(fake)
    cr, cf = np.cov(fr, rowvar=False), np.cov(ff, rowvar=False)
    expected = (np.sum((fr.mean(0) - ff.mean(0)) ** 2) + np.trace(cr + cf)
                - 2 * np.trace(np.real(linalg.sqrtm(cr @ cf))))
    value = M.fid(real, fake, weights=path)
    assert value > 1e-3
    assert value == pytest.approx(expected, rel=1e-6)


# -- the re-rendering protocol ---------------------------------------------------------------

def test_the_four_rerender_methods_agree_in_silhouette_on_a_sphere():
    """IF, VOL, ISO and VOX of one off-centre sphere (radius 0.55 = 4.4 voxels at 16³) from the
    same views: silhouettes (alpha > ½) must overlap with IoU ≥ 0.75 for every pair of methods.

    Why 0.75: the methods put the boundary at different places by design — ISO at density 0.1
    (about ½ voxel outside the ½ level of the anti-aliased sphere), VOX on whole voxels (up to ½
    voxel either way) — and two discs whose radii differ by ½ voxel at r = 4.4 have IoU
    (3.9 / 4.4)² ≈ 0.79. An axis flip or a mis-placed camera in any method moves the off-centre
    sphere by 2 × 0.25 = 0.5 world units (4 pixels) and drops the IoU far below.
    """
    vol = _sphere()
    views, lights = P.rerender_views(4, seed=0), P.rerender_lighting(4, seed=0)
    images = P.rerender(vol, views, lights, "ea", spp=4, max_depth=4)
    assert set(images) == set(P.METHODS)
    for m, img in images.items():
        assert img.shape == (4, 4, N, N), m
        assert torch.isfinite(img).all(), m
        assert float(img[:, 3].sum()) > 0, m
    for i, a in enumerate(P.METHODS):
        for b in P.METHODS[i + 1:]:
            iou = M.silhouette_iou(images[a], images[b])
            assert iou >= 0.75, (a, b, iou)
    # the path-traced methods see light: their covered pixels are not black
    for m in ("VOL", "ISO", "VOX"):
        assert float(images[m][:, :3].sum()) > 0, m


def test_evaluate_pair_identical_and_different():
    vol = _sphere()
    same = P.evaluate_pair(vol, vol, "ea", n_views=2, spp=1, max_depth=2)
    for m in P.METHODS:
        assert same.metrics[f"dssim_{m}"] == pytest.approx(0.0, abs=1e-12), m
        assert same.metrics[f"silhouette_iou_{m}"] == 1.0, m
        x, y = same.images[m]
        assert x.shape == y.shape
    assert same.metrics["iou"] == 1.0 and same.metrics["rmse"] == 0.0
    moved = P.evaluate_pair(_sphere(centre=(-0.2, 0.15, -0.1)), vol, "ea", n_views=2, spp=1, max_depth=2)
    for m in P.METHODS:
        assert moved.metrics[f"dssim_{m}"] > 0.02, m
    assert moved.metrics["iou"] < 0.8 and moved.metrics["cd"] > 0.0


def test_the_if_column_of_a_run_trained_through_light_is_path_traced():
    """For backend 'physical' IF is the run's own image formation: the path tracer under the pair's
    skies (at the run's max depth), not the EA layer; at VOL's depth it is VOL's image exactly."""
    recon, vol = _sphere(centre=(-0.2, 0.15, -0.1)), _sphere()
    kw = dict(n_views=2, spp=1, max_depth=2, methods=("IF", "VOL"))
    traced = P.evaluate_pair(recon, vol, "ea", backend="physical", **kw)
    for a, b in zip(traced.images["IF"], traced.images["VOL"]):
        assert torch.equal(a, b)
    layered = P.evaluate_pair(recon, vol, "ea", **kw)
    assert not torch.equal(layered.images["IF"][0], traced.images["IF"][0])
    deeper = P.evaluate_pair(recon, vol, "ea", backend="physical", if_max_depth=4, **kw)
    assert not torch.equal(deeper.images["IF"][0], deeper.images["VOL"][0])   # its own depth


def test_voxel_mesh_counts_exposed_faces_only():
    v = torch.zeros(4, 4, 4, 4)
    v[:3] = 0.5
    v[3, 1, 1, 2] = v[3, 1, 1, 3] = 1.0                       # two neighbouring voxels along +x
    verts, faces, colours = P.voxel_mesh(v)
    assert len(faces) == 2 * 10                               # 12 faces minus the 2 they share
    assert len(verts) == 4 * 10 and colours.shape == (40, 3)
    # voxels (d, h, w) = (1, 1, 2..3) of a 4³ grid (Δ = ½) span x ∈ [0, 1], y ∈ [0, ½], z ∈ [0, ½]
    np.testing.assert_allclose(verts.min(0), [0.0, 0.0, 0.0])
    np.testing.assert_allclose(verts.max(0), [1.0, 0.5, 0.5])
    assert len(P.voxel_mesh(torch.zeros(1, 4, 4, 4))[1]) == 0


def test_billboard_reproduces_the_input_view():
    img = render(test_volume(N, "figure", "ea"), front_view(1))[0]
    board = P.billboard(img)
    assert board.shape == (4, N, N, N)
    torch.testing.assert_close(render(board[None], front_view(1))[0], img, atol=1e-4, rtol=0)
    mae, iou = P.novel_view_errors(board, test_volume(N, "figure", "ea")[0], "ea")
    assert mae > 0.01 and iou < 1.0                            # blind to depth


# -- the report ------------------------------------------------------------------------------

def test_report_on_synthetic_pairs(tmp_path):
    truth = _sphere()
    image = render(truth[None], front_view(1))[0]
    triples = [(image, truth, truth), (image, _sphere(centre=(-0.2, 0.1, 0.0)), truth)]
    row = R.score_pairs("synthetic", "ea", triples, n_views=2, spp=1, max_depth=2)
    board = R.score_pairs("billboard", "ea", [(image, P.billboard(image), truth)], n_views=2, spp=1, max_depth=2)
    report = R.write_report([row, board], tmp_path / "eval", notes=["tiny synthetic pairs"])
    text = report.read_text()
    assert "| Method | IF | DSSIM VOL | DSSIM ISO | DSSIM VOX | DSSIM IF | RMSE | IoU | CD | pairs |" in text
    line = next(l for l in text.splitlines() if l.startswith("| synthetic |"))
    cells = [c.strip() for c in line.strip("|").split("|")]
    assert cells[1] == "EA" and cells[-1] == "2"
    assert cells[5] == f"{row.mean('dssim_IF') * 10:.2f}"     # the paper's × 10
    assert cells[6] == f"{row.mean('rmse') * 100:.2f}"        # and × 10²
    header = next(l for l in text.splitlines() if l.startswith("| Method"))
    assert "VGG" not in header and "FID" not in header        # not computed: no column
    figures = sorted((tmp_path / "eval" / "figures").glob("*.png"))
    assert [f.name for f in figures] == ["billboard_ea.png", "synthetic_ea.png"]
    from PIL import Image
    with Image.open(figures[1]) as im:
        assert im.width > 200 and im.height > 50
    results = json.loads((tmp_path / "eval" / "results.json").read_text())
    assert results[0]["means"]["iou"] == pytest.approx(row.mean("iou"))
    assert len(results[0]["pairs"]) == 2 and results[0]["pairs"][0]["iou"] == 1.0


def test_class_table_is_ssim_per_class_formation_and_method():
    """Table 3 layout: PlatonicGAN rows only, SSIM = 1 − 2 DSSIM averaged over a cell's runs, — for
    a formation a class was not trained with, and no table without a PlatonicGAN row."""
    def row(cls, formation, dssim, mode="platonic"):
        r = R.Row(f"{cls}-{formation}", formation, shape_class=cls, mode=mode)
        r.pairs = [{f"dssim_{m}": d for m, d in zip(R.CLASS_METHODS, dssim)}]
        return r

    rows = [row("mushroom", "VH", (0.05, 0.10, 0.15)), row("mushroom", "VH", (0.15, 0.10, 0.05)),
            row("chair", "EA", (0.25, 0.20, 0.0)), row("chair", "VH", (0.5, 0.5, 0.5), mode="prgan"),
            R.Row("untrained", "EA")]
    lines = R.write_class_table(rows).splitlines()
    assert lines[0] == "| Class | VH VOL | VH ISO | VH VOX | EA VOL | EA ISO | EA VOX | runs |"
    assert lines[2] == "| mushroom | 0.80 | 0.80 | 0.80 | — | — | — | 2 |"
    assert lines[3] == "| chair | — | — | — | 0.50 | 0.60 | 1.00 | 1 |"
    assert len(lines) == 4
    assert R.write_class_table([rows[3], rows[4]]) is None


def test_evaluate_command_arguments_and_errors(tmp_path):
    import argparse
    args = R.add_arguments(argparse.ArgumentParser()).parse_args(
        ["--run", "a", "--run", "b", "--out", "o", "--views", "3", "--limit", "2"])
    assert args.run == ["a", "b"] and args.views == 3 and args.limit == 2 and args.vgg_weights is None
    with pytest.raises(SystemExit):
        R.main_evaluate(["--out", str(tmp_path)])             # --run is required
    with pytest.raises(UserError):
        R.main_evaluate(["--run", str(tmp_path / "no_run"), "--out", str(tmp_path / "out")])
    with pytest.raises(UserError, match="--spp"):
        R.main_evaluate(["--run", "x", "--out", str(tmp_path / "out"), "--spp", "0"])


def test_rows_are_named_by_the_run_and_a_checkpoint_file_by_its_run_and_file(tmp_path, monkeypatch):
    """--run RUN names its rows RUN; --run RUN/checkpoints/step_….pt names them RUN/step_… (not by the
    file alone), so two checkpoints of one run get rows, baselines and figures of their own."""
    monkeypatch.setattr(R, "read_checkpoint", lambda path: SimpleNamespace(step=4000))
    monkeypatch.setattr(R, "checkpoint_config", lambda ckpt: SimpleNamespace(run=SimpleNamespace(name="trees-s1", seed=0)))
    monkeypatch.setattr(R, "model_from_checkpoint", lambda cls, ckpt, cfg: None)
    folder = tmp_path / "trees-s1"
    (folder / "checkpoints").mkdir(parents=True)
    file = folder / "checkpoints" / "step_0004000.pt"
    file.write_bytes(b"")
    assert R._load(folder)[3:] == (4000, "trees-s1")
    assert R._load(file)[3:] == (4000, "trees-s1/step_0004000")


@pytest.mark.parametrize("backend", ["closed_form", "physical"])
def test_evaluate_runs_on_a_tiny_collection_with_a_stand_in_model(tmp_path, monkeypatch, backend):
    """The run plumbing: held-out split, manifest volumes, truth in the input frame, baselines,
    report. The trained networks are replaced by a stand-in that returns the ground truth for the
    held-out image, so the trained row must score perfectly (IoU 1, RMSE 0, DSSIM 0)."""
    from mitsuba_platonic.config import load_config
    from mitsuba_platonic.data.render_collection import load_manifest
    from mitsuba_platonic.train.data import collection_folder, load_training_data

    cfg = load_config(None, [f"data.cache={tmp_path / 'data'}", "data.shape_class=mushroom", "data.n_shapes=2",
                             "data.views_per_shape=1", "data.split=0.5", "model.resolution=16",
                             "render.model=ea", f"render.backend={backend}"])
    calls = {}

    def fake_load(run_dir):
        def reconstruct(images):                                # the truth of the held-out shape, in frame
            folder = collection_folder(cfg)
            rec = [r for r in load_manifest(folder)["images"] if r["shape"] == 1][0]
            vol = torch.from_numpy(np.load(folder / rec["volume"])["volume"]).float()
            calls["n"] = len(images)
            assert torch.equal(images, load_training_data(cfg, progress=False).held_out[:1])   # held out, not trained on
            return P.truth_in_input_frame(vol, rec["view"], "ea")[None].expand(len(images), -1, -1, -1, -1)
        grey = (lambda images: torch.full((len(images), 4, N, N, N), 0.05))
        return (cfg, SimpleNamespace(reconstruct=reconstruct), lambda: SimpleNamespace(reconstruct=grey), 123, "run")

    monkeypatch.setattr(R, "_load", fake_load)
    with pytest.raises(UserError, match="manifest.json"):       # the collection is not rendered yet
        R.evaluate_runs([tmp_path / "run"], tmp_path / "out", n_views=2, spp=1, progress=False)
    load_training_data(cfg, progress=False)                     # make-dataset at 16³: 2 shapes × 1 view
    report = R.evaluate_runs([tmp_path / "run"], tmp_path / "out", n_views=2, spp=1, max_depth=2, progress=False)
    assert calls["n"] == 1                                      # one held-out image (shape 1)
    results = {r["method"]: r["means"] for r in json.loads((tmp_path / "out" / "results.json").read_text())}
    trained = results["run (platonic, step 123)"]
    assert trained["iou"] == 1.0 and trained["rmse"] == 0.0
    assert all(trained[f"dssim_{m}"] == pytest.approx(0.0, abs=1e-12) for m in P.METHODS)
    assert results["run: untrained"]["iou"] == 0.0             # nothing at density ≥ ½
    assert results["run: billboard"]["rmse"] > 0.0
    assert "| run (platonic, step 123) | EA |" in report.read_text()
    assert "| mushroom | 1.00 | 1.00 | 1.00 | 1 |" in report.read_text()   # Table 3: SSIM of a perfect row
    assert ("IF path traced (max depth" in report.read_text()) == (backend == "physical")


def test_depth_stripes_measures_period_two_layers():
    from mitsuba_platonic.evaluate.metrics import depth_stripes
    n = 32
    c = (np.arange(n) + 0.5) / n * 2 - 1
    d, h, w = np.meshgrid(c, c, c, indexing="ij")
    ball = ((d ** 2 + h ** 2 + w ** 2) <= 0.5).astype(np.float32)
    striped = ball * (np.arange(n)[:, None, None] % 2)          # every other depth layer emptied
    assert depth_stripes(ball) < 0.05
    assert depth_stripes(striped) > 0.9
    ramp = np.broadcast_to(np.linspace(0.1, 0.9, n)[:, None, None], (n, n, n))
    assert depth_stripes(ramp) == pytest.approx(0.0, abs=1e-9)   # linear in depth: nothing alternates
    assert depth_stripes(striped.transpose(1, 0, 2)) < 0.05     # the stripes lie along axis 0 only


def test_half_opacity_depth_tells_a_front_card_from_a_solid():
    from mitsuba_platonic.evaluate.metrics import half_opacity_depth
    n = 32
    card = np.zeros((n, n, n), np.float32)
    card[0, 8:24, 8:24] = 0.9                                   # one painted layer at the front
    solid = np.zeros((n, n, n), np.float32)
    solid[10:22, 8:24, 8:24] = 0.3                              # starts 10 voxels deep
    assert half_opacity_depth(card) == 0.0
    # T after layer k is 0.7^(k − 9) from layer 10 on: below ½ after layer 11 (0.7² = 0.49)
    assert half_opacity_depth(solid) == 11.0
    assert np.isnan(half_opacity_depth(np.zeros((n, n, n), np.float32)))


@pytest.mark.parametrize("elevation", [35.0, -20.0])
def test_best_tilt_of_an_upright_reconstruction_is_the_input_elevation(elevation):
    """A volume seen from an input camera at elevation θ₀ (its truth in that frame) against the
    same volume seen from the same azimuth at elevation 0 (a reconstruction standing upright in
    the frame): best_tilt finds β = θ₀, where the IoU is near 1; for the truth itself, β = 0."""
    from mitsuba_platonic.render.pytorch.closed_form import rotate
    from mitsuba_platonic.views import from_angles
    v = test_volume(32, "figure", "ao").reshape(1, 1, 32, 32, 32)
    truth = rotate(v, from_angles(torch.tensor([30.0]), elevation))[0].clamp(0, 1)
    upright = rotate(v, from_angles(torch.tensor([30.0]), 0.0))[0].clamp(0, 1)
    β, iou = M.best_tilt(upright, truth)
    assert β == elevation and iou > 0.8
    assert iou > M.volume_iou(upright, truth) + 0.2
    assert M.best_tilt(truth, truth) == (0.0, 1.0)


def test_best_tilt_of_a_leaning_rod():
    """Analytic: a rod along the frame's up axis h against the same rod leaning by α in the (d, h)
    plane is best aligned by a tilt of magnitude α."""
    n = 32
    c = (np.arange(n) + 0.5) / n * 2 - 1
    d, h, w = np.meshgrid(c, c, c, indexing="ij")

    def rod(α):                                                 # within 0.2 of the line through 0 along (sin α, cos α, 0)
        a = np.radians(α)
        along = d * np.sin(a) + h * np.cos(a)
        return ((d ** 2 + h ** 2 + w ** 2 - along ** 2 <= 0.04) & (np.abs(along) <= 0.8)).astype(np.float32)

    assert abs(M.best_tilt(rod(0.0), rod(40.0))[0]) == 40.0
    assert abs(M.best_tilt(rod(0.0), rod(-25.0))[0]) == 25.0
    for step in (0.0, 7.0, True):
        with pytest.raises(UserError, match="step must be a number of degrees that divides 90"):
            M.best_tilt(rod(0.0), rod(0.0), step=step)


def test_best_tilt_breaks_ties_towards_zero_and_has_no_tilt_without_overlap():
    n = 16
    empty, block = np.zeros((n, n, n), np.float32), np.zeros((n, n, n), np.float32)
    block[6:10, 6:10, 6:10] = 1.0
    assert M.best_tilt(empty, empty) == (0.0, 1.0)              # every tilt ties (IoU 1): the nearest 0
    β, iou = M.best_tilt(empty, block)                          # nothing to align
    assert np.isnan(β) and iou == 0.0
