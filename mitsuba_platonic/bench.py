"""``platonic bench``: the renderers' speed/accuracy trade, measured and published.

For each resolution N and each image formation model (VH, AO, EA) one batch of B (volume, view)
pairs (the built-in test volume, B random views) is rendered by:

- the closed-form layer (the reference mode, trilinear);
- the batched ray marcher (``backend="mitsuba"``) at its default (step 1, spp 1, trilinear, no
  jitter, termination 0) and with one option varied at a time: step {2, 0.5, 0.25}, spp {4, 16}
  on a regular sub-pixel grid and jittered, jitter at spp 1, nearest lookups, early termination
  {1e-3, 1e-2};
- EA only: a *plain layer* (``affine_grid`` + ``grid_sample`` + ``cumprod``, nothing else: a speed
  yardstick for a layer written the obvious way), the *authors' EA layer* (:func:`authors_ea`, the
  image formation of the PlatonicGAN authors' public code: a different image formation, reported
  for its time and for how far its images are from ours), and the differentiable path tracer
  (``backend="physical"``, :func:`~mitsuba_platonic.render.physical.render_physical_ad`: its own
  image formation under a random sky) at spp {1, 4}.

Every row records (all times per image, the best of ``repeats`` timed calls after an untimed
warm-up call):

- ``fwd_ms``: a forward call under ``torch.no_grad()``; ``fwd_bwd_ms``: forward and backward of
  the loss L = Σ W ⊙ image, W a fixed random weight (:func:`loss_weights`), into a leaf volume.
- ``mem_fwd_mb`` / ``mem_fwd_bwd_mb``: the peak increase of the process's resident memory (RSS,
  sampled from ``/proc/self/statm`` by a background thread every 0.5 ms) over its level just
  before one such call, after Python's, Dr.Jit's and glibc's caches were released. CPU memory
  only; it includes everything the call allocates (outputs, the marcher's T_k record, autograd
  buffers, the gradient).
- ``rmse`` / ``max_abs``: image error against the *converged reference*: the ray marcher at step
  0.25 with spp 16 on a regular grid (rendered pair by pair). Rows of another image formation are
  measured against their own reference: the path tracer against itself at ``physical_ref_spp``
  (the same scene, views and sky, whose sun is drawn from the seed and not from the spp); the
  authors' layer against *our* reference (for information: it renders a different image).
- ``grad_cosine``, ``grad_norm_ratio`` (‖g‖ / ‖g_ref‖) and ``grad_rel_err`` (‖g − g_ref‖ / ‖g_ref‖):
  the gradient of L w.r.t. the volume against the reference's gradient of the same L.
- ``rmse_vs_closed_form`` / ``max_abs_vs_closed_form``: image difference from the closed form.
- A memory-traffic lower bound: the bytes that must move (forward: read the volume once and write
  the image; backward: read the volume and the image gradient, write the volume gradient) divided
  by a bandwidth measured once at the start (the best of several copies of a large tensor,
  counting its read and its write); ``bound_fwd_ms``, ``bound_fwd_bwd_ms`` and the measured time
  over the bound, ``fwd_over_bound`` / ``fwd_bwd_over_bound``.

Plus training images/s per renderer (closed form, the marcher, the path tracer at spp 1 depth 2)
for one small reconstruction configuration (:func:`_bench_train`).

Outputs (:func:`write_outputs`): ``bench.json`` (every measured row and the run's settings),
``bench.md`` (the tables) and ``pareto_<model>_<N>.png`` (image RMSE vs forward+backward ms per
image, log-log, every configuration labelled, the marcher's default marked). :func:`write_doc`
fills the generated section of ``docs/speed_accuracy.md``. Nothing is asserted here: the tests
check correctness, never time.
"""

from __future__ import annotations

import ctypes
import gc
import json
import math
import os
import platform
import shutil
import sys
import threading
import time
from dataclasses import asdict, dataclass
from datetime import datetime, timezone
from pathlib import Path
from typing import Any, Callable, Dict, List, Optional, Sequence, Tuple

import torch
import torch.nn.functional as F

from .compare import _sync, best_of
from .models import RESOLUTIONS
from .views import camera_frames, sample_views
from .volume import CHANNELS, test_volume

__all__ = ["BenchSettings", "run_bench", "write_outputs", "write_doc", "marcher_configs", "authors_ea",
           "plain_ea", "loss_weights", "image_error", "gradient_error", "REFERENCE_OPTIONS",
           "RESOLUTIONS", "DOC_BEGIN", "DOC_END"]

#: The converged reference every row of our image formation is measured against.
REFERENCE_OPTIONS: Dict[str, Any] = {"step": 0.25, "spp": 16, "jitter": False, "filter": "trilinear"}
#: Resolutions the bench accepts (those the training configuration accepts).
#: The authors' EA layer: depth samples per ray and density factor (see :func:`authors_ea`).
AUTHORS_DEPTH_SAMPLES = 1024
AUTHORS_DENSITY_FACTOR = 100.0
#: Markers around the generated section of docs/speed_accuracy.md.
DOC_BEGIN = "<!-- platonic bench: generated section, begin -->"
DOC_END = "<!-- platonic bench: generated section, end -->"

_MIB = 2.0 ** 20


# --------------------------------------------------------------------------- settings


@dataclass
class BenchSettings:
    """What ``platonic bench`` measures (the command's options)."""

    resolutions: Sequence[int] = (32, 64)
    batch: int = 8
    repeats: int = 3
    threads: Optional[int] = None               # torch and Dr.Jit threads (None: leave as they are)
    models: Sequence[str] = ("vh", "ao", "ea")
    volume: str = "figure"
    seed: int = 0
    quick: bool = False
    physical_ref_spp: int = 32
    physical_max_depth: int = 4
    physical: bool = True                       # the path-tracer rows (the slowest part of a run)
    physical_max_resolution: int = 64           # … measured up to this N (128³ path tracing: most of an hour)
    train: bool = True
    train_resolution: int = 32
    train_width: int = 16
    train_batch: int = 8
    train_steps: int = 5
    train_warmup: int = 2

    def validate(self) -> "BenchSettings":
        for n in self.resolutions:
            if n not in RESOLUTIONS:
                raise ValueError(f"resolutions must be among {RESOLUTIONS}, got {n!r}")
        if not self.resolutions:
            raise ValueError("resolutions: give at least one")
        for name in ("batch", "repeats", "physical_ref_spp", "physical_max_depth", "physical_max_resolution", "train_width",
                     "train_batch", "train_steps"):
            v = getattr(self, name)
            if not isinstance(v, int) or isinstance(v, bool) or v < 1:
                raise ValueError(f"{name} must be a positive int, got {v!r}")
        if self.threads is not None and (not isinstance(self.threads, int) or self.threads < 1):
            raise ValueError(f"threads must be a positive int, got {self.threads!r}")
        if self.train_resolution not in RESOLUTIONS:
            raise ValueError(f"train_resolution must be among {RESOLUTIONS}, got {self.train_resolution!r}")
        for m in self.models:
            if m not in CHANNELS:
                raise ValueError(f"models must be among {tuple(CHANNELS)}, got {m!r}")
        return self


def marcher_configs(quick: bool = False) -> List[Tuple[str, Dict[str, Any]]]:
    """(label, options) of the marcher rows: the default first, then one option varied at a time."""
    if quick:
        return [("marcher default", {}), ("step 2", {"step": 2.0}), ("spp 4 jitter", {"spp": 4, "jitter": True}),
                ("termination 1e-2", {"termination": 1e-2})]
    return [
        ("marcher default", {}),
        ("step 2", {"step": 2.0}), ("step 0.5", {"step": 0.5}), ("step 0.25", {"step": 0.25}),
        ("spp 4", {"spp": 4}), ("spp 16", {"spp": 16}),
        ("spp 4 jitter", {"spp": 4, "jitter": True}), ("spp 16 jitter", {"spp": 16, "jitter": True}),
        ("jitter (spp 1)", {"jitter": True}),
        ("nearest", {"filter": "nearest"}),
        ("termination 1e-3", {"termination": 1e-3}), ("termination 1e-2", {"termination": 1e-2}),
    ]


def _physical_spps(quick: bool) -> Tuple[int, ...]:
    return (1,) if quick else (1, 4)


# --------------------------------------------------------------------------- the two extra EA layers


def authors_ea(volume: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """The PlatonicGAN authors' EA layer (github.com/henzler/platonicgan, ``scripts/renderer``),
    re-implemented from its description, for speed and image comparisons only.

    This is *their* image formation, not this package's (docs/paper.md, "Differences"):

    1. Rotation by resampling: the camera-space grid (``linspace(−1, 1, N)`` per axis, z from the
       front +1 to −1, y from the top +1 to −1) is rotated into the world by the view matrix
       [right, up, ω] (the same camera frame as ours) and the volume is read there by
       ``grid_sample`` (trilinear, zero padding) with ``align_corners=True``: the behaviour of
       ``grid_sample`` before PyTorch 1.3, for which their code was written.
    2. The rotated volume is padded by one empty voxel on every side and resampled again at
       1,024 depth samples × N × N pixels (``linspace(−1, 1)`` grids over the padded cube, so the
       pixels frame the object slightly smaller than ours).
    3. Densities are multiplied by 100 / 1,024: a ray across the cube has an optical depth of
       about 100 v whatever N.
    4. Inclusive transmittance T_i = Π_{j≤i}(1 − a_j) (``cumprod``), weights a_i T_i, colour
       renormalised by the weight sum (+1e-8) and multiplied by α = 1 − Π(1 − a_i).

    ``volume`` ``(B, 4, N, N, N)``, ``views`` ``(B, 3)`` → ``(B, 4, N, N)`` premultiplied RGB + alpha.
    """
    b, n = volume.shape[0], volume.shape[-1]
    dtype, dev = volume.dtype, volume.device
    # 1. rotation into camera space
    right, up, w = camera_frames(views.detach().cpu())
    rot = torch.stack([right, up, w], dim=2).to(dtype=dtype, device=dev)          # (B, 3, 3), columns
    ax = torch.linspace(-1.0, 1.0, n, dtype=dtype, device=dev)
    cz, cy, cx = torch.meshgrid(ax.flip(0), ax.flip(0), ax, indexing="ij")       # graphics coordinates
    cam = torch.stack([cx, cy, cz]).reshape(1, 3, -1).expand(b, -1, -1)
    world = torch.bmm(rot, cam).transpose(1, 2).reshape(b, n, n, n, 3)
    grid = world * world.new_tensor([1.0, -1.0, -1.0])                           # grid_sample: y down, z back
    camera_volume = F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=True)
    # 2. pad and resample at 1,024 depth samples per pixel
    padded = F.pad(camera_volume, (1, 1, 1, 1, 1, 1))
    zs = torch.linspace(-1.0, 1.0, AUTHORS_DEPTH_SAMPLES, dtype=dtype, device=dev)
    sz, sy, sx = torch.meshgrid(zs, ax, ax, indexing="ij")
    samples = torch.stack([sx, sy, sz], dim=-1).expand(b, -1, -1, -1, -1)
    # 3. density scale
    density = padded[:, 3:] * (AUTHORS_DENSITY_FACTOR / AUTHORS_DEPTH_SAMPLES)
    a = F.grid_sample(density, samples, mode="bilinear", padding_mode="zeros", align_corners=True)
    colour = F.grid_sample(padded[:, :3], samples, mode="bilinear", padding_mode="zeros", align_corners=True)
    # 4. inclusive transmittance, renormalised colour
    weight = a * torch.cumprod(1.0 - a, dim=2)
    rgb = (weight * colour).sum(dim=2) / (weight.sum(dim=2) + 1e-8)
    alpha = 1.0 - torch.prod(1.0 - a, dim=2)
    return torch.cat([rgb * alpha, alpha], dim=1)


def plain_ea(volume: torch.Tensor, views: torch.Tensor) -> torch.Tensor:
    """A plain EA layer: ``affine_grid`` + ``grid_sample`` + ``cumprod``, no tricks (a speed yardstick).

    Our image formation and sample positions (docs/rendering.md): the affine map sends the output
    grid's normalised coordinates g to F M F g, M = [right, up, ω] (columns), F = diag(1, −1, −1)
    (grid_sample's y and z point down and back); exclusive transmittance, no renormalisation.
    """
    b = volume.shape[0]
    right, up, w = camera_frames(views.detach().cpu())
    m = torch.stack([right, up, w], dim=2)                                       # (B, 3, 3), float64
    flip = torch.diag(torch.tensor([1.0, -1.0, -1.0], dtype=torch.float64))
    theta = torch.cat([flip @ m @ flip, torch.zeros(b, 3, 1, dtype=torch.float64)], dim=2)
    grid = F.affine_grid(theta.to(volume.dtype).to(volume.device), list(volume.shape), align_corners=False)
    rotated = F.grid_sample(volume, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    colour, a = rotated[:, :3], rotated[:, 3:]
    t_incl = torch.cumprod(1.0 - a, dim=2)
    t_excl = torch.cat([torch.ones_like(t_incl[:, :, :1]), t_incl[:, :, :-1]], dim=2)
    return torch.cat([(t_excl * a * colour).sum(dim=2), 1.0 - t_incl[:, :, -1]], dim=1)


# --------------------------------------------------------------------------- measuring


def loss_weights(shape: Sequence[int], seed: int) -> torch.Tensor:
    """The fixed random weights W of the loss L = Σ W ⊙ image (standard normal, seeded)."""
    g = torch.Generator().manual_seed(int(seed) + 12345)
    return torch.randn(*shape, generator=g)


def image_error(image: torch.Tensor, reference: torch.Tensor) -> Tuple[float, float]:
    """(RMSE, max |difference|) over every pixel, channel and view."""
    d = (image.detach().double() - reference.detach().double())
    return float(d.pow(2).mean().sqrt()), float(d.abs().max())


def gradient_error(grad: torch.Tensor, reference: torch.Tensor) -> Dict[str, Optional[float]]:
    """Cosine, norm ratio ‖g‖/‖g_ref‖ and relative error ‖g − g_ref‖/‖g_ref‖ of a volume gradient."""
    g, r = grad.detach().double().flatten(), reference.detach().double().flatten()
    nr, ng = float(r.norm()), float(g.norm())
    if nr == 0.0:
        return {"grad_cosine": None, "grad_norm_ratio": None, "grad_rel_err": None}
    cos = float(g @ r) / (ng * nr) if ng > 0 else 0.0
    return {"grad_cosine": cos, "grad_norm_ratio": ng / nr, "grad_rel_err": float((g - r).norm()) / nr}


_LIBC: Any = None


def _release_memory() -> None:
    """Return cached memory to the system: Python's garbage, Dr.Jit's allocation cache, glibc's heap."""
    global _LIBC
    gc.collect()
    if "drjit" in sys.modules:
        import drjit as dr
        dr.sync_thread()
        dr.flush_malloc_cache()
    if _LIBC is None:
        try:
            _LIBC = ctypes.CDLL("libc.so.6")
            _LIBC.malloc_trim.argtypes = [ctypes.c_size_t]
        except (OSError, AttributeError):
            _LIBC = False
    if _LIBC:
        _LIBC.malloc_trim(0)


def _rss_bytes() -> int:
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class PeakRSS:
    """Context manager: the peak RSS increase over the level at entry, sampled by a background thread."""

    def __init__(self, interval: float = 5e-4):
        self.interval, self.peak_increase = interval, 0
        self._stop = threading.Event()

    def _poll(self) -> None:
        while not self._stop.is_set():
            self._peak = max(self._peak, _rss_bytes())
            time.sleep(self.interval)

    def __enter__(self) -> "PeakRSS":
        _release_memory()
        self.baseline = self._peak = _rss_bytes()
        self._thread = threading.Thread(target=self._poll, daemon=True)
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        _sync()
        self._peak = max(self._peak, _rss_bytes())
        self._stop.set()
        self._thread.join()
        self.peak_increase = max(0, self._peak - self.baseline)




def measure_bandwidth(megabytes: int = 256, repeats: int = 5) -> float:
    """Memory bandwidth in bytes/s: the best copy of a ``megabytes`` float32 tensor (read + write)."""
    n = megabytes * (1 << 20) // 4
    src = torch.rand(n)
    dst = torch.empty_like(src)
    dst.copy_(src)                                            # fault the pages in
    t = best_of(lambda: dst.copy_(src), repeats)
    return 2.0 * n * 4 / t


def _traffic_bytes(b: int, c: int, c_img: int, n: int) -> Tuple[int, int]:
    """Bytes a forward and a backward pass must move at least (float32)."""
    vol, img = b * c * n ** 3 * 4, b * c_img * n * n * 4
    return vol + img, 2 * vol + img


def _available_bytes() -> Optional[int]:
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:
        pass
    return None


# --------------------------------------------------------------------------- one row


RenderFn = Callable[[torch.Tensor, torch.Tensor], torch.Tensor]


def _forward_backward(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor,
                      weights: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    x = volume.detach().requires_grad_()
    image = fn(x, views)
    (image * weights).sum().backward()
    return image.detach(), x.grad


def _measure(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor, weights: torch.Tensor,
             repeats: int) -> Dict[str, Any]:
    """Times (best of ``repeats`` after a warm-up), peak memory, and the image and gradient."""
    b = volume.shape[0]

    def fwd():
        with torch.no_grad():
            return fn(volume, views)

    fwd()                                                     # warm-up: kernel compilation, caches
    _sync()
    with PeakRSS() as mem_f:
        fwd()
    t_f = best_of(fwd, repeats)
    _forward_backward(fn, volume, views, weights)             # warm-up of the backward pass
    _sync()
    with PeakRSS() as mem_fb:
        image, grad = _forward_backward(fn, volume, views, weights)
    t_fb = best_of(lambda: _forward_backward(fn, volume, views, weights), repeats)
    return {"fwd_ms": t_f / b * 1e3, "fwd_bwd_ms": t_fb / b * 1e3,
            "mem_fwd_mb": mem_f.peak_increase / _MIB, "mem_fwd_bwd_mb": mem_fb.peak_increase / _MIB,
            "image": image, "grad": grad}


# --------------------------------------------------------------------------- the bench


def _marcher(model: str, options: Dict[str, Any]) -> RenderFn:
    from .render import render
    return lambda v, w: render(v, w, model, "mitsuba", **options)


def _closed_form(model: str) -> RenderFn:
    from .render import render
    return lambda v, w: render(v, w, model, "closed_form", filter="trilinear")


def _physical(spp: int, max_depth: int, seed: int) -> RenderFn:
    from .render import render
    return lambda v, w: render(v, w, "ea", "physical", seed=seed, physical_spp=spp, max_depth=max_depth,
                               lighting="sunsky")


def _reference(fn: RenderFn, volume: torch.Tensor, views: torch.Tensor,
               weights: torch.Tensor) -> Tuple[torch.Tensor, torch.Tensor]:
    """Image and gradient of L of a (slow) reference renderer, one pair at a time (bounded memory)."""
    images, grads = [], []
    for i in range(volume.shape[0]):
        img, g = _forward_backward(fn, volume[i:i + 1], views[i:i + 1], weights[i:i + 1])
        images.append(img)
        grads.append(g)
        _release_memory()
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
    from .render.variant import ensure_variant
    mi = ensure_variant()
    import drjit as dr

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
                result["train"] = _bench_train(min(s.resolutions), s.train_width, s.batch, 1, 1, log)
            else:
                result["train"] = _bench_train(s.train_resolution, s.train_width, s.train_batch, s.train_steps,
                                               s.train_warmup, log)
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
    traffic = _traffic_bytes(b, CHANNELS[model], c_img, n)
    t0 = time.perf_counter()
    ref_image, ref_grad = _reference(_marcher(model, REFERENCE_OPTIONS), volume, views, weights)
    with torch.no_grad():
        closed = _closed_form(model)(volume, views)
    log(f"{n}³ {model}: reference (marcher step 0.25, spp 16) in {time.perf_counter() - t0:.1f} s")

    rows: List[Dict[str, Any]] = []

    def add(row: Dict[str, Any], fn: RenderFn, ref: Tuple[torch.Tensor, torch.Tensor],
            vs_closed: bool = True) -> None:
        try:
            m = _measure(fn, volume, views, weights, repeats)
        except (ValueError, RuntimeError, MemoryError) as e:   # e.g. the marcher's record limit
            row["skipped"] = f"{type(e).__name__}: {e}"
            log(f"{n}³ {model}: {row['config']}: skipped ({row['skipped']})")
            rows.append(row)
            return
        _fill(row, m, ref[0], ref[1], closed if vs_closed else None, traffic, bandwidth)
        del m
        _release_memory()
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
    need, avail = _authors_bytes_estimate(b, n), _available_bytes()
    if avail is not None and need > 0.6 * avail:
        row["skipped"] = (f"needs about {need / 2**30:.1f} GiB, {avail / 2**30:.1f} GiB available; "
                          f"use a smaller batch")
        log(f"{n}³ ea: {row['config']}: skipped ({row['skipped']})")
        rows.append(row)
    else:
        add(row, authors_ea, ref)

    if not s.physical or n > s.physical_max_resolution:
        return rows
    t0 = time.perf_counter()
    # one call for the whole batch: the path tracer draws pair b's sky as the b-th draw from the seed
    phys_ref = _forward_backward(_physical(ref_spp, s.physical_max_depth, s.seed), volume, views, weights)
    _release_memory()
    log(f"{n}³ ea: path-traced reference (spp {ref_spp}) in {time.perf_counter() - t0:.1f} s")
    for spp in _physical_spps(s.quick):
        add(_row(n, b, model, "physical", f"path tracer spp {spp}",
                 {"physical_spp": spp, "max_depth": s.physical_max_depth, "lighting": "sunsky", "seed": s.seed},
                 formation="physical", reference=f"path tracer spp {ref_spp}, same scene, views and sky"),
            _physical(spp, s.physical_max_depth, s.seed), phys_ref, vs_closed=False)
    return rows


def _bench_train(r: int, width: int, batch: int, steps: int, warmup: int,
                 log: Callable[[str], None]) -> List[Dict[str, Any]]:
    """Training images/s per renderer (reconstruction, EA, one random view per volume)."""
    import drjit as dr

    from .config import load_config
    from .train.data import TrainingData
    from .train.run import training_threads
    from .train.trainer import Trainer

    g = torch.Generator().manual_seed(0)
    data = TrainingData(torch.rand(64, 4, r, r, generator=g) * 0.5, torch.zeros(0, 4, r, r))
    renderers = [("closed_form", "closed form", []), ("mitsuba", "marcher default", []),
                 ("physical", "path tracer spp 1, depth 2", ["render.physical_spp=1", "render.max_depth=2"])]
    rows: List[Dict[str, Any]] = []
    base = None
    for backend, label, extra in renderers:
        row: Dict[str, Any] = {"renderer": backend, "config": label, "overrides": extra, "resolution": r,
                               "width": width, "batch": batch, "steps": steps, "warmup_steps": warmup,
                               "skipped": None}
        try:
            cfg = load_config(None, [f"model.resolution={r}", f"model.width={width}", f"train.batch_size={batch}",
                                     f"render.backend={backend}", "render.model=ea", "data.formation=ea", *extra])
            trainer = Trainer(cfg, data, torch.device("cpu"))
            with training_threads(cfg):                       # as a training run sets them (run.drjit_threads)
                row["drjit_threads"] = None if backend == "closed_form" else dr.thread_count()
                for step in range(warmup):
                    trainer.step(step)
                t0 = time.perf_counter()
                for step in range(warmup, warmup + steps):
                    trainer.step(step)
                per_step = (time.perf_counter() - t0) / steps
        except (ValueError, RuntimeError, TypeError, KeyError) as e:
            row["skipped"] = f"{type(e).__name__}: {e}"
            log(f"train {label}: skipped ({row['skipped']})")
            rows.append(row)
            continue
        rate = batch * 2 / per_step                            # the random view and the input view
        base = base or rate
        row.update({"s_per_step": per_step, "images_per_s": rate, "vs_closed_form": rate / base})
        rows.append(row)
        log(f"train {label}: {per_step:.3f} s/step, {rate:.1f} images/s")
    return rows


# --------------------------------------------------------------------------- outputs


def _fmt(x: Any, spec: str) -> str:
    return "–" if x is None else format(x, spec)


def _config_name(row: Dict[str, Any]) -> str:
    return f"**{row['config']}**" if row.get("default") else row["config"]


def markdown_tables(result: Dict[str, Any], plot_dir: Optional[str] = None) -> str:
    """The measured rows as Markdown: one table per resolution and model, then training speed.

    ``plot_dir``: a relative folder to link the Pareto plots from (None: no links).
    """
    meta = result["meta"]
    lines = [
        f"Measured {meta['started']} on {meta['machine']} ({meta['cpu_count']} CPUs; torch {meta['torch']} with "
        f"{meta['torch_threads']} threads, Mitsuba {meta['mitsuba']} `{meta['variant']}` with "
        f"{meta['drjit_threads']} Dr.Jit threads); batch {meta['settings']['batch']} of random views, "
        f"built-in volume `{meta['settings']['volume']}`, best of {meta['repeats_used']} after a warm-up; "
        f"memory bandwidth (tensor copy) {meta['bandwidth_gb_s']:.2f} GB/s; the whole run took "
        f"{meta.get('duration_s', 0.0) / 60:.1f} min.",
        "",
        "Times are per image. *mem*: peak RSS increase of a forward+backward call. *RMSE*, *max*: image error "
        "against the reference (the marcher at step 0.25, spp 16, regular); *cos*, *rel*: cosine and relative "
        "error ‖g − g_ref‖/‖g_ref‖ of the gradient of a random-weighted loss; *bound*: the memory-traffic lower "
        "bound of forward+backward, and the measured time over it. The default is in bold. The authors' layer "
        "and the path tracer are other image formations: the first is compared with our reference, the second "
        f"with itself at spp {meta['physical_ref_spp_used']} (measured up to "
        f"{meta['settings'].get('physical_max_resolution', 64)}³).",
        "",
    ]
    rows = result["rows"]
    keys: List[Tuple[int, str]] = []
    for r in rows:
        if (r["resolution"], r["model"]) not in keys:
            keys.append((r["resolution"], r["model"]))
    for n, model in keys:
        lines += [f"### {model.upper()} at {n}³", "",
                  "| configuration | fwd ms | f+b ms | mem MB | RMSE | max | cos | rel | bound ms | ×bound |",
                  "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for r in rows:
            if (r["resolution"], r["model"]) != (n, model):
                continue
            if r.get("skipped"):
                lines.append(f"| {_config_name(r)} | skipped: {r['skipped']} |||||||||")
                continue
            lines.append(
                f"| {_config_name(r)} | {_fmt(r['fwd_ms'], '.3f')} | {_fmt(r['fwd_bwd_ms'], '.3f')} | "
                f"{_fmt(r['mem_fwd_bwd_mb'], '.1f')} | {_fmt(r['rmse'], '.2e')} | {_fmt(r['max_abs'], '.2e')} | "
                f"{_fmt(r['grad_cosine'], '.5f')} | {_fmt(r['grad_rel_err'], '.2e')} | "
                f"{_fmt(r['bound_fwd_bwd_ms'], '.4f')} | {_fmt(r['fwd_bwd_over_bound'], '.0f')} |")
        if plot_dir is not None:
            lines += ["", f"![{model.upper()} {n}³: image error vs time]({plot_dir}/pareto_{model}_{n}.png)"]
        lines.append("")
    if result.get("train"):
        t = result["train"][0]
        lines += [f"### Training speed (reconstruction, EA, {t['resolution']}³, width {t['width']}, batch "
                  f"{t['batch']}, {t['steps']} steps after {t['warmup_steps']} warm-up)", "",
                  "| renderer | Dr.Jit threads | s/step | images/s | vs closed form |", "|---|---:|---:|---:|---:|"]
        for t in result["train"]:
            threads = "—" if t.get("drjit_threads") is None else t["drjit_threads"]
            if t.get("skipped"):
                lines.append(f"| {t['config']} | {threads} | skipped: {t['skipped']} |||")
            else:
                lines.append(f"| {t['config']} | {threads} | {t['s_per_step']:.3f} | {t['images_per_s']:.1f} | "
                             f"{t['vs_closed_form']:.2f}× |")
        lines.append("")
    return "\n".join(lines)


def _place_labels(ax, points: List[Tuple[float, float, str, str]], fontsize: float = 7.0) -> None:
    """Label each (x, y, text, colour) point without overlaps: a label that would cover one already
    placed moves up in steps of one line, with a leader line back to its point."""
    fig = ax.figure
    fig.canvas.draw()                                         # fixes the axes' transforms
    to_px = ax.transData.transform
    line = fontsize * 1.35 * fig.dpi / 72.0
    char = fontsize * 0.55 * fig.dpi / 72.0
    placed: List[Tuple[float, float, float, float]] = []
    for x, y, text, colour in sorted(points, key=lambda p: (to_px((p[0], p[1]))[1], to_px((p[0], p[1]))[0])):
        px, py = to_px((x, y))
        x0, y0 = px + 6.0, py + 2.0
        w = char * len(text)
        shift = 0
        while any(x0 < bx1 and bx0 < x0 + w and y0 + shift * line < by1 and by0 < y0 + (shift + 1) * line
                  for bx0, by0, bx1, by1 in placed) and shift < 40:
            shift += 1
        box = (x0, y0 + shift * line, x0 + w, y0 + (shift + 1) * line)
        placed.append(box)
        ax.annotate(text, (x, y), xytext=(6.0 * 72.0 / fig.dpi, (2.0 + shift * line) * 72.0 / fig.dpi),
                    textcoords="offset points", fontsize=fontsize, color=colour, va="bottom",
                    arrowprops=dict(arrowstyle="-", color="0.6", lw=0.5) if shift else None)


def _log_axes(ax, xs: Sequence[float], ys: Sequence[float]) -> None:
    """Log-log axes spanning the data with room for labels (at least a factor 4 on each axis),
    ticks at 1, 2, 5 × 10^k labelled in plain numbers."""
    from matplotlib.ticker import FuncFormatter, LogLocator, NullFormatter

    ax.set_xscale("log")
    ax.set_yscale("log")
    for values, setter, axis, room in ((xs, ax.set_xlim, ax.xaxis, (1.25, 2.2)), (ys, ax.set_ylim, ax.yaxis, (1.4, 1.6))):
        if not values:
            continue
        lo, hi = min(values) / room[0], max(values) * room[1]
        if hi / lo < 4.0:
            mid = math.sqrt(lo * hi)
            lo, hi = mid / 2.0, mid * 2.0
        setter(lo, hi)
        axis.set_major_locator(LogLocator(base=10.0, subs=(1.0, 2.0, 5.0)))
        axis.set_major_formatter(FuncFormatter(lambda v, _: f"{v:g}"))
        axis.set_minor_formatter(NullFormatter())
    ax.grid(True, which="major", alpha=0.3)
    ax.grid(True, which="minor", alpha=0.1)


def pareto_plot(rows: List[Dict[str, Any]], path: Path, title: str) -> Path:
    """Image RMSE vs forward+backward ms per image (log-log) of one (resolution, model).

    Left: our image formation (closed form, marcher configurations, plain layer) against the
    converged reference, with its Pareto front (no other point is both faster and more accurate).
    Right, when present: the other image formations (the authors' layer against our reference, the
    path tracer against its own high-spp render), on their own axes.
    """
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure
    from matplotlib.lines import Line2D

    done = [r for r in rows if not r.get("skipped") and r.get("rmse") is not None]
    ours = [r for r in done if r["formation"] == "ours"]
    others = [r for r in done if r["formation"] != "ours"]
    floor = 1e-9                                              # log axes: an exact 0 is drawn here
    fig = Figure(figsize=(12.0 if others else 8.5, 6.0), dpi=110)
    FigureCanvasAgg(fig)
    if others:
        gs = fig.add_gridspec(1, 2, width_ratios=[2.6, 1.0])
        ax, ax2 = fig.add_subplot(gs[0, 0]), fig.add_subplot(gs[0, 1])
    else:
        ax, ax2 = fig.add_subplot(1, 1, 1), None
    labels = []
    for r in ours:
        x, y = r["fwd_bwd_ms"], max(r["rmse"], floor)
        if r.get("default"):
            ax.scatter([x], [y], marker="*", s=260, color="tab:red", zorder=4)
        elif r["renderer"] == "closed_form":
            ax.scatter([x], [y], marker="s", s=60, color="tab:green", zorder=3)
        elif r["renderer"] == "plain":
            ax.scatter([x], [y], marker="D", s=45, color="tab:purple", zorder=3)
        else:
            ax.scatter([x], [y], marker="o", s=40, color="tab:blue", zorder=3)
        labels.append((x, y, r["config"], "black"))
    pts = sorted((r["fwd_bwd_ms"], max(r["rmse"], floor)) for r in ours)
    front, best = [], float("inf")
    for x, y in pts:
        if y < best:
            front.append((x, y))
            best = y
    if len(front) > 1:
        ax.plot([p[0] for p in front], [p[1] for p in front], color="tab:blue", alpha=0.35, lw=1.5, zorder=1,
                drawstyle="steps-post")
    for a, sel in ((ax, ours), (ax2, others)):
        if a is not None:
            _log_axes(a, [r["fwd_bwd_ms"] for r in sel], [max(r["rmse"], floor) for r in sel])
            a.set_xlabel("forward + backward, ms per image")
    ax.set_ylabel("image RMSE vs reference (marcher step 0.25, spp 16)")
    ax.set_title(title, fontsize=10)
    handles = [Line2D([], [], marker="*", ls="", color="tab:red", ms=14, label="marcher default"),
               Line2D([], [], marker="o", ls="", color="tab:blue", label="marcher, one option varied"),
               Line2D([], [], marker="s", ls="", color="tab:green", label="closed form (reference mode)"),
               Line2D([], [], color="tab:blue", alpha=0.35, lw=1.5, label="Pareto front")]
    if any(r["renderer"] == "plain" for r in ours):
        handles.insert(3, Line2D([], [], marker="D", ls="", color="tab:purple", label="plain layer"))
    if any(r["rmse"] < floor for r in ours):
        handles.append(Line2D([], [], ls="", label=f"RMSE 0 drawn at {floor:g}"))
    ax.legend(handles=handles, fontsize=7, loc="upper center", bbox_to_anchor=(0.5, -0.11), ncol=3, frameon=False)
    if ax2 is not None:
        for r in others:
            x, y = r["fwd_bwd_ms"], max(r["rmse"], floor)
            ax2.scatter([x], [y], marker="o", s=40, facecolors="none", edgecolors="dimgrey", zorder=3)
        ax2.set_title("other image formations\nauthors' layer: vs our reference\n"
                      "path tracer: vs its own high-spp render", fontsize=8)
        ax2.set_ylabel("image RMSE vs its reference")
        fig.tight_layout()
        _place_labels(ax2, [(r["fwd_bwd_ms"], max(r["rmse"], floor), r["config"], "dimgrey") for r in others])
    fig.tight_layout()
    _place_labels(ax, labels)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    return path


def write_outputs(result: Dict[str, Any], out: Path) -> Dict[str, Any]:
    """Write ``bench.json``, ``bench.md`` and the Pareto plots into ``out``; return their paths."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    js = out / "bench.json"
    js.write_text(json.dumps(result, indent=1, allow_nan=False))
    plots = []
    keys = []
    for r in result["rows"]:
        if (r["resolution"], r["model"]) not in keys:
            keys.append((r["resolution"], r["model"]))
    for n, model in keys:
        sel = [r for r in result["rows"] if (r["resolution"], r["model"]) == (n, model)]
        plots.append(pareto_plot(sel, out / f"pareto_{model}_{n}.png",
                                 f"{model.upper()} at {n}³, batch {result['meta']['settings']['batch']}: "
                                 f"image error vs forward+backward time"))
    md = out / "bench.md"
    md.write_text("# platonic bench\n\n" + markdown_tables(result, plot_dir=".") + "\n")
    return {"json": js, "markdown": md, "plots": plots}


def write_doc(result: Dict[str, Any], doc: Path, plots: Sequence[Path]) -> Path:
    """Replace the generated section of ``doc`` (between :data:`DOC_BEGIN` and :data:`DOC_END`) with
    the tables, and copy the plots into ``<doc folder>/<doc stem>/`` to link them from there."""
    doc = Path(doc)
    text = doc.read_text()
    if DOC_BEGIN not in text or DOC_END not in text:
        raise ValueError(f"{doc} has no generated section: it needs the lines {DOC_BEGIN!r} and {DOC_END!r}")
    folder = doc.parent / doc.stem
    folder.mkdir(parents=True, exist_ok=True)
    for p in plots:
        shutil.copyfile(p, folder / Path(p).name)
    head, rest = text.split(DOC_BEGIN, 1)
    _, tail = rest.split(DOC_END, 1)
    body = markdown_tables(result, plot_dir=doc.stem)
    doc.write_text(f"{head}{DOC_BEGIN}\n\n{body}\n{DOC_END}{tail}")
    return doc
