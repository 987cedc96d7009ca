"""``platonic bench``'s driver: every renderer row of every resolution and image formation model,
measured against its reference (:func:`run_bench`; the rows are described in :mod:`mitsuba_platonic.bench`)."""

from __future__ import annotations

import math
import os
import platform
import time
from dataclasses import asdict
from datetime import datetime, timezone
from typing import Any, Callable, Dict, List, Optional, Tuple

import numpy as np
import torch

from ..render import render
from ..render.mitsuba.single_scatter_reference import reference_render
from ..render.pytorch.single_scatter import LightBatch, render_single_scatter, sample_lights, sample_sun_and_sky
from ..render.variant import ensure_variant
from ..views import sample_views
from ..volume import CHANNELS, test_volume
from .layers import (AUTHORS_DENSITY_FACTOR, AUTHORS_DEPTH_SAMPLES, authors_ea, gradient_error, image_error,
                     loss_weights, plain_ea)
from .settings import REFERENCE_OPTIONS, BenchSettings, marcher_configs, physical_spps
from .timing import RenderFn, available_bytes, forward_backward, measure, measure_bandwidth, release_memory, traffic_bytes
from .train import bench_train

__all__ = ["run_bench"]


# --------------------------------------------------------------------------- the bench


def _marcher(model: str, options: Dict[str, Any]) -> RenderFn:
    return lambda v, w: render(v, w, model, "mitsuba", **options)


def _closed_form(model: str) -> RenderFn:
    return lambda v, w: render(v, w, model, "closed_form", filter="trilinear")


def _physical(spp: int, max_depth: int, seed: int) -> RenderFn:
    return lambda v, w: render(v, w, "ea", "physical", seed=seed, physical_spp=spp, max_depth=max_depth,
                               lighting="sunsky")


#: The single-scattering rows (label, options) and their converged reference: 8 samples per voxel,
#: a shadow ray of 4 planes (one ray per pixel, as the rows).
SINGLE_SCATTER_CONFIGS = (("single scattering", {}), ("single scattering m 2", {"steps_per_voxel": 2}))
SINGLE_SCATTER_REFERENCE = {"steps_per_voxel": 8, "shadow_planes": 4}


def _pair_light(lights: LightBatch, i: int) -> LightBatch:
    """Pair i's light alone (a reference renders pair by pair)."""
    return LightBatch(lights.direction[i:i + 1], lights.irradiance[i:i + 1], lights.sky[i:i + 1])


def _single_scatter(lights: LightBatch, options: Dict[str, Any]) -> RenderFn:
    return lambda v, w: render_single_scatter(v, w, lights, **options)


#: The rows of single scattering in Dr.Jit (label, options) and the converged options of its gradient
#: reference (its image reference is volpath at max_depth 2).
SCATTER_MARCH_CONFIGS = (("scatter march (m 2, spp 1)", {}), ("scatter march m 4", {"steps_per_voxel": 4}),
                         ("scatter march spp 4", {"spp": 4}))
SCATTER_MARCH_REFERENCE = {"steps_per_voxel": 8, "spp": 4}


def _scatter_march(lights: LightBatch, options: Dict[str, Any]) -> RenderFn:
    from ..render.drjit.scatter_march import render_scatter_march  # imports Dr.Jit: on first use
    return lambda v, w: render_scatter_march(v, w, lights, **options)


def _reference(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor,
               weights: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """Image and gradient of L of a (slow) reference renderer, one pair at a time (bounded memory)."""
    images, grads = [], []
    for i in range(volume.shape[0]):
        img, g = forward_backward(fn, volume[i:i + 1], views[i:i + 1], weights[i:i + 1])
        images.append(img)
        grads.append(g)
        release_memory()
    return torch.cat(images), torch.cat(grads)


def _clean(value: Any) -> Any:
    """JSON-safe: non-finite floats → None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _clean(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_clean(v) for v in value]
    return value


def _row(n: int, b: int, model: str, renderer: str, config: str, options: Dict[str, Any], *, default: bool = False,
         formation: str = "ours", reference: str = "marcher step 0.25 spp 16") -> Dict[str, Any]:
    return {"resolution": n, "batch": b, "model": model, "renderer": renderer, "config": config,
            "options": dict(options), "default": default, "formation": formation, "reference": reference,
            "skipped": None}


def _fill(row: Dict[str, Any], m: Dict[str, Any], ref_image: torch.Tensor, ref_grad: torch.Tensor,
          closed: Optional[torch.Tensor], traffic: Tuple[int, int], bandwidth: float) -> None:
    row.update({k: m[k] for k in ("fwd_ms", "fwd_bwd_ms", "mem_fwd_mb", "mem_fwd_bwd_mb")})
    row["rmse"], row["max_abs"] = image_error(m["image"], ref_image)
    row.update(gradient_error(m["grad"], ref_grad))
    if closed is not None:
        row["rmse_vs_closed_form"], row["max_abs_vs_closed_form"] = image_error(m["image"], closed)
    else:
        row["rmse_vs_closed_form"] = row["max_abs_vs_closed_form"] = None
    b = row["batch"]
    f, bw = traffic
    row["bytes_fwd"], row["bytes_bwd"] = f // b, bw // b
    row["bound_fwd_ms"] = f / b / bandwidth * 1e3
    row["bound_fwd_bwd_ms"] = (f + bw) / b / bandwidth * 1e3
    row["fwd_over_bound"] = row["fwd_ms"] / row["bound_fwd_ms"]
    row["fwd_bwd_over_bound"] = row["fwd_bwd_ms"] / row["bound_fwd_bwd_ms"]


def _authors_bytes_estimate(b: int, n: int) -> int:
    """Rough peak of :func:`authors_ea`'s forward + backward (its depth-sampled tensors dominate)."""
    return 24 * b * AUTHORS_DEPTH_SAMPLES * n * n * 4


def run_bench(settings: BenchSettings, log: Callable[[str], None] = print) -> Dict[str, Any]:
    """Measure every row (see the module docstring); returns the result dictionary (JSON-ready)."""
    s = settings.validate()
    mi = ensure_variant()
    import drjit as dr               # after the variant is set (ensure_variant): Dr.Jit only where the bench runs

    old_threads = (torch.get_num_threads(), dr.thread_count())
    if s.threads:
        torch.set_num_threads(s.threads)
        dr.set_thread_count(s.threads)
    t_start = time.perf_counter()
    try:
        resolutions = [min(s.resolutions)] if s.quick else list(s.resolutions)
        repeats = 1 if s.quick else s.repeats
        ref_spp = min(s.physical_ref_spp, 4) if s.quick else s.physical_ref_spp
        bandwidth = measure_bandwidth(32 if s.quick else 256)
        log(f"bandwidth (tensor copy): {bandwidth / 1e9:.2f} GB/s; threads: torch {torch.get_num_threads()}, "
            f"Dr.Jit {dr.thread_count()}; variant {mi.variant()}")
        result: Dict[str, Any] = {
            "meta": {
                "started": datetime.now(timezone.utc).isoformat(timespec="seconds"),
                "machine": platform.processor() or platform.machine(), "platform": platform.platform(),
                "cpu_count": os.cpu_count(), "torch": torch.__version__, "mitsuba": mi.__version__,
                "drjit": dr.__version__, "variant": mi.variant(),
                "torch_threads": torch.get_num_threads(), "drjit_threads": dr.thread_count(),
                "bandwidth_gb_s": bandwidth / 1e9, "settings": asdict(s), "repeats_used": repeats,
                "resolutions_used": resolutions, "physical_ref_spp_used": ref_spp,
                "reference": dict(REFERENCE_OPTIONS), "loss": "L = sum(W * image), W = loss_weights(shape, seed)",
            },
            "views": {}, "rows": [], "train": [],
        }
        for n in resolutions:
            views = sample_views(s.batch, seed=s.seed)
            result["views"][str(n)] = views.tolist()
            for model in s.models:
                result["rows"].extend(_bench_model(s, n, model, views, repeats, ref_spp, bandwidth, log))
        if s.train:
            if s.quick:
                result["train"] = bench_train([min(s.resolutions)], s.train_width, s.batch, 1, 1, log, s.physical)
            else:
                result["train"] = bench_train(resolutions, s.train_width, s.train_batch, s.train_steps,
                                               s.train_warmup, log, s.physical)
        result["meta"]["duration_s"] = time.perf_counter() - t_start
        return _clean(result)
    finally:
        torch.set_num_threads(old_threads[0])
        dr.set_thread_count(old_threads[1])


def _bench_model(s: BenchSettings, n: int, model: str, views: torch.Tensor, repeats: int, ref_spp: int,
                 bandwidth: float, log: Callable[[str], None]) -> List[Dict[str, Any]]:
    b = s.batch
    volume = test_volume(n, s.volume, model).expand(b, -1, -1, -1, -1).contiguous()
    c_img = 4 if model == "ea" else 1
    weights = loss_weights((b, c_img, n, n), s.seed)
    traffic = traffic_bytes(b, CHANNELS[model], c_img, n)
    t0 = time.perf_counter()
    ref_image, ref_grad = _reference(_marcher(model, REFERENCE_OPTIONS), volume, views, weights)
    with torch.no_grad():
        closed = _closed_form(model)(volume, views)
    log(f"{n}³ {model}: reference (marcher step 0.25, spp 16) in {time.perf_counter() - t0:.1f} s")

    rows: List[Dict[str, Any]] = []

    def add(row: Dict[str, Any], fn: RenderFn, ref: Tuple[torch.Tensor, torch.Tensor],
            vs_closed: bool = True) -> None:
        try:
            m = measure(fn, volume, views, weights, repeats)
        except (ValueError, RuntimeError, MemoryError) as e:   # e.g. the marcher's record limit
            row["skipped"] = f"{type(e).__name__}: {e}"
            log(f"{n}³ {model}: {row['config']}: skipped ({row['skipped']})")
            rows.append(row)
            return
        _fill(row, m, ref[0], ref[1], closed if vs_closed else None, traffic, bandwidth)
        del m
        release_memory()
        rows.append(row)
        log(f"{n}³ {model}: {row['config']:<28} fwd {row['fwd_ms']:8.3f} ms  f+b {row['fwd_bwd_ms']:8.3f} ms  "
            f"mem {row['mem_fwd_bwd_mb']:7.1f} MB  rmse {row['rmse']:.2e}  grad cos {row['grad_cosine'] or 0:.4f}")

    ref = (ref_image, ref_grad)
    add(_row(n, b, model, "closed_form", "closed form", {"filter": "trilinear"}), _closed_form(model), ref)
    for label, options in marcher_configs(s.quick):
        full = {"step": 1.0, "spp": 1, "jitter": False, "filter": "trilinear", "termination": 0.0, **options}
        add(_row(n, b, model, "mitsuba", label, full, default=not options), _marcher(model, options), ref)
    if model != "ea":
        return rows

    add(_row(n, b, model, "plain", "plain layer (affine_grid)", {}), plain_ea, ref)
    row = _row(n, b, model, "authors", "authors' EA (1024 samples)",
               {"depth_samples": AUTHORS_DEPTH_SAMPLES, "density_factor": AUTHORS_DENSITY_FACTOR},
               formation="authors", reference="ours: marcher step 0.25 spp 16 (a different image formation)")
    need, avail = _authors_bytes_estimate(b, n), available_bytes()
    if avail is not None and need > 0.6 * avail:
        row["skipped"] = (f"needs about {need / 2**30:.1f} GiB, {avail / 2**30:.1f} GiB available; "
                          f"use a smaller batch")
        log(f"{n}³ ea: {row['config']}: skipped ({row['skipped']})")
        rows.append(row)
    else:
        add(row, authors_ea, ref)

    if not s.physical:                                        # the light formations: path tracer, single scattering
        return rows
    if n <= s.physical_max_resolution:
        _path_tracer_rows(s, n, b, model, volume, views, weights, ref_spp, add, log)
    if n <= s.single_scatter_max_resolution:
        _single_scatter_rows(s, n, b, model, volume, views, weights, add, log)
    if n <= s.scatter_march_max_resolution:
        _scatter_march_rows(s, n, b, model, volume, views, weights, add, log)
    return rows


def _path_tracer_rows(s: BenchSettings, n: int, b: int, model: str, volume: torch.Tensor, views: torch.Tensor,
                      weights: torch.Tensor, ref_spp: int, add: Callable, log: Callable[[str], None]) -> None:
    """The path tracer's rows (``add`` measures and records one), against itself at ``ref_spp``."""
    t0 = time.perf_counter()
    # one call for the whole batch: the path tracer draws pair b's sky as the b-th draw from the seed
    phys_ref = forward_backward(_physical(ref_spp, s.physical_max_depth, s.seed), volume, views, weights)
    release_memory()
    log(f"{n}³ ea: path-traced reference (spp {ref_spp}) in {time.perf_counter() - t0:.1f} s")
    for spp in physical_spps(s.quick):
        add(_row(n, b, model, "physical", f"path tracer spp {spp}",
                 {"physical_spp": spp, "max_depth": s.physical_max_depth, "lighting": "sunsky", "seed": s.seed},
                 formation="physical", reference=f"path tracer spp {ref_spp}, same scene, views and sky"),
            _physical(spp, s.physical_max_depth, s.seed), phys_ref, vs_closed=False)


def _single_scatter_rows(s: BenchSettings, n: int, b: int, model: str, volume: torch.Tensor, views: torch.Tensor,
                         weights: torch.Tensor, add: Callable, log: Callable[[str], None]) -> None:
    """The single-scattering rows (``add`` measures and records one), against
    :data:`SINGLE_SCATTER_REFERENCE` under the same suns and skies."""
    t0 = time.perf_counter()
    lights = sample_lights(b, s.seed)                         # as the single_scatter backend draws them
    images, grads = [], []
    for i in range(b):                                        # pair by pair: the reference's samples are many
        light = _pair_light(lights, i)
        img, g = forward_backward(_single_scatter(light, SINGLE_SCATTER_REFERENCE), volume[i:i + 1],
                                   views[i:i + 1], weights[i:i + 1])
        images.append(img)
        grads.append(g)
        release_memory()
    log(f"{n}³ ea: single-scattering reference in {time.perf_counter() - t0:.1f} s")
    for label, options in SINGLE_SCATTER_CONFIGS:
        add(_row(n, b, model, "single_scatter", label, {"steps_per_voxel": 4, "shadow_planes": 2, **options},
                 formation="single_scatter",
                 reference="single scattering, 8 samples per voxel, shadow ray 4 planes; same views and suns"),
            _single_scatter(lights, options), (torch.cat(images), torch.cat(grads)), vs_closed=False)


def _scatter_march_rows(s: BenchSettings, n: int, b: int, model: str, volume: torch.Tensor, views: torch.Tensor,
                        weights: torch.Tensor, add: Callable, log: Callable[[str], None]) -> None:
    """Single scattering in Dr.Jit (``add`` measures and records one row): its RGB against Mitsuba's
    volpath at max_depth 2 (the same suns and skies, ``scatter_ref_spp``), its α and gradients
    against itself at :data:`SCATTER_MARCH_REFERENCE`."""
    t0 = time.perf_counter()
    lights = sample_lights(b, s.seed)                         # as the scatter_march backend draws them
    suns = [sample_sun_and_sky(np.random.default_rng([s.seed, i])) for i in range(b)]   # the same, one by one
    spp = min(s.scatter_ref_spp, 16) if s.quick else s.scatter_ref_spp
    images = torch.cat([reference_render(volume[i:i + 1], views[i:i + 1], suns[i:i + 1], spp=spp, seed=s.seed + i)
                        for i in range(b)])
    alphas, grads = [], []
    for i in range(b):                                        # pair by pair: bounded memory
        light = _pair_light(lights, i)
        img, g = forward_backward(_scatter_march(light, SCATTER_MARCH_REFERENCE), volume[i:i + 1],
                                   views[i:i + 1], weights[i:i + 1])
        alphas.append(img[:, 3])
        grads.append(g)
        release_memory()
    grad = torch.cat(grads)
    images[:, 3] = torch.cat(alphas)                            # volpath's alpha is not α = 1 − e^{−τ}
    log(f"{n}³ ea: volpath (max_depth 2, spp {spp}) and scatter-march references in "
        f"{time.perf_counter() - t0:.1f} s")
    for label, options in SCATTER_MARCH_CONFIGS:
        add(_row(n, b, model, "scatter_march", label, {"steps_per_voxel": 2, "spp": 1, **options},
                 formation="scatter_march",
                 reference=f"RGB: volpath max_depth 2 at spp {spp}, same views, suns and skies; α and "
                           f"gradients: scatter march at 8 samples per voxel, spp 4"),
            _scatter_march(lights, options), (images, grad), vs_closed=False)
