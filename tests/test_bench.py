"""`platonic bench` (cli/renderers.py + bench/): its outputs exist and its numbers are what they claim.

The quick bench runs once at 16³ with a batch of 2 (seconds); nothing here looks at a time.
"""

from __future__ import annotations

import contextlib
import io
import json
import math
import shutil
import time
from pathlib import Path

import pytest
import torch
from PIL import Image

from mitsuba_platonic import render
from mitsuba_platonic.bench import (DOC_BEGIN, DOC_END, REFERENCE_OPTIONS, authors_ea, loss_weights, plain_ea,
                                    write_doc)
from mitsuba_platonic.cli import main
from mitsuba_platonic.views import front_view, sample_views
from mitsuba_platonic.volume import test_volume

N, BATCH = 16, 2
MODELS = ("vh", "ao", "ea")
DOC = Path(__file__).resolve().parents[1] / "docs" / "speed_accuracy.md"
MEASURED = ("fwd_ms", "fwd_bwd_ms", "mem_fwd_mb", "mem_fwd_bwd_mb", "rmse", "max_abs", "grad_cosine",
            "grad_norm_ratio", "grad_rel_err", "bytes_fwd", "bytes_bwd", "bound_fwd_ms", "bound_fwd_bwd_ms",
            "fwd_over_bound", "fwd_bwd_over_bound")
LABELS = ("resolution", "batch", "model", "renderer", "config", "options", "default", "formation", "reference",
          "skipped", "rmse_vs_closed_form", "max_abs_vs_closed_form")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        code = main(["bench", "--quick", "--resolutions", str(N), "--batch", str(BATCH), "--threads", "1",
                     "--out", str(out)])
    assert code == 0, stderr.getvalue()
    return out, json.loads((out / "bench.json").read_text()), stdout.getvalue()


def rows_of(result, model):
    return {r["config"]: r for r in result["rows"] if r["model"] == model}


def the_volume(model):
    return test_volume(N, "figure", model).expand(BATCH, -1, -1, -1, -1).contiguous()


def rmse_max(a, b):
    d = (a.double() - b.double())
    return float(d.pow(2).mean().sqrt()), float(d.abs().max())


# --------------------------------------------------------------------------- outputs


def test_outputs_exist(quick):
    out, result, stdout = quick
    for model in MODELS:
        png = out / f"pareto_{model}_{N}.png"
        with Image.open(png) as im:
            assert im.format == "PNG" and im.size[0] > 300
        assert str(png) in stdout
    md = (out / "bench.md").read_text()
    for model in MODELS:
        assert f"### {model.upper()} at {N}³" in md
        assert f"pareto_{model}_{N}.png" in md
    assert "| **marcher default** |" in md
    assert "### Training speed" in md


def test_rows_have_the_fields(quick):
    _, result, _ = quick
    assert result["meta"]["bandwidth_gb_s"] > 0
    assert result["meta"]["resolutions_used"] == [N]
    assert len(result["views"][str(N)]) == BATCH
    for model in MODELS:
        rows = rows_of(result, model)
        assert {"closed form", "marcher default"} <= set(rows)
        assert [c for c, r in rows.items() if r["default"]] == ["marcher default"]
        if model == "ea":
            assert {"plain layer (affine_grid)", "authors' EA (1024 samples)", "path tracer spp 1"} <= set(rows)
            assert rows["authors' EA (1024 samples)"]["formation"] == "authors"
            assert rows["path tracer spp 1"]["formation"] == "physical"
            assert {"single scattering", "single scattering m 2"} <= set(rows)
            assert rows["single scattering"]["formation"] == "single_scatter"
            assert rows["single scattering"]["grad_cosine"] > 0.9     # against 8 samples per voxel
            marches = {"scatter march (m 2, spp 1)", "scatter march m 4", "scatter march spp 4"}
            assert marches <= set(rows) and {rows[c]["formation"] for c in marches} == {"scatter_march"}
            assert "volpath max_depth 2" in rows["scatter march m 4"]["reference"]
            assert rows["scatter march m 4"]["grad_cosine"] > 0.9      # against 8 samples per voxel, spp 4
        for r in rows.values():
            assert set(LABELS) <= set(r)
            assert r["skipped"] is None, r["skipped"]
            assert r["resolution"] == N and r["batch"] == BATCH
            for k in MEASURED:
                assert isinstance(r[k], (int, float)) and math.isfinite(r[k]) and r[k] >= 0, (r["config"], k, r[k])
            assert r["fwd_ms"] > 0 and r["fwd_bwd_ms"] > 0
            assert -1.0 <= r["grad_cosine"] <= 1.0 + 1e-9
    for t in result["train"]:
        assert t["skipped"] is None, t["skipped"]
        assert t["images_per_s"] > 0 and t["resolution"] == N
        shares = (t["renderer_share"], t["networks_share"], t["optimiser_share"])
        assert all(0.0 <= x <= 1.0 for x in shares) and sum(shares) == pytest.approx(1.0, abs=1e-6), shares
        assert 0.0 < t["renderer_backward_share"] <= t["renderer_share"] and t["optimiser_share"] > 0
    assert [t["renderer"] for t in result["train"]] == ["closed_form", "mitsuba", "scatter_march", "physical"]


def test_traffic_bound_is_bytes_over_bandwidth(quick):
    _, result, _ = quick
    bw = result["meta"]["bandwidth_gb_s"] * 1e9
    for r in result["rows"]:
        c, c_img = (4, 4) if r["model"] == "ea" else (1, 1)
        vol, img = c * N ** 3 * 4, c_img * N * N * 4                   # per image, float32
        assert r["bytes_fwd"] == vol + img
        assert r["bytes_bwd"] == 2 * vol + img
        assert r["bound_fwd_bwd_ms"] == pytest.approx((3 * vol + 2 * img) / bw * 1e3, rel=1e-9)
        assert r["fwd_bwd_over_bound"] == pytest.approx(r["fwd_bwd_ms"] / r["bound_fwd_bwd_ms"], rel=1e-9)


# --------------------------------------------------------------------------- the numbers, recomputed


@pytest.mark.parametrize("model", MODELS)
def test_reported_errors_match_our_own_renders(quick, model):
    """RMSE / max of the closed form and the marcher's default, recomputed from render() with the
    views the bench recorded and a reference rendered here in one batched call."""
    _, result, _ = quick
    rows = rows_of(result, model)
    views = torch.tensor(result["views"][str(N)])
    vol = the_volume(model)
    with torch.no_grad():
        ref = render(vol, views, model, "mitsuba", **REFERENCE_OPTIONS)
        closed = render(vol, views, model, "closed_form")
        default = render(vol, views, model, "mitsuba")
    for config, image in (("closed form", closed), ("marcher default", default)):
        rmse, mx = rmse_max(image, ref)
        assert rows[config]["rmse"] == pytest.approx(rmse, rel=1e-4, abs=1e-8)
        assert rows[config]["max_abs"] == pytest.approx(mx, rel=1e-4, abs=1e-7)
    rmse, mx = rmse_max(default, closed)
    assert rows["marcher default"]["max_abs_vs_closed_form"] == pytest.approx(mx, rel=1e-3, abs=1e-7)
    assert rows["marcher default"]["max_abs_vs_closed_form"] <= 1e-4        # README: oblique views agree to 1e-4
    assert rows["closed form"]["max_abs_vs_closed_form"] == 0.0


def test_default_front_view_matches_closed_form():
    vol = test_volume(N, "figure", "ea")
    with torch.no_grad():
        a = render(vol, front_view(1), "ea", "closed_form")
        b = render(vol, front_view(1), "ea", "mitsuba")
    assert float((a - b).abs().max()) <= 1e-5


def test_reported_gradient_error_matches(quick):
    _, result, _ = quick
    row = rows_of(result, "ea")["marcher default"]
    views = torch.tensor(result["views"][str(N)])
    w = loss_weights((BATCH, 4, N, N), result["meta"]["settings"]["seed"])
    grads = []
    for options in (REFERENCE_OPTIONS, {}):
        x = the_volume("ea").requires_grad_()
        (render(x, views, "ea", "mitsuba", **options) * w).sum().backward()
        grads.append(x.grad.double().flatten())
    ref, g = grads
    assert row["grad_cosine"] == pytest.approx(float(g @ ref / (g.norm() * ref.norm())), abs=1e-6)
    assert row["grad_rel_err"] == pytest.approx(float((g - ref).norm() / ref.norm()), rel=1e-4)
    assert row["grad_norm_ratio"] == pytest.approx(float(g.norm() / ref.norm()), rel=1e-5)


def test_the_scatter_march_rows_are_measured_against_volpath(quick):
    """The default row's RGB error recomputed: volpath at max_depth 2 (the bench's quick spp, 16, and
    seeds) under the lights the backend draws from the seed; α from the converged march."""
    import drjit as dr
    import numpy as np

    from mitsuba_platonic.render.drjit.scatter_march import render_scatter_march
    from mitsuba_platonic.render.mitsuba.single_scatter_reference import reference_render
    from mitsuba_platonic.render.pytorch.single_scatter import sample_lights, sample_sun_and_sky

    _, result, _ = quick
    row = rows_of(result, "ea")["scatter march (m 2, spp 1)"]
    views = torch.tensor(result["views"][str(N)])
    seed = result["meta"]["settings"]["seed"]
    vol = the_volume("ea")
    lights = sample_lights(BATCH, seed)
    suns = [sample_sun_and_sky(np.random.default_rng([seed, i])) for i in range(BATCH)]
    threads = dr.thread_count()
    dr.set_thread_count(1)                   # as the bench ran (--threads 1): volpath's samples follow the threads
    try:
        with torch.no_grad():
            ref = torch.cat([reference_render(vol[i:i + 1], views[i:i + 1], suns[i:i + 1], spp=16, seed=seed + i)
                             for i in range(BATCH)])
    finally:
        dr.set_thread_count(threads)
    with torch.no_grad():
        ref[:, 3] = render_scatter_march(vol, views, lights, steps_per_voxel=8, spp=4)[:, 3]
        ours = render_scatter_march(vol, views, lights)
    rmse, mx = rmse_max(ours, ref)
    assert row["rmse"] == pytest.approx(rmse, rel=1e-3) and row["max_abs"] == pytest.approx(mx, rel=1e-3)
    assert row["rmse"] < 0.2 * float(ref[:, :3].abs().max())


# --------------------------------------------------------------------------- the extra EA layers


def test_plain_layer_is_our_image_formation():
    vol = the_volume("ea")
    views = sample_views(BATCH, seed=5)
    with torch.no_grad():
        assert float((plain_ea(vol, views) - render(vol, views, "ea")).abs().max()) <= 1e-5


def test_authors_layer_density_scale_and_orientation():
    # an optically thin uniform cube: 1,024 samples of the padded cube integrate a piecewise-linear
    # density profile whose mean over [−1, 1] is v N / (N + 1), times their factor 100
    v = 1e-3
    vol = torch.zeros(1, 4, N, N, N)
    vol[:, :3], vol[:, 3] = 0.5, v
    with torch.no_grad():
        img = authors_ea(vol, front_view(1))
    alpha = img[0, 3]
    assert float(alpha[N // 2, N // 2]) == pytest.approx(1.0 - math.exp(-100.0 * v * N / (N + 1)), rel=0.01)
    assert float(alpha[0].max()) == 0.0 and float(alpha[:, 0].max()) == 0.0      # the padding frames it
    # the same orientation as ours: correlated with our alpha, far less with its mirror images
    vol = the_volume("ea")
    views = sample_views(BATCH, seed=3)
    with torch.no_grad():
        a, c = authors_ea(vol, views)[:, 3], render(vol, views, "ea")[:, 3]

    def corr(x, y):
        x, y = x - x.mean(), y - y.mean()
        return float((x * y).sum() / (x.norm() * y.norm()))

    for b in range(BATCH):
        same = corr(a[b], c[b])
        assert same > 0.9
        assert same > corr(a[b].flip(0), c[b]) + 0.1 and same > corr(a[b].flip(1), c[b]) + 0.1


# --------------------------------------------------------------------------- the doc


def test_doc_section_is_written(quick, tmp_path):
    out, result, _ = quick
    doc = tmp_path / "speed_accuracy.md"
    shutil.copyfile(DOC, doc)
    plots = sorted(out.glob("pareto_*.png"))
    write_doc(result, doc, plots)
    text = doc.read_text()
    head, rest = text.split(DOC_BEGIN)
    body, tail = rest.split(DOC_END)
    assert head == DOC.read_text().split(DOC_BEGIN)[0]                # the hand-written part is kept
    assert "| **marcher default** |" in body and "Not measured yet" not in body
    for p in plots:
        assert (tmp_path / "speed_accuracy" / p.name).is_file()
        assert f"speed_accuracy/{p.name}" in body
    write_doc(result, doc, plots)                                     # idempotent
    assert doc.read_text() == text
    bad = tmp_path / "bad.md"
    bad.write_text("no markers\n")
    with pytest.raises(ValueError, match="generated section"):
        write_doc(result, bad, plots)


# --------------------------------------------------------------------------- where a training step's time goes


class _SlowIdentity(torch.autograd.Function):
    """An identity that sleeps a known time forward and backward."""

    @staticmethod
    def forward(ctx, x, seconds):
        ctx.seconds = seconds
        time.sleep(seconds)
        return x.clone()

    @staticmethod
    def backward(ctx, grad):
        time.sleep(ctx.seconds)
        return grad, None


@pytest.mark.usefixtures("tiny_class")
def test_the_step_clock_gives_the_renderer_its_forward_and_backward_and_the_optimisers_their_steps(tmp_path):
    from mitsuba_platonic.bench.train import StepClock
    from mitsuba_platonic.config import load_config
    from mitsuba_platonic.train.data import load_training_data
    from mitsuba_platonic.train.trainer import Trainer
    from tiny_shapes import TINY

    cfg = load_config(None, [f"run.out_dir={tmp_path}/runs", f"data.cache={tmp_path}/data", f"data.shape_class={TINY}",
                             "data.n_shapes=4", "data.views_per_shape=2", "model.resolution=16", "model.width=4",
                             "model.latent=8", "train.batch_size=2", "render.backend=closed_form"])
    trainer = Trainer(cfg, load_training_data(cfg, progress=False), torch.device("cpu"))
    own_render, own_step = trainer.render, trainer.opt_g.step
    calls = []
    pause = 0.05

    def slow_render(volume, views, seed):           # the real render between two known sleeps
        calls.append(volume.requires_grad)
        return _SlowIdentity.apply(own_render(_SlowIdentity.apply(volume, pause), views, seed), pause)
    trainer.render = slow_render
    clock = StepClock(trainer)
    t0 = time.perf_counter()
    trainer.step(0)
    wall = time.perf_counter() - t0
    parts = clock.totals()
    # a step renders the random view and the input view, both through G: each call's forward holds two
    # sleeps, and each backward two more, between the marks
    assert calls == [True, True]
    assert parts["renderer_forward"] >= 2 * 2 * pause
    assert parts["renderer_backward"] >= 2 * 2 * pause
    assert 0.0 < parts["optimiser"] and sum(parts.values()) <= wall
    clock.detach()
    assert trainer.render is slow_render and trainer.opt_g.step == own_step
    clock.reset()
    assert clock.totals() == {"renderer_forward": 0.0, "renderer_backward": 0.0, "optimiser": 0.0}


def test_the_part_clock_splits_a_photo_step_into_its_named_parts():
    """The photo recipe at 16³, 2 steps: every part of PARTS is timed (> 0), the parts sum to the
    steps' time less the clock's bookkeeping (≤ the wall time around them), a known sleep in the
    renderer's and in G's forward and backward lands in that part, the priors' share is the sum of
    their terms' (each active prior timed by name), and detach gives everything back."""
    from mitsuba_platonic.bench.train import PARTS, TERM_PARTS, PartClock, random_training_data
    from mitsuba_platonic.config import load_config
    from mitsuba_platonic.train.terms import active_terms
    from mitsuba_platonic.files.resources import config_path
    from mitsuba_platonic.train.trainer import Trainer

    assert PARTS == ("G", "E", "D", "renderer", "priors", "pose", "optimiser", "other")   # as docs/training.md names them
    cfg = load_config(config_path("photos"), ["model.resolution=16", "data.path=unused"])
    trainer = Trainer(cfg, random_training_data(16), torch.device("cpu"))
    pause = 0.05
    own_render = trainer.render

    def slow_render(volume, views, seed):          # the real render between two known sleeps
        return _SlowIdentity.apply(own_render(_SlowIdentity.apply(volume, pause), views, seed), pause)

    def slow_g(_module, _args, out):                # G's volume through one known sleep, forward and backward
        return (_SlowIdentity.apply(out[0], pause), *out[1:]) if isinstance(out, tuple) else _SlowIdentity.apply(out, pause)
    trainer.render = slow_render
    handle = trainer.nets["G"].register_forward_hook(slow_g)
    own = (trainer.terms, trainer.opt_g.step, trainer.opt_d.step)
    clock = PartClock(trainer)
    t0 = time.perf_counter()
    for step in range(2):
        trainer.step(step)
    wall = time.perf_counter() - t0
    parts = clock.totals()
    assert tuple(parts) == PARTS and all(parts[p] > 0 for p in PARTS), parts
    assert clock.steps == 2 and clock.overhead > 0
    assert sum(parts.values()) == pytest.approx(clock.wall - clock.overhead, abs=1e-9)
    assert sum(parts.values()) <= clock.wall <= wall
    priors = clock.priors()                         # the priors by term: every active one but the four of TERM_PARTS
    assert set(priors) == {t.name for t in active_terms(cfg.train)} - set(TERM_PARTS), priors
    assert all(v > 0 for v in priors.values()) and sum(priors.values()) == pytest.approx(parts["priors"], abs=1e-12)
    # per step two renders (the random views and the input view), each with two sleeps forward and two backward
    assert parts["renderer"] >= 2 * 2 * 4 * pause
    assert parts["G"] >= 2 * 2 * pause              # G's sleep forward and its node's backward
    clock.detach()
    handle.remove()
    assert trainer.render is slow_render and (trainer.terms, trainer.opt_g.step, trainer.opt_d.step) == own
    assert "step" not in vars(trainer) and "_volumes" not in vars(trainer)
    assert not trainer.nets["E"]._forward_hooks and not trainer.nets["E"]._forward_pre_hooks
    trainer.step(2)                                 # detached: untimed
    assert clock.totals() == parts
