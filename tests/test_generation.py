"""Generation runs judged and shown (mitsuba_platonic.evaluate.generation, .generation_report,
mitsuba_platonic.sheets): the nearest-truth IoU and coverage against hand-made volume sets, the
diversity and the collapse warning, the latent walk's ends, the sheets of ``platonic generate`` and
the report of a tiny generation run. Tiny sizes only: 16³ volumes, 2-step trainings, a few critic steps."""

import json
import math

import numpy as np
import pytest
import torch
from PIL import Image

from cli_runner import one_line, run_cli
from mitsuba_platonic.config import load_config
from mitsuba_platonic.errors import UserError
from mitsuba_platonic.evaluate import generation as G
from mitsuba_platonic.evaluate.metrics import volume_iou
from mitsuba_platonic.model import Model
from mitsuba_platonic.sheets import interpolation_latents, save_interpolation, slerp
from mitsuba_platonic.volume import voxel_centres

N = 32


def _box(n, half, centre=(0.0, 0.0, 0.0)):
    """An RGBA box of half-extents ``half`` (x, y, z) about ``centre``, density 1 inside."""
    p = voxel_centres(n) - torch.tensor(centre, dtype=torch.float64)
    inside = (p.abs() <= torch.tensor(half, dtype=torch.float64)).all(-1).float()
    return torch.cat([0.5 * inside[None].repeat(3, 1, 1, 1), inside[None]])


def _ball(n, radius=0.5, centre=(0.0, 0.0, 0.0)):
    p = voxel_centres(n) - torch.tensor(centre, dtype=torch.float64)
    inside = (p.norm(dim=-1) <= radius).float()
    return torch.cat([0.5 * inside[None].repeat(3, 1, 1, 1), inside[None]])


def _ell(n, scale=1.0, shift=(0.0, 0.0, 0.0)):
    """A chunky L (a foot along x, a post up y): no turn about the vertical but 0° maps it onto itself."""
    s, (dx, dy, dz) = scale, shift
    foot = _box(n, (0.6 * s, 0.25 * s, 0.25 * s), (dx, dy - 0.3 * s, dz))
    post = _box(n, (0.25 * s, 0.55 * s, 0.25 * s), (dx - 0.35 * s, dy + 0.05 * s, dz))
    return torch.maximum(foot, post)


SHAPES = [_box(N, (0.3, 0.6, 0.2)), _ball(N), _ell(N)]


# -- nearest truth and coverage ---------------------------------------------------------------

def test_identical_sets_have_coverage_one_and_iou_one():
    found = G.nearest_truth(SHAPES, SHAPES)
    assert found["nearest"] == [0, 1, 2] and found["coverage"] == 1.0
    assert found["sample_iou"] == pytest.approx(1.0) and found["truth_iou"] == pytest.approx(1.0)
    assert all(found["similarity"][i, j] < 0.9 for i in range(3) for j in range(3) if i != j)   # distinct shapes


def test_samples_all_one_truth_of_n_cover_one_nth():
    for j in range(3):
        found = G.nearest_truth([SHAPES[j]] * 5, SHAPES)
        assert found["nearest"] == [j] * 5 and found["coverage"] == pytest.approx(1.0 / 3.0)
        assert found["sample_iou"] == pytest.approx(1.0)
        # each truth's best sample is that one shape: 1 for truth j, its similarity to j for the others
        sim = found["similarity"]
        assert found["truth_iou"] == pytest.approx(float(sim[0].mean()))


def test_similarity_is_the_best_volume_iou_over_the_turns():
    """Against metrics.volume_iou on the normalised occupancies, each turn by hand."""
    found = G.nearest_truth(SHAPES[:2], SHAPES, turns=4)
    for i in range(2):
        for j in range(3):
            a = G.normalised_occupancy(SHAPES[i])
            b = G.normalised_occupancy(SHAPES[j])
            best = max(volume_iou(a[None], G.turned(b, 90.0 * k)[None]) for k in range(4))
            assert found["similarity"][i, j] == pytest.approx(best, abs=1e-9)


def test_the_match_forgives_a_turn_a_scale_and_a_shift():
    ell = _ell(N)
    quarter = torch.rot90(ell, 1, dims=(1, 3))                 # (d, w) = (z, x): a quarter turn about +y
    assert volume_iou(ell[3], quarter[3]) < 0.5                # as they stand they differ
    assert G.nearest_truth([quarter], [ell])["sample_iou"] > 0.98
    small = _ell(N, scale=0.6, shift=(0.2, -0.15, 0.1))        # a smaller L off the cube's centre
    matched = G.nearest_truth([small], [ell, _ball(N)])
    assert matched["nearest"] == [0] and matched["nearest_iou"][0] > 0.85
    assert matched["similarity"][0, 1] < 0.7                   # the ball is no match
    coarse = torch.nn.functional.interpolate(ell[None], size=16, mode="nearest")[0]
    assert G.nearest_truth([coarse], [ell])["sample_iou"] > 0.9          # another resolution, the same shape


def test_empty_volumes_match_nothing_but_each_other():
    empty = torch.zeros(4, 16, 16, 16)
    found = G.nearest_truth([empty, SHAPES[1]], [empty, SHAPES[1]])
    assert found["similarity"][0, 0] == 1.0 and found["similarity"][0, 1] == 0.0 and found["coverage"] == 1.0
    with pytest.raises(UserError, match="at least one sample"):
        G.nearest_truth([], SHAPES)


# -- diversity and the collapse warning --------------------------------------------------------

def test_diversity_is_zero_for_identical_samples_and_one_minus_iou_otherwise():
    assert G.volume_diversity([SHAPES[2]] * 4) == 0.0
    pairs = [(0, 1), (0, 2), (1, 2)]
    expected = np.mean([1.0 - volume_iou(SHAPES[i][3], SHAPES[j][3]) for i, j in pairs])
    assert G.volume_diversity(SHAPES) == pytest.approx(expected)
    images = torch.rand(1, 4, 8, 8).expand(5, -1, -1, -1)
    assert G.image_diversity(images) == 0.0
    disc = torch.zeros(2, 4, 8, 8)
    disc[0, 3, :4] = 1.0                                       # top half against bottom half: IoU 0
    disc[1, 3, 4:] = 1.0
    assert G.image_diversity(disc) == 1.0
    assert G.volume_diversity(SHAPES[:1]) is None


class _Stub:
    """A generator of balls: radius 0.2–0.8 from the latent's first coordinate, or always one ball."""

    formation = "ea"

    def __init__(self, collapsed):
        self.collapsed = collapsed

    def latents(self, n, seed=0):
        return torch.randn(n, 4, generator=torch.Generator().manual_seed(seed))

    def generate(self, n, seed=0):
        z = self.latents(n, seed)
        radii = [0.5] * n if self.collapsed else (0.5 + 0.3 * torch.tanh(z[:, 0])).tolist()
        return torch.stack([_ball(16, r) for r in radii])


def _judge(model, steps=0, truths=None):
    cfg = load_config(None, ["model.resolution=16", "render.model=ea", "render.backend=closed_form"])
    photos = torch.stack([_ball(16, 0.3 + 0.05 * i) for i in range(6)])
    from mitsuba_platonic.render import render_with
    from mitsuba_platonic.views import turntable
    images = render_with(photos, turntable(6, elevation=20.0), cfg.render).clamp(0, 1)
    return G.judge_generation(model, images[:4], images[4:], cfg.render, cfg.train, truths, n_samples=6,
                              steps=steps, repeats=2, train_views=2)


def test_a_collapsed_generator_is_named_and_a_varied_one_is_not():
    collapsed = _judge(_Stub(True))
    assert collapsed.diversity["volumes"] == 0.0 and collapsed.diversity["renders"] == 0.0
    assert len(collapsed.warnings) == 2 and all(w.startswith("COLLAPSED") for w in collapsed.warnings)
    assert collapsed.summary()["collapsed"] is True
    varied = _judge(_Stub(False))
    assert varied.diversity["volumes"] > G.COLLAPSE and varied.warnings == []
    lines = G.collapse_warnings({"volumes": 0.2, "renders": 0.05}, empty=2, samples=8)
    assert len(lines) == 2 and "renders' silhouettes" in lines[0] and lines[1].startswith("EMPTY: 2 of 8")


def test_judge_generation_scores_every_band_and_the_truth():
    truths = [_ball(16, 0.5), _box(16, (0.5, 0.5, 0.5))]
    j = _judge(_Stub(True), steps=3, truths=truths)
    assert set(j.c2st["accuracy"]) == set(G.GENERATION_BANDS) and j.c2st["photos"] == 2
    assert all(0.0 <= a <= 1.0 for a in j.c2st["accuracy"].values())
    assert j.c2st["renders"]["random"] == 6 * 2 and j.c2st["renders"]["front"] == 6
    assert j.truth["nearest"] == [0] * 6 and j.truth["coverage"] == 0.5 and j.truth["sample_iou"] == pytest.approx(1.0)
    assert j.roughness["ratio"] == pytest.approx(j.roughness["renders"] / j.roughness["photos"])
    assert j.volumes.shape == (6, 4, 16, 16, 16) and j.views.shape == (6, 4, 16, 16)


def test_run_views_follow_the_runs_p_view():
    cfg = load_config(None, ["train.view_distribution=band", "train.elevation=[10, 30]"])
    views = G.run_views(cfg.train, 200, seed=0)
    elevation = torch.rad2deg(torch.asin(views[:, 1].double()))
    assert elevation.min() >= 10.0 - 1e-4 and elevation.max() <= 30.0 + 1e-4


# -- the latent walk -------------------------------------------------------------------------

def test_slerp_ends_are_the_latents_and_its_middle_keeps_the_norm():
    g = torch.Generator().manual_seed(3)
    z0, z1 = torch.randn(16, generator=g), torch.randn(16, generator=g)
    walk = interpolation_latents(z0, z1, 5)
    assert torch.equal(walk[0], z0) and torch.equal(walk[-1], z1)
    e0, e1 = torch.tensor([2.0, 0.0]), torch.tensor([0.0, 2.0])        # orthogonal, norm 2
    mid = slerp(e0, e1, 0.5)[0]
    assert float(mid.norm()) == pytest.approx(2.0) and torch.allclose(mid, torch.tensor([math.sqrt(2)] * 2))
    assert float((0.5 * e0 + 0.5 * e1).norm()) == pytest.approx(math.sqrt(2))        # the straight line's: 2/√2
    with pytest.raises(UserError, match="at least 2 steps"):
        interpolation_latents(z0, z1, 1)


def test_interpolation_ends_are_g_of_the_two_latents(tmp_path):
    torch.manual_seed(0)
    cfg = load_config(None, ["model.resolution=16", "model.width=4", "model.latent=8", "train.task=generation"])
    model = Model.from_config(cfg)
    z = model.latents(2, seed=5)
    path, volumes = save_interpolation(model, z[0], z[1], tmp_path / "walk.png", steps=4)
    samples = model.generate(2, seed=5)
    assert torch.equal(volumes[0], samples[0].clamp(0, 1)) and torch.equal(volumes[-1], samples[1].clamp(0, 1))
    assert not torch.equal(volumes[1], volumes[0])
    # generate's walk takes latents(2, seed): the first two of any generate(n, seed), n ≥ 2
    assert torch.equal(model.latents(5, seed=5)[:2], z)
    assert torch.equal(model.generate(5, seed=5)[:2], samples)
    with Image.open(path) as im:
        assert im.width >= 4 * 128 and im.height >= 128


# -- platonic generate's sheets ----------------------------------------------------------------

def _train(tmp_path, *extra):
    overrides = [f"run.out_dir={tmp_path}/runs", "run.name=g", "run.steps=2", "run.threads=1", "run.sample_every=2",
                 "run.checkpoint_every=2", f"data.cache={tmp_path}/data", "data.shape_class=mushroom",
                 "data.n_shapes=6", "data.views_per_shape=2", "model.resolution=16", "model.width=4",
                 "model.latent=8", "train.batch_size=2", "train.task=generation", *extra]
    code, _, err = run_cli(["train", "--quiet"] + sum((["--set", o] for o in overrides), []))
    assert code == 0, err
    return tmp_path / "runs" / "g"


@pytest.fixture(scope="module")
def generation_run(tmp_path_factory):
    return _train(tmp_path_factory.mktemp("generation_run"))


def test_generate_writes_a_readable_grid_turntables_and_a_walk(generation_run, tmp_path):
    out = tmp_path / "gen"
    code, stdout, err = run_cli(["generate", "--run", str(generation_run), "-n", "5", "--out", str(out), "--quiet",
                                 "--turntable", "6", "--interpolate", "3"])
    assert code == 0, err
    assert "samples.png (the grid), turntables.png, interpolation.png" in stdout
    with Image.open(out / "samples.png") as im:               # 4 columns, 2 lines of 16² samples upscaled ≥ 128 px
        assert im.width >= 4 * 128 and im.height >= 2 * 128
    with Image.open(out / "turntables.png") as im:
        assert im.width >= 6 * 128 and im.height >= 5 * 128
    with Image.open(out / "interpolation.png") as im:
        assert im.width >= 3 * 128
    # --overwrite clears the sheets too; --turntable 0 and --interpolate 0 write none
    code, _, err = run_cli(["generate", "--run", str(generation_run), "-n", "2", "--out", str(out), "--quiet",
                            "--turntable", "0", "--interpolate", "0", "--overwrite"])
    assert code == 0, err
    assert (out / "samples.png").is_file() and not (out / "turntables.png").exists()
    assert not (out / "interpolation.png").exists() and not (out / "sample_002.npz").exists()
    code, _, err = run_cli(["generate", "--run", str(generation_run), "--out", str(tmp_path / "g2"), "--interpolate", "1"])
    assert code == 2 and "--interpolate" in one_line(err, "generate")


# -- the report -------------------------------------------------------------------------------

def test_evaluate_writes_the_generation_section_with_the_truth(generation_run, tmp_path):
    """A procedural generation run: its held-out shapes are the truth."""
    out = tmp_path / "eval"
    code, _, err = run_cli(["evaluate", "--run", str(generation_run), "--out", str(out), "--quiet", "--judge-steps", "0"])
    assert code == 0, err
    text = (out / "report.md").read_text()
    assert "## Generation: g (generation, step 2)" in text
    assert "| samples | volume diversity | render diversity (shared views) |" in text
    assert "| samples | truth volumes | nearest-truth IoU (mean over samples) |" in text
    assert "Two-sample critic" not in text                     # --judge-steps 0: no critic
    entry = json.loads((out / "results.json").read_text())[0]
    assert entry["section"] == "generation" and entry["truth"]["samples"] == G.SAMPLES
    assert entry["truth"]["truths"] == 1 and entry["truth"]["coverage"] == 1.0     # 6 shapes, 1 held out
    for name in ("samples", "turntables", "interpolation", "photos_and_samples", "nearest_truth"):
        figure = out / "figures" / f"g_generation_step_2_{name}.png"
        assert figure.is_file() and f"](figures/{figure.name})" in text


def test_the_report_of_a_tiny_generation_run_on_photos(tmp_path):
    """A folder generation run judged with a few critic steps, written by write_report."""
    from mitsuba_platonic.evaluate.generation_report import evaluate_generation_run
    from mitsuba_platonic.evaluate.report import write_report

    photos = tmp_path / "photos"
    photos.mkdir()
    rng = np.random.default_rng(0)
    for i in range(8):
        y, x = np.mgrid[0:24, 0:24] + 0.5
        r = rng.uniform(5, 10)
        arr = np.zeros((24, 24, 4), np.uint8)
        inside = (x - 12) ** 2 + (y - 12) ** 2 <= r * r
        arr[inside, :3], arr[inside, 3], arr[0, 0, :3] = rng.integers(30, 230, 3), 255, i
        Image.fromarray(arr, "RGBA").save(photos / f"p{i}.png")
    run = _train(tmp_path, "data.source=folder", f"data.path={photos}", "data.split=0.5", "render.model=ea",
                 "render.backend=closed_form")
    cfg = load_config(run / "config.yaml")
    section = evaluate_generation_run("g (generation, step 2)", cfg, Model.from_checkpoint(run), judge_steps=3,
                                      n_samples=4, repeats=2)
    report = write_report([], tmp_path / "eval", generation_sections=[section])
    text = report.read_text()
    assert "## Generation: g (generation, step 2)" in text and "| random p_view views | front (0°) |" in text
    assert "truth volumes" not in text                         # photos: no truth
    entry = json.loads((tmp_path / "eval" / "results.json").read_text())[0]
    assert set(entry["c2st"]["accuracy"]) == set(G.GENERATION_BANDS) and entry["c2st"]["photos"] == 4
    assert entry["means"]["samples"] == 4 and "truth" not in entry
    with Image.open(tmp_path / "eval" / "figures" / "g_generation_step_2_samples.png") as im:
        assert im.width >= 4 * 128
