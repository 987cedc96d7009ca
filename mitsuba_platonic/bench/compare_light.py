"""Single scattering vs Mitsuba: the ``scatter_march`` formation against ``volpath`` at depth 2.

The light counterpart of :mod:`mitsuba_platonic.bench.compare`. A volume is rendered under a sun and a
uniform sky (:class:`~mitsuba_platonic.render.pytorch.single_scatter.SunAndSky`) by
:func:`~mitsuba_platonic.render.drjit.scatter_march.render_scatter_march` and by Mitsuba's ``volpath`` with
``max_depth`` 2 (:func:`~mitsuba_platonic.render.mitsuba.single_scatter_reference.reference_render`: the same medium, single
scattering, Monte Carlo) in ``R`` independent renders of ``spp`` samples each. Per case:

- ``rel_total`` = (Σ I − Σ Ī) / Σ Ī over the RGB pixels, Ī the mean of the ``R`` volpath renders;
- per 4 × 4 pixel block b and channel, z_b = (I_b − Ī_b) / s_b with s_b the standard error of the
  ``R`` renders' block means; ``z2`` = mean z_b² and ``beyond_3se`` = the share of |z_b| > 3.
  Were the formation exact, z_b would follow Student's t with R − 1 degrees of freedom:
  E[z²] = (R − 1)/(R − 3) and a share 2 (1 − F_t(3; R − 1)) beyond 3 (``expected_z2``,
  ``expected_beyond_3se``). s_b is floored at 10⁻³ of the brightest block (``SE_FLOOR``): where
  no volpath path scattered, s_b = 0;
- ``max_abs``: the largest |I − Ī| of a pixel's R, G or B (the opacities are not compared: volpath's
  alpha is not α = 1 − e^{−τ});
- ``grad_fd_rel``: the gradient of L = Σ W ⊙ I (W random, fixed) along a random direction d ≥ 0
  against the one-sided second-order difference (−3 L(v) + 4 L(v + εd) − L(v + 2εd)) / 2ε,
  ε = 10⁻³, d zero on voxels above 1 − 2ε (so every difference stays inside [0, 1]): the relative
  error |⟨∇L, d⟩ − FD| / max(|FD|, 10⁻¹²); ``grad_finite``: every gradient entry finite;
- ``ours_ms`` / ``volpath_ms``: forward time per image, the best of ``repeats`` calls after a
  warm-up (:func:`~.timing.time_render`) / the fastest of volpath's renders of ``spp`` each.

The cases (:func:`light_cases`): the volume from each view under a random daylight
(:func:`~.single_scatter.sample_sun_and_sky`, seeded), then the extremes: a cube of exact
1s and 0s (opaque voxels beside empty ones), an empty volume, the volume under a sun at the horizon,
a sun behind the camera, a sun behind the object (back light) and the sky alone. docs/rendering.md,
"Single scattering at the marcher's speed", gives the figures and what the residuals are.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Dict, List, Optional, Sequence, Union

import numpy as np
import torch
import torch.nn.functional as F

from ..errors import UserError
from ..files.fileio import atomic_write, make_folder, write_text
from ..images import linear_to_srgb
from ..runtime.progress import progress_bar
from ..views import front_view
from .timing import time_render
from ..render.mitsuba.single_scatter_reference import reference_render
from ..render.pytorch.single_scatter import SunAndSky, sample_sun_and_sky

__all__ = ["LightCase", "light_cases", "compare_light", "format_light_table", "write_light_summary",
           "light_figure", "block_z", "BLOCK", "FD_EPSILON", "SE_FLOOR"]

#: Pixel block side for the per-block z statistics.
BLOCK = 4
#: s_b's floor, relative to the brightest block of the volpath mean.
SE_FLOOR = 1e-3
#: The finite-difference step (in volume units).
FD_EPSILON = 1e-3


@dataclass
class LightCase:
    """One comparison: a ``(1, 4, N, N, N)`` volume, a ``(1, 3)`` view and its light."""

    name: str
    volume: torch.Tensor
    view: torch.Tensor
    light: SunAndSky


def _cube(n: int) -> torch.Tensor:
    """A cube of exact 1s (the middle half of each axis) in exact 0s, two colours (orange top, blue bottom)."""
    i = torch.arange(n)
    inside = (i >= n // 4) & (i < n - n // 4)
    v = (inside[:, None, None] & inside[None, :, None] & inside[None, None, :]).float()
    top = (i < n // 2).float()[None, :, None].expand(n, n, n)      # H runs top to bottom
    rgb = torch.stack([0.2 + 0.7 * top, 0.5 * torch.ones_like(v), 0.9 - 0.7 * top])
    return torch.cat([rgb * v, v[None]])[None]


def light_cases(volume: torch.Tensor, views: torch.Tensor, seed: int = 0) -> List[LightCase]:
    """The volume from each of ``views`` under a random daylight (pair i's from ``(seed, i)``), then
    the extreme cases (module docstring), from the front view unless said otherwise."""
    if volume.dim() == 4:
        volume = volume[None]
    if volume.dim() != 5 or volume.shape[:2] != (1, 4):
        raise UserError(f"volume: expected (4, N, N, N) or (1, 4, N, N, N) [r, g, b, density], "
                        f"got {tuple(volume.shape)}")
    n = volume.shape[-1]
    front = front_view(1).to(torch.float32)
    cases = [LightCase(f"view {i}, random daylight", volume, views[i:i + 1].to(torch.float32),
                       sample_sun_and_sky(np.random.default_rng([seed, i]))) for i in range(len(views))]
    oblique = tuple(x / math.sqrt(0.98) for x in (0.3, 0.8, 0.5))
    sun, sky = (math.pi,) * 3, (0.25,) * 3
    f = tuple(float(x) for x in front[0])
    cases += [
        LightCase("opaque voxels (a cube of 1s in 0s)", _cube(n), front, SunAndSky(oblique, sun, sky)),
        LightCase("empty volume", torch.zeros(1, 4, n, n, n), front, SunAndSky(oblique, sun, sky)),
        LightCase("sun at the horizon", volume, front, SunAndSky((1.0, 0.0, 0.0), sun, (0.0,) * 3)),
        LightCase("sun behind the camera", volume, front, SunAndSky(f, sun, (0.0,) * 3)),
        LightCase("sun behind the object", volume, front, SunAndSky(tuple(-x for x in f), sun, (0.0,) * 3)),
        LightCase("sky alone", volume, front, SunAndSky(oblique, (0.0,) * 3, sky)),
    ]
    return cases


def _blocks(image: torch.Tensor) -> torch.Tensor:
    return F.avg_pool2d(image[:, :3].double(), BLOCK)


def block_z(image: torch.Tensor, renders: torch.Tensor) -> torch.Tensor:
    """z per :data:`BLOCK` × :data:`BLOCK` block and R, G, B channel of ``image`` ``(C ≥ 3, H, W)``
    against ``renders`` ``(R, C, H, W)``: (I_b − Ī_b) / s_b, s_b the standard error of the renders'
    block means, floored at :data:`SE_FLOOR` of the brightest block; ``(3, H/4, W/4)``."""
    block_means = _blocks(renders)                                # (R, 3, H/4, W/4)
    mean = block_means.mean(0)
    se = block_means.std(0) / math.sqrt(renders.shape[0])
    floor = SE_FLOOR * float(mean.abs().max())                    # blocks no volpath path reached
    return (_blocks(image[None])[0] - mean) / se.clamp_min(max(floor, 1e-300))


def _gradient_check(volume: torch.Tensor, render_fn, seed: int) -> Dict[str, Any]:
    """``grad_finite`` and ``grad_fd_rel`` of L = Σ W ⊙ I along d ≥ 0 (module docstring)."""
    g = torch.Generator().manual_seed(seed)
    v = volume.detach().to(torch.float32).clone().requires_grad_()
    image = render_fn(v)
    w = torch.rand(image.shape, generator=g, dtype=image.dtype)
    (image * w).sum().backward()
    grad = v.grad
    d = torch.rand(v.shape, generator=g) * (v.detach() <= 1.0 - 2.0 * FD_EPSILON)
    with torch.no_grad():
        loss = [float((render_fn(v.detach() + k * FD_EPSILON * d).double() * w.double()).sum()) for k in (0, 1, 2)]
    fd = (-3.0 * loss[0] + 4.0 * loss[1] - loss[2]) / (2.0 * FD_EPSILON)
    analytic = float((grad.double() * d.double()).sum())
    return {"grad_finite": bool(torch.isfinite(grad).all()), "grad_directional": analytic, "grad_fd": fd,
            "grad_fd_rel": abs(analytic - fd) / max(abs(fd), 1e-12)}


def _t_beyond(k: float, dof: int) -> float:
    """2 (1 − F_t(k; dof)): the share of Student's t beyond ±k."""
    from scipy.stats import t as student_t   # lazy: scipy only where the comparison runs
    return float(2.0 * student_t.sf(k, dof))


def compare_light(cases: Sequence[LightCase], spp: int = 128, renders: int = 8, steps_per_voxel: int = 2,
                  ours_spp: int = 1, seed: int = 0, repeats: int = 3, progress: bool = True) -> List[Dict[str, Any]]:
    """Each case through ``scatter_march`` and through ``volpath`` at depth 2 (``renders`` × ``spp``);
    one dict per case with the figures of the module docstring, the images ``ours`` and ``volpath``
    (the renders' mean), ``(4, H, W)``, and ``z`` per block, ``(3, H/4, W/4)``."""
    from ..render.drjit.scatter_march import render_scatter_march    # imports Dr.Jit: on first use

    for name, value, least in (("spp", spp, 1), ("renders", renders, 4)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise UserError(f"{name}: expected an int ≥ {least}, got {value!r}")
    bar = progress_bar(len(cases) * (renders + 1), unit="render", desc="single scattering vs volpath",
                       disable=not progress)
    results = []
    try:
        for c, case in enumerate(cases):
            lights = [case.light]

            def ours(v: torch.Tensor) -> torch.Tensor:
                return render_scatter_march(v, case.view, lights, exposure="none",
                                            steps_per_voxel=steps_per_voxel, spp=ours_spp)

            image, seconds = time_render(lambda: ours(case.volume.to(torch.float32)), repeats)
            image, ours_ms = image[0].double(), 1e3 * seconds
            grads = _gradient_check(case.volume, ours, seed + c)
            bar.update(1)
            refs, volpath_ms = [], math.inf
            for r in range(renders):
                t0 = time.perf_counter()
                refs.append(reference_render(case.volume, case.view, lights, spp=spp, seed=1000 * seed + 97 * c + r,
                                             exposure="none")[0].double())
                volpath_ms = min(volpath_ms, 1e3 * (time.perf_counter() - t0))   # the first compiles
                bar.update(1)
            refs_t = torch.stack(refs)
            mean = refs_t.mean(0)
            z = block_z(image, refs_t)
            total = float(mean[:3].sum())
            results.append({
                "case": case.name, "resolution": case.volume.shape[-1], "view": case.view[0].tolist(),
                "sun_direction": list(case.light.sun_direction), "sun_irradiance": list(case.light.sun_irradiance),
                "sky_radiance": list(case.light.sky_radiance),
                "rel_total": (float(image[:3].sum()) - total) / total if total > 0 else
                             (0.0 if float(image[:3].abs().sum()) == 0 else math.inf),
                "z2": float((z ** 2).mean()), "beyond_3se": float((z.abs() > 3).double().mean()),
                "max_abs": float((image[:3] - mean[:3]).abs().max()),
                "ours_ms": ours_ms, "volpath_ms": volpath_ms, **grads,
                "ours": image.float(), "volpath": mean.float(),
                "z": z.float(),
            })
    finally:
        bar.close()
    dof = renders - 1
    for r in results:
        r["expected_z2"] = dof / (dof - 2) if dof > 2 else math.inf
        r["expected_beyond_3se"] = _t_beyond(3.0, dof)
    return results


#: The keys of a result that ``compare_light.json`` keeps (the images stay out).
LIGHT_SUMMARY_KEYS = ("case", "resolution", "view", "sun_direction", "sun_irradiance", "sky_radiance", "rel_total",
                      "z2", "expected_z2", "beyond_3se", "expected_beyond_3se", "max_abs", "grad_finite",
                      "grad_directional", "grad_fd", "grad_fd_rel", "ours_ms", "volpath_ms")


def write_light_summary(path: Union[str, Path], volume: str, settings: Dict[str, Any],
                        results: Sequence[Dict[str, Any]]) -> Path:
    """``compare_light.json``: the volume's name, the settings and each result's :data:`LIGHT_SUMMARY_KEYS`."""
    path = Path(path)
    clean = lambda x: None if isinstance(x, float) and not math.isfinite(x) else x  # noqa: E731
    write_text(path, json.dumps({"volume": volume, "settings": settings,
                                 "results": [{k: clean(r[k]) for k in LIGHT_SUMMARY_KEYS} for r in results]},
                                indent=2))
    return path


def format_light_table(results: Sequence[Dict[str, Any]]) -> str:
    """A plain-text table: case | Σ rel. | mean z² (exact: …) | beyond 3 SE | max |diff| | FD rel. |
    finite | ours ms | volpath ms."""
    header = ("case", "total rel.", "mean z²", "beyond 3 SE", "max |diff|", "grad vs FD", "finite",
              "ours ms", "volpath ms/render")
    rows = [(r["case"], f"{100 * r['rel_total']:+.1f} %", f"{r['z2']:.1f}", f"{100 * r['beyond_3se']:.0f} %",
             f"{r['max_abs']:.2e}", f"{r['grad_fd_rel']:.1e}", "yes" if r["grad_finite"] else "NO",
             f"{r['ours_ms']:.0f}", f"{r['volpath_ms']:.0f}") for r in results]
    widths = [max(len(h), *(len(row[i]) for row in rows)) if rows else len(h) for i, h in enumerate(header)]
    line = lambda cells: " | ".join(c.ljust(w) if i == 0 else c.rjust(w)  # noqa: E731
                                    for i, (c, w) in enumerate(zip(cells, widths)))
    out = [line(header), "-+-".join("-" * w for w in widths)] + [line(r) for r in rows]
    if results:
        r = results[0]
        out.append(f"(an exact formation: mean z² {r['expected_z2']:.2f}, {100 * r['expected_beyond_3se']:.1f} % "
                   f"beyond 3 SE, from the volpath renders' own spread)")
    return "\n".join(out)


def light_figure(results: Sequence[Dict[str, Any]], path: Union[str, Path], title: str) -> Path:
    """One row per case: ours | volpath's mean (linear RGB over black, both scaled by the volpath
    image's 99th percentile, shown in sRGB) | z per 4 × 4 block (max over R, G, B by magnitude;
    blue below, red above, ±5 at full colour)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg  # lazy: matplotlib is slow to import
    from matplotlib.figure import Figure

    path = Path(path)
    fig = Figure(figsize=(9.0, 2.6 * len(results) + 0.8), layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(len(results), 3, squeeze=False)
    for i, r in enumerate(results):
        ref = r["volpath"][:3].double()
        scale = float(torch.quantile(ref.flatten(), 0.99)) or 1.0
        show = lambda im: linear_to_srgb(np.clip(im[:3].double().permute(1, 2, 0).numpy() / scale, 0.0, 1.0))  # noqa: E731
        axes[i, 0].imshow(show(r["ours"]), interpolation="nearest")
        axes[i, 1].imshow(show(r["volpath"]), interpolation="nearest")
        z = r["z"]
        worst = z.gather(0, z.abs().argmax(0, keepdim=True))[0]
        im = axes[i, 2].imshow(worst.numpy(), cmap="RdBu_r", vmin=-5.0, vmax=5.0, interpolation="nearest")
        fig.colorbar(im, ax=axes[i, 2], fraction=0.046, pad=0.04).set_label("z per block")
        axes[i, 0].set_ylabel(r["case"], fontsize=9)
        axes[i, 2].set_title(f"total {100 * r['rel_total']:+.1f} %, mean z² {r['z2']:.1f}", fontsize=8)
        for ax in axes[i]:
            ax.set_xticks([])
            ax.set_yticks([])
    axes[0, 0].set_title("scatter_march", fontsize=10)
    axes[0, 1].set_title("volpath, max_depth 2", fontsize=10)
    fig.suptitle(title, fontsize=10)
    make_folder(path.parent)
    atomic_write(path, lambda tmp: fig.savefig(tmp, dpi=90))      # whole, and never through a link
    return path
